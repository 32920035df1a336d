// image_compare.cpp — pixel comparison, diff images, golden references.
#include <dm/io/image_io.hpp>
#include <dm/renderer/image_compare.hpp>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <system_error>

namespace dm {

namespace {

// Channel c of pixel (x, y) as RGB(A) even for gray images.
int channel(const Image& img, int x, int y, int c) {
  const int ch = img.channels() <= 2 ? 0 : c;
  return static_cast<int>(img.at<std::uint8_t>(x, y, ch));
}

}  // namespace

Result<ImageDiff> compareImages(const Image& actual, const Image& reference,
                                const ImageTolerance& tolerance) {
  if (actual.type() != PixelType::U8 || reference.type() != PixelType::U8)
    return fail(ErrorCode::Unsupported,
                std::string("pixel types ") + toString(actual.type()) + " and " + toString(reference.type()),
                "compareImages", "compare 8-bit images");
  if (actual.width() != reference.width() || actual.height() != reference.height())
    return fail(ErrorCode::InvalidArgument,
                formatString("rendered %dx%d, reference %dx%d", actual.width(), actual.height(),
                             reference.width(), reference.height()),
                "compareImages", "render at the reference's size, or regenerate it with DM_UPDATE_GOLDEN=1");
  const bool grayA = actual.channels() <= 2, grayR = reference.channels() <= 2;
  if (grayA != grayR)
    return fail(ErrorCode::InvalidArgument,
                formatString("%d channels vs %d channels", actual.channels(), reference.channels()),
                "compareImages", "compare images of the same colour model");
  const int colorChannels = grayA ? 1 : 3;
  ImageDiff d;
  d.total = static_cast<std::size_t>(actual.width()) * static_cast<std::size_t>(actual.height());
  auto vis = Image::create(actual.width(), actual.height(), 3, PixelType::U8);
  if (!vis) return vis.error();
  double sum = 0;
  for (int y = 0; y < actual.height(); ++y)
    for (int x = 0; x < actual.width(); ++x) {
      int m = 0, lum = 0;
      for (int c = 0; c < colorChannels; ++c) {
        m = std::max(m, std::abs(channel(actual, x, y, c) - channel(reference, x, y, c)));
        lum += channel(reference, x, y, c);
      }
      sum += m;
      d.maxDifference = std::max(d.maxDifference, m);
      const bool over = m > tolerance.pixelThreshold;
      if (over) ++d.differing;
      const auto grey = static_cast<std::uint8_t>(lum / colorChannels / 3);
      vis->at<std::uint8_t>(x, y, 0) = over ? 255 : grey;
      vis->at<std::uint8_t>(x, y, 1) = over ? 0 : grey;
      vis->at<std::uint8_t>(x, y, 2) = over ? 0 : grey;
    }
  d.meanDifference = d.total == 0 ? 0.0 : sum / double(d.total);
  d.passed = double(d.differing) <= tolerance.maxFraction * double(d.total);
  d.diff = std::move(*vis);
  return d;
}

Status checkGolden(const Image& actual, const std::filesystem::path& reference,
                   const std::filesystem::path& outDir, const ImageTolerance& tolerance) {
  const char* update = std::getenv("DM_UPDATE_GOLDEN");
  if (update != nullptr && std::string_view(update) == "1") {
    std::error_code ec;
    std::filesystem::create_directories(reference.parent_path(), ec);
    return writePng(actual, reference);
  }
  std::error_code ec;
  if (!std::filesystem::exists(reference, ec))
    return fail(ErrorCode::NotFound, "no reference image", reference.string(),
                "render it once on purpose with DM_UPDATE_GOLDEN=1 (scripts/update_golden.sh), look at it, "
                "commit it");
  auto ref = readPng(reference);
  if (!ref) return ref.error();
  auto diff = compareImages(actual, *ref, tolerance);
  if (!diff) return diff.error().within(reference.string());
  if (diff->passed) return ok();
  std::filesystem::create_directories(outDir, ec);
  const std::string stem = reference.stem().string();
  const auto actualPath = outDir / (stem + ".actual.png");
  const auto diffPath = outDir / (stem + ".diff.png");
  (void)writePng(actual, actualPath);
  (void)writePng(diff->diff, diffPath);
  return fail(
      ErrorCode::InvalidArgument,
      formatString("%zu of %zu pixels (%.4f%%) differ by more than %d (allowed %.4f%%); max %d, mean %.3f",
                   diff->differing, diff->total, 100.0 * diff->fraction(), tolerance.pixelThreshold,
                   100.0 * tolerance.maxFraction, diff->maxDifference, diff->meanDifference),
      reference.string(),
      "rendered image: " + actualPath.string() + ", diff: " + diffPath.string() +
          "; if the change is intended, regenerate with DM_UPDATE_GOLDEN=1");
}

std::size_t countCoveredPixels(const Image& image, const Vec3f& background, int threshold) {
  if (image.type() != PixelType::U8 || image.empty()) return 0;
  const int cc = image.channels() <= 2 ? 1 : 3;
  std::size_t n = 0;
  for (int y = 0; y < image.height(); ++y)
    for (int x = 0; x < image.width(); ++x) {
      bool over = false;
      for (int c = 0; c < cc && !over; ++c)
        over = std::abs(channel(image, x, y, c) - static_cast<int>(std::lround(background[c]))) > threshold;
      if (over) ++n;
    }
  return n;
}

}  // namespace dm
