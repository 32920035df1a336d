// The node kinds of dm::FilterGraph: sources, filters and sinks on OpenCV.
// Each kind reads its parameters in its factory, so validate() reports every
// bad value with its JSON path before anything runs.
#include "filter_nodes.hpp"

#include <dm/core/filesystem.hpp>
#include <dm/io/volume_io.hpp>
#include <dm/vision/cv_image.hpp>

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video.hpp>
#include <opencv2/videoio.hpp>
#include <random>

namespace dm::graph {

Result<bool> Node::read(Value&, std::int64_t) {
  return fail(ErrorCode::Internal, "read() called on a node that is not a source", "FilterGraph");
}

Status Node::process(std::span<const Value* const>, Value&, std::int64_t) {
  return fail(ErrorCode::Internal, "process() called on a source", "FilterGraph");
}

Image imageOf(const cv::Mat& m) {
  auto img = wrapCvMat(m);
  return img ? std::move(*img) : Image();
}

namespace {

using Inputs = std::span<const Value* const>;

// ---- shared parameter readers ----------------------------------------------

/// A path parameter resolved through dm::FileSystem ("opencv:vtest.avi").
std::string resolvedPath(ConfigReader& r, std::string_view key, bool mustExist = true) {
  const std::string name = r.string(key);
  if (name.empty() || !mustExist) return name;
  auto p = FileSystem::global().resolve(name);
  if (!p) {
    r.addError(p.error().what, key, p.error().hint);
    return {};
  }
  return p->string();
}

ColorSpace readOrder(ConfigReader& r) {
  return r.oneOf("order", {"rgb", "bgr"}, "rgb") == "bgr" ? ColorSpace::Bgr : ColorSpace::Rgb;
}

int oddSize(ConfigReader& r, std::string_view key, int fallback, int min = 1) {
  const auto k = static_cast<int>(r.integer(key, {double(min), 255}, fallback));
  if (k % 2 == 0) r.addError("must be odd, is " + std::to_string(k), key, "use " + std::to_string(k + 1));
  return k;
}

/// Reorders an image OpenCV produced in BGR into `want`.
void toOrder(cv::Mat& m, ColorSpace want) {
  if (want != ColorSpace::Rgb || m.channels() < 3) return;
  cv::cvtColor(m, m, m.channels() == 4 ? cv::COLOR_BGRA2RGBA : cv::COLOR_BGR2RGB);
}

ColorSpace spaceOf(const cv::Mat& m, ColorSpace colour) {
  if (m.channels() == 1) return ColorSpace::Gray;
  if (m.channels() == 4) return colour == ColorSpace::Bgr ? ColorSpace::Bgra : ColorSpace::Rgba;
  return colour;
}

Status needChannels(const Value& v, std::initializer_list<int> allowed, const char* what) {
  for (int c : allowed)
    if (v.mat.channels() == c) return ok();
  return fail(ErrorCode::InvalidArgument,
              std::string(what) + " got an image with " + std::to_string(v.mat.channels()) + " channels",
              "input", "convert it first, e.g. with a \"color\" node (code \"gray\")");
}

Status needDepth(const Value& v, int depth, const char* what) {
  if (v.mat.depth() == depth) return ok();
  return fail(ErrorCode::InvalidArgument, std::string(what) + " needs 8-bit input", "input",
              "add a \"convert\" node with \"to\": \"u8\"");
}

// ---- sources ---------------------------------------------------------------

int imreadMode(ConfigReader& r) {
  const std::string m = r.oneOf("mode", {"color", "gray", "unchanged"}, "color");
  return m == "gray" ? cv::IMREAD_GRAYSCALE : m == "unchanged" ? cv::IMREAD_UNCHANGED : cv::IMREAD_COLOR;
}

Result<cv::Mat> readImageFile(const std::string& path, int mode) {
  cv::Mat m = cv::imread(path, mode);
  if (m.empty())
    return fail(ErrorCode::Parse, "cannot read image", path,
                "check that the file exists and is a PNG/JPEG/...");
  return m;
}

class ImageFileSource final : public Node {
 public:
  static std::unique_ptr<Node> make(ConfigReader& r, const NodeContext&) {
    auto n = std::make_unique<ImageFileSource>();
    n->path_ = resolvedPath(r, "path");
    n->frames_ = r.integer("frames", {1, 1e12}, 1);
    n->order_ = readOrder(r);
    n->mode_ = imreadMode(r);
    if (!n->path_.empty()) {
      auto m = readImageFile(n->path_, n->mode_);
      if (!m) return r.addError(m.error().what + ": " + n->path_, "path"), nullptr;
      n->image_ = std::move(*m);
      toOrder(n->image_, n->order_);
    }
    return n;
  }
  Result<bool> read(Value& out, std::int64_t frame) override {
    if (frame >= frames_) return false;
    out.mat = image_;  // shared: every frame is the same picture
    out.space = spaceOf(image_, order_);
    return true;
  }

 private:
  std::string path_;
  std::int64_t frames_ = 1;
  ColorSpace order_ = ColorSpace::Rgb;
  int mode_ = cv::IMREAD_COLOR;
  cv::Mat image_;
};

/// The one integer conversion of a printf pattern ("img_%04d.png"), or an error.
bool validPattern(const std::string& p) {
  int conversions = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (p[i] != '%') continue;
    if (i + 1 < p.size() && p[i + 1] == '%') {
      ++i;
      continue;
    }
    std::size_t j = i + 1;
    while (j < p.size() && (p[j] == '0' || std::isdigit(static_cast<unsigned char>(p[j])))) ++j;
    if (j >= p.size() || p[j] != 'd') return false;
    ++conversions;
    i = j;
  }
  return conversions == 1;
}

std::string formatPattern(const std::string& pattern, std::int64_t index) {
  char buf[4096];
  std::snprintf(buf, sizeof buf, pattern.c_str(), static_cast<int>(index));
  return buf;
}

class ImageSequenceSource final : public Node {
 public:
  static std::unique_ptr<Node> make(ConfigReader& r, const NodeContext&) {
    auto n = std::make_unique<ImageSequenceSource>();
    n->order_ = readOrder(r);
    n->mode_ = imreadMode(r);
    if (r.has("files")) {
      ConfigReader files = r.child("files");
      for (std::size_t i = 0; i < files.size(); ++i) {
        if (!files.node()[i].is_string()) {
          files.addError("must be a file name", std::to_string(i));
          continue;
        }
        auto p = FileSystem::global().resolve(files.node()[i].get<std::string>());
        if (!p)
          files.addError(p.error().what, std::to_string(i), p.error().hint);
        else
          n->files_.push_back(p->string());
      }
      if (files.size() == 0) r.addError("is empty", "files", "list at least one image");
    } else {
      n->pattern_ = r.string("pattern");
      n->start_ = r.integer("start", {0, 1e9}, 0);
      if (!n->pattern_.empty() && !validPattern(n->pattern_))
        r.addError("needs exactly one integer conversion such as %04d", "pattern");
    }
    return n;
  }
  Result<bool> read(Value& out, std::int64_t frame) override {
    std::string path;
    if (!files_.empty()) {
      if (frame >= std::int64_t(files_.size())) return false;
      path = files_[std::size_t(frame)];
    } else {
      auto resolved = FileSystem::global().resolve(formatPattern(pattern_, start_ + frame));
      if (!resolved) return false;  // the sequence ends at the first missing index
      path = resolved->string();
    }
    auto m = readImageFile(path, mode_);
    if (!m) return m.error();
    out.mat = std::move(*m);
    toOrder(out.mat, order_);
    out.space = spaceOf(out.mat, order_);
    return true;
  }

