// FilterGraph overhead on a real video: the graph of the DMVision acceptance
// line (vtest.avi → gray → blur → Canny, and gray → MOG2 background
// subtraction → opening) against the same OpenCV calls written by hand in a
// loop, in this process, on the same frames. Prints frames per second and
// the ratio (graph time / hand time; goal ≤ 1.05). The graph runs both
// sequentially (parallel = false: only the dispatch overhead differs) and in
// parallel (branches concurrent, next frame decoded while filtering).
//
//   build-hgo-bench/Bench/vision_graph_bench [REPEATS]
#include <dm/core/filesystem.hpp>
#include <dm/vision/filter_graph.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <opencv2/imgproc.hpp>
#include <opencv2/video.hpp>
#include <opencv2/videoio.hpp>
#include <vector>

namespace {

constexpr const char* kGraph = R"({"nodes": [
  {"name": "video", "kind": "video_file", "path": "opencv:vtest.avi", "order": "bgr"},
  {"name": "gray", "kind": "color", "input": "video", "code": "gray"},
  {"name": "blur", "kind": "gaussian_blur", "input": "gray", "ksize": 5, "sigma": 1.5},
  {"name": "edges", "kind": "canny", "input": "blur", "low": 40, "high": 120},
  {"name": "fg", "kind": "background_subtraction", "input": "gray", "history": 200},
  {"name": "clean", "kind": "morphology", "input": "fg", "op": "open", "size": 3},
  {"name": "ne", "kind": "count_nonzero", "input": "edges"},
  {"name": "nf", "kind": "count_nonzero", "input": "clean"},
  {"name": "edge_count", "kind": "callback", "input": "ne"},
  {"name": "fg_count", "kind": "callback", "input": "nf"}
]})";

struct Run {
  double seconds = 0;
  long frames = 0;
  double checksum = 0;  // sum of the counts: both sides must agree
};

Run byHand(const std::string& path) {
  const auto t0 = std::chrono::steady_clock::now();
  cv::VideoCapture cap(path);
  auto mog = cv::createBackgroundSubtractorMOG2(200, 16, false);
  const cv::Mat kernel = cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(3, 3));
  cv::Mat frame, gray, blur, edges, fg, clean;
  Run r;
  while (cap.read(frame)) {
    cv::cvtColor(frame, gray, cv::COLOR_BGR2GRAY);
    cv::GaussianBlur(gray, blur, cv::Size(5, 5), 1.5, 1.5, cv::BORDER_REFLECT_101);
    cv::Canny(blur, edges, 40, 120);
    mog->apply(gray, fg, -1);
    cv::morphologyEx(fg, clean, cv::MORPH_OPEN, kernel);
    r.checksum += cv::countNonZero(edges) + cv::countNonZero(clean);
    ++r.frames;
  }
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return r;
}

Run byGraph(bool parallel) {
  const auto t0 = std::chrono::steady_clock::now();
  auto g = dm::FilterGraph::parse(kGraph);
  if (!g) {
    std::fprintf(stderr, "%s\n", g.error().message().c_str());
    std::exit(1);
  }
  Run r;
  auto add = [&r](const dm::GraphValue& v, std::int64_t) { r.checksum += v.scalar; };
  (void)g->setCallback("edge_count", add);
  (void)g->setCallback("fg_count", add);
  auto stats = g->run({.parallel = parallel});
  if (!stats) {
    std::fprintf(stderr, "%s\n", stats.error().message().c_str());
    std::exit(1);
  }
  r.frames = long(stats->frames);
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return r;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  const int repeats = argc > 1 ? std::max(1, std::atoi(argv[1])) : 5;
  auto path = dm::FileSystem::global().resolve("opencv:vtest.avi");
  if (!path) {
    std::fprintf(stderr, "%s\n", path.error().message().c_str());
    return 1;
  }
  std::vector<double> hand, seq, par;
  Run h, s, p;
  for (int i = 0; i < repeats; ++i) {  // interleaved, so load drifts hit all three alike
    h = byHand(path->string());
    s = byGraph(false);
    p = byGraph(true);
    hand.push_back(h.seconds);
    seq.push_back(s.seconds);
    par.push_back(p.seconds);
  }
  if (h.frames != s.frames || h.frames != p.frames || h.checksum != s.checksum || h.checksum != p.checksum) {
    std::fprintf(stderr, "results differ: frames %ld/%ld/%ld, checksum %.0f/%.0f/%.0f\n", h.frames, s.frames,
                 p.frames, h.checksum, s.checksum, p.checksum);
    return 1;
  }
  const double th = median(hand), ts = median(seq), tp = median(par);
  std::printf("vtest.avi, %ld frames 768x576, %d repeats (median), identical results\n", h.frames, repeats);
  std::printf("%-34s %8.1f fps\n", "OpenCV calls by hand", double(h.frames) / th);
  std::printf("%-34s %8.1f fps   ratio %.3f\n", "FilterGraph, sequential", double(s.frames) / ts, ts / th);
  std::printf("%-34s %8.1f fps   ratio %.3f\n", "FilterGraph, parallel + prefetch", double(p.frames) / tp,
              tp / th);
  return 0;
}
