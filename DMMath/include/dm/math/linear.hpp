// dm/math/linear.hpp — linear solvers: dense direct (Eigen), sparse direct
// (Eigen SimplicialLDLT) and our preconditioned conjugate gradient (PCG).
//
// Which one to use:
//  * small dense systems (n up to a few hundred): solveDense();
//  * sparse SPD systems solved once, or many times with the same matrix:
//    SparseLdltSolver (factor once, solve many);
//  * large sparse SPD systems that change every step (soft bodies, implicit
//    integration), or operators never assembled: PcgSolver, whose workspace is
//    kept between solves so a simulation step does not allocate.
//
// Every solver checks its input (sizes, NaN/Inf, symmetry) and returns a
// dm::Result whose message says what went wrong and what to try.
//
// @code
//   dm::PcgSolver pcg({.tolerance = 1e-10, .preconditioner = dm::Preconditioner::IncompleteCholesky});
//   if (auto s = pcg.compute(A); !s) return s.error();
//   dm::VecX x;  auto report = pcg.solve(b, x);  // report->iterations, report->relativeResidual
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/math/types.hpp>

#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

namespace dm {

// ---------------------------------------------------------------------------
// Dense direct solvers
// ---------------------------------------------------------------------------

/// Factorization used by solveDense().
enum class DenseMethod : std::uint8_t {
  Ldlt,          ///< symmetric matrices: robust pivoted LDLᵀ (Eigen::LDLT); SPD unless allowIndefinite
  PartialPivLu,  ///< general square invertible matrices: LU with partial pivoting (fastest general)
  ColPivQr,      ///< general square matrices: Householder QR with column pivoting (rank-revealing, safest)
};

/// Options of solveDense().
struct DenseSolveOptions {
  DenseMethod method = DenseMethod::Ldlt;
  /// Ldlt only: accept symmetric indefinite matrices (negative pivots). When
  /// false (default) a non-positive pivot is reported as "not positive definite".
  bool allowIndefinite = false;
  /// Ldlt only: max |A − Aᵀ| allowed, relative to max |A|.
  double symmetryTolerance = 1e-10;
  /// A matrix whose estimated reciprocal condition number (LU, LDLT) or whose
  /// relative smallest |R_ii| (QR) is below this is reported as singular.
  double singularTolerance = 1e-13;
};

/// Solves the dense square system A x = b (n×n, n) with the chosen
/// factorization. O(n³). Fails with InvalidArgument on an empty or
/// non-square A, a size mismatch, NaN/Inf, an asymmetric A (Ldlt), a matrix
/// that is not positive definite (Ldlt without allowIndefinite), or a
/// numerically singular matrix; the message names the pivot or the estimated
/// condition number.
/// @code
///   auto x = dm::solveDense(K, f);                                         // K SPD
///   auto y = dm::solveDense(J, r, {.method = dm::DenseMethod::ColPivQr});  // general J
/// @endcode
Result<VecX> solveDense(const MatX& A, const VecX& b, const DenseSolveOptions& options = {});

// ---------------------------------------------------------------------------
// Sparse direct solver
// ---------------------------------------------------------------------------

/// Sparse LDLᵀ factorization (Eigen::SimplicialLDLT, AMD ordering) of a
/// symmetric matrix, factored once and solved many times. Both triangles of A
/// must be stored (A is checked for symmetry). Re-factoring a matrix with the
/// same sparsity pattern reuses the symbolic analysis (factorize()).
/// Move-only.
class SparseLdltSolver {
 public:
  SparseLdltSolver();
  ~SparseLdltSolver();
  SparseLdltSolver(SparseLdltSolver&&) noexcept;
  SparseLdltSolver& operator=(SparseLdltSolver&&) noexcept;
  SparseLdltSolver(const SparseLdltSolver&) = delete;
  SparseLdltSolver& operator=(const SparseLdltSolver&) = delete;

  /// Symbolic analysis + numeric factorization of the n×n symmetric A.
  /// `requirePositiveDefinite` (default) rejects a non-positive pivot.
  /// Fails on non-square, NaN/Inf, asymmetric (relative 1e-10), zero pivot
  /// (singular) or non-positive pivot (not SPD) matrices.
  Status compute(const SparseMat& A, bool requirePositiveDefinite = true);
  /// Numeric re-factorization of a matrix with the same pattern as the last
  /// compute() (e.g. a stiffness matrix whose values changed); same checks.
  Status factorize(const SparseMat& A, bool requirePositiveDefinite = true);
  /// Solves A x = b with the current factorization (b of size n). O(nnz(L)).
  /// Fails if nothing was factored, on a size mismatch or NaN/Inf in b.
  Result<VecX> solve(const VecX& b) const;
  /// Size n of the factored matrix, 0 before compute().
  Eigen::Index size() const noexcept;