 private:
  std::vector<std::string> files_;
  std::string pattern_;
  std::int64_t start_ = 0;
  ColorSpace order_ = ColorSpace::Rgb;
  int mode_ = cv::IMREAD_COLOR;
};

/// Video files and cameras: cv::VideoCapture.
class CaptureSource final : public Node {
 public:
  static std::unique_ptr<Node> makeFile(ConfigReader& r, const NodeContext&) {
    auto n = std::make_unique<CaptureSource>();
    n->order_ = readOrder(r);
    const std::string path = resolvedPath(r, "path");
    if (path.empty()) return nullptr;
    if (!n->capture_.open(path, cv::CAP_ANY) || !n->capture_.isOpened())
      return r.addError("cannot open video " + path, "path", "is it a video OpenCV's FFmpeg backend reads?"),
             nullptr;
    return n;
  }
  static std::unique_ptr<Node> makeCamera(ConfigReader& r, const NodeContext&) {
    auto n = std::make_unique<CaptureSource>();
    n->order_ = readOrder(r);
    const int index = static_cast<int>(r.integer("index", {0, 63}, 0));
    const auto width = r.integer("width", {0, 16384}, 0), height = r.integer("height", {0, 16384}, 0);
    if (!r.status()) return nullptr;
    if (!n->capture_.open(index, cv::CAP_ANY) || !n->capture_.isOpened())
      return r.addError("cannot open camera " + std::to_string(index), "index",
                        "is /dev/video" + std::to_string(index) + " present and readable?"),
             nullptr;
    if (width > 0) n->capture_.set(cv::CAP_PROP_FRAME_WIDTH, double(width));
    if (height > 0) n->capture_.set(cv::CAP_PROP_FRAME_HEIGHT, double(height));
    return n;
  }
  Result<bool> read(Value& out, std::int64_t) override {
    ownOutput(out.mat);
    if (!capture_.read(out.mat) || out.mat.empty()) return false;
    toOrder(out.mat, order_);
    out.space = spaceOf(out.mat, order_);
    return true;
  }

 private:
  cv::VideoCapture capture_;
  ColorSpace order_ = ColorSpace::Rgb;
};

/// Synthetic frames with known motion, for tests and demos (8-bit gray).
class SyntheticSource final : public Node {
 public:
  static std::unique_ptr<Node> make(ConfigReader& r, const NodeContext&) {
    auto n = std::make_unique<SyntheticSource>();
    n->pattern_ =
        r.oneOf("pattern", {"moving_disc", "moving_texture", "checkerboard", "noise"}, "moving_disc");
    n->width_ = static_cast<int>(r.integer("width", {8, 4096}, 320));
    n->height_ = static_cast<int>(r.integer("height", {8, 4096}, 240));
    n->frames_ = r.integer("frames", {1, 1e9}, 100);
    const auto v = r.numbers("velocity", 2, std::vector<double>{1.0, 0.0});
    n->velocity_ = {v[0], v[1]};
    n->radius_ = r.number("radius", {1, 4096}, 20);
    n->square_ = static_cast<int>(r.integer("square", {1, 4096}, 20));
    n->seed_ = static_cast<unsigned>(r.integer("seed", {0, 4294967295.0}, 1));
    if (n->pattern_ == "moving_texture" || n->pattern_ == "moving_disc") {
      // A smooth random texture, larger than the frame so it can slide.
      const int margin = 64;
      cv::Mat noise(n->height_ + 2 * margin, n->width_ + 2 * margin, CV_32F);
      cv::RNG rng(n->seed_);
      rng.fill(noise, cv::RNG::UNIFORM, 0.0, 255.0);
      cv::GaussianBlur(noise, noise, cv::Size(0, 0), 2.0);
      cv::normalize(noise, noise, 20, 235, cv::NORM_MINMAX);
      noise.convertTo(n->texture_, CV_8U);
      n->margin_ = margin;
    }
    return n;
  }
  Result<bool> read(Value& out, std::int64_t frame) override {
    if (frame >= frames_) return false;
    ownOutput(out.mat);
    const double t = double(frame);
    if (pattern_ == "moving_texture") {
      // Frame k shows the texture shifted by k·velocity (sub-pixel, bilinear).
      const cv::Matx23d shift(1, 0, velocity_.x() * t - margin_, 0, 1, velocity_.y() * t - margin_);
      cv::warpAffine(texture_, out.mat, shift, cv::Size(width_, height_), cv::INTER_LINEAR,
                     cv::BORDER_REFLECT);
    } else if (pattern_ == "moving_disc") {
      // A static textured background and a white disc moving by velocity per frame.
      texture_(cv::Rect(margin_, margin_, width_, height_)).copyTo(out.mat);
      const cv::Point2d c(width_ / 4.0 + velocity_.x() * t, height_ / 2.0 + velocity_.y() * t);
      const int shift = 4;  // sub-pixel centre
      cv::circle(out.mat, cv::Point(int(std::lround(c.x * 16)), int(std::lround(c.y * 16))),
                 int(std::lround(radius_ * 16)), cv::Scalar(255), cv::FILLED, cv::LINE_AA, shift);
    } else if (pattern_ == "checkerboard") {
      out.mat.create(height_, width_, CV_8U);
      const int ox = int(std::lround(velocity_.x() * t)), oy = int(std::lround(velocity_.y() * t));
      for (int y = 0; y < height_; ++y) {
        auto* row = out.mat.ptr<std::uint8_t>(y);
        for (int x = 0; x < width_; ++x) row[x] = (((x + ox) / square_ + (y + oy) / square_) % 2) ? 230 : 25;
      }
    } else {
      out.mat.create(height_, width_, CV_8U);
      cv::RNG rng(seed_ + static_cast<unsigned>(frame));
      rng.fill(out.mat, cv::RNG::UNIFORM, 0, 256);
    }
    out.space = ColorSpace::Gray;
    return true;
  }

 private:
  std::string pattern_;
  int width_ = 320, height_ = 240, margin_ = 0, square_ = 20;
  std::int64_t frames_ = 100;
  Eigen::Vector2d velocity_{1, 0};
  double radius_ = 20;
  unsigned seed_ = 1;
  cv::Mat texture_;
};

class VolumeFileSource final : public Node {
 public:
  static std::unique_ptr<Node> make(ConfigReader& r, const NodeContext&) {
    auto n = std::make_unique<VolumeFileSource>();
    n->frames_ = r.integer("frames", {1, 1e12}, 1);
    const std::string path = resolvedPath(r, "path");
    if (path.empty()) return nullptr;
    auto v = readVolume(path);
    if (!v) return r.addError(v.error().message(), "path"), nullptr;
    n->volume_ = std::make_shared<const Volume>(std::move(*v));
    return n;
  }
  Result<bool> read(Value& out, std::int64_t frame) override {
    if (frame >= frames_) return false;
    out.type = PortType::Volume;
    out.volume = volume_;
    return true;
  }

