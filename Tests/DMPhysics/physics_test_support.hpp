// Helpers shared by the DMPhysics tests.
#pragma once

#include <dm/collide/bvh.hpp>
#include <dm/core/mesh.hpp>

#include <gtest/gtest.h>

#include <utility>

namespace dm::test {

inline constexpr double kG = 9.81;  // standard gravity, m/s²

/// The bounding-volume hierarchy of `mesh` (a test failure if it cannot be built).
inline dm::MeshBvh treeOf(const dm::Mesh& mesh) {
  auto t = dm::MeshBvh::build(mesh);
  EXPECT_TRUE(t.ok());
  return std::move(*t);
}

}  // namespace dm::test
