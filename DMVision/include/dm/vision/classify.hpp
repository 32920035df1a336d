// dm/vision/classify.hpp — supervised classification of feature vectors
// behind one interface, with cross-validation and a UCI letter loader.
//
// Kinds (all on OpenCV; OpenCV stays private):
//   KNearest     k-nearest neighbours (cv::ml::KNearest, brute force, Euclidean)
//   NormalBayes  Gaussian class-conditional densities (cv::ml::NormalBayesClassifier)
//   SvmRbf       C-SVC with an RBF kernel (cv::ml::SVM), one-vs-one
//   Lda          Fisher LDA projection (cv::LDA, classes − 1 axes) + nearest class mean
//   PcaKnn       PCA projection (cv::PCA, `pcaVariance` of the variance kept) + k-NN
// Samples are rows of float features; labels are any ints.
//
// @code
//   auto data = dm::readLetterData("opencv:letter-recognition.data");
//   auto clf = dm::Classifier::create(dm::ClassifierKind::KNearest);
//   if (auto s = (*clf)->train(data->slice(0, 16000)); !s) return s.error();
//   auto labels = (*clf)->predict(data->slice(16000, 20000));
// @endcode
#pragma once

#include <dm/core/result.hpp>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace dm {

/// Labelled samples: `size()` rows of `dims` float features, row-major.
struct Dataset {
  int dims = 0;
  std::vector<float> features;  ///< size() · dims values
  std::vector<int> labels;      ///< one per sample

  std::size_t size() const { return labels.size(); }
  /// Features of sample i (dims values).
  std::span<const float> sample(std::size_t i) const {
    return {features.data() + i * static_cast<std::size_t>(dims), static_cast<std::size_t>(dims)};
  }
  /// Copy of samples [begin, end) (clamped to size()). O(rows · dims).
  Dataset slice(std::size_t begin, std::size_t end) const;
  /// Copy of the samples at `indices` (each < size()). O(rows · dims).
  Dataset select(std::span<const std::size_t> indices) const;
};

/// Parses the UCI letter-recognition format: one sample per line, a capital
/// letter then comma-separated integer features ("T,2,8,3,5,1,8,13,0,6,6,10,
/// 8,0,8,0,8"); labels are 0 for 'A' … 25 for 'Z'. Every row must have the
/// same number of features (16 in the UCI file). Blank lines and a trailing
/// '\r' are ignored. O(bytes). Fails with Parse naming `sourceName`, the
/// line, the field and the byte offset of a bad row (label not A–Z,
/// non-integer or out-of-int-range feature, wrong field count).
/// @code
///   auto data = dm::parseLetterData("A,1,2\nB,3,4\n");
///   if (data) std::printf("%zu samples of %d features\n", data->size(), data->dims);
/// @endcode
Result<Dataset> parseLetterData(std::string_view text, std::string_view sourceName = "<memory>");

/// Reads and parses a letter-recognition file (name via dm::FileSystem,
/// "opencv:letter-recognition.data" works). Errors name the file.
/// @code
///   auto data = dm::readLetterData("opencv:letter-recognition.data");
///   if (!data) return data.error();
///   auto train = data->slice(0, 16000);
/// @endcode
Result<Dataset> readLetterData(const std::string& file);

enum class ClassifierKind : std::uint8_t { KNearest, NormalBayes, SvmRbf, Lda, PcaKnn };

/// "knn", "bayes", "svm-rbf", "lda", "pca-knn".
const char* toString(ClassifierKind kind) noexcept;
/// Inverse of toString(); fails with InvalidArgument listing the names.
Result<ClassifierKind> classifierKindFromString(std::string_view name);

/// Parameters of the classifiers (each kind reads its own).
struct ClassifierOptions {
  int k = 3;           ///< neighbours of KNearest and PcaKnn (≥ 1)
  double svmC = 10.0;  ///< SVM soft-margin constant C > 0
  /// RBF γ in exp(−γ‖x − y‖²); 0 = 1 / (dims · feature variance) of the training set.
  double svmGamma = 0.0;
  double pcaVariance = 0.95;  ///< fraction of the variance PcaKnn keeps, (0, 1]
};