 private:
  std::int64_t frames_ = 1;
  std::shared_ptr<const Volume> volume_;
};

// ---- filters ---------------------------------------------------------------

class ColorNode final : public Node {
 public:
  static std::unique_ptr<Node> make(ConfigReader& r, const NodeContext&) {
    auto n = std::make_unique<ColorNode>();
    const std::string code = r.oneOf("code", {"gray", "rgb", "bgr", "hsv", "lab"});
    n->target_ = code == "gray"  ? ColorSpace::Gray
                 : code == "rgb" ? ColorSpace::Rgb
                 : code == "bgr" ? ColorSpace::Bgr
                 : code == "hsv" ? ColorSpace::Hsv
                                 : ColorSpace::Lab;
    return n;
  }
  Status process(Inputs in, Value& out, std::int64_t) override {
    const Value& a = *in[0];
    const bool bgr = a.space == ColorSpace::Bgr || a.space == ColorSpace::Bgra;
    int code = -1;
    switch (a.space) {
      case ColorSpace::Gray:
        if (target_ == ColorSpace::Rgb || target_ == ColorSpace::Bgr) code = cv::COLOR_GRAY2BGR;
        if (target_ == ColorSpace::Gray) code = -2;
        break;
      case ColorSpace::Rgb:
      case ColorSpace::Bgr:
        if (target_ == ColorSpace::Gray) code = bgr ? cv::COLOR_BGR2GRAY : cv::COLOR_RGB2GRAY;
        if (target_ == ColorSpace::Hsv) code = bgr ? cv::COLOR_BGR2HSV : cv::COLOR_RGB2HSV;
        if (target_ == ColorSpace::Lab) code = bgr ? cv::COLOR_BGR2Lab : cv::COLOR_RGB2Lab;
        if (target_ == ColorSpace::Rgb || target_ == ColorSpace::Bgr)
          code = target_ == a.space ? -2 : cv::COLOR_BGR2RGB;
        break;
      case ColorSpace::Rgba:
      case ColorSpace::Bgra:
        if (target_ == ColorSpace::Gray) code = bgr ? cv::COLOR_BGRA2GRAY : cv::COLOR_RGBA2GRAY;
        if (target_ == ColorSpace::Rgb) code = bgr ? cv::COLOR_BGRA2RGB : cv::COLOR_RGBA2RGB;
        if (target_ == ColorSpace::Bgr) code = bgr ? cv::COLOR_BGRA2BGR : cv::COLOR_RGBA2BGR;
        break;
      case ColorSpace::Hsv:
        if (target_ == ColorSpace::Rgb) code = cv::COLOR_HSV2RGB;
        if (target_ == ColorSpace::Bgr) code = cv::COLOR_HSV2BGR;
        break;
      case ColorSpace::Lab:
        if (target_ == ColorSpace::Rgb) code = cv::COLOR_Lab2RGB;
        if (target_ == ColorSpace::Bgr) code = cv::COLOR_Lab2BGR;
        break;
      case ColorSpace::Other:
        break;
    }
    if (code == -1)
      return fail(ErrorCode::InvalidArgument,
                  "no conversion from this image's colour space to the requested one", "code",
                  "convert to rgb first");
    ownOutput(out.mat);
    if (code == -2)
      a.mat.copyTo(out.mat);
    else
      cv::cvtColor(a.mat, out.mat, code);
    out.space = target_;
    return ok();
  }

 private:
  ColorSpace target_ = ColorSpace::Gray;
};

/// Filters whose output keeps the input's colour space: one OpenCV call.
class SameSpaceNode : public Node {
 public:
  Status process(Inputs in, Value& out, std::int64_t) override {
    ownOutput(out.mat);
    if (auto s = apply(*in[0], out.mat); !s) return s;
    out.space =
        out.mat.channels() == in[0]->mat.channels() ? in[0]->space : spaceOf(out.mat, ColorSpace::Other);
    return ok();
  }

 protected:
  virtual Status apply(const Value& in, cv::Mat& out) = 0;
};

int interpolation(ConfigReader& r) {
  const std::string m = r.oneOf("interpolation", {"linear", "nearest", "area", "cubic"}, "linear");
  return m == "nearest" ? cv::INTER_NEAREST
         : m == "area"  ? cv::INTER_AREA
         : m == "cubic" ? cv::INTER_CUBIC
                        : cv::INTER_LINEAR;
}

class ResizeNode final : public SameSpaceNode {
 public:
  static std::unique_ptr<Node> make(ConfigReader& r, const NodeContext&) {
    auto n = std::make_unique<ResizeNode>();
    if (r.has("scale")) {
      n->scale_ = r.number("scale", {1e-3, 64});
    } else {
      n->size_ = cv::Size(int(r.integer("width", {1, 16384})), int(r.integer("height", {1, 16384})));
    }
    n->interp_ = interpolation(r);
    return n;
  }
  Status apply(const Value& in, cv::Mat& out) override {
    if (scale_ > 0)
      cv::resize(in.mat, out, cv::Size(), scale_, scale_, interp_);
    else
      cv::resize(in.mat, out, size_, 0, 0, interp_);
    return ok();
  }

 private:
  double scale_ = 0;
  cv::Size size_;
  int interp_ = cv::INTER_LINEAR;
};

class GaussianNode final : public SameSpaceNode {
 public:
  static std::unique_ptr<Node> make(ConfigReader& r, const NodeContext&) {
    auto n = std::make_unique<GaussianNode>();
    n->ksize_ = r.has("ksize") ? oddSize(r, "ksize", 5) : 0;
    n->sigma_ = r.number("sigma", {1e-3, 1000}, 0 + (n->ksize_ == 0 ? 1.5 : 0));
    if (n->ksize_ == 0 && n->sigma_ <= 0) r.addError("give ksize or a positive sigma", "sigma");
    return n;
  }
  Status apply(const Value& in, cv::Mat& out) override {
    cv::GaussianBlur(in.mat, out, cv::Size(ksize_, ksize_), sigma_, sigma_, cv::BORDER_REFLECT_101);
    return ok();
  }

 private:
  int ksize_ = 0;
  double sigma_ = 1.5;
};

class MedianNode final : public SameSpaceNode {
 public:
  static std::unique_ptr<Node> make(ConfigReader& r, const NodeContext&) {
    auto n = std::make_unique<MedianNode>();
    n->ksize_ = oddSize(r, "ksize", 5, 3);
    return n;
  }
  Status apply(const Value& in, cv::Mat& out) override {
    if (ksize_ > 5)
      if (auto s = needDepth(in, CV_8U, "median_blur with ksize > 5"); !s) return s;
    cv::medianBlur(in.mat, out, ksize_);
    return ok();
  }

