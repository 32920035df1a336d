// Private: constants shared by several DMCollide sources. Not installed.
#pragma once

#include <dm/collide/bvh.hpp>

#include <limits>

namespace dm::detail {

inline constexpr double kInf = std::numeric_limits<double>::infinity();

/// Entries of the stack of a depth-first walk down one MeshBvh (mesh queries,
/// mesh sweeps): <= depth + 1.
inline constexpr int kStack = 128;
static_assert(kStack > MeshBvh::kMaxDepth + 1);

}  // namespace dm::detail
