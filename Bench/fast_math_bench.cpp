// fast_math_bench — dm::fast* against <cmath> on the same input arrays.
//
// Each benchmark maps a 4096-element input array to an output array with one
// function (a typical hot loop: the compiler may inline and vectorise it).
// After the Google Benchmark table it prints, per function, the ratio
// std_time / fast_time (> 1: the fast version is faster on this machine).
//
//   ./Bench/fast_math_bench [--benchmark_min_time=0.2] [--benchmark_repetitions=N]
#include <dm/math/fast_math.hpp>

#include <benchmark/benchmark.h>

#include <cmath>
#include <cstdio>
#include <map>
#include <random>
#include <string>
#include <vector>

namespace {

constexpr std::size_t kCount = 4096;

template <class T>
std::vector<T> logUniform(T lo, T hi, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(std::log(static_cast<double>(lo)),
                                           std::log(static_cast<double>(hi)));
  std::vector<T> v(kCount);
  for (T& x : v) x = static_cast<T>(std::exp(u(rng)));
  return v;
}

std::vector<double> uniform(double lo, double hi, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(lo, hi);
  std::vector<double> v(kCount);
  for (double& x : v) x = u(rng);
  return v;
}

// Inputs: sqrt/invsqrt over six decades, sin/cos over ±100 rad (the common
// case: glibc's fast path), exp over ±50.
const std::vector<double>& sqrtInput() {
  static const auto v = logUniform(1e-3, 1e3, 1);
  return v;
}
const std::vector<float>& sqrtInputF() {
  static const auto v = logUniform(1e-3f, 1e3f, 2);
  return v;
}
const std::vector<double>& trigInput() {
  static const auto v = uniform(-100.0, 100.0, 3);
  return v;
}
const std::vector<double>& expInput() {
  static const auto v = uniform(-50.0, 50.0, 4);
  return v;
}

template <class T, class F>
void mapArray(benchmark::State& state, const std::vector<T>& in, F f) {
  std::vector<T> out(in.size());
  for (auto _ : state) {
    for (std::size_t i = 0; i < in.size(); ++i) out[i] = f(in[i]);
    benchmark::DoNotOptimize(out.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations() * in.size()));
}

void sqrtStd(benchmark::State& s) {
  mapArray(s, sqrtInput(), [](double x) { return std::sqrt(x); });
}
void sqrtFast(benchmark::State& s) {
  mapArray(s, sqrtInput(), [](double x) { return dm::fastSqrt(x); });
}
void invSqrtStd(benchmark::State& s) {
  mapArray(s, sqrtInput(), [](double x) { return 1.0 / std::sqrt(x); });
}
void invSqrtFast(benchmark::State& s) {
  mapArray(s, sqrtInput(), [](double x) { return dm::fastInvSqrt(x); });
}
void sqrtfStd(benchmark::State& s) {
  mapArray(s, sqrtInputF(), [](float x) { return std::sqrt(x); });
}
void sqrtfFast(benchmark::State& s) {
  mapArray(s, sqrtInputF(), [](float x) { return dm::fastSqrt(x); });
}
void invSqrtfStd(benchmark::State& s) {
  mapArray(s, sqrtInputF(), [](float x) { return 1.0f / std::sqrt(x); });
}
void invSqrtfFast(benchmark::State& s) {
  mapArray(s, sqrtInputF(), [](float x) { return dm::fastInvSqrt(x); });
}
void sinStd(benchmark::State& s) {
  mapArray(s, trigInput(), [](double x) { return std::sin(x); });
}
void sinFast(benchmark::State& s) {
  mapArray(s, trigInput(), [](double x) { return dm::fastSin(x); });
}
void cosStd(benchmark::State& s) {
  mapArray(s, trigInput(), [](double x) { return std::cos(x); });
}
void cosFast(benchmark::State& s) {
  mapArray(s, trigInput(), [](double x) { return dm::fastCos(x); });
}
void expStd(benchmark::State& s) {
  mapArray(s, expInput(), [](double x) { return std::exp(x); });
}
void expFast(benchmark::State& s) {
  mapArray(s, expInput(), [](double x) { return dm::fastExp(x); });
}

// Benchmarks are named "<function>/std" and "<function>/fast".
const char* const kFunctions[] = {"sqrt", "invsqrt", "sqrtf", "invsqrtf", "sin", "cos", "exp"};

void registerAll() {
  const struct {
    const char* name;
    void (*fn)(benchmark::State&);
  } list[] = {{"sqrt/std", sqrtStd},         {"sqrt/fast", sqrtFast},
              {"invsqrt/std", invSqrtStd},   {"invsqrt/fast", invSqrtFast},
              {"sqrtf/std", sqrtfStd},       {"sqrtf/fast", sqrtfFast},
              {"invsqrtf/std", invSqrtfStd}, {"invsqrtf/fast", invSqrtfFast},
              {"sin/std", sinStd},           {"sin/fast", sinFast},
              {"cos/std", cosStd},           {"cos/fast", cosFast},
              {"exp/std", expStd},           {"exp/fast", expFast}};
  for (const auto& b : list) benchmark::RegisterBenchmark(b.name, b.fn);
}

// Console output as usual, plus the time per element of every run, kept
// for the ratio table (the last repetition or the mean aggregate wins).
class RatioReporter : public benchmark::ConsoleReporter {
 public:
  RatioReporter() : ConsoleReporter(OO_Tabular) {}  // no colour codes: the output is usually logged
  void ReportRuns(const std::vector<Run>& runs) override {
    ConsoleReporter::ReportRuns(runs);
    for (const Run& r : runs) {
      if (r.error_occurred) continue;
      std::string name = r.run_name.function_name;
      if (r.run_type == Run::RT_Aggregate && r.aggregate_name != "mean") continue;
      // CPU time: on a shared machine it is less disturbed by other load.
      nsPerElement_[name] = r.GetAdjustedCPUTime() / static_cast<double>(kCount);  // default unit: ns
    }
  }

  void printRatios() const {
    std::printf("\nstd_time / fast_time per element, CPU time (> 1: dm::fast* is faster here)\n");
    std::printf("%-10s %12s %12s %8s\n", "function", "std ns/elt", "fast ns/elt", "ratio");
    for (const char* f : kFunctions) {
      const auto s = nsPerElement_.find(std::string(f) + "/std");
      const auto q = nsPerElement_.find(std::string(f) + "/fast");
      if (s == nsPerElement_.end() || q == nsPerElement_.end()) continue;  // filtered out
      std::printf("%-10s %12.3f %12.3f %8.2f\n", f, s->second, q->second, s->second / q->second);
    }
  }

 private:
  std::map<std::string, double> nsPerElement_;
};

}  // namespace

int main(int argc, char** argv) {
  registerAll();
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  RatioReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  reporter.printRatios();
  benchmark::Shutdown();
  return 0;
}