 private:
  int ksize_ = 5;
};

class BilateralNode final : public SameSpaceNode {
 public:
  static std::unique_ptr<Node> make(ConfigReader& r, const NodeContext&) {
    auto n = std::make_unique<BilateralNode>();
    n->d_ = static_cast<int>(r.integer("d", {1, 64}, 9));
    n->sigmaColor_ = r.number("sigma_color", {1e-3, 1e6}, 50);
    n->sigmaSpace_ = r.number("sigma_space", {1e-3, 1e6}, 5);
    return n;
  }
  Status apply(const Value& in, cv::Mat& out) override {
    if (auto s = needChannels(in, {1, 3}, "bilateral"); !s) return s;
    cv::bilateralFilter(in.mat, out, d_, sigmaColor_, sigmaSpace_);
    return ok();
  }

 private:
  int d_ = 9;
  double sigmaColor_ = 50, sigmaSpace_ = 5;
};

class ThresholdNode final : public SameSpaceNode {
 public:
  static std::unique_ptr<Node> make(ConfigReader& r, const NodeContext&) {
    auto n = std::make_unique<ThresholdNode>();
    n->value_ = r.number("value", {}, 128);
    n->max_ = r.number("max", {}, 255);
    const std::string t =
        r.oneOf("type", {"binary", "binary_inv", "trunc", "tozero", "tozero_inv"}, "binary");
    n->type_ = t == "binary"       ? cv::THRESH_BINARY
               : t == "binary_inv" ? cv::THRESH_BINARY_INV
               : t == "trunc"      ? cv::THRESH_TRUNC
               : t == "tozero"     ? cv::THRESH_TOZERO
                                   : cv::THRESH_TOZERO_INV;
    if (r.boolean("otsu", false)) n->type_ |= cv::THRESH_OTSU;
    return n;
  }
  Status apply(const Value& in, cv::Mat& out) override {
    if (type_ & cv::THRESH_OTSU) {
      if (auto s = needChannels(in, {1}, "threshold with otsu"); !s) return s;
      if (auto s = needDepth(in, CV_8U, "threshold with otsu"); !s) return s;
    }
    cv::threshold(in.mat, out, value_, max_, type_);
    return ok();
  }

 private:
  double value_ = 128, max_ = 255;
  int type_ = cv::THRESH_BINARY;
};

class AdaptiveThresholdNode final : public SameSpaceNode {
 public:
  static std::unique_ptr<Node> make(ConfigReader& r, const NodeContext&) {
    auto n = std::make_unique<AdaptiveThresholdNode>();
    n->max_ = r.number("max", {0, 255}, 255);
    n->method_ = r.oneOf("method", {"mean", "gaussian"}, "mean") == "mean" ? cv::ADAPTIVE_THRESH_MEAN_C
                                                                           : cv::ADAPTIVE_THRESH_GAUSSIAN_C;
    n->type_ = r.oneOf("type", {"binary", "binary_inv"}, "binary") == "binary" ? cv::THRESH_BINARY
                                                                               : cv::THRESH_BINARY_INV;
    n->block_ = oddSize(r, "block", 11, 3);
    n->c_ = r.number("c", {}, 2);
    return n;
  }
  Status apply(const Value& in, cv::Mat& out) override {
    if (auto s = needChannels(in, {1}, "adaptive_threshold"); !s) return s;
    if (auto s = needDepth(in, CV_8U, "adaptive_threshold"); !s) return s;
    cv::adaptiveThreshold(in.mat, out, max_, method_, type_, block_, c_);
    return ok();
  }

 private:
  double max_ = 255, c_ = 2;
  int method_ = cv::ADAPTIVE_THRESH_MEAN_C, type_ = cv::THRESH_BINARY, block_ = 11;
};

int sobelSize(ConfigReader& r) {
  const auto k = static_cast<int>(r.integer("ksize", {1, 7}, 3));
  if (k % 2 == 0) r.addError("must be 1, 3, 5 or 7", "ksize");
  return k;
}

class SobelNode final : public SameSpaceNode {
 public:
  static std::unique_ptr<Node> make(ConfigReader& r, const NodeContext&) {
    auto n = std::make_unique<SobelNode>();
    n->dx_ = static_cast<int>(r.integer("dx", {0, 2}, 1));
    n->dy_ = static_cast<int>(r.integer("dy", {0, 2}, 0));
    n->ksize_ = sobelSize(r);
    if (n->dx_ + n->dy_ == 0) r.addError("dx and dy are both 0", "dx", "set dx or dy to 1");
    return n;
  }
  Status apply(const Value& in, cv::Mat& out) override {
    cv::Sobel(in.mat, out, CV_32F, dx_, dy_, ksize_);
    return ok();
  }

 private:
  int dx_ = 1, dy_ = 0, ksize_ = 3;
};

class GradientMagnitudeNode final : public Node {
 public:
  static std::unique_ptr<Node> make(ConfigReader& r, const NodeContext&) {
    auto n = std::make_unique<GradientMagnitudeNode>();
    n->ksize_ = sobelSize(r);
    return n;
  }
  Status process(Inputs in, Value& out, std::int64_t) override {
    if (auto s = needChannels(*in[0], {1}, "gradient_magnitude"); !s) return s;
    cv::Sobel(in[0]->mat, gx_, CV_32F, 1, 0, ksize_);
    cv::Sobel(in[0]->mat, gy_, CV_32F, 0, 1, ksize_);
    ownOutput(out.mat);
    cv::magnitude(gx_, gy_, out.mat);
    out.space = ColorSpace::Gray;
    return ok();
  }

 private:
  int ksize_ = 3;
  cv::Mat gx_, gy_;
};

class VectorMagnitudeNode final : public Node {
 public:
  static std::unique_ptr<Node> make(ConfigReader&, const NodeContext&) {
    return std::make_unique<VectorMagnitudeNode>();
  }
  Status process(Inputs in, Value& out, std::int64_t) override {
    if (auto s = needChannels(*in[0], {2}, "vector_magnitude"); !s) return s;
    cv::Mat parts[2];
    cv::split(in[0]->mat, parts);
    if (parts[0].depth() != CV_32F && parts[0].depth() != CV_64F) {
      parts[0].convertTo(parts[0], CV_32F);
      parts[1].convertTo(parts[1], CV_32F);
    }
    ownOutput(out.mat);
    cv::magnitude(parts[0], parts[1], out.mat);
    out.space = ColorSpace::Gray;
    return ok();
  }
};

class CannyNode final : public SameSpaceNode {
 public:
  static std::unique_ptr<Node> make(ConfigReader& r, const NodeContext&) {
    auto n = std::make_unique<CannyNode>();
    n->low_ = r.number("low", {0, 1e6}, 50);
    n->high_ = r.number("high", {0, 1e6}, 150);
    n->aperture_ = static_cast<int>(r.integer("aperture", {3, 7}, 3));
    if (n->aperture_ % 2 == 0) r.addError("must be 3, 5 or 7", "aperture");
    if (n->high_ < n->low_) r.addError("high is below low", "high");
    n->l2_ = r.boolean("l2", false);
    return n;
  }
  Status apply(const Value& in, cv::Mat& out) override {
    if (auto s = needDepth(in, CV_8U, "canny"); !s) return s;
    cv::Canny(in.mat, out, low_, high_, aperture_, l2_);
    return ok();
  }

