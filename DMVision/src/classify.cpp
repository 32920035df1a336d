// Classifiers on OpenCV ml / core, cross-validation and the UCI letter
// loader (see dm/vision/classify.hpp). OpenCV exceptions stop here.
#include <dm/core/filesystem.hpp>
#include <dm/vision/classify.hpp>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>
#include <opencv2/core.hpp>
#include <opencv2/ml.hpp>
#include <random>
#include <string>
#include <utility>

namespace dm {

Dataset Dataset::slice(std::size_t begin, std::size_t end) const {
  end = std::min(end, size());
  begin = std::min(begin, end);
  Dataset out;
  out.dims = dims;
  const auto d = static_cast<std::size_t>(dims);
  out.features.assign(features.begin() + static_cast<std::ptrdiff_t>(begin * d),
                      features.begin() + static_cast<std::ptrdiff_t>(end * d));
  out.labels.assign(labels.begin() + static_cast<std::ptrdiff_t>(begin),
                    labels.begin() + static_cast<std::ptrdiff_t>(end));
  return out;
}

Dataset Dataset::select(std::span<const std::size_t> indices) const {
  Dataset out;
  out.dims = dims;
  out.features.reserve(indices.size() * static_cast<std::size_t>(dims));
  out.labels.reserve(indices.size());
  for (std::size_t i : indices) {
    DM_DEMAND(i < size(), "Dataset::select index out of range");
    const auto s = sample(i);
    out.features.insert(out.features.end(), s.begin(), s.end());
    out.labels.push_back(labels[i]);
  }
  return out;
}

Result<Dataset> parseLetterData(std::string_view text, std::string_view sourceName) {
  Dataset data;
  std::size_t pos = 0;
  int lineNo = 0;
  const std::string source(sourceName);
  while (pos < text.size()) {
    ++lineNo;
    const std::size_t lineStart = pos;
    std::size_t end = text.find('\n', pos);
    if (end == std::string_view::npos) end = text.size();
    pos = end + 1;
    std::string_view line = text.substr(lineStart, end - lineStart);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    if (line.find_first_not_of(" \t") == std::string_view::npos) continue;
    auto where = [&](int field, std::size_t offset) {
      return formatString("%s: line %d, field %d, byte %zu", source.c_str(), lineNo, field, offset);
    };
    const std::size_t rowStart = data.features.size();
    int field = 0;
    std::size_t fieldStart = 0;
    while (true) {
      std::size_t comma = line.find(',', fieldStart);
      const std::string_view f = line.substr(
          fieldStart, comma == std::string_view::npos ? line.size() - fieldStart : comma - fieldStart);
      const std::size_t offset = lineStart + fieldStart;
      if (field == 0) {
        if (f.size() != 1 || f[0] < 'A' || f[0] > 'Z')
          return fail(ErrorCode::Parse,
                      "the label \"" + std::string(f.substr(0, 16)) + "\" is not a letter A-Z",
                      where(1, offset), "each row starts with the capital letter it shows");
        data.labels.push_back(f[0] - 'A');
      } else {
        int value = 0;
        const auto [ptr, ec] = std::from_chars(f.data(), f.data() + f.size(), value);
        if (f.empty() || ec != std::errc() || ptr != f.data() + f.size())
          return fail(ErrorCode::Parse, "feature \"" + std::string(f.substr(0, 16)) + "\" is not an integer",
                      where(field + 1, offset), "features are comma-separated integers");
        data.features.push_back(static_cast<float>(value));
      }
      ++field;
      if (comma == std::string_view::npos) break;
      fieldStart = comma + 1;
    }
    const int dims = static_cast<int>(data.features.size() - rowStart);
    if (dims == 0)
      return fail(ErrorCode::Parse, "a row without features", where(1, lineStart),
                  "write the letter, then its comma-separated features");
    if (data.dims == 0) data.dims = dims;
    if (dims != data.dims)
      return fail(ErrorCode::Parse, formatString("%d features where earlier rows have %d", dims, data.dims),
                  where(field, lineStart), "every row needs the same number of features");
  }
  if (data.labels.empty())
    return fail(ErrorCode::Parse, "no samples", source, "the file is empty or has only blank lines");
  return data;
}

Result<Dataset> readLetterData(const std::string& file) {
  auto path = FileSystem::global().resolve(file);
  if (!path) return path.error();
  auto bytes = readFile(*path);
  if (!bytes) return bytes.error();
  return parseLetterData(std::string_view(reinterpret_cast<const char*>(bytes->data()), bytes->size()),
                         path->string());
}

namespace {

struct KindName {
  ClassifierKind kind;
  const char* name;
};
constexpr KindName kKindNames[] = {{ClassifierKind::KNearest, "knn"},
                                   {ClassifierKind::NormalBayes, "bayes"},
                                   {ClassifierKind::SvmRbf, "svm-rbf"},
                                   {ClassifierKind::Lda, "lda"},
                                   {ClassifierKind::PcaKnn, "pca-knn"}};

// Header over the dataset's features (no copy; OpenCV only reads it).
cv::Mat featureMat(const Dataset& d) {
  return cv::Mat(static_cast<int>(d.size()), d.dims, CV_32F, const_cast<float*>(d.features.data()));
}

cv::Mat labelMat(const Dataset& d) {
  return cv::Mat(static_cast<int>(d.size()), 1, CV_32S, const_cast<int*>(d.labels.data()));
}

Error openCvFailure(const cv::Exception& e, ClassifierKind kind, const char* step) {
  return fail(ErrorCode::Internal, "OpenCV: " + std::string(e.what()),
              std::string(toString(kind)) + " classifier, " + step);
}

// Predicted labels come back as CV_32F (k-NN, SVM) or CV_32S (Bayes).
void copyLabels(const cv::Mat& results, std::span<int> out) {
  cv::Mat labels;
  results.convertTo(labels, CV_32S);  // rounds floats to the nearest int
  for (int i = 0; i < labels.rows; ++i) out[static_cast<std::size_t>(i)] = labels.at<int>(i);
}

// k nearest neighbours on `features` (rows), used by KNearest and PcaKnn.
class KnnModel {
 public:
  void train(const cv::Mat& features, const cv::Mat& labels, int k) {
    k_ = k;
    model_ = cv::ml::KNearest::create();
    model_->setDefaultK(k);
    model_->setIsClassifier(true);
    model_->train(cv::ml::TrainData::create(features, cv::ml::ROW_SAMPLE, labels));
  }
  void predict(const cv::Mat& features, std::span<int> out) const {
    cv::Mat results;
    model_->findNearest(features, k_, results);
    copyLabels(results, out);
  }

