// Soft-tissue indentation and the inverse fit of its material — an example
// simulator built from the SDK's parts.
//
// A block of tissue (40 × 40 × 20 mm, co-rotational FEM on 1536 tetrahedra
// of a 5 mm grid, dm::FemBody, bottom fixed) is indented by a flat punch
// bonded to its top face: the 9 top nodes within 7.5 mm of the axis, a
// 10 × 10 mm square. The punch follows a haptic device:
// sim-haptic moving its stylus down 3 mm and back up (a triangle wave), the
// punch's nodes moved with the prescribed velocity that brings them to the
// device's depth each physics step, and the tissue's reaction
// (FemBody::computeConstraintForces) displayed on the device every haptic
// tick. Two engines in a dm::MasterEngine: "haptics" at 1 kHz and
// "physics" at 100 Hz, in lockstep on a virtual clock (bit-reproducible) or
// on real-time threads.
//
// The material is linear elastic with stiffness-proportional (Kelvin–Voigt)
// damping: Young's modulus E and the damping time β, with ν = 0.45 assumed
// (near-incompressible tissue). The force–displacement curve of a cycle is a
// hysteresis loop: its slope gives E, its width β.
//
// The inverse fit recovers (E, β) from a measured curve: Levenberg–Marquardt
// on (ln E, ln β), each residual evaluation replaying the measured
// displacement history through the same FEM model with the candidate
// coefficients, the Jacobian by forward differences; it stops when a step
// changes the coefficients by less than 1e-4 relative. By default the
// "measured" curve is the one just simulated plus Gaussian noise (seeded),
// so the fit's answer can be checked against the coefficients that made it;
// --measured FILE fits a curve of your own instead (CSV rows
// "t,displacement,force" in s, m, N; the displacement positive into the
// tissue, one row per 10 ms physics step).
//
//   dm_example_tissue_indentation [--out DIR] [--youngs PA] [--beta S]
//       [--noise N] [--seed K] [--cycles C] [--measured FILE] [--realtime]
//
// Outputs in DIR: curve.csv (t, displacement, simulated, measured and
// fitted force), measured.csv (the measurement alone, as --measured reads
// it), curve.png (force against displacement: measured points,
// fitted loop), forces.png (the force on the hand over time) and
// summary.json (the true and fitted coefficients, their relative errors,
// the residual RMS against the noise, the iterations, the engines' rates).
//
// Exit codes: 0 done, 1 failure (message on stderr), 2 bad command line.
#include <dm/core/filesystem.hpp>
#include <dm/core/units.hpp>
#include <dm/engine/master_engine.hpp>
#include <dm/haptics/force_plot.hpp>
#include <dm/haptics/probe.hpp>
#include <dm/io/drivers.hpp>
#include <dm/io/haptic_device.hpp>
#include <dm/io/image_io.hpp>
#include <dm/physics/fem.hpp>

#include <CLI/CLI.hpp>
#include <Eigen/Dense>
#include <nlohmann/json.hpp>

#include "../common/example_support.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <thread>
#include <vector>

namespace {

namespace fs = std::filesystem;
using dm::Vec3;

constexpr double kPhysicsRate = 100.0;  // Hz
constexpr double kH = 1.0 / kPhysicsRate;
constexpr double kDepth = 3e-3;         // m, deepest indentation
constexpr double kSweep = 1.0;          // s, down or up
constexpr double kPunchRadius = 7.5e-3;  // m: the 9 top nodes of a 10 × 10 mm square
constexpr double kPoisson = 0.45;

struct Options {
  fs::path out = "tissue_indentation_out";
  double youngs = 12e3;  // Pa
  double beta = 0.04;    // s
  double noise = 0.01;   // N, standard deviation of the measurement noise
  unsigned seed = 7;
  int cycles = 1;
  std::string measured;
  bool realtime = false;
};

// One sample of the curve: time, indentation depth (m, into the tissue),
// force on the punch (N, pushing it out of the tissue).
struct CurvePoint {
  double t = 0, depth = 0, force = 0;
};

// The tissue block and its punch.
class Indentation {
 public:
  static dm::Result<Indentation> create(double youngs, double beta) {
    auto mesh = dm::tetMeshBox({8, 8, 4}, Vec3(0.04, 0.04, 0.02), Vec3(-0.02, -0.02, -0.02));
    if (!mesh) return mesh.error();
    auto body = dm::FemBody::create(*mesh, {.youngsModulus = youngs, .poissonRatio = kPoisson, .density = 1000},
                                    {.beta = beta}, {.tolerance = 1e-6, .maxIterations = 500});
    if (!body) return body.error();
    Indentation in(std::move(*body));
    in.body_.fixNodesWhere([](const Vec3& p) { return p.z() < -0.02 + 1e-9; });
    for (std::size_t i = 0; i < mesh->nodeCount(); ++i) {
      const Vec3& p = mesh->nodes[i];
      if (p.z() > -1e-9 && std::hypot(p.x(), p.y()) <= kPunchRadius + 1e-9) {
        in.body_.setFixed(i, true);
        in.punch_.push_back(i);
      }
    }
    in.reaction_.resize(in.body_.nodeCount());
    return in;
  }

