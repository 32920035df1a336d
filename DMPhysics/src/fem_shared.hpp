// Internal to DMPhysics: what fem.cpp (FemBody) and fem_mesh.cpp (TetMesh
// and its builders) share: error helpers and the resolution of hanging
// nodes into independent ones.
#pragma once

#include <dm/core/result.hpp>
#include <dm/physics/fem.hpp>

#include <cstdint>
#include <string>
#include <vector>

namespace dm::femimpl {

// "%g" of a double, for error messages.
std::string num(double v);

// An InvalidArgument error.
Error invalid(std::string what, std::string where, std::string hint = {});

// Hanging nodes resolved to independent nodes: hanging node node[k] is
// Σ weight[s]·(node master[s]) for s in [start[k], start[k+1]), the weights
// summing to 1, masters distinct and sorted.
struct ResolvedHanging {
  std::vector<std::uint32_t> node, start{0}, master;
  std::vector<double> weight;
};

// Expands every entry of mesh.hanging through chains of hanging masters.
// Needs indices in range (validate() checks them first). Fails, naming the
// entry, on a cycle or on a chain that expands to more than kMaxTerms terms.
Result<ResolvedHanging> resolveHanging(const TetMesh& mesh, const char* where);

}  // namespace dm::femimpl