 private:
  cv::Ptr<cv::ml::KNearest> model_;
  int k_ = 1;
};

class KnnClassifier final : public Classifier {
 public:
  explicit KnnClassifier(const ClassifierOptions& o) : Classifier(ClassifierKind::KNearest, o) {}

 private:
  Status doTrain(const Dataset& d) override {
    try {
      knn_.train(featureMat(d), labelMat(d), options().k);
    } catch (const cv::Exception& e) {
      return openCvFailure(e, kind(), "train");
    }
    return ok();
  }
  Status doPredict(const Dataset& d, std::span<int> out) const override {
    try {
      knn_.predict(featureMat(d), out);
    } catch (const cv::Exception& e) {
      return openCvFailure(e, kind(), "predict");
    }
    return ok();
  }
  KnnModel knn_;
};

// Bayes and SVM share OpenCV's StatModel train/predict.
class StatModelClassifier final : public Classifier {
 public:
  StatModelClassifier(ClassifierKind kind, const ClassifierOptions& o) : Classifier(kind, o) {}

 private:
  Status doTrain(const Dataset& d) override {
    try {
      const cv::Mat x = featureMat(d), y = labelMat(d);
      if (kind() == ClassifierKind::NormalBayes) {
        model_ = cv::ml::NormalBayesClassifier::create();
      } else {
        double gamma = options().svmGamma;
        if (gamma == 0.0) {
          cv::Scalar mean, stddev;
          cv::meanStdDev(x.reshape(1, 1), mean, stddev);
          const double var = stddev[0] * stddev[0];
          gamma = var > 0 ? 1.0 / (d.dims * var) : 1.0;
        }
        auto svm = cv::ml::SVM::create();
        svm->setType(cv::ml::SVM::C_SVC);
        svm->setKernel(cv::ml::SVM::RBF);
        svm->setC(options().svmC);
        svm->setGamma(gamma);
        svm->setTermCriteria(
            cv::TermCriteria(cv::TermCriteria::MAX_ITER + cv::TermCriteria::EPS, 10000, 1e-3));
        model_ = svm;
      }
      if (!model_->train(cv::ml::TrainData::create(x, cv::ml::ROW_SAMPLE, y)))
        return fail(ErrorCode::Internal, "OpenCV training returned false", toString(kind()));
    } catch (const cv::Exception& e) {
      return openCvFailure(e, kind(), "train");
    }
    return ok();
  }
  Status doPredict(const Dataset& d, std::span<int> out) const override {
    try {
      cv::Mat results;
      model_->predict(featureMat(d), results);
      copyLabels(results, out);
    } catch (const cv::Exception& e) {
      return openCvFailure(e, kind(), "predict");
    }
    return ok();
  }
  cv::Ptr<cv::ml::StatModel> model_;
};

// Fisher LDA projection, then the nearest projected class mean.
class LdaClassifier final : public Classifier {
 public:
  explicit LdaClassifier(const ClassifierOptions& o) : Classifier(ClassifierKind::Lda, o) {}