  // One physics step: the punch moves to `depth` (m) over h, then the force
  // the tissue exerts on it (N, positive out of the tissue).
  dm::Result<double> step(double depth) {
    const double v = -(depth - depth_) / kH;  // z velocity of the punch
    for (std::size_t i : punch_) body_.setVelocity(i, Vec3(0, 0, v));
    if (auto r = body_.step(kH); !r) return r.error();
    depth_ = depth;
    body_.computeConstraintForces(reaction_);
    Vec3 f = Vec3::Zero();
    for (std::size_t i : punch_) f -= reaction_[i];
    return f.z();
  }

  std::size_t punchNodes() const { return punch_.size(); }
  const dm::FemBody& body() const { return body_; }

 private:
  explicit Indentation(dm::FemBody body) : body_(std::move(body)) {}
  dm::FemBody body_;
  std::vector<std::size_t> punch_;
  std::vector<Vec3> reaction_;
  double depth_ = 0;
};

// The model's force for a displacement history, with coefficients (E, β).
dm::Result<std::vector<double>> simulate(const std::vector<CurvePoint>& curve, double youngs, double beta) {
  auto model = Indentation::create(youngs, beta);
  if (!model) return model.error();
  std::vector<double> f;
  f.reserve(curve.size());
  for (const CurvePoint& c : curve) {
    auto r = model->step(c.depth);
    if (!r) return r.error();
    f.push_back(*r);
  }
  return f;
}

struct Fit {
  double youngs = 0, beta = 0, rms = 0;
  int iterations = 0, evaluations = 0;
};

// Levenberg–Marquardt on p = (ln E, ln β) (see the file comment).
dm::Result<Fit> fitMaterial(const std::vector<CurvePoint>& curve, double youngs0, double beta0) {
  const auto n = static_cast<Eigen::Index>(curve.size());
  Eigen::VectorXd measured(n);
  for (Eigen::Index k = 0; k < n; ++k) measured[k] = curve[static_cast<std::size_t>(k)].force;
  Fit fit;
  const auto residual = [&](const Eigen::Vector2d& p) -> dm::Result<Eigen::VectorXd> {
    ++fit.evaluations;
    auto f = simulate(curve, std::exp(p[0]), std::exp(p[1]));
    if (!f) return f.error();
    Eigen::VectorXd res = Eigen::Map<const Eigen::VectorXd>(f->data(), n) - measured;
    return res;
  };
  Eigen::Vector2d p(std::log(youngs0), std::log(beta0));
  auto r = residual(p);
  if (!r) return r.error();
  double cost = r->squaredNorm(), lambda = 1e-3;
  for (fit.iterations = 1; fit.iterations <= 50; ++fit.iterations) {
    Eigen::MatrixXd J(n, 2);
    for (int j = 0; j < 2; ++j) {
      Eigen::Vector2d q = p;
      q[j] += 1e-4;
      auto rq = residual(q);
      if (!rq) return rq.error();
      J.col(j) = (*rq - *r) / 1e-4;
    }
    const Eigen::Matrix2d JtJ = J.transpose() * J;
    const Eigen::Vector2d g = J.transpose() * *r;
    bool accepted = false;
    Eigen::Vector2d delta = Eigen::Vector2d::Zero();
    for (int tries = 0; tries < 20 && !accepted; ++tries) {
      Eigen::Matrix2d A = JtJ;
      A.diagonal() *= 1.0 + lambda;
      delta = A.ldlt().solve(-g);
      auto rt = residual(p + delta);
      if (!rt) return rt.error();
      const double c = rt->squaredNorm();
      if (c < cost) {
        p += delta, r = std::move(rt), cost = c, lambda = std::max(lambda / 10, 1e-9), accepted = true;
      } else {
        lambda *= 10;
      }
    }
    if (!accepted || delta.cwiseAbs().maxCoeff() < 1e-4) break;
  }
  fit.youngs = std::exp(p[0]);
  fit.beta = std::exp(p[1]);
  fit.rms = std::sqrt(cost / static_cast<double>(n));
  return fit;
}

dm::Result<std::vector<CurvePoint>> readCurve(const std::string& file) {
  auto bytes = dm::readFile(file);
  if (!bytes) return bytes.error();
  const auto text = std::make_unique<std::string>(reinterpret_cast<const char*>(bytes->data()), bytes->size());
  std::vector<CurvePoint> curve;
  std::size_t line = 0, pos = 0;
  while (pos < text->size()) {
    const std::size_t nl = text->find('\n', pos);
    const std::string row = text->substr(pos, nl == std::string::npos ? std::string::npos : nl - pos);
    pos = nl == std::string::npos ? text->size() : nl + 1;
    ++line;
    if (row.empty() || row[0] == '#' || (line == 1 && row.find_first_of("0123456789") != 0)) continue;
    CurvePoint c;
    char tail = 0;
    if (std::sscanf(row.c_str(), "%lf,%lf,%lf%c", &c.t, &c.depth, &c.force, &tail) < 3 ||
        (tail != 0 && tail != '\r' && tail != ',') || !std::isfinite(c.t) || !std::isfinite(c.depth) ||
        !std::isfinite(c.force))
      return dm::fail(dm::ErrorCode::Parse, "expected \"t,displacement,force\" (three finite numbers)",
                      dm::formatString("%s:%zu", file.c_str(), line), "s, m (into the tissue), N");
    if (c.depth < -1e-3 || c.depth > 0.01)
      return dm::fail(dm::ErrorCode::InvalidArgument,
                      dm::formatString("displacement %g m is outside [-1, 10] mm", c.depth),
                      dm::formatString("%s:%zu", file.c_str(), line), "give metres, positive into the tissue");
    curve.push_back(c);
  }
  if (curve.size() < 20)
    return dm::fail(dm::ErrorCode::InvalidArgument, dm::formatString("%zu samples; at least 20 needed", curve.size()),
                    file, "one row per 10 ms physics step");
  return curve;
}

int fail(const dm::Error& e) {
  std::cerr << "dm_example_tissue_indentation: " << e << '\n';
  return 1;
}

// Runs the simulator: the device drives the punch, the hand feels the tissue.
dm::Result<std::vector<CurvePoint>> runSimulator(const Options& o, nlohmann::json& engines,
                                                 std::vector<dm::ProbeSample>& trace) {
  auto tissue = Indentation::create(o.youngs, o.beta);
  if (!tissue) return tissue.error();
  dm::FactoryRegistry registry;
  dm::PluginLinker linker(registry);
  if (auto s = dm::registerBuiltinDrivers(linker); !s) return s.error();
  // The stylus: from the surface down kDepth and back, kSweep each way.
  auto device = dm::HapticDevice::open(registry, "sim-haptic",
                                       {{"path", "line"},
                                        {"from", "0,0,0"},
                                        {"to", dm::formatString("0,0,%.9f", -kDepth)},
                                        {"period", dm::formatString("%.9f", 2 * kSweep)},
                                        {"max_force", "20"}});
  if (!device) return device.error();
  const double duration = 2 * kSweep * o.cycles;
  const auto physicsSteps = static_cast<std::size_t>(std::llround(duration * kPhysicsRate));
  std::vector<CurvePoint> curve;
  curve.reserve(physicsSteps + 8);
  trace.reserve(static_cast<std::size_t>(duration * 1000) + 16);
  std::atomic<double> depth{0.0}, force{0.0};  // device → physics, physics → device
  std::int64_t startNs = -1;
  dm::HapticDevice& dev = **device;
  auto haptics = dm::makeFunctionEngine("haptics", [&](const dm::TickInfo& t) {
    if (dev.servo(t.scheduled_ns) != dm::DeviceStatus::Ok) return false;
    if (startNs < 0) startNs = t.scheduled_ns;
    depth.store(std::max(0.0, -dev.state().position.z()), std::memory_order_relaxed);
    const Vec3 f(0, 0, force.load(std::memory_order_relaxed));  // pushes the stylus up
    dev.command(f, Vec3::Zero(), t.scheduled_ns);
    if (trace.size() < trace.capacity()) {
      dm::ProbeSample s;
      s.t = 1e-9 * static_cast<double>(t.scheduled_ns - startNs);
      s.devicePose.translation() = dev.state().position;
      s.response.force = f;
      trace.push_back(s);
    }
    return true;
  });
  dm::Error physicsError;
  auto physics = dm::makeFunctionEngine("physics", [&](const dm::TickInfo& t) {
    if (curve.size() >= physicsSteps) return true;
    const double d = depth.load(std::memory_order_relaxed);
    auto f = tissue->step(d);
    if (!f) {
      physicsError = f.error();
      return false;
    }
    force.store(*f, std::memory_order_relaxed);
    curve.push_back({1e-9 * static_cast<double>(t.scheduled_ns), d, *f});
    return true;
  });
  dm::MasterEngine master;
  if (auto s = master.addEngine(haptics, {.rateHz = 1000, .priority = 80}); !s) return s.error();
  if (auto s = master.addEngine(physics, {.rateHz = kPhysicsRate}); !s) return s.error();
  std::vector<dm::EngineStats> stats;
  const dm::Status ran = dm_example::runEngines(master, "tissue indentation", o.realtime, duration, stats);
  if (!physicsError.what.empty()) return physicsError;
  if (!ran) return ran.error();
  engines = dm::engineStatsJson(stats);
  return curve;
}

int run(const Options& o) {
  nlohmann::json engines = nlohmann::json::array();
  std::vector<dm::ProbeSample> trace;
  std::vector<CurvePoint> curve;
  std::vector<double> simulated;
  const bool synthetic = o.measured.empty();
  if (synthetic) {
    auto c = runSimulator(o, engines, trace);
    if (!c) return fail(c.error());
    curve = std::move(*c);
    // The measurement: the simulated force plus Gaussian noise.
    std::mt19937_64 rng(o.seed);
    std::normal_distribution<double> noise(0.0, o.noise);
    for (CurvePoint& p : curve) {
      simulated.push_back(p.force);
      p.force += noise(rng);
    }
  } else {
    auto c = readCurve(o.measured);
    if (!c) return fail(c.error());
    curve = std::move(*c);
  }

  // Start far from the answer: 5 kPa and 10 ms.
  auto fit = fitMaterial(curve, 5e3, 0.01);
  if (!fit) return fail(fit.error());
  auto fitted = simulate(curve, fit->youngs, fit->beta);
  if (!fitted) return fail(fitted.error());

  if (auto s = dm_example::makeOutputDir(o.out); !s) return fail(s.error());
  std::vector<std::string> written;
  std::string csv = "t,displacement_m,simulated_N,measured_N,fitted_N\n";
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::vector<double> depthMm, measured;
  for (std::size_t k = 0; k < curve.size(); ++k) {
    csv += dm::formatString("%.6f,%.9g,%.9g,%.9g,%.9g\n", curve[k].t, curve[k].depth,
                            synthetic ? simulated[k] : nan, curve[k].force, (*fitted)[k]);
    depthMm.push_back(1e3 * curve[k].depth);
    measured.push_back(curve[k].force);
  }
  if (auto s = dm_example::writeOutput(o.out / "curve.csv", csv, written); !s) return fail(s.error());
  if (synthetic) {  // the measurement alone, in the format --measured reads
    std::string m = "t,displacement_m,force_N\n";
    for (const CurvePoint& c : curve) m += dm::formatString("%.6f,%.17g,%.17g\n", c.t, c.depth, c.force);
    if (auto s = dm_example::writeOutput(o.out / "measured.csv", m, written); !s) return fail(s.error());
  }
  const dm::PlotSeries series[] = {{"MEASURED", {30, 60, 220}, depthMm, measured, true},
                                   {"FIT", {220, 30, 30}, depthMm, *fitted}};
  auto plot = dm::plotSeries(series, {.xUnit = "mm", .yUnit = "N"});
  if (!plot) return fail(plot.error());
  if (auto s = dm::writePng(*plot, o.out / "curve.png"); !s) return fail(s.error());
  written.push_back("curve.png");
  if (!trace.empty()) {
    auto forces = dm::plotForceTrace(trace);
    if (!forces) return fail(forces.error());
    if (auto s = dm::writePng(*forces, o.out / "forces.png"); !s) return fail(s.error());
    written.push_back("forces.png");
  }

  double maxForce = 0;
  for (double f : measured) maxForce = std::max(maxForce, std::abs(f));
  nlohmann::json summary = {{"mode", synthetic ? (o.realtime ? "realtime" : "lockstep") : "measured"},
                            {"samples", curve.size()},
                            {"poisson_ratio", kPoisson},
                            {"punch_radius_m", kPunchRadius},
                            {"max_force_N", maxForce},
                            {"fit",
                             {{"youngs_modulus_Pa", fit->youngs},
                              {"beta_s", fit->beta},
                              {"rms_N", fit->rms},
                              {"iterations", fit->iterations},
                              {"evaluations", fit->evaluations}}},
                            {"engines", engines},
                            {"outputs", written}};
  if (synthetic) {
    summary["true"] = {{"youngs_modulus_Pa", o.youngs}, {"beta_s", o.beta}, {"noise_N", o.noise}};
    summary["relative_error"] = {{"youngs_modulus", std::abs(fit->youngs - o.youngs) / o.youngs},
                                 {"beta", std::abs(fit->beta - o.beta) / o.beta}};
    summary["rms_over_noise"] = o.noise > 0 ? fit->rms / o.noise : nan;
  }
  if (auto s = dm_example::writeOutput(o.out / "summary.json", summary.dump(2) + "\n", written); !s)
    return fail(s.error());
  std::printf("fitted E = %.1f Pa, beta = %.4f s (residual RMS %.4f N, %d iterations, %d simulations)", fit->youngs,
              fit->beta, fit->rms, fit->iterations, fit->evaluations);
  if (synthetic)
    std::printf("; true E = %.1f Pa, beta = %.4f s, noise %.4f N; peak force %.3f N", o.youngs, o.beta, o.noise,
                maxForce);
  std::printf("; outputs in %s\n", o.out.string().c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{"Soft-tissue indentation with an FEM block and the inverse fit of its material"};
  app.add_option("--out", o.out, "Output directory (default tissue_indentation_out)");
  app.add_option("--youngs", o.youngs, "Young's modulus of the simulated tissue, Pa (default 12000)")
      ->check(CLI::Range(100.0, 1e7));
  app.add_option("--beta", o.beta, "Stiffness-proportional damping time, s (default 0.04)")
      ->check(CLI::Range(1e-4, 1.0));
  app.add_option("--noise", o.noise, "Measurement noise added to the simulated force, N (default 0.01)")
      ->check(CLI::Range(0.0, 10.0));
  app.add_option("--seed", o.seed, "Noise seed (default 7)");
  app.add_option("--cycles", o.cycles, "Indentation cycles (default 1)")->check(CLI::Range(1, 20));
  app.add_option("--measured", o.measured, "Fit this curve (CSV t,displacement,force) instead of a simulated one");
  app.add_flag("--realtime", o.realtime, "Real-time threads instead of lockstep on a virtual clock");
  bool parsed = false;
  const int code = dm_example::parseCommandLine(app, argc, argv, parsed);
  return parsed ? run(o) : code;
}
