#include <dm/math/linear.hpp>

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

namespace {

using dm::MatX;
using dm::SparseMat;
using dm::VecX;

MatX randomSpd(int n, std::mt19937& rng) {
  std::normal_distribution<double> g(0.0, 1.0);
  MatX M(n, n);
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) M(i, j) = g(rng);
  return M * M.transpose() + 0.5 * n * MatX::Identity(n, n);
}

VecX randomVec(int n, std::mt19937& rng) {
  std::normal_distribution<double> g(0.0, 1.0);
  VecX v(n);
  for (int i = 0; i < n; ++i) v[i] = g(rng);
  return v;
}

// -∇·(k ∇u) on an m^dim grid of unit spacing, Dirichlet boundary, 2·dim+1
// point stencil; k is evaluated at cell faces (harmonic-free arithmetic mean).
// k ≡ 1 gives the standard Laplacian (diagonal 2·dim, off-diagonals −1).
template <class K>
SparseMat poisson(int m, int dim, K k) {
  const int n = dim == 2 ? m * m : m * m * m;
  std::vector<dm::Triplet> t;
  auto idx = [&](int i, int j, int l) { return i + m * (j + m * l); };
  for (int l = 0; l < (dim == 3 ? m : 1); ++l)
    for (int j = 0; j < m; ++j)
      for (int i = 0; i < m; ++i) {
        const int c = idx(i, j, l);
        double diag = 0.0;
        const int off[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
        for (int a = 0; a < dim; ++a)
          for (int s : {-1, 1}) {
            const int ii = i + s * off[a][0], jj = j + s * off[a][1], ll = l + s * off[a][2];
            const double kf = 0.5 * (k(i, j, l) + k(ii, jj, ll));
            diag += kf;
            if (ii >= 0 && ii < m && jj >= 0 && jj < m && ll >= 0 && ll < (dim == 3 ? m : 1))
              t.emplace_back(c, idx(ii, jj, ll), -kf);
          }
        t.emplace_back(c, c, diag);
      }
  SparseMat A(n, n);
  A.setFromTriplets(t.begin(), t.end());
  return A;
}

SparseMat laplacian(int m, int dim) {
  return poisson(m, dim, [](int, int, int) { return 1.0; });
}

// Diffusion coefficient varying over four orders of magnitude, so the
// diagonal is far from constant and Jacobi scaling matters.
SparseMat heterogeneous(int m) {
  return poisson(m, 2, [m](int i, int j, int) {
    return std::pow(10.0, 2.0 * std::sin(6.0 * i / m) * std::cos(5.0 * j / m));
  });
}

double relResidual(const SparseMat& A, const VecX& x, const VecX& b) { return (b - A * x).norm() / b.norm(); }

// ----- dense ----------------------------------------------------------------

TEST(LinearDense, LdltMatchesEigenCholeskyOnRandomSpd) {
  std::mt19937 rng(1);
  for (int n : {1, 3, 17, 60}) {
    const MatX A = randomSpd(n, rng);
    const VecX b = randomVec(n, rng);
    auto x = dm::solveDense(A, b);
    ASSERT_TRUE(x) << x.error();
    const VecX ref = A.llt().solve(b);
    EXPECT_LT((*x - ref).norm(), 1e-12 * ref.norm()) << "n=" << n;
    EXPECT_LT((A * *x - b).norm(), 1e-12 * b.norm());
  }
}

TEST(LinearDense, LuAndQrMatchEigenOnGeneralMatrix) {
  std::mt19937 rng(2);
  const int n = 40;
  MatX A(n, n);
  for (int j = 0; j < n; ++j) A.col(j) = randomVec(n, rng);
  A += 5.0 * MatX::Identity(n, n);
  const VecX b = randomVec(n, rng);
  const VecX ref = A.fullPivLu().solve(b);
  for (auto m : {dm::DenseMethod::PartialPivLu, dm::DenseMethod::ColPivQr}) {
    auto x = dm::solveDense(A, b, {.method = m});
    ASSERT_TRUE(x) << x.error();
    EXPECT_LT((*x - ref).norm(), 1e-11 * ref.norm());
  }
  // A general (non-symmetric) matrix is refused by LDLT, with a pointer to LU/QR.
  auto bad = dm::solveDense(A, b);
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.error().what.find("not symmetric"), std::string::npos);
  EXPECT_NE(bad.error().hint.find("PartialPivLu"), std::string::npos);
}