 private:
  Status doTrain(const Dataset& d) override {
    try {
      const cv::Mat x = featureMat(d);
      std::map<int, int> index;
      for (int l : d.labels) index.emplace(l, 0);
      classes_.clear();
      for (auto& [label, i] : index) {
        i = static_cast<int>(classes_.size());
        classes_.push_back(label);
      }
      const int components = std::min(static_cast<int>(classes_.size()) - 1, d.dims);
      cv::LDA lda(components);
      lda.compute(x, labelMat(d));
      eigenvectors_ = lda.eigenvectors();
      cv::Mat projected = cv::LDA::subspaceProject(eigenvectors_, cv::Mat(), x);  // CV_64F
      means_ = cv::Mat::zeros(static_cast<int>(classes_.size()), projected.cols, CV_64F);
      std::vector<int> counts(classes_.size(), 0);
      for (int r = 0; r < projected.rows; ++r) {
        const int c = index[d.labels[static_cast<std::size_t>(r)]];
        means_.row(c) += projected.row(r);
        ++counts[static_cast<std::size_t>(c)];
      }
      for (int c = 0; c < means_.rows; ++c) means_.row(c) /= counts[static_cast<std::size_t>(c)];
    } catch (const cv::Exception& e) {
      return openCvFailure(e, kind(), "train");
    }
    return ok();
  }
  Status doPredict(const Dataset& d, std::span<int> out) const override {
    try {
      const cv::Mat projected = cv::LDA::subspaceProject(eigenvectors_, cv::Mat(), featureMat(d));
      for (int r = 0; r < projected.rows; ++r) {
        double best = std::numeric_limits<double>::infinity();
        int bestClass = 0;
        for (int c = 0; c < means_.rows; ++c) {
          const double dist = cv::norm(projected.row(r), means_.row(c), cv::NORM_L2SQR);
          if (dist < best) {
            best = dist;
            bestClass = c;
          }
        }
        out[static_cast<std::size_t>(r)] = classes_[static_cast<std::size_t>(bestClass)];
      }
    } catch (const cv::Exception& e) {
      return openCvFailure(e, kind(), "predict");
    }
    return ok();
  }
  cv::Mat eigenvectors_;  // LDA axes, one column per component
  cv::Mat means_;         // class means in the projected space, one row per classes_ entry
  std::vector<int> classes_;
};

// PCA keeping `pcaVariance` of the variance, then k-NN on the projection.
class PcaKnnClassifier final : public Classifier {
 public:
  explicit PcaKnnClassifier(const ClassifierOptions& o) : Classifier(ClassifierKind::PcaKnn, o) {}

