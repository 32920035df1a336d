// dm/renderer/image_compare.hpp — image comparison for golden-image render
// tests, and the reference-image workflow.
//
// compareImages() counts pixels whose largest channel difference exceeds a
// per-pixel threshold and passes when their fraction stays within a maximum;
// it also returns a diff image (differing pixels red over a dimmed grey copy
// of the reference) to write next to a failing test's output.
// checkGolden() is what render tests call: compare a rendered image with
// Tests/DMRenderer/golden/NAME.png; on failure write NAME.actual.png and
// NAME.diff.png into the output directory and say where they are. With the
// environment variable DM_UPDATE_GOLDEN=1 it (re)writes the reference instead
// and passes — the one deliberate way to regenerate references
// (scripts/update_golden.sh runs the render tests that way).
//
// @code
//   auto r = dm::checkGolden(img, golden / "sphere_lit.png", outDir, {.pixelThreshold = 8, .maxFraction =
//   0.002}); EXPECT_TRUE(r) << r.error();
// @endcode
#pragma once

#include <dm/core/image.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <cstddef>
#include <filesystem>

namespace dm {

/// How close two images must be.
struct ImageTolerance {
  int pixelThreshold = 8;      ///< largest |a - b| over channels (0..255) a pixel may differ by
  double maxFraction = 0.002;  ///< fraction of pixels allowed over the threshold
};

/// What a comparison found.
struct ImageDiff {
  std::size_t differing = 0;  ///< pixels over the threshold
  std::size_t total = 0;      ///< pixels compared
  int maxDifference = 0;      ///< largest channel difference anywhere (0..255)
  double meanDifference = 0;  ///< mean of the per-pixel largest channel difference
  bool passed = false;        ///< differing <= maxFraction * total
  Image diff;                 ///< RGB8 visualisation (empty when sizes differ)
  double fraction() const { return total == 0 ? 0.0 : double(differing) / double(total); }
};

/// Compares two U8 images of equal size (gray, RGB or RGBA; alpha ignored
/// when only one has it). Fails on size or format mismatch, naming both.
Result<ImageDiff> compareImages(const Image& actual, const Image& reference,
                                const ImageTolerance& tolerance = {});

/// Golden-image check (see the file comment). Fails when the reference is
/// missing (hint: how to create it), unreadable, or differs beyond the
/// tolerance (the message gives the numbers and the paths written).
Status checkGolden(const Image& actual, const std::filesystem::path& reference,
                   const std::filesystem::path& outDir, const ImageTolerance& tolerance = {});

/// Number of pixels of a U8 image whose colour differs from `background`
/// (0..255 per channel; alpha ignored) by more than `threshold` in any
/// colour channel — the covered area, for geometric render checks.
std::size_t countCoveredPixels(const Image& image, const Vec3f& background, int threshold = 16);

}  // namespace dm