 private:
  double low_ = 50, high_ = 150;
  int aperture_ = 3;
  bool l2_ = false;
};

class MorphologyNode final : public SameSpaceNode {
 public:
  static std::unique_ptr<Node> make(ConfigReader& r, const NodeContext&) {
    auto n = std::make_unique<MorphologyNode>();
    const std::string op =
        r.oneOf("op", {"erode", "dilate", "open", "close", "gradient", "tophat", "blackhat"}, "open");
    n->op_ = op == "erode"      ? cv::MORPH_ERODE
             : op == "dilate"   ? cv::MORPH_DILATE
             : op == "open"     ? cv::MORPH_OPEN
             : op == "close"    ? cv::MORPH_CLOSE
             : op == "gradient" ? cv::MORPH_GRADIENT
             : op == "tophat"   ? cv::MORPH_TOPHAT
                                : cv::MORPH_BLACKHAT;
    const std::string shape = r.oneOf("shape", {"rect", "ellipse", "cross"}, "ellipse");
    const int size = oddSize(r, "size", 3);
    n->kernel_ = cv::getStructuringElement(shape == "rect"    ? cv::MORPH_RECT
                                           : shape == "cross" ? cv::MORPH_CROSS
                                                              : cv::MORPH_ELLIPSE,
                                           cv::Size(size, size));
    n->iterations_ = static_cast<int>(r.integer("iterations", {1, 100}, 1));
    return n;
  }
  Status apply(const Value& in, cv::Mat& out) override {
    cv::morphologyEx(in.mat, out, op_, kernel_, cv::Point(-1, -1), iterations_);
    return ok();
  }

 private:
  int op_ = cv::MORPH_OPEN, iterations_ = 1;
  cv::Mat kernel_;
};

class UndistortNode final : public SameSpaceNode {
 public:
  static std::unique_ptr<Node> make(ConfigReader& r, const NodeContext&) {
    auto n = std::make_unique<UndistortNode>();
    const auto k = r.numbers("camera_matrix", 9);
    n->k_ = cv::Mat(3, 3, CV_64F);
    for (int i = 0; i < 9; ++i) n->k_.at<double>(i / 3, i % 3) = k[std::size_t(i)];
    std::size_t count = 0;
    if (const Json& node = r.node();
        node.is_object() && node.contains("dist_coeffs") && node["dist_coeffs"].is_array())
      count = node["dist_coeffs"].size();
    if (count != 4 && count != 5 && count != 8 && count != 12 && count != 14) {
      r.addError("needs 4, 5, 8, 12 or 14 numbers (OpenCV's distortion model)", "dist_coeffs");
      return nullptr;
    }
    const auto d = r.numbers("dist_coeffs", count);
    n->dist_ = cv::Mat(d, true).reshape(1, 1);
    return n;
  }
  Status apply(const Value& in, cv::Mat& out) override {
    if (map1_.empty() || mapSize_ != in.mat.size()) {
      mapSize_ = in.mat.size();
      cv::initUndistortRectifyMap(k_, dist_, cv::Mat(), k_, mapSize_, CV_16SC2, map1_, map2_);
    }
    cv::remap(in.mat, out, map1_, map2_, cv::INTER_LINEAR);
    return ok();
  }

 private:
  cv::Mat k_, dist_, map1_, map2_;
  cv::Size mapSize_;
};

class BackgroundNode final : public Node {
 public:
  static std::unique_ptr<Node> make(ConfigReader& r, const NodeContext&) {
    auto n = std::make_unique<BackgroundNode>();
    const std::string method = r.oneOf("method", {"mog2", "knn"}, "mog2");
    const int history = static_cast<int>(r.integer("history", {1, 100000}, 500));
    const bool shadows = r.boolean("shadows", false);
    n->rate_ = r.number("learning_rate", {-1, 1}, -1);
    if (method == "mog2")
      n->model_ = cv::createBackgroundSubtractorMOG2(history, r.number("threshold", {0, 1e6}, 16), shadows);
    else
      n->model_ = cv::createBackgroundSubtractorKNN(history, r.number("threshold", {0, 1e6}, 400), shadows);
    return n;
  }
  Status process(Inputs in, Value& out, std::int64_t) override {
    ownOutput(out.mat);
    model_->apply(in[0]->mat, out.mat, rate_);
    out.space = ColorSpace::Gray;
    return ok();
  }

 private:
  cv::Ptr<cv::BackgroundSubtractor> model_;
  double rate_ = -1;
};

/// Dense Farnebäck flow from the previous frame: 2-channel float (dx, dy) in
/// pixels per frame; zero on the first frame.
class OpticalFlowNode final : public Node {
 public:
  static std::unique_ptr<Node> make(ConfigReader& r, const NodeContext&) {
    auto n = std::make_unique<OpticalFlowNode>();
    n->pyrScale_ = r.number("pyr_scale", {0.1, 0.9}, 0.5);
    n->levels_ = static_cast<int>(r.integer("levels", {1, 10}, 3));
    n->window_ = static_cast<int>(r.integer("window", {3, 255}, 15));
    n->iterations_ = static_cast<int>(r.integer("iterations", {1, 100}, 3));
    n->polyN_ = static_cast<int>(r.integer("poly_n", {5, 7}, 5));
    n->polySigma_ = r.number("poly_sigma", {0.1, 10}, 1.2);
    return n;
  }
  Status process(Inputs in, Value& out, std::int64_t) override {
    if (auto s = needChannels(*in[0], {1}, "optical_flow"); !s) return s;
    if (auto s = needDepth(*in[0], CV_8U, "optical_flow"); !s) return s;
    ownOutput(out.mat);
    if (previous_.empty() || previous_.size() != in[0]->mat.size()) {
      out.mat.create(in[0]->mat.size(), CV_32FC2);
      out.mat.setTo(cv::Scalar::all(0));
    } else {
      cv::calcOpticalFlowFarneback(previous_, in[0]->mat, out.mat, pyrScale_, levels_, window_, iterations_,
                                   polyN_, polySigma_, 0);
    }
    in[0]->mat.copyTo(previous_);
    out.space = ColorSpace::Other;
    return ok();
  }

 private:
  double pyrScale_ = 0.5, polySigma_ = 1.2;
  int levels_ = 3, window_ = 15, iterations_ = 3, polyN_ = 5;
  cv::Mat previous_;
};

class AbsDiffNode final : public Node {
 public:
  static std::unique_ptr<Node> make(ConfigReader&, const NodeContext&) {
    return std::make_unique<AbsDiffNode>();
  }
  Status process(Inputs in, Value& out, std::int64_t) override {
    if (in[0]->mat.size() != in[1]->mat.size() || in[0]->mat.type() != in[1]->mat.type())
      return fail(ErrorCode::InvalidArgument, "the two inputs differ in size or type", "inputs",
                  "resize or convert one of them");
    ownOutput(out.mat);
    cv::absdiff(in[0]->mat, in[1]->mat, out.mat);
    out.space = in[0]->space;
    return ok();
  }
};

class ConvertNode final : public SameSpaceNode {
 public:
  static std::unique_ptr<Node> make(ConfigReader& r, const NodeContext&) {
    auto n = std::make_unique<ConvertNode>();
    const std::string to = r.oneOf("to", {"u8", "u16", "f32"}, "u8");
    n->depth_ = to == "u8" ? CV_8U : to == "u16" ? CV_16U : CV_32F;
    n->scale_ = r.number("scale", {}, 1);
    n->offset_ = r.number("offset", {}, 0);
    n->abs_ = r.boolean("abs", false);
    return n;
  }
  Status apply(const Value& in, cv::Mat& out) override {
    if (abs_) {
      cv::Mat tmp;
      in.mat.convertTo(tmp, CV_32F, scale_, offset_);
      tmp = cv::abs(tmp);
      tmp.convertTo(out, depth_);
    } else {
      in.mat.convertTo(out, depth_, scale_, offset_);
    }
    return ok();
  }

