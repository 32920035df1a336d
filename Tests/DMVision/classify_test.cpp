// Classifiers behind dm::Classifier, cross-validation, confusion matrices and
// the UCI letter loader; accuracies on the UCI letter data (opencv-doc) with
// OpenCV's letter_recog split (first 16000 train, last 4000 test).
#include <dm/core/filesystem.hpp>
#include <dm/vision/classify.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

namespace {

// Three well-separated 2-D Gaussian classes (σ = 1, centres 8 apart): the
// Bayes error is below 0.01 %, so any reasonable classifier is near 100 %.
dm::Dataset blobs(int perClass, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> g(0.0f, 1.0f);
  const float centres[3][2] = {{0, 0}, {8, 0}, {4, 7}};
  dm::Dataset d;
  d.dims = 2;
  for (int i = 0; i < perClass; ++i)
    for (int c = 0; c < 3; ++c) {
      d.features.push_back(centres[c][0] + g(rng));
      d.features.push_back(centres[c][1] + g(rng));
      d.labels.push_back(10 * c + 5);  // labels need not be 0..n−1
    }
  return d;
}

TEST(LetterData, ParsesRowsAndNamesBadFields) {
  auto d = dm::parseLetterData("T,2,8,3\r\nA,0,15,1\n\nZ,1,1,1", "mem");
  ASSERT_TRUE(d) << d.error();
  EXPECT_EQ(d->dims, 3);
  ASSERT_EQ(d->size(), 3u);
  EXPECT_EQ(d->labels, (std::vector<int>{19, 0, 25}));
  EXPECT_EQ(d->sample(1)[1], 15.0f);

  auto badLabel = dm::parseLetterData("A,1,2\nt,1,2\n", "letters.data");
  ASSERT_FALSE(badLabel);
  EXPECT_EQ(badLabel.error().code, dm::ErrorCode::Parse);
  EXPECT_NE(badLabel.error().where.find("letters.data: line 2, field 1, byte 6"), std::string::npos)
      << badLabel.error().where;
  auto badValue = dm::parseLetterData("A,1,2\nB,1,x3\n", "f");
  ASSERT_FALSE(badValue);
  EXPECT_NE(badValue.error().where.find("line 2, field 3, byte 10"), std::string::npos)
      << badValue.error().where;
  auto overflow = dm::parseLetterData("A,99999999999\n");
  ASSERT_FALSE(overflow);
  EXPECT_NE(overflow.error().where.find("field 2"), std::string::npos);
  auto count = dm::parseLetterData("A,1,2\nB,1,2,3\n");
  ASSERT_FALSE(count);
  EXPECT_NE(count.error().what.find("3 features where earlier rows have 2"), std::string::npos);
  EXPECT_FALSE(dm::parseLetterData(""));
  EXPECT_FALSE(dm::parseLetterData("A\n"));
  EXPECT_FALSE(dm::parseLetterData("A,,1\n"));
  EXPECT_FALSE(dm::parseLetterData("AB,1\n"));
  EXPECT_FALSE(dm::readLetterData("/nonexistent/letters.data"));
}

TEST(Confusion, CountsTruthAgainstPrediction) {
  const std::vector<int> truth = {1, 1, 1, 2, 2, 7};
  const std::vector<int> pred = {1, 2, 1, 2, 7, 7};
  auto m = dm::confusionMatrix(truth, pred);
  ASSERT_TRUE(m) << m.error();
  EXPECT_EQ(m->classes, (std::vector<int>{1, 2, 7}));
  EXPECT_EQ(m->at(1, 1), 2u);
  EXPECT_EQ(m->at(1, 2), 1u);
  EXPECT_EQ(m->at(2, 2), 1u);
  EXPECT_EQ(m->at(2, 7), 1u);
  EXPECT_EQ(m->at(7, 7), 1u);
  EXPECT_EQ(m->at(7, 1), 0u);
  EXPECT_EQ(m->at(3, 3), 0u);
  EXPECT_DOUBLE_EQ(m->accuracy(), 4.0 / 6.0);
  EXPECT_FALSE(dm::confusionMatrix(truth, std::vector<int>{1}));
}

TEST(Classifier, EveryKindSeparatesGaussianBlobs) {
  const dm::Dataset train = blobs(100, 1), test = blobs(100, 2);
  for (auto kind : {dm::ClassifierKind::KNearest, dm::ClassifierKind::NormalBayes, dm::ClassifierKind::SvmRbf,
                    dm::ClassifierKind::Lda, dm::ClassifierKind::PcaKnn}) {
    SCOPED_TRACE(dm::toString(kind));
    auto clf = dm::Classifier::create(kind);
    ASSERT_TRUE(clf) << clf.error();
    EXPECT_EQ((*clf)->kind(), kind);
    auto name = dm::classifierKindFromString(dm::toString(kind));
    ASSERT_TRUE(name);
    EXPECT_EQ(*name, kind);
    ASSERT_TRUE((*clf)->train(train));
    auto pred = (*clf)->predict(test);
    ASSERT_TRUE(pred) << pred.error();
    auto m = dm::confusionMatrix(test.labels, *pred);
    ASSERT_TRUE(m);
    EXPECT_EQ(m->classes, (std::vector<int>{5, 15, 25}));
    EXPECT_GT(m->accuracy(), 0.99);
  }
}

TEST(Classifier, CrossValidationIsDeterministicAndCoversEverySample) {
  const dm::Dataset data = blobs(60, 3);
  auto a = dm::crossValidate(dm::ClassifierKind::NormalBayes, {}, data, 5, 42);
  auto b = dm::crossValidate(dm::ClassifierKind::NormalBayes, {}, data, 5, 42);
  ASSERT_TRUE(a && b) << (a ? b.error() : a.error());
  ASSERT_EQ(a->foldAccuracy.size(), 5u);
  EXPECT_EQ(a->foldAccuracy, b->foldAccuracy);
  EXPECT_EQ(a->confusion.counts, b->confusion.counts);
  std::size_t total = 0;
  for (std::size_t c : a->confusion.counts) total += c;
  EXPECT_EQ(total, data.size());
  EXPECT_GT(a->accuracy, 0.99);
  double mean = 0.0;
  for (double f : a->foldAccuracy) mean += f / 5.0;
  EXPECT_NEAR(mean, a->accuracy, 1e-12);  // equal folds (180 / 5)
  EXPECT_FALSE(dm::crossValidate(dm::ClassifierKind::KNearest, {}, data, 1, 42));
  EXPECT_FALSE(dm::crossValidate(dm::ClassifierKind::KNearest, {}, data, 1000, 42));
}

TEST(Classifier, BadInputIsAnError) {
  EXPECT_FALSE(dm::Classifier::create(dm::ClassifierKind::KNearest, {.k = 0}));
  EXPECT_FALSE(dm::Classifier::create(dm::ClassifierKind::SvmRbf, {.svmC = -1}));
  EXPECT_FALSE(dm::Classifier::create(dm::ClassifierKind::PcaKnn, {.pcaVariance = 1.5}));
  auto unknown = dm::classifierKindFromString("forest");
  ASSERT_FALSE(unknown);
  EXPECT_NE(unknown.error().hint.find("svm-rbf"), std::string::npos);

  auto clf = dm::Classifier::create(dm::ClassifierKind::NormalBayes);
  ASSERT_TRUE(clf);
  const dm::Dataset data = blobs(10, 4);
  EXPECT_FALSE((*clf)->predict(data));  // untrained
  dm::Dataset one = data;
  for (int& l : one.labels) l = 1;
  EXPECT_FALSE((*clf)->train(one));
  dm::Dataset nan = data;
  nan.features[7] = NAN;
  auto e = (*clf)->train(nan);
  ASSERT_FALSE(e);
  EXPECT_NE(e.error().where.find("sample 3, feature 1"), std::string::npos) << e.error().where;
  dm::Dataset ragged = data;
  ragged.features.pop_back();
  EXPECT_FALSE((*clf)->train(ragged));
  ASSERT_TRUE((*clf)->train(data));
  dm::Dataset wide;
  wide.dims = 3;
  wide.features = {1, 2, 3};
  wide.labels = {0};
  EXPECT_FALSE((*clf)->predict(wide));
}

TEST(Classifier, LetterRecognitionAccuracies) {
  auto path = dm::FileSystem::global().resolve("opencv:letter-recognition.data");
  if (!path) GTEST_SKIP() << "letter-recognition.data is missing: install the package opencv-doc";
  auto data = dm::readLetterData(path->string());
  ASSERT_TRUE(data) << data.error();
  ASSERT_EQ(data->size(), 20000u);
  ASSERT_EQ(data->dims, 16);
  const dm::Dataset train = data->slice(0, 16000), test = data->slice(16000, 20000);
  // Measured with the default options (OpenCV 4.6): k-NN (k = 3) 95.1 %,
  // normal Bayes 87.5 %, SVM RBF (C = 10, automatic gamma) 96.3 %, LDA +
  // nearest mean 67.5 %, PCA (95 % variance) + k-NN 93.5 %. The bounds keep
  // 2-5 points of margin, and stay at the level each method is known to reach
  // on this data (a broken classifier lands near 1/26 = 4 %).
  struct Case {
    dm::ClassifierKind kind;
    double bound;
  };
  for (const Case& c : {Case{dm::ClassifierKind::KNearest, 0.93}, Case{dm::ClassifierKind::NormalBayes, 0.82},
                        Case{dm::ClassifierKind::SvmRbf, 0.94}, Case{dm::ClassifierKind::Lda, 0.63},
                        Case{dm::ClassifierKind::PcaKnn, 0.90}}) {
    auto clf = dm::Classifier::create(c.kind);
    ASSERT_TRUE(clf);
    ASSERT_TRUE((*clf)->train(train));
    auto pred = (*clf)->predict(test);
    ASSERT_TRUE(pred) << pred.error();
    auto m = dm::confusionMatrix(test.labels, *pred);
    ASSERT_TRUE(m);
    std::printf("letter %-8s held-out accuracy %.2f %% (bound %.0f %%)\n", dm::toString(c.kind),
                100 * m->accuracy(), 100 * c.bound);
    EXPECT_GT(m->accuracy(), c.bound) << dm::toString(c.kind);
  }
}

}  // namespace