 private:
  Status checkAndFactor(const SparseMat& A, bool requirePositiveDefinite, bool analyze);
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// One-shot sparse SPD solve with SparseLdltSolver. O(nnz(L)) after ordering.
/// @code
///   auto x = dm::solveSparseSpd(L, b);   // L: symmetric positive definite
///   if (!x) dm::log::error("%s", x.error().message().c_str());
/// @endcode
Result<VecX> solveSparseSpd(const SparseMat& A, const VecX& b);

// ---------------------------------------------------------------------------
// Preconditioned conjugate gradient
// ---------------------------------------------------------------------------

/// Preconditioner M ≈ A used by PcgSolver.
enum class Preconditioner : std::uint8_t {
  None,                ///< M = I
  Jacobi,              ///< M = diag(A); needs a positive diagonal
  IncompleteCholesky,  ///< M = L Lᵀ, IC(0): L has the pattern of tril(A); shifted on breakdown
};

/// Options of PcgSolver.
struct PcgOptions {
  /// Converged when ‖b − A x‖₂ ≤ tolerance · ‖b‖₂ (relative residual; the true
  /// residual is recomputed before convergence is declared).
  double tolerance = 1e-8;
  /// Iteration limit; exceeding it is an error (ErrorCode::Timeout).
  int maxIterations = 1000;
  Preconditioner preconditioner = Preconditioner::Jacobi;
  /// When true, x passed to solve() is the initial guess (it must have size
  /// n); otherwise the iteration starts from x = 0.
  bool useInitialGuess = false;
};

/// What a PCG solve did.
struct PcgReport {
  int iterations = 0;             ///< CG iterations (matrix-vector products after the first residual)
  double relativeResidual = 0.0;  ///< ‖b − A x‖ / ‖b‖ at exit (0 when b = 0)
  double residualNorm = 0.0;      ///< ‖b − A x‖₂ at exit
};

/// y = A x for a symmetric positive definite operator A; y is already sized n.
using LinearOperator = std::function<void(const VecX& x, VecX& y)>;

/// Preconditioned conjugate gradient for symmetric positive definite systems.
///
/// Model/data split: compute() captures the matrix and builds the
/// preconditioner; solve() reuses the solver's vectors, so once compute() (or
/// reserve()) has sized them, repeated solves do not allocate. compute() on a
/// matrix with the same size and sparsity pattern as before copies values
/// into the existing storage and does not allocate either.
///
/// Errors: size mismatch and NaN/Inf (InvalidArgument), a non-positive
/// diagonal for Jacobi/IC(0) or negative curvature pᵀAp ≤ 0 during the
/// iteration (InvalidArgument: the matrix is not SPD), and non-convergence
/// within maxIterations (Timeout; the message gives the residual reached).
/// After any solve, x holds the last iterate and lastReport() the counts.
/// Not thread-safe: use one solver per thread.
class PcgSolver {
 public:
  explicit PcgSolver(PcgOptions options = {});

  /// Replaces the options; a new preconditioner kind takes effect at the
  /// next compute().
  void setOptions(const PcgOptions& options) { options_ = options; }
  const PcgOptions& options() const noexcept { return options_; }

  /// Captures the n×n SPD matrix A (both triangles stored) and builds the
  /// preconditioner. Fails on a non-square or empty A, NaN/Inf, an asymmetric
  /// A (relative 1e-10), or a missing/non-positive diagonal entry when a
  /// preconditioner needs it. O(nnz) for None/Jacobi; IC(0) costs
  /// O(Σ_j nnz(col j)²) of the lower triangle.
  Status compute(const SparseMat& A);

  /// Solves A x = b with the matrix of the last compute(). x: initial guess
  /// when options().useInitialGuess, else overwritten; resized to n.
  Result<PcgReport> solve(const VecX& b, VecX& x);

  /// Matrix-free solve: A is given as an operator y = A x of size n = b.size().
  /// `preconditioner`, when non-empty, applies z = M⁻¹ r (SPD); otherwise M = I
  /// (options().preconditioner is ignored here: a matrix-free solve has no
  /// matrix to build Jacobi or IC(0) from — pass the inverse diagonal yourself).
  Result<PcgReport> solve(const LinearOperator& A, const VecX& b, VecX& x,
                          const LinearOperator& preconditioner = {});

  /// Sizes the workspace for systems of size n, so the first matrix-free
  /// solve does not allocate either.
  void reserve(Eigen::Index n);

  /// Counts of the last solve (also after a failed one).
  const PcgReport& lastReport() const noexcept { return report_; }
  /// Diagonal shift α actually used by IC(0) (factor of A + α·diag(A));
  /// 0 unless plain IC(0) broke down.
  double incompleteCholeskyShift() const noexcept { return icShift_; }
  /// Size n of the captured matrix; 0 before compute() or after a failed one.
  Eigen::Index size() const noexcept { return ready_ ? A_.rows() : 0; }

 private:
  template <class ApplyA, class ApplyM>
  Result<PcgReport> iterate(const ApplyA& applyA, const ApplyM& applyM, const VecX& b, VecX& x,
                            const char* where, const char* preconditionerLabel, const char* advice);
  Status buildIncompleteCholesky();
  bool factorIc(double shift);
  void applyIc(const VecX& r, VecX& z) const;

  PcgOptions options_;
  bool ready_ = false;  // the last compute() succeeded
  Preconditioner builtPreconditioner_ = Preconditioner::None;
  SparseMat A_;
  VecX invDiag_;
  // IC(0) factor L, compressed columns, diagonal first in each column.
  std::vector<int> icColPtr_;
  std::vector<int> icRowIdx_;
  std::vector<double> icVal_;
  std::vector<double> icDiagA_;
  double icShift_ = 0.0;
  // Workspace.
  VecX r_, z_, p_, q_;
  PcgReport report_;
};

/// One-shot PCG solve (allocates a PcgSolver). x: see PcgOptions::useInitialGuess.
/// @code
///   dm::VecX x;
///   auto rep = dm::solvePcg(A, b, x, {.preconditioner = dm::Preconditioner::IncompleteCholesky});
/// @endcode
Result<PcgReport> solvePcg(const SparseMat& A, const VecX& b, VecX& x, const PcgOptions& options = {});

}  // namespace dm