 private:
  Status doTrain(const Dataset& d) override {
    try {
      const cv::Mat x = featureMat(d);
      pca_ = cv::PCA(x, cv::noArray(), cv::PCA::DATA_AS_ROW, options().pcaVariance);
      knn_.train(pca_.project(x), labelMat(d), options().k);
    } catch (const cv::Exception& e) {
      return openCvFailure(e, kind(), "train");
    }
    return ok();
  }
  Status doPredict(const Dataset& d, std::span<int> out) const override {
    try {
      knn_.predict(pca_.project(featureMat(d)), out);
    } catch (const cv::Exception& e) {
      return openCvFailure(e, kind(), "predict");
    }
    return ok();
  }
  cv::PCA pca_;
  KnnModel knn_;
};

}  // namespace

const char* toString(ClassifierKind kind) noexcept {
  for (const KindName& k : kKindNames)
    if (k.kind == kind) return k.name;
  return "unknown";
}

Result<ClassifierKind> classifierKindFromString(std::string_view name) {
  for (const KindName& k : kKindNames)
    if (name == k.name) return k.kind;
  return fail(ErrorCode::InvalidArgument, "unknown classifier \"" + std::string(name) + "\"",
              "classifier kind", "use knn, bayes, svm-rbf, lda or pca-knn");
}

Classifier::~Classifier() = default;

Result<std::unique_ptr<Classifier>> Classifier::create(ClassifierKind kind, const ClassifierOptions& o) {
  if (o.k < 1 || !(o.svmC > 0) || !std::isfinite(o.svmC) || !(o.svmGamma >= 0) ||
      !std::isfinite(o.svmGamma) || !(o.pcaVariance > 0 && o.pcaVariance <= 1))
    return fail(
        ErrorCode::InvalidArgument,
        formatString("k %d, svmC %g, svmGamma %g, pcaVariance %g", o.k, o.svmC, o.svmGamma, o.pcaVariance),
        "ClassifierOptions", "need k >= 1, svmC > 0, svmGamma >= 0 (0 = automatic), 0 < pcaVariance <= 1");
  std::unique_ptr<Classifier> c;
  switch (kind) {
    case ClassifierKind::KNearest:
      c = std::make_unique<KnnClassifier>(o);
      break;
    case ClassifierKind::NormalBayes:
    case ClassifierKind::SvmRbf:
      c = std::make_unique<StatModelClassifier>(kind, o);
      break;
    case ClassifierKind::Lda:
      c = std::make_unique<LdaClassifier>(o);
      break;
    case ClassifierKind::PcaKnn:
      c = std::make_unique<PcaKnnClassifier>(o);
      break;
    default:
      return fail(ErrorCode::InvalidArgument, "unknown classifier kind", "Classifier::create");
  }
  return c;
}

Status Classifier::train(const Dataset& data) {
  const char* name = toString(kind_);
  if (data.dims <= 0 || data.size() == 0 ||
      data.features.size() != data.size() * static_cast<std::size_t>(data.dims))
    return fail(
        ErrorCode::InvalidArgument,
        formatString("%zu labels, %zu feature values, dims %d", data.size(), data.features.size(), data.dims),
        std::string(name) + " train", "give dims > 0 and size() * dims feature values");
  if (data.size() > static_cast<std::size_t>(std::numeric_limits<int>::max()))
    return fail(ErrorCode::InvalidArgument, "too many samples for OpenCV", std::string(name) + " train");
  for (std::size_t i = 0; i < data.features.size(); ++i)
    if (!std::isfinite(data.features[i]))
      return fail(
          ErrorCode::InvalidArgument, "non-finite feature",
          formatString("%s train: sample %zu, feature %zu", name, i / static_cast<std::size_t>(data.dims),
                       i % static_cast<std::size_t>(data.dims)));
  std::map<int, std::size_t> perClass;
  for (int l : data.labels) ++perClass[l];
  if (perClass.size() < 2)
    return fail(ErrorCode::InvalidArgument, "training data with a single class", std::string(name) + " train",
                "give samples of at least two classes");
  if (kind_ == ClassifierKind::NormalBayes || kind_ == ClassifierKind::Lda)
    for (const auto& [label, n] : perClass)
      if (n < 2)
        return fail(ErrorCode::InvalidArgument, formatString("class %d has %zu sample", label, n),
                    std::string(name) + " train", "each class needs at least 2 samples for its covariance");
  dims_ = 0;
  if (auto s = doTrain(data); !s) return s;
  dims_ = data.dims;
  return ok();
}

Result<std::vector<int>> Classifier::predict(const Dataset& data) const {
  const std::string where = std::string(toString(kind_)) + " predict";
  if (!trained())
    return fail(ErrorCode::InvalidArgument, "the classifier is not trained", where, "call train() first");
  if (data.dims != dims_ || data.features.size() != data.size() * static_cast<std::size_t>(data.dims))
    return fail(ErrorCode::InvalidArgument,
                formatString("samples have %d features (%zu values for %zu labels), the classifier %d",
                             data.dims, data.features.size(), data.size(), dims_),
                where, "give one label slot per sample (any value) and the trained feature count");
  std::vector<int> out(data.size(), 0);
  if (data.size() == 0) return out;
  if (auto s = doPredict(data, out); !s) return s.error();
  return out;
}

double ConfusionMatrix::accuracy() const {
  const std::size_t n = classes.size();
  std::size_t total = 0, diag = 0;
  for (std::size_t t = 0; t < n; ++t)
    for (std::size_t p = 0; p < n; ++p) {
      total += counts[t * n + p];
      if (t == p) diag += counts[t * n + p];
    }
  return total ? static_cast<double>(diag) / static_cast<double>(total) : 0.0;
}

std::size_t ConfusionMatrix::at(int truthLabel, int predictedLabel) const {
  const auto t = std::lower_bound(classes.begin(), classes.end(), truthLabel);
  const auto p = std::lower_bound(classes.begin(), classes.end(), predictedLabel);
  if (t == classes.end() || *t != truthLabel || p == classes.end() || *p != predictedLabel) return 0;
  return counts[static_cast<std::size_t>(t - classes.begin()) * classes.size() +
                static_cast<std::size_t>(p - classes.begin())];
}

Result<ConfusionMatrix> confusionMatrix(std::span<const int> truth, std::span<const int> predicted) {
  if (truth.empty() || truth.size() != predicted.size())
    return fail(ErrorCode::InvalidArgument,
                formatString("%zu true and %zu predicted labels", truth.size(), predicted.size()),
                "confusionMatrix", "give one prediction per sample");
  ConfusionMatrix m;
  m.classes.assign(truth.begin(), truth.end());
  m.classes.insert(m.classes.end(), predicted.begin(), predicted.end());
  std::sort(m.classes.begin(), m.classes.end());
  m.classes.erase(std::unique(m.classes.begin(), m.classes.end()), m.classes.end());
  const std::size_t n = m.classes.size();
  m.counts.assign(n * n, 0);
  auto index = [&](int l) {
    return static_cast<std::size_t>(std::lower_bound(m.classes.begin(), m.classes.end(), l) -
                                    m.classes.begin());
  };
  for (std::size_t i = 0; i < truth.size(); ++i) ++m.counts[index(truth[i]) * n + index(predicted[i])];
  return m;
}

Result<CrossValidation> crossValidate(ClassifierKind kind, const ClassifierOptions& options,
                                      const Dataset& data, int folds, std::uint64_t seed) {
  if (folds < 2 || static_cast<std::size_t>(folds) > data.size())
    return fail(ErrorCode::InvalidArgument, formatString("%d folds for %zu samples", folds, data.size()),
                "crossValidate", "use 2 <= folds <= number of samples");
  std::vector<std::size_t> order(data.size());
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::mt19937_64 rng(seed);
  // Fisher–Yates with our own index draw: std::shuffle's use of the engine is
  // implementation-defined, and the split must not depend on the library.
  for (std::size_t i = order.size() - 1; i > 0; --i) std::swap(order[i], order[rng() % (i + 1)]);
  CrossValidation result;
  std::vector<int> predicted(data.size());
  const std::size_t n = data.size();
  for (int f = 0; f < folds; ++f) {
    const std::size_t begin = n * static_cast<std::size_t>(f) / static_cast<std::size_t>(folds);
    const std::size_t end = n * static_cast<std::size_t>(f + 1) / static_cast<std::size_t>(folds);
    std::vector<std::size_t> trainIdx(order.begin(), order.begin() + static_cast<std::ptrdiff_t>(begin));
    trainIdx.insert(trainIdx.end(), order.begin() + static_cast<std::ptrdiff_t>(end), order.end());
    const std::span<const std::size_t> testIdx(order.data() + begin, end - begin);
    auto clf = Classifier::create(kind, options);
    if (!clf) return clf.error();
    if (auto s = (*clf)->train(data.select(trainIdx)); !s)
      return s.error().within(formatString("crossValidate fold %d", f));
    const Dataset test = data.select(testIdx);
    auto labels = (*clf)->predict(test);
    if (!labels) return labels.error().within(formatString("crossValidate fold %d", f));
    std::size_t correct = 0;
    for (std::size_t i = 0; i < testIdx.size(); ++i) {
      predicted[testIdx[i]] = (*labels)[i];
      if ((*labels)[i] == test.labels[i]) ++correct;
    }
    result.foldAccuracy.push_back(static_cast<double>(correct) / static_cast<double>(testIdx.size()));
  }
  auto m = confusionMatrix(data.labels, predicted);
  if (!m) return m.error();
  result.confusion = std::move(*m);
  result.accuracy = result.confusion.accuracy();
  return result;
}

}  // namespace dm
