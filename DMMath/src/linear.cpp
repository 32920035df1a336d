#include <dm/math/linear.hpp>

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <Eigen/OrderingMethods>
#include <Eigen/QR>
#include <Eigen/SparseCholesky>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

#include "math_internal.hpp"

namespace dm {
namespace {

using detail::firstNonFinite;
using detail::invalid;

Status checkFiniteVector(const VecX& v, const char* name, const char* where) {
  if (const Eigen::Index i = firstNonFinite(v); i >= 0)
    return invalid(formatString("%s[%td] is %g (NaN or Inf)", name, i, v[i]), where,
                   "check the inputs of the system for uninitialised or diverged values");
  return ok();
}

// ----- dense ---------------------------------------------------------------

Status checkDense(const MatX& A, const VecX& b, const char* where) {
  if (A.rows() == 0 || A.cols() == 0)
    return invalid("the matrix is empty", where, "pass an n×n matrix, n ≥ 1");
  if (A.rows() != A.cols())
    return invalid(formatString("the matrix is %td×%td, not square", A.rows(), A.cols()), where,
                   "these solvers need a square system; for least squares use Eigen's QR on Aᵀ directly");
  if (b.size() != A.rows())
    return invalid(formatString("right-hand side has %td entries but the matrix is %td×%td", b.size(),
                                A.rows(), A.cols()),
                   where, "b must have one entry per matrix row");
  for (Eigen::Index j = 0; j < A.cols(); ++j)
    for (Eigen::Index i = 0; i < A.rows(); ++i)
      if (!std::isfinite(A(i, j)))
        return invalid(formatString("A(%td,%td) is %g (NaN or Inf)", i, j, A(i, j)), where,
                       "check how the matrix was assembled");
  return checkFiniteVector(b, "b", where);
}

Status checkSingular(double rcond, double tol, const char* method, const char* where) {
  if (!(rcond >= tol))
    return invalid(
        formatString("the matrix is numerically singular: %s estimates reciprocal condition number "
                     "%.3e < singularTolerance %.3e",
                     method, rcond, tol),
        where,
        "check for a missing constraint (e.g. an unfixed rigid-body mode) or duplicated rows; "
        "lower singularTolerance only if you accept an inaccurate solution");
  return ok();
}

Result<VecX> solveLdlt(const MatX& A, const VecX& b, const DenseSolveOptions& o, const char* where) {
  const double scale = A.cwiseAbs().maxCoeff();
  double asym = 0.0;
  Eigen::Index ai = 0, aj = 0;
  for (Eigen::Index j = 0; j < A.cols(); ++j)
    for (Eigen::Index i = j + 1; i < A.rows(); ++i)
      if (const double d = std::abs(A(i, j) - A(j, i)); d > asym) asym = d, ai = i, aj = j;
  if (asym > o.symmetryTolerance * scale)
    return invalid(formatString("the matrix is not symmetric: |A(%td,%td) − A(%td,%td)| = %.3e > %.1e·max|A|",
                                ai, aj, aj, ai, asym, o.symmetryTolerance),
                   where, "use DenseMethod::PartialPivLu or ColPivQr for general matrices");
  Eigen::LDLT<MatX> ldlt(A);
  if (ldlt.info() != Eigen::Success)
    return invalid("LDLT factorization reported a numerical issue", where,
                   "the matrix may be singular or badly scaled; try DenseMethod::ColPivQr");
  const VecX& d = ldlt.vectorD();
  const double dmax = d.cwiseAbs().maxCoeff();
  Eigen::Index kmin = 0;
  const double dmin = d.cwiseAbs().minCoeff(&kmin);
  if (dmax == 0.0 || dmin <= o.singularTolerance * dmax)
    return invalid(formatString("the matrix is numerically singular: LDLT pivot %td is %.3e (largest %.3e)",
                                kmin, d[kmin], dmax),
                   where,
                   "check for a missing constraint (e.g. an unfixed rigid-body mode) or duplicated rows");
  if (!o.allowIndefinite) {
    Eigen::Index kneg = 0;
    if (d.minCoeff(&kneg) <= 0.0)
      return invalid(
          formatString("the matrix is not positive definite: LDLT pivot %td is %.3e", kneg, d[kneg]), where,
          "check the sign convention of the assembly; for symmetric indefinite systems (saddle "
          "points, constraints) set allowIndefinite = true");
  }
  if (Status s = checkSingular(ldlt.rcond(), o.singularTolerance, "LDLT", where); !s)
    return std::move(s).error();
  return VecX(ldlt.solve(b));
}

Result<VecX> solveLu(const MatX& A, const VecX& b, const DenseSolveOptions& o, const char* where) {
  Eigen::PartialPivLU<MatX> lu(A);
  const auto u = lu.matrixLU().diagonal().cwiseAbs();
  Eigen::Index kmin = 0;
  const double umin = u.minCoeff(&kmin);
  const double umax = u.maxCoeff();
  if (umax == 0.0 || umin <= o.singularTolerance * umax)
    return invalid(
        formatString("the matrix is numerically singular: LU pivot U(%td,%td) = %.3e (largest %.3e)", kmin,
                     kmin, lu.matrixLU()(kmin, kmin), umax),
        where, "check for dependent rows/columns; DenseMethod::ColPivQr reports the numerical rank");
  if (Status s = checkSingular(lu.rcond(), o.singularTolerance, "LU", where); !s) return std::move(s).error();
  return VecX(lu.solve(b));
}

Result<VecX> solveQr(const MatX& A, const VecX& b, const DenseSolveOptions& o, const char* where) {
  Eigen::ColPivHouseholderQR<MatX> qr(A);
  qr.setThreshold(o.singularTolerance);
  if (qr.rank() < A.rows())
    return invalid(formatString("the matrix is rank deficient: numerical rank %td of %td (|R_ii| ≤ %.1e·max)",
                                qr.rank(), A.rows(), o.singularTolerance),
                   where, "remove dependent equations or add the missing constraints");
  return VecX(qr.solve(b));
}

// ----- sparse helpers --------------------------------------------------------

Status checkSparseSquareFinite(const SparseMat& A, const char* where) {
  if (A.rows() == 0 || A.cols() == 0)
    return invalid("the matrix is empty", where, "pass an n×n matrix, n ≥ 1");
  if (A.rows() != A.cols())
    return invalid(formatString("the matrix is %td×%td, not square", A.rows(), A.cols()), where,
                   "a symmetric solver needs a square matrix");
  for (Eigen::Index j = 0; j < A.outerSize(); ++j)
    for (SparseMat::InnerIterator it(A, j); it; ++it)
      if (!std::isfinite(it.value()))
        return invalid(formatString("A(%td,%td) is %g (NaN or Inf)", it.row(), it.col(), it.value()), where,
                       "check how the matrix was assembled");
  return ok();
}

// Symmetry check without allocating: every stored (i,j) is compared with
// A(j,i) (binary search in column i). O(nnz log nnz_col).
Status checkSparseSymmetric(const SparseMat& A, double relTol, const char* where) {
  double scale = 0.0;
  for (Eigen::Index j = 0; j < A.outerSize(); ++j)
    for (SparseMat::InnerIterator it(A, j); it; ++it) scale = std::max(scale, std::abs(it.value()));
  for (Eigen::Index j = 0; j < A.outerSize(); ++j)
    for (SparseMat::InnerIterator it(A, j); it; ++it) {
      if (it.row() == j) continue;
      const double other = A.coeff(j, it.row());
      if (std::abs(other - it.value()) > relTol * scale)
        return invalid(formatString("the matrix is not symmetric: A(%td,%td) = %.6g but A(%td,%td) = %.6g",
                                    it.row(), j, it.value(), j, it.row(), other),
                       where,
                       "store both triangles of a symmetric matrix; for non-symmetric systems use "
                       "solveDense() with PartialPivLu/ColPivQr or Eigen::SparseLU");
    }
  return ok();
}

constexpr double kSymmetryTolerance = 1e-10;

const char* preconditionerName(Preconditioner p) {
  switch (p) {
    case Preconditioner::None:
      return "none";
    case Preconditioner::Jacobi:
      return "Jacobi";
    case Preconditioner::IncompleteCholesky:
      return "IC(0)";
  }
  return "?";
}

}  // namespace

Result<VecX> solveDense(const MatX& A, const VecX& b, const DenseSolveOptions& options) {
  constexpr const char* where = "solveDense";
  if (Status s = checkDense(A, b, where); !s) return std::move(s).error();
  if (!(options.singularTolerance >= 0.0) || !(options.symmetryTolerance >= 0.0))
    return invalid("singularTolerance and symmetryTolerance must be ≥ 0", where);
  Result<VecX> x = [&]() -> Result<VecX> {
    switch (options.method) {
      case DenseMethod::Ldlt:
        return solveLdlt(A, b, options, where);
      case DenseMethod::PartialPivLu:
        return solveLu(A, b, options, where);
      case DenseMethod::ColPivQr:
        return solveQr(A, b, options, where);
    }
    return invalid("unknown DenseMethod", where);
  }();
  if (x && !x->allFinite())
    return fail(ErrorCode::Internal, "the solution has NaN/Inf entries although the factorization passed",
                where, "the matrix is probably extremely ill-conditioned; try DenseMethod::ColPivQr");
  return x;
}

// ----- SparseLdltSolver --------------------------------------------------------

struct SparseLdltSolver::Impl {
  Eigen::SimplicialLDLT<SparseMat, Eigen::Lower, Eigen::AMDOrdering<int>> ldlt;
  Eigen::Index n = 0;
  bool factored = false;
};

SparseLdltSolver::SparseLdltSolver() : impl_(std::make_unique<Impl>()) {}
SparseLdltSolver::~SparseLdltSolver() = default;
SparseLdltSolver::SparseLdltSolver(SparseLdltSolver&&) noexcept = default;
SparseLdltSolver& SparseLdltSolver::operator=(SparseLdltSolver&&) noexcept = default;

Eigen::Index SparseLdltSolver::size() const noexcept { return impl_ ? impl_->n : 0; }

Status SparseLdltSolver::compute(const SparseMat& A, bool requirePositiveDefinite) {
  return checkAndFactor(A, requirePositiveDefinite, true);
}

Status SparseLdltSolver::factorize(const SparseMat& A, bool requirePositiveDefinite) {
  if (!impl_ || impl_->n == 0)
    return invalid("factorize() before compute()", "SparseLdltSolver::factorize",
                   "call compute() once to analyse the sparsity pattern");
  if (A.rows() != impl_->n || A.cols() != impl_->n)
    return invalid(formatString("the matrix is %td×%td but the analysed pattern is %td×%td", A.rows(),
                                A.cols(), impl_->n, impl_->n),
                   "SparseLdltSolver::factorize", "call compute() for a matrix with a new pattern");
  return checkAndFactor(A, requirePositiveDefinite, false);
}

Status SparseLdltSolver::checkAndFactor(const SparseMat& A, bool requirePositiveDefinite, bool analyze) {
  constexpr const char* where = "SparseLdltSolver";
  if (!impl_) impl_ = std::make_unique<Impl>();
  impl_->factored = false;
  if (Status s = checkSparseSquareFinite(A, where); !s) return s;
  if (Status s = checkSparseSymmetric(A, kSymmetryTolerance, where); !s) return s;
  if (analyze) {
    impl_->ldlt.analyzePattern(A);
    impl_->n = A.rows();
  }
  impl_->ldlt.factorize(A);
  if (impl_->ldlt.info() != Eigen::Success)
    return invalid("the matrix is singular: sparse LDLT met a zero pivot", where,
                   "check for an unconstrained mode (free rigid motion, floating node) or duplicated rows");
  const VecX& d = impl_->ldlt.vectorD();
  const double dmax = d.cwiseAbs().maxCoeff();
  Eigen::Index kmin = 0;
  const double dmin = d.cwiseAbs().minCoeff(&kmin);
  const double tiny = 64.0 * std::numeric_limits<double>::epsilon() * static_cast<double>(d.size());
  if (dmin <= tiny * dmax)
    return invalid(formatString("the matrix is numerically singular: LDLT pivot %td is %.3e (largest %.3e)",
                                kmin, d[kmin], dmax),
                   where, "check for an unconstrained mode (free rigid motion, floating node)");
  if (requirePositiveDefinite) {
    Eigen::Index kneg = 0;
    if (d.minCoeff(&kneg) <= 0.0)
      return invalid(
          formatString("the matrix is not positive definite: LDLT pivot %td (in AMD order) is %.3e", kneg,
                       d[kneg]),
          where, "check the sign convention of the assembly, or pass requirePositiveDefinite = false");
  }
  impl_->factored = true;
  return ok();
}

Result<VecX> SparseLdltSolver::solve(const VecX& b) const {
  constexpr const char* where = "SparseLdltSolver::solve";
  if (!impl_ || !impl_->factored)
    return invalid("no factorization", where, "call compute() successfully before solve()");
  if (b.size() != impl_->n)
    return invalid(formatString("right-hand side has %td entries but the matrix is %td×%td", b.size(),
                                impl_->n, impl_->n),
                   where, "b must have one entry per matrix row");
  if (Status s = checkFiniteVector(b, "b", where); !s) return std::move(s).error();
  return VecX(impl_->ldlt.solve(b));
}

Result<VecX> solveSparseSpd(const SparseMat& A, const VecX& b) {
  SparseLdltSolver solver;
  if (Status s = solver.compute(A); !s) return std::move(s).error();
  return solver.solve(b);
}

// ----- PcgSolver ---------------------------------------------------------------

PcgSolver::PcgSolver(PcgOptions options) : options_(options) {}

void PcgSolver::reserve(Eigen::Index n) {
  if (r_.size() != n) r_.resize(n);
  if (z_.size() != n) z_.resize(n);
  if (p_.size() != n) p_.resize(n);
  if (q_.size() != n) q_.resize(n);
}

namespace {
bool samePattern(const SparseMat& a, const SparseMat& b) {
  if (a.rows() != b.rows() || a.cols() != b.cols() || !a.isCompressed() || !b.isCompressed() ||
      a.nonZeros() != b.nonZeros())
    return false;
  return std::equal(a.outerIndexPtr(), a.outerIndexPtr() + a.outerSize() + 1, b.outerIndexPtr()) &&
         std::equal(a.innerIndexPtr(), a.innerIndexPtr() + a.nonZeros(), b.innerIndexPtr());
}
}  // namespace

Status PcgSolver::compute(const SparseMat& A) {
  constexpr const char* where = "PcgSolver::compute";
  ready_ = false;
  builtPreconditioner_ = Preconditioner::None;
  if (Status s = checkSparseSquareFinite(A, where); !s) return s;
  if (Status s = checkSparseSymmetric(A, kSymmetryTolerance, where); !s) return s;
  const bool patternKept = samePattern(A, A_);
  if (patternKept) {
    std::copy(A.valuePtr(), A.valuePtr() + A.nonZeros(), A_.valuePtr());
  } else {
    A_ = A;
    A_.makeCompressed();
  }
  const Eigen::Index n = A_.rows();
  reserve(n);

  if (options_.preconditioner != Preconditioner::None) {
    // Both preconditioners need diag(A) > 0, which every SPD matrix has.
    if (invDiag_.size() != n) invDiag_.resize(n);
    for (Eigen::Index j = 0; j < n; ++j) {
      const double d = A_.coeff(j, j);
      if (!(d > 0.0))
        return invalid(
            formatString("diagonal entry A(%td,%td) = %g is not positive, so the matrix is not SPD", j, j, d),
            where, "PCG needs a symmetric positive definite matrix; check the assembly");
      invDiag_[j] = 1.0 / d;
    }
  }
  if (options_.preconditioner == Preconditioner::IncompleteCholesky) {
    if (!patternKept || icColPtr_.size() != static_cast<std::size_t>(n) + 1) {
      // Pattern of tril(A), diagonal first in each column (rows are sorted).
      icColPtr_.assign(static_cast<std::size_t>(n) + 1, 0);
      icRowIdx_.clear();
      for (Eigen::Index j = 0; j < n; ++j) {
        bool hasDiag = false;
        for (SparseMat::InnerIterator it(A_, j); it; ++it) {
          if (it.row() < j) continue;
          if (it.row() == j) hasDiag = true;
          if (!hasDiag)
            return invalid(
                formatString("diagonal entry A(%td,%td) is not stored, so the matrix is not SPD", j, j),
                where, "store the diagonal explicitly (a zero diagonal is never SPD)");
          icRowIdx_.push_back(static_cast<int>(it.row()));
        }
        if (!hasDiag)
          return invalid(
              formatString("diagonal entry A(%td,%td) is not stored, so the matrix is not SPD", j, j), where,
              "store the diagonal explicitly (a zero diagonal is never SPD)");
        icColPtr_[static_cast<std::size_t>(j) + 1] = static_cast<int>(icRowIdx_.size());
      }
      icVal_.resize(icRowIdx_.size());
      icDiagA_.resize(static_cast<std::size_t>(n));
    }
    if (Status s = buildIncompleteCholesky(); !s) return s;
  }
  builtPreconditioner_ = options_.preconditioner;
  ready_ = true;
  return ok();
}

// Copies tril(A) (diagonal scaled by 1 + shift) into the IC storage and
// factors it in place; false on breakdown (a non-positive pivot).
bool PcgSolver::factorIc(double shift) {
  const auto n = static_cast<int>(A_.rows());
  for (int j = 0; j < n; ++j) {
    int p = icColPtr_[static_cast<std::size_t>(j)];
    for (SparseMat::InnerIterator it(A_, j); it; ++it) {
      if (it.row() < j) continue;
      icVal_[static_cast<std::size_t>(p++)] = it.row() == j ? it.value() * (1.0 + shift) : it.value();
    }
  }
  const int* colPtr = icColPtr_.data();
  const int* row = icRowIdx_.data();
  double* val = icVal_.data();
  // Right-looking IC(0): column k scales, then updates the later columns it
  // touches, dropping fill outside the pattern (merge walk of sorted rows).
  for (int k = 0; k < n; ++k) {
    const int kBeg = colPtr[k], kEnd = colPtr[k + 1];
    const double pivot = val[kBeg];
    if (!(pivot > 0.0) || !std::isfinite(pivot)) return false;
    const double d = std::sqrt(pivot);
    val[kBeg] = d;
    for (int p = kBeg + 1; p < kEnd; ++p) val[p] /= d;
    for (int p = kBeg + 1; p < kEnd; ++p) {
      const int j = row[p];
      const double ljk = val[p];
      int a = colPtr[j];
      const int aEnd = colPtr[j + 1];
      for (int q = p; q < kEnd; ++q) {
        const int i = row[q];
        while (a < aEnd && row[a] < i) ++a;
        if (a == aEnd) break;
        if (row[a] == i) val[a] -= val[q] * ljk;
      }
    }
  }
  return true;
}

Status PcgSolver::buildIncompleteCholesky() {
  // Plain IC(0) can break down on SPD matrices that are not M-matrices; then
  // factor A + α·diag(A) with growing α (Manteuffel's shifted IC).
  icShift_ = 0.0;
  if (factorIc(0.0)) return ok();
  for (double shift = 1e-3; shift <= 1e3; shift *= 2.0) {
    if (factorIc(shift)) {
      icShift_ = shift;
      return ok();
    }
  }
  return invalid("incomplete Cholesky IC(0) broke down even with a diagonal shift of 1000·diag(A)",
                 "PcgSolver::compute",
                 "the matrix is probably not SPD; check the assembly, or use Preconditioner::Jacobi");
}

void PcgSolver::applyIc(const VecX& r, VecX& z) const {
  const auto n = static_cast<int>(r.size());
  const int* colPtr = icColPtr_.data();
  const int* row = icRowIdx_.data();
  const double* val = icVal_.data();
  z = r;
  // Forward: L y = r.
  for (int j = 0; j < n; ++j) {
    const double yj = z[j] / val[colPtr[j]];
    z[j] = yj;
    for (int p = colPtr[j] + 1; p < colPtr[j + 1]; ++p) z[row[p]] -= val[p] * yj;
  }
  // Backward: Lᵀ z = y.
  for (int j = n - 1; j >= 0; --j) {
    double s = z[j];
    for (int p = colPtr[j] + 1; p < colPtr[j + 1]; ++p) s -= val[p] * z[row[p]];
    z[j] = s / val[colPtr[j]];
  }
}

template <class ApplyA, class ApplyM>
Result<PcgReport> PcgSolver::iterate(const ApplyA& applyA, const ApplyM& applyM, const VecX& b, VecX& x,
                                     const char* where, const char* preconditionerLabel, const char* advice) {
  report_ = {};
  const Eigen::Index n = b.size();
  if (!(options_.tolerance >= 0.0) || !std::isfinite(options_.tolerance))
    return invalid(formatString("tolerance %g must be finite and ≥ 0", options_.tolerance), where);
  if (options_.maxIterations < 0)
    return invalid(formatString("maxIterations %d must be ≥ 0", options_.maxIterations), where);
  if (Status s = checkFiniteVector(b, "b", where); !s) return std::move(s).error();
  if (options_.useInitialGuess) {
    if (x.size() != n)
      return invalid(formatString("initial guess has %td entries but the system has %td", x.size(), n), where,
                     "pass x of size n, or set useInitialGuess = false");
    if (Status s = checkFiniteVector(x, "x (initial guess)", where); !s) return std::move(s).error();
  } else {
    if (x.size() != n) x.resize(n);
    x.setZero();
  }
  reserve(n);

  const double bnorm = b.norm();
  if (bnorm == 0.0) {
    x.setZero();
    return report_;
  }
  const auto sizeError = [&] {
    return invalid(
        formatString("the operator returned a vector of size %td for a system of size %td", q_.size(), n),
        where, "the operator must write y = A x into the given y without resizing it");
  };
  // r = b − A x, the true residual.
  auto fresh = [&]() -> bool {
    applyA(x, q_);
    if (q_.size() != n) return false;
    r_.noalias() = b - q_;
    return true;
  };
  if (options_.useInitialGuess) {
    if (!fresh()) return sizeError();
  } else {
    r_ = b;
  }
  double rnorm = r_.norm();
  report_.residualNorm = rnorm;
  report_.relativeResidual = rnorm / bnorm;
  if (report_.relativeResidual <= options_.tolerance) return report_;

  auto restart = [&](double& rz) -> Status {
    applyM(r_, z_);
    rz = r_.dot(z_);
    if (!(rz > 0.0) || !std::isfinite(rz))
      return invalid(
          formatString("preconditioner is not positive definite: rᵀM⁻¹r = %g", rz), where,
          "a preconditioner must be SPD; use Jacobi or IC(0), or check your preconditioner operator");
    p_ = z_;
    return ok();
  };
  double rz = 0.0;
  if (Status s = restart(rz); !s) return std::move(s).error();

  for (int it = 1; it <= options_.maxIterations; ++it) {
    applyA(p_, q_);
    if (q_.size() != n) return sizeError();
    const double pAp = p_.dot(q_);
    if (!std::isfinite(pAp))
      return invalid(formatString("pᵀAp is %g at iteration %d (NaN/Inf)", pAp, it), where,
                     "the operator or matrix produced a non-finite value; check its inputs");
    if (pAp <= 0.0)
      return invalid(
          formatString("negative curvature pᵀAp = %.3e at iteration %d: the matrix is not positive definite",
                       pAp, it),
          where,
          "CG needs an SPD matrix; check its sign convention, or use SparseLdltSolver with "
          "requirePositiveDefinite = false / solveDense() for indefinite systems");
    const double alpha = rz / pAp;
    x += alpha * p_;
    r_ -= alpha * q_;
    report_.iterations = it;
    rnorm = r_.norm();
    report_.residualNorm = rnorm;
    report_.relativeResidual = rnorm / bnorm;
    if (report_.relativeResidual <= options_.tolerance) {
      // The recurrence drifts from the true residual: confirm before stopping,
      // and restart from the true residual if it is not small enough yet.
      if (!fresh()) return sizeError();
      rnorm = r_.norm();
      report_.residualNorm = rnorm;
      report_.relativeResidual = rnorm / bnorm;
      if (report_.relativeResidual <= options_.tolerance) return report_;
      if (Status s = restart(rz); !s) return std::move(s).error();
      continue;
    }
    applyM(r_, z_);
    const double rzNew = r_.dot(z_);
    if (!(rzNew > 0.0) || !std::isfinite(rzNew))
      return invalid(
          formatString("preconditioner is not positive definite: rᵀM⁻¹r = %g at iteration %d", rzNew, it),
          where, "a preconditioner must be SPD; use Jacobi or IC(0), or check your preconditioner");
    const double beta = rzNew / rz;
    rz = rzNew;
    p_ = z_ + beta * p_;
  }
  return fail(
      ErrorCode::Timeout,
      formatString("PCG (preconditioner %s) did not converge in %d iterations: relative residual %.3e > "
                   "tolerance %.3e",
                   preconditionerLabel, options_.maxIterations, report_.relativeResidual, options_.tolerance),
      where, advice);
}

Result<PcgReport> PcgSolver::solve(const VecX& b, VecX& x) {
  constexpr const char* where = "PcgSolver::solve";
  if (!ready_) return invalid("no matrix", where, "call compute(A) successfully before solve()");
  if (b.size() != A_.rows())
    return invalid(formatString("right-hand side has %td entries but the matrix is %td×%td", b.size(),
                                A_.rows(), A_.cols()),
                   where, "b must have one entry per matrix row");
  if (builtPreconditioner_ != options_.preconditioner)
    return invalid(
        formatString("the preconditioner built by compute() is %s but the options ask for %s",
                     preconditionerName(builtPreconditioner_), preconditionerName(options_.preconditioner)),
        where, "call compute(A) again after changing options (or after a failed compute)");
  auto applyA = [this](const VecX& v, VecX& y) { y.noalias() = A_ * v; };
  const char* label = preconditionerName(builtPreconditioner_);
  switch (builtPreconditioner_) {
    case Preconditioner::Jacobi:
      return iterate(
          applyA, [this](const VecX& r, VecX& z) { z = invDiag_.cwiseProduct(r); }, b, x, where, label,
          "use Preconditioner::IncompleteCholesky, or raise maxIterations");
    case Preconditioner::IncompleteCholesky:
      return iterate(
          applyA, [this](const VecX& r, VecX& z) { applyIc(r, z); }, b, x, where, label,
          "raise maxIterations or loosen the tolerance; the matrix may be very ill-conditioned");
    case Preconditioner::None:
      break;
  }
  return iterate(
      applyA, [](const VecX& r, VecX& z) { z = r; }, b, x, where, label,
      "use a preconditioner (Preconditioner::Jacobi or IncompleteCholesky), or raise maxIterations");
}

Result<PcgReport> PcgSolver::solve(const LinearOperator& A, const VecX& b, VecX& x,
                                   const LinearOperator& preconditioner) {
  constexpr const char* where = "PcgSolver::solve (matrix-free)";
  if (!A) return invalid("the operator is empty", where, "pass a callable y = A x");
  if (b.size() == 0) return invalid("the system is empty (b has no entries)", where);
  // iterate() sizes the workspace (reserve) before any operator call.
  auto applyA = [&](const VecX& v, VecX& y) { A(v, y); };
  if (preconditioner) {
    const Eigen::Index n = b.size();
    return iterate(
        applyA,
        [&](const VecX& r, VecX& z) {
          preconditioner(r, z);
          if (z.size() != n) z.setConstant(n, std::numeric_limits<double>::quiet_NaN());
        },
        b, x, where, "user operator",
        "use a stronger preconditioner, raise maxIterations, or loosen the tolerance");
  }
  return iterate(
      applyA, [](const VecX& r, VecX& z) { z = r; }, b, x, where, "none",
      "pass a preconditioner (e.g. z = r ./ diag(A)), or raise maxIterations");
}

Result<PcgReport> solvePcg(const SparseMat& A, const VecX& b, VecX& x, const PcgOptions& options) {
  PcgSolver solver(options);
  if (Status s = solver.compute(A); !s) return std::move(s).error();
  return solver.solve(b, x);
}

}  // namespace dm