 private:
  int depth_ = CV_8U;
  double scale_ = 1, offset_ = 0;
  bool abs_ = false;
};

class GoodFeaturesNode final : public Node {
 public:
  static std::unique_ptr<Node> make(ConfigReader& r, const NodeContext&) {
    auto n = std::make_unique<GoodFeaturesNode>();
    n->max_ = static_cast<int>(r.integer("max_corners", {1, 100000}, 200));
    n->quality_ = r.number("quality", {1e-6, 1}, 0.01);
    n->minDistance_ = r.number("min_distance", {0, 1e4}, 10);
    return n;
  }
  Status process(Inputs in, Value& out, std::int64_t) override {
    if (auto s = needChannels(*in[0], {1}, "good_features"); !s) return s;
    cv::goodFeaturesToTrack(in[0]->mat, corners_, max_, quality_, minDistance_);
    out.type = PortType::PointSet;
    out.points.clear();
    for (const auto& p : corners_) out.points.emplace_back(p.x, p.y);
    return ok();
  }

 private:
  int max_ = 200;
  double quality_ = 0.01, minDistance_ = 10;
  std::vector<cv::Point2f> corners_;
};

class MeanNode final : public Node {
 public:
  static std::unique_ptr<Node> make(ConfigReader& r, const NodeContext&) {
    auto n = std::make_unique<MeanNode>();
    n->channel_ = static_cast<int>(r.integer("channel", {0, 3}, 0));
    return n;
  }
  Status process(Inputs in, Value& out, std::int64_t) override {
    if (channel_ >= in[0]->mat.channels())
      return fail(ErrorCode::InvalidArgument,
                  "channel " + std::to_string(channel_) + " of a " + std::to_string(in[0]->mat.channels()) +
                      "-channel image",
                  "channel");
    out.type = PortType::Number;
    out.scalar = cv::mean(in[0]->mat)[channel_];
    return ok();
  }

 private:
  int channel_ = 0;
};

class CountNonZeroNode final : public Node {
 public:
  static std::unique_ptr<Node> make(ConfigReader&, const NodeContext&) {
    return std::make_unique<CountNonZeroNode>();
  }
  Status process(Inputs in, Value& out, std::int64_t) override {
    if (auto s = needChannels(*in[0], {1}, "count_nonzero"); !s) return s;
    out.type = PortType::Number;
    out.scalar = double(cv::countNonZero(in[0]->mat));
    return ok();
  }
};

class PointCountNode final : public Node {
 public:
  static std::unique_ptr<Node> make(ConfigReader&, const NodeContext&) {
    return std::make_unique<PointCountNode>();
  }
  Status process(Inputs in, Value& out, std::int64_t) override {
    out.type = PortType::Number;
    out.scalar = double(in[0]->points.size());
    return ok();
  }
};

/// One slice of a volume as a float image of voxel values. Axis "z" gives
/// the slice k = index with columns i and rows j; "y" gives (i, k); "x" (j, k).
class VolumeSliceNode final : public Node {
 public:
  static std::unique_ptr<Node> make(ConfigReader& r, const NodeContext&) {
    auto n = std::make_unique<VolumeSliceNode>();
    const std::string axis = r.oneOf("axis", {"x", "y", "z"}, "z");
    n->axis_ = axis == "x" ? 0 : axis == "y" ? 1 : 2;
    n->index_ = static_cast<int>(r.integer("index", {-1, 1e6}, -1));
    return n;
  }
  Status process(Inputs in, Value& out, std::int64_t) override {
    const Volume& v = *in[0]->volume;
    const Vec3i d = v.dims();
    const int k = index_ < 0 ? d[axis_] / 2 : index_;
    if (k >= d[axis_])
      return fail(ErrorCode::InvalidArgument,
                  "slice " + std::to_string(k) + " of a volume " + std::to_string(d[axis_]) + " voxels deep",
                  "index");
    const int u = axis_ == 0 ? 1 : 0, w = axis_ == 2 ? 1 : 2;
    ownOutput(out.mat);
    out.mat.create(d[w], d[u], CV_32F);
    for (int row = 0; row < d[w]; ++row) {
      float* dst = out.mat.ptr<float>(row);
      for (int col = 0; col < d[u]; ++col) {
        Vec3i ijk;
        ijk[axis_] = k;
        ijk[u] = col;
        ijk[w] = row;
        dst[col] = static_cast<float>(v.value(ijk[0], ijk[1], ijk[2]));
      }
    }
    out.space = ColorSpace::Gray;
    return ok();
  }

 private:
  int axis_ = 2, index_ = -1;
};

// ---- sinks -----------------------------------------------------------------

/// Creates the folder a sink writes into; a failure shows when the file is opened.
void makeParentDirectory(const std::string& file) {
  std::error_code ec;
  const auto dir = std::filesystem::path(file).parent_path();
  if (!dir.empty()) std::filesystem::create_directories(dir, ec);
}

/// imwrite wants BGR order.
const cv::Mat& forWriting(const Value& v, cv::Mat& scratch) {
  if (v.space == ColorSpace::Rgb) {
    cv::cvtColor(v.mat, scratch, cv::COLOR_RGB2BGR);
    return scratch;
  }
  if (v.space == ColorSpace::Rgba) {
    cv::cvtColor(v.mat, scratch, cv::COLOR_RGBA2BGRA);
    return scratch;
  }
  return v.mat;
}

class FileSink final : public Node {
 public:
  static std::unique_ptr<Node> make(ConfigReader& r, const NodeContext& c) {
    auto n = std::make_unique<FileSink>();
    n->pattern_ = r.string("pattern");
    if (!n->pattern_.empty() && !validPattern(n->pattern_))
      r.addError("needs exactly one integer conversion such as %04d", "pattern");
    n->pattern_ = outputPath(c, n->pattern_);
    n->every_ = r.integer("every", {1, 1e9}, 1);
    return n;
  }
  Status process(Inputs in, Value&, std::int64_t frame) override {
    if (frame % every_ != 0) return ok();
    const Value& v = *in[0];
    if (v.mat.depth() != CV_8U && v.mat.depth() != CV_16U)
      return fail(ErrorCode::InvalidArgument, "image files take 8- or 16-bit pixels", "input",
                  "add a \"convert\" node with \"to\": \"u8\" before this sink");
    const std::string path = formatPattern(pattern_, frame);
    makeParentDirectory(path);
    if (!cv::imwrite(path, forWriting(v, scratch_)))
      return fail(ErrorCode::Io, "cannot write image", path, "check the directory and the extension");
    return ok();
  }