/// A trainable classifier. train() and predict() validate their input and
/// delegate to the kind's implementation; predict() does not change the
/// trained model.
class Classifier {
 public:
  /// A new untrained classifier of `kind`. Fails with InvalidArgument on
  /// options outside their ranges.
  /// @code
  ///   auto svm = dm::Classifier::create(dm::ClassifierKind::SvmRbf, {.svmC = 10});
  ///   if (!svm) return svm.error();
  /// @endcode
  static Result<std::unique_ptr<Classifier>> create(ClassifierKind kind,
                                                    const ClassifierOptions& options = {});
  virtual ~Classifier();
  Classifier(const Classifier&) = delete;
  Classifier& operator=(const Classifier&) = delete;

  ClassifierKind kind() const { return kind_; }
  const ClassifierOptions& options() const { return options_; }
  bool trained() const { return dims_ > 0; }
  int dims() const { return dims_; }

  /// Trains on `data` (replacing any earlier training). Cost per kind:
  /// k-NN O(1) (stores the samples), Bayes/LDA/PCA O(n·d²), SVM roughly
  /// O(n²·d). Fails with InvalidArgument on an empty set, dims ≤ 0,
  /// inconsistent sizes, non-finite features, fewer than 2 classes, or a
  /// class too small for the kind (Bayes needs ≥ 2 samples per class); with
  /// Internal when OpenCV fails.
  Status train(const Dataset& data);
  /// Predicted label of each sample of `data` (its labels are ignored).
  /// O(rows · cost of one prediction; k-NN: O(rows · n · d)). Fails when
  /// untrained or on a dims mismatch.
  Result<std::vector<int>> predict(const Dataset& data) const;

 protected:
  Classifier(ClassifierKind kind, const ClassifierOptions& options) : kind_(kind), options_(options) {}

 private:
  virtual Status doTrain(const Dataset& data) = 0;
  virtual Status doPredict(const Dataset& data, std::span<int> out) const = 0;

  ClassifierKind kind_;
  ClassifierOptions options_;
  int dims_ = 0;
};

/// Confusion matrix: counts[t · classes.size() + p] samples of true class
/// classes[t] predicted as classes[p].
struct ConfusionMatrix {
  std::vector<int> classes;  ///< sorted distinct labels of truth and predictions
  std::vector<std::size_t> counts;
  double accuracy() const;                                   ///< trace / total
  std::size_t at(int truthLabel, int predictedLabel) const;  ///< 0 for unknown labels
};

/// Builds the confusion matrix of `predicted` against `truth`. O(n log n).
/// Fails with InvalidArgument on different lengths or empty input.
/// @code
///   auto m = dm::confusionMatrix(test.labels, *predicted);
///   std::printf("accuracy %.1f %%, A as B: %zu\n", 100 * m->accuracy(), m->at(0, 1));
/// @endcode
Result<ConfusionMatrix> confusionMatrix(std::span<const int> truth, std::span<const int> predicted);

/// k-fold cross-validation result.
struct CrossValidation {
  std::vector<double> foldAccuracy;  ///< accuracy of each fold's held-out part
  double accuracy = 0.0;             ///< over all samples (each predicted once)
  ConfusionMatrix confusion;         ///< of all held-out predictions
};

/// Shuffles the samples with std::mt19937_64(seed), splits them into
/// `folds` parts, trains a fresh classifier on folds − 1 parts and predicts
/// the remaining one, for each part. Deterministic for a seed.
/// O(folds · train + n · predict). Fails with InvalidArgument when folds is
/// outside 2..size() or any training fails.
/// @code
///   auto cv = dm::crossValidate(dm::ClassifierKind::NormalBayes, {}, data, 5, 42);
///   if (cv) std::printf("accuracy %.1f %%\n", 100 * cv->accuracy);
/// @endcode
Result<CrossValidation> crossValidate(ClassifierKind kind, const ClassifierOptions& options,
                                      const Dataset& data, int folds, std::uint64_t seed);

}  // namespace dm
