#include <dm/math/registration.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

namespace {

using dm::Mat3;
using dm::Vec3;

Mat3 randomRotation(std::mt19937& rng) {
  std::normal_distribution<double> g;
  return dm::Quat(g(rng), g(rng), g(rng), g(rng)).normalized().toRotationMatrix();
}

std::vector<Vec3> randomPoints(int n, double extent, std::mt19937& rng) {
  std::uniform_real_distribution<double> u(-extent, extent);
  std::vector<Vec3> p;
  for (int i = 0; i < n; ++i) p.emplace_back(u(rng), u(rng), u(rng));
  return p;
}

std::vector<Vec3> transformed(const std::vector<Vec3>& p, double s, const Mat3& R, const Vec3& t) {
  std::vector<Vec3> q;
  for (const Vec3& x : p) q.push_back(s * R * x + t);
  return q;
}

TEST(Registration, RecoversRigidAndSimilarityTransformsExactly) {
  std::mt19937 rng(1);
  for (int n : {3, 4, 10, 50}) {
    for (bool withScale : {false, true}) {
      const Mat3 R = randomRotation(rng);
      const Vec3 t(0.3, -1.2, 0.05);
      const double s = withScale ? 1.7 : 1.0;
      const auto p = randomPoints(n, 0.1, rng);
      const auto q = transformed(p, s, R, t);
      auto reg = dm::registerPoints(p, q, {.estimateScale = withScale});
      ASSERT_TRUE(reg) << reg.error();
      EXPECT_LT((reg->rotation - R).norm(), 1e-10) << "n=" << n;
      EXPECT_LT((reg->translation - t).norm(), 1e-10);
      EXPECT_NEAR(reg->scale, s, 1e-10);
      EXPECT_NEAR(reg->rotation.determinant(), 1.0, 1e-12);
      EXPECT_LT(reg->fre, 1e-12);
      ASSERT_EQ(reg->residuals.size(), static_cast<std::size_t>(n));
      EXPECT_FALSE(reg->reflectionAvoided);
      EXPECT_LT((reg->transform() * p[0] - q[0]).norm(), 1e-12);
    }
  }
}

TEST(Registration, CoplanarFiducialsAreFine) {
  std::mt19937 rng(2);
  std::vector<Vec3> p = {{0, 0, 0}, {0.1, 0, 0}, {0, 0.08, 0}, {0.05, 0.05, 0}};
  const Mat3 R = randomRotation(rng);
  const Vec3 t(1, 2, 3);
  auto reg = dm::registerPoints(p, transformed(p, 1.0, R, t));
  ASSERT_TRUE(reg) << reg.error();
  EXPECT_LT((reg->rotation - R).norm(), 1e-10);
  EXPECT_LT((reg->translation - t).norm(), 1e-10);
  EXPECT_NEAR(reg->rotation.determinant(), 1.0, 1e-12);
  EXPECT_FALSE(reg->reflectionAvoided);  // coplanar: the third axis sign is free, not a reflection
}

TEST(Registration, MirroredDataGivesProperRotationAndFlagsReflection) {
  std::mt19937 rng(3);
  const auto p = randomPoints(8, 0.1, rng);
  std::vector<Vec3> q;
  for (const Vec3& x : p) q.emplace_back(x.x(), x.y(), -x.z());  // a reflection, det = −1
  auto reg = dm::registerPoints(p, q);
  ASSERT_TRUE(reg) << reg.error();
  EXPECT_NEAR(reg->rotation.determinant(), 1.0, 1e-12);
  EXPECT_LT((reg->rotation.transpose() * reg->rotation - Mat3::Identity()).norm(), 1e-12);
  EXPECT_TRUE(reg->reflectionAvoided);
  EXPECT_GT(reg->fre, 1e-3);  // a rotation cannot fit a mirror image
  // Umeyama's constrained optimum: no proper rotation does better.
  for (int k = 0; k < 200; ++k) {
    const Mat3 R = randomRotation(rng);
    double sq = 0;
    const Vec3 mp = [&] {
      Vec3 m = Vec3::Zero();
      for (const Vec3& x : p) m += x;
      return Vec3(m / p.size());
    }();
    Vec3 mq = Vec3::Zero();
    for (const Vec3& x : q) mq += x;
    mq /= q.size();
    for (std::size_t i = 0; i < p.size(); ++i) sq += (R * (p[i] - mp) + mq - q[i]).squaredNorm();
    EXPECT_GE(std::sqrt(sq / p.size()), reg->fre - 1e-12);
  }
}

TEST(Registration, FreMatchesFitzpatrickExpectation) {
  // Isotropic Gaussian FLE, σ per axis, on the target points only:
  // ⟨FLE²⟩ = 3σ², and the residual sum of squares has 3N − 6 degrees of
  // freedom (3N − 7 with scale), so ⟨FRE²⟩ = (1 − 2/N)·3σ² for rigid and
  // (1 − 7/(3N))·3σ² for similarity registration (first order in σ).
  std::mt19937 rng(4);
  std::normal_distribution<double> g;
  const double sigma = 0.5e-3;  // 0.5 mm on a 0.2 m layout
  for (int n : {4, 8, 20}) {
    const auto p = randomPoints(n, 0.1, rng);
    const Mat3 R = randomRotation(rng);
    const Vec3 t(0.2, 0.1, -0.3);
    const int trials = 3000;
    double sumRigid = 0, sumSim = 0;
    for (int k = 0; k < trials; ++k) {
      auto q = transformed(p, 1.0, R, t);
      for (Vec3& x : q) x += sigma * Vec3(g(rng), g(rng), g(rng));
      auto rigid = dm::registerPoints(p, q);
      auto sim = dm::registerPoints(p, q, {.estimateScale = true});
      ASSERT_TRUE(rigid && sim);
      sumRigid += rigid->fre * rigid->fre;
      sumSim += sim->fre * sim->fre;
    }
    const double fle2 = 3 * sigma * sigma;
    const double expectRigid = (1.0 - 2.0 / n) * fle2, expectSim = (1.0 - 7.0 / (3.0 * n)) * fle2;
    const double meanRigid = sumRigid / trials, meanSim = sumSim / trials;
    std::printf("  N=%2d  <FRE²>/<FLE²>: rigid %.4f (expect %.4f), similarity %.4f (expect %.4f)\n", n,
                meanRigid / fle2, expectRigid / fle2, meanSim / fle2, expectSim / fle2);
    // N·FRE²/σ² ~ χ²(3N−6): the mean of `trials` samples has relative standard
    // deviation √(2/(3N−6)/trials) ≤ 1.2 %; allow about five of those.
    const double tol = 5.0 * std::sqrt(2.0 / (3.0 * n - 7.0) / trials);
    EXPECT_NEAR(meanRigid / expectRigid, 1.0, tol) << "N=" << n;
    EXPECT_NEAR(meanSim / expectSim, 1.0, tol) << "N=" << n;
  }
}

TEST(Registration, TreMatchesKnownTransformAndFitzpatrickPrediction) {
  std::mt19937 rng(5);
  std::normal_distribution<double> g;
  // Six fiducials on a head-sized layout, targets inside and far outside it.
  const std::vector<Vec3> p = {{0.08, 0, 0},  {-0.08, 0.01, 0}, {0, 0.09, 0.01},
                               {0, -0.07, 0}, {0.01, 0, 0.06},  {-0.02, 0.03, 0.05}};
  const std::vector<Vec3> targets = {{0, 0, 0.02}, {0.05, 0.05, -0.05}, {0.3, 0, 0}, {0, -0.2, 0.2}};
  const Mat3 R = randomRotation(rng);
  const Vec3 t(0.5, 0.2, 0.1);
  dm::Affine3 truth = dm::Affine3::Identity();
  truth.linear() = R;
  truth.translation() = t;
  const double sigma = 0.3e-3, fleRms = std::sqrt(3.0) * sigma;
  auto predicted = dm::predictedTre(p, targets, fleRms);
  ASSERT_TRUE(predicted) << predicted.error();

  // Noise-free: TRE is zero everywhere.
  {
    auto reg = dm::registerPoints(p, transformed(p, 1.0, R, t));
    ASSERT_TRUE(reg);
    auto tre = dm::targetRegistrationError(*reg, truth, targets);
    ASSERT_TRUE(tre);
    EXPECT_LT(tre->max, 1e-12);
  }
  // A known error: translate the estimate by 1 mm → TRE = 1 mm at every target.
  {
    auto reg = dm::registerPoints(p, transformed(p, 1.0, R, t));
    ASSERT_TRUE(reg);
    reg->translation += Vec3(0, 1e-3, 0);
    auto tre = dm::targetRegistrationError(*reg, truth, targets);
    ASSERT_TRUE(tre);
    for (double e : tre->errors) EXPECT_NEAR(e, 1e-3, 1e-12);
    EXPECT_NEAR(tre->rms, 1e-3, 1e-12);
  }
  // Monte Carlo ⟨TRE²⟩ against Fitzpatrick's first-order prediction.
  const int trials = 4000;
  std::vector<double> sum(targets.size(), 0.0);
  for (int k = 0; k < trials; ++k) {
    auto q = transformed(p, 1.0, R, t);
    for (Vec3& x : q) x += sigma * Vec3(g(rng), g(rng), g(rng));
    auto reg = dm::registerPoints(p, q);
    ASSERT_TRUE(reg);
    auto tre = dm::targetRegistrationError(*reg, truth, targets);
    ASSERT_TRUE(tre);
    for (std::size_t j = 0; j < targets.size(); ++j) sum[j] += tre->errors[j] * tre->errors[j];
  }
  for (std::size_t j = 0; j < targets.size(); ++j) {
    const double measured = std::sqrt(sum[j] / trials);
    std::printf("  target %zu: RMS TRE %.4f mm, predicted %.4f mm\n", j, 1e3 * measured,
                1e3 * (*predicted)[j]);
    // TRE² of one trial is a weighted sum of 3 χ²(1); the mean of 4000 has
    // relative sd ≤ √(2/4000) ≈ 2.2 %, so the RMS ≤ 1.1 %: allow 6 %.
    EXPECT_NEAR(measured / (*predicted)[j], 1.0, 0.06) << "target " << j;
  }
  // Far targets have larger TRE than the one near the centroid.
  EXPECT_GT((*predicted)[2], 2.0 * (*predicted)[0]);
}

TEST(Registration, WeightsIgnoreZeroWeightOutliersAndWeightTheFre) {
  std::mt19937 rng(6);
  auto p = randomPoints(6, 0.1, rng);
  const Mat3 R = randomRotation(rng);
  const Vec3 t(0.1, 0.2, 0.3);
  auto q = transformed(p, 1.0, R, t);
  q[5] += Vec3(0.05, 0, 0);                          // a gross outlier...
  const std::vector<double> w = {1, 2, 1, 3, 1, 0};  // ...with zero weight
  auto reg = dm::registerPoints(p, q, {.weights = w});
  ASSERT_TRUE(reg) << reg.error();
  EXPECT_LT((reg->rotation - R).norm(), 1e-10);
  EXPECT_LT((reg->translation - t).norm(), 1e-10);
  EXPECT_LT(reg->fre, 1e-12);                   // weighted: the outlier does not count
  EXPECT_NEAR(reg->residuals[5], 0.05, 1e-10);  // but its residual is reported
  // Weighted FRE = √(Σ w r² / Σ w) on noisy data.
  std::normal_distribution<double> g;
  auto qn = transformed(p, 1.0, R, t);
  for (Vec3& x : qn) x += 1e-3 * Vec3(g(rng), g(rng), g(rng));
  auto wr = dm::registerPoints(p, qn, {.weights = w});
  ASSERT_TRUE(wr);
  double num = 0, den = 0;
  for (std::size_t i = 0; i < p.size(); ++i) num += w[i] * wr->residuals[i] * wr->residuals[i], den += w[i];
  EXPECT_NEAR(wr->fre, std::sqrt(num / den), 1e-15);
  // Weighted optimum: perturbing the rotation only increases Σ w r².
  const Mat3 Rp = dm::AngleAxis(1e-4, Vec3::UnitZ()).toRotationMatrix() * wr->rotation;
  double perturbed = 0;
  for (std::size_t i = 0; i < p.size(); ++i)
    perturbed += w[i] * (Rp * p[i] + wr->translation - qn[i]).squaredNorm();
  EXPECT_GT(perturbed / den, wr->fre * wr->fre);
}

TEST(Registration, DegenerateAndInvalidInputFailClearly) {
  const std::vector<Vec3> line = {{0, 0, 0}, {1, 1, 1}, {2, 2, 2}, {-1, -1, -1}};
  const std::vector<Vec3> ok = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  auto collinear = dm::registerPoints(line, ok);
  ASSERT_FALSE(collinear);
  EXPECT_NE(collinear.error().what.find("source points are collinear"), std::string::npos)
      << collinear.error();
  auto collinearTarget = dm::registerPoints(ok, line);
  ASSERT_FALSE(collinearTarget);
  EXPECT_NE(collinearTarget.error().what.find("target points are collinear"), std::string::npos);
  const std::vector<Vec3> same(4, Vec3(1, 2, 3));
  auto coincident = dm::registerPoints(same, ok);
  ASSERT_FALSE(coincident);
  EXPECT_NE(coincident.error().what.find("coincident"), std::string::npos) << coincident.error();
  // Nearly collinear (10 nm off a 1 m line) is still degenerate at tol 1e-6.
  std::vector<Vec3> almost = line;
  almost[1] += Vec3(1e-8, -1e-8, 0);
  EXPECT_FALSE(dm::registerPoints(almost, ok));
  EXPECT_FALSE(dm::registerPoints(std::span(ok).first(2), std::span(ok).first(2)));
  EXPECT_FALSE(dm::registerPoints(ok, std::span(ok).first(3)));
  std::vector<Vec3> nan = ok;
  nan[2].y() = NAN;
  auto bad = dm::registerPoints(ok, nan);
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.error().what.find("target[2]"), std::string::npos);
  const std::vector<double> neg = {1, 1, -1, 1}, two = {1, 1, 0, 0}, short3 = {1, 1, 1};
  EXPECT_FALSE(dm::registerPoints(ok, ok, {.weights = neg}));
  EXPECT_FALSE(dm::registerPoints(ok, ok, {.weights = two}));
  EXPECT_FALSE(dm::registerPoints(ok, ok, {.weights = short3}));
  // Zero weights can make the remaining points collinear.
  const std::vector<Vec3> mixed = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {0, 1, 0}};
  const std::vector<double> dropOff = {1, 1, 1, 0};
  EXPECT_FALSE(dm::registerPoints(mixed, mixed, {.weights = dropOff}));
  EXPECT_FALSE(dm::predictedTre(line, ok, 1e-3));
  EXPECT_FALSE(dm::predictedTre(ok, ok, -1.0));
  dm::Registration identity;
  EXPECT_FALSE(dm::targetRegistrationError(identity, dm::Affine3::Identity(), {}));
}

}  // namespace