TEST(LinearDense, SingularMatrixIsReportedByEveryMethod) {
  std::mt19937 rng(3);
  const int n = 12;
  MatX B(n, n - 2);
  for (int j = 0; j < n - 2; ++j) B.col(j) = randomVec(n, rng);
  const MatX A = B * B.transpose();  // symmetric PSD, rank n-2
  const VecX b = randomVec(n, rng);
  for (auto m : {dm::DenseMethod::Ldlt, dm::DenseMethod::PartialPivLu, dm::DenseMethod::ColPivQr}) {
    auto x = dm::solveDense(A, b, {.method = m, .allowIndefinite = true});
    ASSERT_FALSE(x) << "method " << static_cast<int>(m);
    const std::string& w = x.error().what;
    EXPECT_TRUE(w.find("singular") != std::string::npos || w.find("rank") != std::string::npos) << w;
  }
}

TEST(LinearDense, IndefiniteMatrixFailsUnlessAllowed) {
  MatX A(3, 3);
  A << 2, 1, 0, 1, -3, 0.5, 0, 0.5, 4;
  const VecX b(VecX::LinSpaced(3, 1.0, 3.0));
  auto x = dm::solveDense(A, b);
  ASSERT_FALSE(x);
  EXPECT_NE(x.error().what.find("not positive definite"), std::string::npos) << x.error();
  auto y = dm::solveDense(A, b, {.allowIndefinite = true});
  ASSERT_TRUE(y) << y.error();
  EXPECT_LT((A * *y - b).norm(), 1e-13);
}

TEST(LinearDense, RejectsBadShapesAndNonFinite) {
  EXPECT_FALSE(dm::solveDense(MatX(0, 0), VecX(0)));
  EXPECT_FALSE(dm::solveDense(MatX::Identity(3, 4), VecX::Ones(3)));
  auto mismatch = dm::solveDense(MatX::Identity(3, 3), VecX::Ones(4));
  ASSERT_FALSE(mismatch);
  EXPECT_NE(mismatch.error().what.find("4 entries"), std::string::npos);
  MatX A = MatX::Identity(3, 3);
  A(1, 2) = std::nan("");
  auto nan = dm::solveDense(A, VecX::Ones(3));
  ASSERT_FALSE(nan);
  EXPECT_NE(nan.error().what.find("A(1,2)"), std::string::npos);
  VecX b = VecX::Ones(3);
  b[2] = INFINITY;
  auto inf = dm::solveDense(MatX::Identity(3, 3), b);
  ASSERT_FALSE(inf);
  EXPECT_NE(inf.error().what.find("b[2]"), std::string::npos);
}

// ----- sparse direct ------------------------------------------------------------

TEST(LinearSparse, LdltMatchesDenseCholeskyOnPoisson) {
  for (int dim : {2, 3}) {
    const SparseMat A = laplacian(dim == 2 ? 15 : 6, dim);
    std::mt19937 rng(4);
    const VecX b = randomVec(static_cast<int>(A.rows()), rng);
    auto x = dm::solveSparseSpd(A, b);
    ASSERT_TRUE(x) << x.error();
    const VecX ref = MatX(A).llt().solve(b);
    EXPECT_LT((*x - ref).norm(), 1e-12 * ref.norm()) << "dim " << dim;
  }
}

TEST(LinearSparse, RefactorizationReusesPattern) {
  const SparseMat A = laplacian(10, 2);
  std::mt19937 rng(5);
  const VecX b = randomVec(100, rng);
  dm::SparseLdltSolver s;
  ASSERT_TRUE(s.compute(A));
  auto x1 = s.solve(b);
  ASSERT_TRUE(x1);
  ASSERT_TRUE(s.factorize(3.0 * A));
  auto x3 = s.solve(b);
  ASSERT_TRUE(x3);
  // (3A)⁻¹ b = A⁻¹ b / 3.
  EXPECT_LT((*x3 - *x1 / 3.0).norm(), 1e-12 * x1->norm());
  EXPECT_FALSE(s.solve(VecX::Ones(7)));
  EXPECT_FALSE(s.factorize(laplacian(3, 2)));
}

