// Helpers shared by the DMVision tests.
#pragma once

#include <dm/core/volume.hpp>

#include <cstddef>

namespace dm::test {

/// The number of non-zero voxels of `v` (the size of a mask).
inline std::size_t countOn(const Volume& v) {
  std::size_t c = 0;
  for (std::size_t n = 0; n < v.voxelCount(); ++n) c += v.valueAt(n) != 0;
  return c;
}

}  // namespace dm::test
