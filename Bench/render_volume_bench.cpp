// render_volume_bench — frames per second of DMRenderer's volume ray caster
// on the Colin27 MRI volumes (mricron:ch2.nii.gz 181x217x181 at 1 mm and
// mricron:ch2better.nii.gz 301x370x316 at 0.5 mm) at 512x512: composite
// (skin transfer function, shaded) with and without empty-space skipping,
// composite with a brain transfer function, and MIP. Each row renders a few
// warm-up frames, then frames until `--seconds` (default 3) have passed, with
// glFinish() after each frame so the time covers the whole GPU work.
// Prints a table and the skipping speed-up (ratio of frame rates).
//
//   render_volume_bench [--seconds S] [--size N]
#include <dm/core/filesystem.hpp>
#include <dm/io/volume_io.hpp>
#include <dm/renderer/context.hpp>
#include <dm/renderer/render_target.hpp>
#include <dm/renderer/volume_renderer.hpp>

#ifndef GL_GLEXT_PROTOTYPES
#define GL_GLEXT_PROTOTYPES 1
#endif
#include <GL/glcorearb.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

namespace {

struct Row {
  const char* name;
  dm::VolumeRenderMode mode;
  bool skip;
  bool brain;
};

struct Timing {
  double fps = 0;
  int frames = 0;
  double samplesPerRay = 0, skippedPerRay = 0;
};

Timing timeRow(dm::VolumeRenderer& vr, const dm::RenderTarget& rt, const dm::Camera& cam, dm::VolumeId id,
               const dm::VolumeRenderSettings& s, double seconds) {
  using Clock = std::chrono::steady_clock;
  Timing t;
  dm::VolumeRenderSettings stats = s;
  stats.collectStats = true;
  rt.clear(dm::Vec4f(0, 0, 0, 1));
  if (auto r = vr.render(rt, cam, id, stats); !r) {
    std::fprintf(stderr, "render failed: %s\n", r.error().message().c_str());
    std::exit(1);
  }
  glFinish();
  const dm::VolumeRenderStats& st = vr.lastStats();
  if (st.rays > 0) {
    t.samplesPerRay = double(st.samples) / double(st.rays);
    t.skippedPerRay = double(st.skippedSamples) / double(st.rays);
  }
  const auto start = Clock::now();
  double elapsed = 0;
  while (elapsed < seconds || t.frames < 3) {
    rt.clear(dm::Vec4f(0, 0, 0, 1));
    (void)vr.render(rt, cam, id, s);
    glFinish();
    ++t.frames;
    elapsed = std::chrono::duration<double>(Clock::now() - start).count();
  }
  t.fps = t.frames / elapsed;
  return t;
}

}  // namespace

int main(int argc, char** argv) {
  double seconds = 3;
  int size = 512;
  for (int i = 1; i + 1 < argc; i += 2) {
    if (std::strcmp(argv[i], "--seconds") == 0) seconds = std::atof(argv[i + 1]);
    if (std::strcmp(argv[i], "--size") == 0) size = std::atoi(argv[i + 1]);
  }
  auto ctx = dm::GlContext::create();
  if (!ctx) {
    std::fprintf(stderr, "%s\n", ctx.error().message().c_str());
    return 1;
  }
  std::printf("GL: %s | %s\n", (*ctx)->info().glRenderer.c_str(), (*ctx)->info().glVersion.c_str());
  auto rt = dm::RenderTarget::create({.width = size, .height = size, .samples = 1});
  auto vr = dm::VolumeRenderer::create();
  if (!rt || !vr) {
    std::fprintf(stderr, "setup failed: %s\n", (!rt ? rt.error() : vr.error()).message().c_str());
    return 1;
  }
  const Row rows[] = {
      {"composite skin, skipping", dm::VolumeRenderMode::Composite, true, false},
      {"composite skin, no skipping", dm::VolumeRenderMode::Composite, false, false},
      {"composite brain, skipping", dm::VolumeRenderMode::Composite, true, true},
      {"composite brain, no skipping", dm::VolumeRenderMode::Composite, false, true},
      {"MIP, skipping", dm::VolumeRenderMode::Mip, true, false},
      {"MIP, no skipping", dm::VolumeRenderMode::Mip, false, false},
  };
  std::printf("%dx%d, step 0.5 voxel, %.1f s per row\n\n", size, size, seconds);
  std::printf("%-18s %-30s %9s %7s %12s %12s\n", "volume", "mode", "fps", "frames", "samples/ray",
              "skipped/ray");
  for (const char* name : {"ch2.nii.gz", "ch2better.nii.gz"}) {
    auto path = dm::FileSystem::global().resolve(std::string("mricron:") + name);
    if (!path) {
      std::fprintf(stderr, "%s\n", path.error().message().c_str());
      return 1;
    }
    auto vol = dm::readVolume(*path);
    if (!vol) {
      std::fprintf(stderr, "%s\n", vol.error().message().c_str());
      return 1;
    }
    auto id = vr->addVolume(*vol);
    if (!id) {
      std::fprintf(stderr, "%s\n", id.error().message().c_str());
      return 1;
    }
    const auto [lo, hi] = vol->range();
    auto skin = dm::TransferFunction::mriSkin(lo, hi);
    auto brain = dm::TransferFunction::mriBrain(lo, hi);
    const dm::Vec3 c = vol->worldBounds().center();
    dm::Camera cam = dm::Camera::lookAt(c + dm::Vec3(0.25, 0.35, 0.12), c, dm::Vec3(0, 0, 1));
    cam.fovYDeg = 40;
    double fps[6] = {};
    for (int r = 0; r < 6; ++r) {
      (void)vr->setTransferFunction(*id, rows[r].brain ? *brain : *skin);
      const dm::VolumeRenderSettings s{.mode = rows[r].mode, .emptySpaceSkipping = rows[r].skip};
      const Timing t = timeRow(*vr, *rt, cam, *id, s, seconds);
      fps[r] = t.fps;
      std::printf("%-18s %-30s %9.2f %7d %12.1f %12.1f\n", name, rows[r].name, t.fps, t.frames,
                  t.samplesPerRay, t.skippedPerRay);
    }
    std::printf("%-18s skipping speed-up: skin %.2fx, brain %.2fx, MIP %.2fx\n\n", name, fps[0] / fps[1],
                fps[2] / fps[3], fps[4] / fps[5]);
    (void)vr->removeVolume(*id);
  }
  return 0;
}