TEST(LinearSparse, SingularIndefiniteAndAsymmetricAreReported) {
  // Pure-Neumann Laplacian of a path graph: constants are in the kernel.
  const int n = 20;
  std::vector<dm::Triplet> t;
  for (int i = 0; i + 1 < n; ++i) {
    t.emplace_back(i, i, 1.0), t.emplace_back(i + 1, i + 1, 1.0);
    t.emplace_back(i, i + 1, -1.0), t.emplace_back(i + 1, i, -1.0);
  }
  SparseMat N(n, n);
  N.setFromTriplets(t.begin(), t.end());
  dm::SparseLdltSolver s;
  auto sing = s.compute(N);
  ASSERT_FALSE(sing);
  EXPECT_NE(sing.error().what.find("singular"), std::string::npos) << sing.error();
  EXPECT_FALSE(s.solve(VecX::Ones(n)));

  SparseMat D(3, 3);
  D.insert(0, 0) = 1.0, D.insert(1, 1) = -2.0, D.insert(2, 2) = 3.0;
  auto indef = s.compute(D);
  ASSERT_FALSE(indef);
  EXPECT_NE(indef.error().what.find("not positive definite"), std::string::npos);
  ASSERT_TRUE(s.compute(D, /*requirePositiveDefinite=*/false));
  auto x = s.solve(VecX::Ones(3));
  ASSERT_TRUE(x);
  EXPECT_NEAR((*x)[1], -0.5, 1e-15);

  SparseMat U = laplacian(3, 2);
  U.coeffRef(0, 1) = -0.5;
  auto asym = s.compute(U);
  ASSERT_FALSE(asym);
  EXPECT_NE(asym.error().what.find("not symmetric"), std::string::npos);
}

// ----- PCG ------------------------------------------------------------------------

TEST(LinearPcg, MatchesDirectSolveOnPoissonAndRandomSpd) {
  std::mt19937 rng(6);
  std::vector<SparseMat> systems = {laplacian(30, 2), laplacian(10, 3), heterogeneous(20)};
  {
    const MatX S = randomSpd(40, rng);
    systems.push_back(S.sparseView());
  }
  for (const SparseMat& A : systems) {
    const VecX b = randomVec(static_cast<int>(A.rows()), rng);
    auto ref = dm::solveSparseSpd(A, b);
    ASSERT_TRUE(ref) << ref.error();
    for (auto p :
         {dm::Preconditioner::None, dm::Preconditioner::Jacobi, dm::Preconditioner::IncompleteCholesky}) {
      VecX x;
      const double tol = 1e-10;
      auto rep = dm::solvePcg(A, b, x, {.tolerance = tol, .maxIterations = 5000, .preconditioner = p});
      ASSERT_TRUE(rep) << rep.error();
      EXPECT_LE(rep->relativeResidual, tol);
      // The reported residual is the true one.
      EXPECT_NEAR(relResidual(A, x, b), rep->relativeResidual, 1e-14);
      // Forward error ≤ κ · residual; these systems have κ ≲ 1e4.
      EXPECT_LT((x - *ref).norm(), 1e-5 * ref->norm());
    }
  }
}

TEST(LinearPcg, IterationCountsOrderedIcJacobiNone) {
  struct Case {
    const char* name;
    SparseMat A;
    bool jacobiStrict;  // constant diagonal makes Jacobi a mere rescaling of plain CG
  };
  const Case cases[] = {{"poisson2d", laplacian(40, 2), false},
                        {"poisson3d", laplacian(12, 3), false},
                        {"heterogeneous2d", heterogeneous(40), true}};
  for (const Case& c : cases) {
    const VecX b = VecX::Ones(c.A.rows());
    int its[3];
    int k = 0;
    for (auto p :
         {dm::Preconditioner::None, dm::Preconditioner::Jacobi, dm::Preconditioner::IncompleteCholesky}) {
      dm::PcgSolver pcg({.tolerance = 1e-8, .maxIterations = 5000, .preconditioner = p});
      ASSERT_TRUE(pcg.compute(c.A));
      VecX x;
      auto rep = pcg.solve(b, x);
      ASSERT_TRUE(rep) << rep.error();
      EXPECT_LE(relResidual(c.A, x, b), 1e-8);
      its[k++] = rep->iterations;
    }
    std::printf("  %-16s iterations: none %d, Jacobi %d, IC(0) %d\n", c.name, its[0], its[1], its[2]);
    EXPECT_LT(its[2], its[1]) << c.name;
    if (c.jacobiStrict)
      EXPECT_LT(its[1], its[0]) << c.name;
    else
      EXPECT_LE(its[1], its[0]) << c.name;
  }
}