 private:
  std::string pattern_;
  std::int64_t every_ = 1;
  cv::Mat scratch_;
};

class VideoWriterSink final : public Node {
 public:
  static std::unique_ptr<Node> make(ConfigReader& r, const NodeContext& c) {
    auto n = std::make_unique<VideoWriterSink>();
    n->path_ = outputPath(c, r.string("path"));
    n->fps_ = r.number("fps", {0.1, 1000}, 25);
    const std::string fourcc = r.string("fourcc", "MJPG");
    if (fourcc.size() != 4)
      r.addError("must be four characters, e.g. MJPG", "fourcc");
    else
      n->fourcc_ = cv::VideoWriter::fourcc(fourcc[0], fourcc[1], fourcc[2], fourcc[3]);
    return n;
  }
  Status process(Inputs in, Value&, std::int64_t frame) override {
    const Value& v = *in[0];
    if (v.mat.depth() != CV_8U)
      return fail(ErrorCode::InvalidArgument, "video frames take 8-bit pixels", "input",
                  "add a \"convert\" node with \"to\": \"u8\"");
    if (!writer_.isOpened()) {
      makeParentDirectory(path_);
      size_ = v.mat.size();
      if (!writer_.open(path_, fourcc_, fps_, size_, v.mat.channels() != 1))
        return fail(ErrorCode::Io, "cannot open the video for writing", path_,
                    "check the directory and fourcc");
    }
    if (v.mat.size() != size_)
      return fail(ErrorCode::InvalidArgument,
                  "frame " + std::to_string(frame) + " is " + std::to_string(v.mat.cols) + "x" +
                      std::to_string(v.mat.rows) + ", the video " + std::to_string(size_.width) + "x" +
                      std::to_string(size_.height),
                  path_, "resize before this sink");
    writer_.write(forWriting(v, scratch_));
    return ok();
  }
  Status finish() override {
    writer_.release();
    return ok();
  }

 private:
  std::string path_;
  double fps_ = 25;
  int fourcc_ = cv::VideoWriter::fourcc('M', 'J', 'P', 'G');
  cv::VideoWriter writer_;
  cv::Size size_;
  cv::Mat scratch_;
};

/// "slot" keeps the latest image; "texture" does the same for a renderer
/// (FilterGraph::texture) and refuses what a texture cannot show as is.
class SlotSink final : public Node {
 public:
  static std::unique_ptr<Node> make(ConfigReader&, const NodeContext& c) { return make(c, false); }
  static std::unique_ptr<Node> makeTexture(ConfigReader&, const NodeContext& c) { return make(c, true); }
  Status process(Inputs in, Value&, std::int64_t frame) override {
    const Value& v = *in[0];
    if (texture_) {
      const int channels = v.mat.channels();
      const bool colour = v.space == ColorSpace::Rgb || v.space == ColorSpace::Bgr || v.space == ColorSpace::Rgba ||
                          v.space == ColorSpace::Bgra;
      if (v.mat.depth() != CV_8U || channels == 2 || (channels > 1 && !colour))
        return fail(ErrorCode::InvalidArgument,
                    formatString("a texture needs 8-bit gray, RGB or RGBA pixels; got %s%s",
                                 cv::typeToString(v.mat.type()).c_str(),
                                 channels > 1 && !colour ? " in a non-RGB colour space" : ""),
                    "input", "convert first: a \"color\" node (code gray/rgb/bgr) or \"convert\" (to u8)");
    }
    std::lock_guard lock(slot_->mutex);
    slot_->mat = v.mat;  // shares the buffer; the producer allocates anew next frame
    slot_->frame = frame;
    slot_->space = v.space;
    return ok();
  }

 private:
  static std::unique_ptr<Node> make(const NodeContext& c, bool texture) {
    auto n = std::make_unique<SlotSink>();
    auto& slot = (*c.slots)[c.name];
    if (!slot) slot = std::make_shared<SlotState>();
    n->slot_ = slot;
    n->texture_ = texture;
    return n;
  }

  std::shared_ptr<SlotState> slot_;
  bool texture_ = false;
};

// The host's images (FilterGraph::setInput): the newest one at every read,
// 8-bit gray, RGB or RGBA (as RGB: the alpha a renderer reads back is
// opaque), copied into OpenCV's layout so the caller may reuse its buffer.
class InputSource final : public Node {
 public:
  static std::unique_ptr<Node> make(ConfigReader&, const NodeContext& c) {
    auto n = std::make_unique<InputSource>();
    auto& state = (*c.inputs)[c.name];
    if (!state) state = std::make_shared<InputState>();
    n->state_ = state;
    n->name_ = c.name;
    return n;
  }
  Result<bool> read(Value& out, std::int64_t) override {
    Image image;
    {
      std::lock_guard lock(state_->mutex);
      image = state_->image;  // shares the pixels; the host replaces, never rewrites, them
    }
    if (image.empty())
      return fail(ErrorCode::InvalidArgument, "input \"" + name_ + "\" was given no image", "",
                  "call FilterGraph::setInput before running the graph");
    const int channels = image.channels();
    if (image.type() != PixelType::U8 || channels == 2)
      return fail(ErrorCode::InvalidArgument,
                  formatString("input \"%s\" takes 8-bit gray, RGB or RGBA images, got %d channels of %s",
                               name_.c_str(), channels, toString(image.type())),
                  "");
    const cv::Mat view(image.height(), image.width(), CV_MAKETYPE(CV_8U, channels),
                       const_cast<std::byte*>(image.data()), image.strideBytes());
    ownOutput(out.mat);
    if (channels == 4)
      cv::cvtColor(view, out.mat, cv::COLOR_RGBA2RGB);
    else
      view.copyTo(out.mat);
    out.type = PortType::Image;
    out.space = channels == 1 ? ColorSpace::Gray : ColorSpace::Rgb;
    return true;
  }

 private:
  std::shared_ptr<InputState> state_;
  std::string name_;
};

class CallbackSink final : public Node {
 public:
  static std::unique_ptr<Node> make(ConfigReader&, const NodeContext& c) {
    auto n = std::make_unique<CallbackSink>();
    n->callbacks_ = c.callbacks;
    n->name_ = c.name;
    return n;
  }
  Status process(Inputs in, Value&, std::int64_t frame) override {
    auto it = callbacks_->find(name_);
    if (it == callbacks_->end() || !it->second) return ok();  // nothing registered: a no-op sink
    const Value& v = *in[0];
    GraphValue g;
    g.type = v.type;
    Image image;
    if (v.type == PortType::Image) {
      image = imageOf(v.mat);
      g.image = &image;
    }
    g.volume = v.volume.get();
    g.scalar = v.scalar;
    g.points = v.points;
    it->second(g, frame);
    return ok();
  }

 private:
  std::map<std::string, GraphCallback, std::less<>>* callbacks_ = nullptr;
  std::string name_;
};

class CsvSink final : public Node {
 public:
  static std::unique_ptr<Node> make(ConfigReader& r, const NodeContext& c) {
    auto n = std::make_unique<CsvSink>();
    n->path_ = outputPath(c, r.string("path"));
    return n;
  }
  Status process(Inputs in, Value&, std::int64_t frame) override {
    if (!file_.is_open()) {
      makeParentDirectory(path_);
      file_.open(path_, std::ios::trunc);
      if (!file_) return fail(ErrorCode::Io, "cannot open for writing", path_);
      file_ << "frame,value\n";
    }
    char line[64];
    std::snprintf(line, sizeof line, "%lld,%.9g\n", static_cast<long long>(frame), in[0]->scalar);
    file_ << line;
    if (!file_) return fail(ErrorCode::Io, "write failed", path_, "is the disk full?");
    return ok();
  }
  Status finish() override {
    if (file_.is_open()) file_.close();
    return ok();
  }

