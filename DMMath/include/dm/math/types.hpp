// dm/math/types.hpp — the Eigen aliases of dm/core/types.hpp, plus the
// dynamic-size and sparse types DMMath's solvers use. Simulation is double.
#pragma once

#include <dm/core/types.hpp>

#include <Eigen/SparseCore>

namespace dm {
using SparseMat = Eigen::SparseMatrix<double>;  ///< column-major, int indices
using Triplet = Eigen::Triplet<double>;
}  // namespace dm