TEST(LinearPcg, ReusedWorkspaceAndPatternGiveConsistentSolves) {
  const SparseMat A = laplacian(20, 2);
  const VecX b = VecX::LinSpaced(A.rows(), -1.0, 1.0);
  dm::PcgSolver pcg({.tolerance = 1e-12, .preconditioner = dm::Preconditioner::IncompleteCholesky});
  ASSERT_TRUE(pcg.compute(A));
  VecX x1;
  auto r1 = pcg.solve(b, x1);
  ASSERT_TRUE(r1);
  // Same pattern, new values: (2A) x = b → x = x1 / 2, same iteration count
  // (CG with IC(0) is invariant to scaling A).
  ASSERT_TRUE(pcg.compute(2.0 * A));
  VecX x2;
  auto r2 = pcg.solve(b, x2);
  ASSERT_TRUE(r2);
  EXPECT_LT((x2 - 0.5 * x1).norm(), 1e-10 * x1.norm());
  EXPECT_EQ(r1->iterations, r2->iterations);
  // Warm start from the solution: no iteration needed.
  pcg.setOptions(
      {.tolerance = 1e-8, .preconditioner = dm::Preconditioner::IncompleteCholesky, .useInitialGuess = true});
  auto r3 = pcg.solve(b, x2);
  ASSERT_TRUE(r3);
  EXPECT_EQ(r3->iterations, 0);
  // Zero right-hand side: zero solution at once.
  VecX z = VecX::Ones(A.rows());
  pcg.setOptions({.preconditioner = dm::Preconditioner::IncompleteCholesky});
  auto r4 = pcg.solve(VecX::Zero(A.rows()), z);
  ASSERT_TRUE(r4);
  EXPECT_EQ(r4->iterations, 0);
  EXPECT_EQ(z.norm(), 0.0);
}

TEST(LinearPcg, MatrixFreeOperatorMatchesAssembledMatrix) {
  constexpr int m = 25;
  const SparseMat A = laplacian(m, 2);
  const VecX b = VecX::LinSpaced(m * m, 0.0, 1.0);
  // The 5-point Laplacian applied as a stencil, never assembled.
  const dm::LinearOperator stencil = [](const VecX& u, VecX& y) {
    for (int j = 0; j < m; ++j)
      for (int i = 0; i < m; ++i) {
        const int c = i + m * j;
        double v = 4.0 * u[c];
        if (i > 0) v -= u[c - 1];
        if (i + 1 < m) v -= u[c + 1];
        if (j > 0) v -= u[c - m];
        if (j + 1 < m) v -= u[c + m];
        y[c] = v;
      }
  };
  dm::PcgSolver pcg({.tolerance = 1e-11});
  pcg.reserve(m * m);
  VecX x;
  auto rep = pcg.solve(stencil, b, x);
  ASSERT_TRUE(rep) << rep.error();
  EXPECT_LE(relResidual(A, x, b), 1e-11);
  const dm::LinearOperator jacobi = [](const VecX& r, VecX& z) { z = 0.25 * r; };
  VecX xj;
  auto repj = pcg.solve(stencil, b, xj, jacobi);
  ASSERT_TRUE(repj) << repj.error();
  EXPECT_LT((xj - x).norm(), 1e-9 * x.norm());
  auto ref = dm::solveSparseSpd(A, b);
  ASSERT_TRUE(ref);
  EXPECT_LT((x - *ref).norm(), 1e-8 * ref->norm());
  EXPECT_FALSE(pcg.solve(dm::LinearOperator{}, b, x));
}

TEST(LinearPcg, NonConvergenceReportsResidualAndAdvice) {
  const SparseMat A = laplacian(30, 2);
  const VecX b = VecX::Ones(A.rows());
  dm::PcgSolver pcg({.tolerance = 1e-10, .maxIterations = 5, .preconditioner = dm::Preconditioner::None});
  ASSERT_TRUE(pcg.compute(A));
  VecX x;
  auto rep = pcg.solve(b, x);
  ASSERT_FALSE(rep);
  EXPECT_EQ(rep.error().code, dm::ErrorCode::Timeout);
  EXPECT_NE(rep.error().what.find("relative residual"), std::string::npos) << rep.error();
  EXPECT_NE(rep.error().hint.find("preconditioner"), std::string::npos);
  EXPECT_EQ(pcg.lastReport().iterations, 5);
  EXPECT_GT(pcg.lastReport().relativeResidual, 1e-10);
  // x holds the last iterate. CG does not make the residual monotone, but it
  // minimizes the A-norm of the error over the Krylov space: ‖e₅‖_A < ‖e₀‖_A.
  EXPECT_NEAR(relResidual(A, x, b), pcg.lastReport().relativeResidual, 1e-12);
  auto exact = dm::solveSparseSpd(A, b);
  ASSERT_TRUE(exact);
  const VecX e5 = x - *exact;
  const VecX& e0 = *exact;  // the iteration started from x = 0
  EXPECT_LT(e5.dot(A * e5), 0.9 * e0.dot(A * e0));
}