 private:
  std::string path_;
  std::ofstream file_;
};

// ---- the table ----------------------------------------------------------------

constexpr auto I = PortType::Image;
constexpr auto V = PortType::Volume;
constexpr auto S = PortType::Number;
constexpr auto P = PortType::PointSet;

KindInfo source(std::string kind, PortType out, std::string summary, std::vector<std::string_view> keys,
                std::unique_ptr<Node> (*make)(ConfigReader&, const NodeContext&)) {
  return {{std::move(kind), "source", {}, false, out, std::move(summary)}, std::move(keys), make};
}
KindInfo filter(std::string kind, std::vector<PortType> in, PortType out, std::string summary,
                std::vector<std::string_view> keys,
                std::unique_ptr<Node> (*make)(ConfigReader&, const NodeContext&)) {
  return {{std::move(kind), "filter", std::move(in), false, out, std::move(summary)}, std::move(keys), make};
}
KindInfo sink(std::string kind, std::vector<PortType> in, std::string summary,
              std::vector<std::string_view> keys,
              std::unique_ptr<Node> (*make)(ConfigReader&, const NodeContext&)) {
  return {{std::move(kind), "sink", std::move(in), false, std::nullopt, std::move(summary)},
          std::move(keys),
          make};
}

}  // namespace

const std::vector<KindInfo>& kindTable() {
  static const std::vector<KindInfo> table = [] {
    std::vector<KindInfo> t{
        source("image_file", I, "one image file, repeated `frames` times",
               {"path", "frames", "order", "mode"}, &ImageFileSource::make),
        source("image_sequence", I, "numbered files (`pattern` from `start`) or a `files` list",
               {"pattern", "start", "files", "order", "mode"}, &ImageSequenceSource::make),
        source("video_file", I, "a video file through OpenCV's FFmpeg backend", {"path", "order"},
               &CaptureSource::makeFile),
        source("camera", I, "a V4L2 camera by index", {"index", "width", "height", "order"},
               &CaptureSource::makeCamera),
        source("synthetic", I,
               "8-bit frames with known motion: moving_disc, moving_texture, checkerboard, noise",
               {"pattern", "width", "height", "frames", "velocity", "radius", "square", "seed"},
               &SyntheticSource::make),
        source("input", I, "the host's images (FilterGraph::setInput): a scene's rendered frames", {},
               &InputSource::make),
        source("volume_file", V, "a volume file (NIfTI, NRRD, MetaImage, DICOM, VDB)", {"path", "frames"},
               &VolumeFileSource::make),
        filter("color", {I}, I, "colour conversion to gray, rgb, bgr, hsv or lab", {"code"},
               &ColorNode::make),
        filter("resize", {I}, I, "to width x height or by scale",
               {"width", "height", "scale", "interpolation"}, &ResizeNode::make),
        filter("gaussian_blur", {I}, I, "Gaussian blur (ksize, sigma in pixels)", {"ksize", "sigma"},
               &GaussianNode::make),
        filter("median_blur", {I}, I, "median filter", {"ksize"}, &MedianNode::make),
        filter("bilateral", {I}, I, "edge-preserving bilateral filter", {"d", "sigma_color", "sigma_space"},
               &BilateralNode::make),
        filter("threshold", {I}, I, "fixed or Otsu threshold", {"value", "max", "type", "otsu"},
               &ThresholdNode::make),
        filter("adaptive_threshold", {I}, I, "local mean or Gaussian threshold",
               {"max", "method", "type", "block", "c"}, &AdaptiveThresholdNode::make),
        filter("sobel", {I}, I, "Sobel derivative (float)", {"dx", "dy", "ksize"}, &SobelNode::make),
        filter("gradient_magnitude", {I}, I, "|grad| by Sobel (float)", {"ksize"},
               &GradientMagnitudeNode::make),
        filter("vector_magnitude", {I}, I, "length of a 2-channel vector image, e.g. optical flow", {},
               &VectorMagnitudeNode::make),
        filter("canny", {I}, I, "Canny edges", {"low", "high", "aperture", "l2"}, &CannyNode::make),
        filter("morphology", {I}, I, "erode, dilate, open, close, gradient, tophat, blackhat",
               {"op", "shape", "size", "iterations"}, &MorphologyNode::make),
        filter("undistort", {I}, I, "lens undistortion (camera_matrix row-major, dist_coeffs)",
               {"camera_matrix", "dist_coeffs"}, &UndistortNode::make),
        filter("background_subtraction", {I}, I, "foreground mask (MOG2 or KNN)",
               {"method", "history", "threshold", "shadows", "learning_rate"}, &BackgroundNode::make),
        filter("optical_flow", {I}, I,
               "dense Farneback flow from the previous frame (2-channel float, px/frame)",
               {"pyr_scale", "levels", "window", "iterations", "poly_n", "poly_sigma"},
               &OpticalFlowNode::make),
        filter("absdiff", {I, I}, I, "per-pixel |a - b|", {}, &AbsDiffNode::make),
        filter("convert", {I}, I, "pixel type conversion: to u8/u16/f32 with scale, offset, abs",
               {"to", "scale", "offset", "abs"}, &ConvertNode::make),
        filter("good_features", {I}, P, "Shi-Tomasi corners", {"max_corners", "quality", "min_distance"},
               &GoodFeaturesNode::make),
        filter("mean", {I}, S, "mean of one channel", {"channel"}, &MeanNode::make),
        filter("count_nonzero", {I}, S, "number of non-zero pixels", {}, &CountNonZeroNode::make),
        filter("point_count", {P}, S, "number of points", {}, &PointCountNode::make),
        filter("volume_slice", {V}, I, "one axis-aligned slice as a float image", {"axis", "index"},
               &VolumeSliceNode::make),
        sink("file", {I}, "image files named by a printf pattern", {"pattern", "every"}, &FileSink::make),
        sink("video_writer", {I}, "a video file", {"path", "fps", "fourcc"}, &VideoWriterSink::make),
        sink("slot", {I}, "keeps the latest image for FilterGraph::slot(name)", {}, &SlotSink::make),
        sink("texture", {I},
             "the latest 8-bit gray/RGB/BGR(A) frame for a renderer texture (FilterGraph::texture)", {},
             &SlotSink::makeTexture),
        sink("callback", {}, "calls the function given to FilterGraph::setCallback", {}, &CallbackSink::make),
        sink("csv", {S}, "frame,value lines", {"path"}, &CsvSink::make),
    };
    for (auto& k : t)
      if (k.info.kind == "callback") k.info.anyInputType = true;
    return t;
  }();
  return table;
}

const KindInfo* findKind(std::string_view kind) {
  for (const auto& k : kindTable())
    if (k.info.kind == kind) return &k;
  return nullptr;
}

}  // namespace dm::graph
