// Helpers shared by the DMCollide tests.
#pragma once

#include <dm/core/types.hpp>

#include <random>

namespace dm::test {

/// The pose translated to (x, y, z), without rotation.
inline dm::Isometry3 at(double x, double y, double z) {
  dm::Isometry3 p = dm::Isometry3::Identity();
  p.translation() = dm::Vec3(x, y, z);
  return p;
}

/// The pose translated to `t`, without rotation.
inline dm::Isometry3 at(const dm::Vec3& t) {
  dm::Isometry3 p = dm::Isometry3::Identity();
  p.translation() = t;
  return p;
}

/// A unit vector of uniformly random direction.
inline dm::Vec3 randomUnit(std::mt19937_64& rng) {
  std::normal_distribution<double> g(0.0, 1.0);
  return dm::Vec3(g(rng), g(rng), g(rng)).normalized();
}

}  // namespace dm::test