TEST(LinearPcg, NonSpdIsDetected) {
  // Negative curvature: with b = (1,1,1), p₀ = b and p₀ᵀAp₀ = 1 + 2 − 5 < 0.
  SparseMat D(3, 3);
  D.insert(0, 0) = 1.0, D.insert(1, 1) = 2.0, D.insert(2, 2) = -5.0;
  dm::PcgSolver none({.preconditioner = dm::Preconditioner::None});
  ASSERT_TRUE(none.compute(D));
  VecX x;
  auto r = none.solve(VecX::Ones(3), x);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().what.find("negative curvature"), std::string::npos) << r.error();
  // Jacobi and IC(0) already see the negative diagonal.
  for (auto p : {dm::Preconditioner::Jacobi, dm::Preconditioner::IncompleteCholesky}) {
    dm::PcgSolver s({.preconditioner = p});
    auto c = s.compute(D);
    ASSERT_FALSE(c);
    EXPECT_NE(c.error().what.find("not"), std::string::npos) << c.error();
    EXPECT_FALSE(s.solve(VecX::Ones(3), x));  // nothing usable was built
  }
}

TEST(LinearPcg, RejectsMismatchAndNonFinite) {
  const SparseMat A = laplacian(4, 2);
  dm::PcgSolver pcg;
  VecX x;
  EXPECT_FALSE(pcg.solve(VecX::Ones(16), x));  // before compute()
  ASSERT_TRUE(pcg.compute(A));
  auto mis = pcg.solve(VecX::Ones(15), x);
  ASSERT_FALSE(mis);
  EXPECT_NE(mis.error().what.find("15 entries"), std::string::npos);
  VecX b = VecX::Ones(16);
  b[3] = std::nan("");
  auto nan = pcg.solve(b, x);
  ASSERT_FALSE(nan);
  EXPECT_NE(nan.error().what.find("b[3]"), std::string::npos);
  pcg.setOptions({.useInitialGuess = true});
  ASSERT_TRUE(pcg.compute(A));
  x = VecX::Ones(5);
  EXPECT_FALSE(pcg.solve(VecX::Ones(16), x));
  SparseMat bad = A;
  bad.coeffRef(2, 2) = INFINITY;
  EXPECT_FALSE(pcg.compute(bad));
  SparseMat asym = A;
  asym.coeffRef(0, 1) = -2.0;
  auto as = pcg.compute(asym);
  ASSERT_FALSE(as);
  EXPECT_NE(as.error().what.find("not symmetric"), std::string::npos);
}

TEST(LinearPcg, IncompleteCholeskyBreakdownIsRepairedByDiagonalShift) {
  // Kershaw (1978): SPD (eigenvalues 3 ± 2√2, twice each) but plain IC(0)
  // meets a negative pivot (−5) in the last column.
  MatX K(4, 4);
  K << 3, -2, 0, 2, -2, 3, -2, 0, 0, -2, 3, -2, 2, 0, -2, 3;
  const SparseMat A = K.sparseView();
  dm::PcgSolver pcg({.tolerance = 1e-12, .preconditioner = dm::Preconditioner::IncompleteCholesky});
  ASSERT_TRUE(pcg.compute(A));
  EXPECT_GT(pcg.incompleteCholeskyShift(), 0.0);
  const VecX b(VecX::LinSpaced(4, 1.0, 4.0));
  VecX x;
  auto rep = pcg.solve(b, x);
  ASSERT_TRUE(rep) << rep.error();
  EXPECT_LT((x - K.llt().solve(b)).norm(), 1e-10);
  EXPECT_LE(rep->iterations, 4);  // CG is exact in n steps (in exact arithmetic)
}

TEST(LinearPcg, IncompleteCholeskyOnNonMMatrixStillConverges) {
  // Random sparse SPD matrix with positive and negative off-diagonals (not an
  // M-matrix): IC(0) may need its diagonal shift, and PCG must still converge.
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::uniform_int_distribution<int> pick(0, 199);
  const int n = 200;
  MatX B = MatX::Zero(n, n);
  for (int k = 0; k < 600; ++k) B(pick(rng), pick(rng)) = u(rng);
  MatX S = B * B.transpose() + 1e-2 * MatX::Identity(n, n);
  const SparseMat A = S.sparseView(1e-300, 1.0);
  dm::PcgSolver pcg(
      {.tolerance = 1e-9, .maxIterations = 2000, .preconditioner = dm::Preconditioner::IncompleteCholesky});
  ASSERT_TRUE(pcg.compute(A));
  EXPECT_GE(pcg.incompleteCholeskyShift(), 0.0);
  const VecX b = randomVec(n, rng);
  VecX x;
  auto rep = pcg.solve(b, x);
  ASSERT_TRUE(rep) << rep.error();
  EXPECT_LE(relResidual(A, x, b), 1e-9);
}

}  // namespace
