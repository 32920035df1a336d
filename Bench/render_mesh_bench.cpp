// render_mesh_bench — triangle throughput of dm::SceneRenderer on the EGL
// context it runs on (llvmpipe on CI machines), against a minimal EGL + GL
// program drawing the same vertices and indices with the same lighting in the
// same process and context, plus the cost of colour read-back synchronous vs
// through the PBO ring (dm::AsyncReadback).
//
//   render_mesh_bench [maxTriangles] [seconds per case]
//
// Scenes: one bumpy UV sphere of about 0.1M, 1M and 10M triangles (radius
// 10 cm, filling about 60% of the image height), viewed at 1280x720 and
// 1920x1080, one directional light, Blinn–Phong, no MSAA, no shadows.
// A frame is: clear, draw, glFinish (so the rasteriser's work is inside the
// timed interval); ours and the minimal program's frames alternate, so a
// change of load during the run affects both. Columns: ms per frame (median of the timed frames) for
// ours and the minimal program, their ratio (goal: at most 1.10), and
// triangles per second (ours). The read-back table: per-frame cost on the
// rendering thread of readColor() against request() + the previous frame's
// wait() through a ring of 3 PBOs, at each size. Last, an endoscope-like
// zoomed-in view of the 1M sphere drawn whole and with cluster culling
// through a dm::MeshBvh (SceneRenderer::setMeshTree).
#include <dm/collide/bvh.hpp>
#include <dm/core/log.hpp>
#include <dm/math/primitives.hpp>
#include <dm/renderer/context.hpp>
#include <dm/renderer/render_target.hpp>
#include <dm/renderer/scene_renderer.hpp>
#include <dm/renderer/shader.hpp>

#ifndef GL_GLEXT_PROTOTYPES
#define GL_GLEXT_PROTOTYPES 1
#endif
#include <GL/glcorearb.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

// A UV sphere with radial bumps (so shading varies across it), ~n triangles.
dm::Mesh bumpySphere(std::size_t n) {
  const int k = std::max(8, static_cast<int>(std::sqrt(double(n) / 2.0)));
  dm::Mesh m = dm::makeUvSphere(0.1, k, k);
  for (auto& p : m.positions) {
    const dm::Vec3 u = p.normalized();
    p = u * (0.1 + 0.002 * std::sin(20 * u.x()) * std::sin(20 * u.y()) * std::sin(20 * u.z()));
  }
  m.computeNormals();
  return m;
}

// The minimal program: the same Blinn–Phong directional term as the
// renderer's shader, position + normal per vertex, one draw call.
constexpr const char* kMinimalVs = R"(
layout(location = 0) in vec3 a_position;
layout(location = 1) in vec3 a_normal;
uniform mat4 u_viewProj;
out vec3 v_worldPos;
out vec3 v_normal;
void main() {
  v_worldPos = a_position;
  v_normal = a_normal;
  gl_Position = u_viewProj * vec4(a_position, 1.0);
}
)";
constexpr const char* kMinimalFs = R"(
in vec3 v_worldPos;
in vec3 v_normal;
uniform vec3 u_cameraPos;
uniform vec3 u_lightDir;
uniform vec3 u_baseColor;
out vec4 o_color;
void main() {
  vec3 n = normalize(v_normal);
  vec3 l = -u_lightDir;
  vec3 v = normalize(u_cameraPos - v_worldPos);
  vec3 h = normalize(l + v);
  float ndl = max(dot(n, l), 0.0);
  float spec = ndl > 0.0 ? pow(max(dot(n, h), 0.0), 32.0) : 0.0;
  o_color = vec4(u_baseColor * (0.03 + ndl) + vec3(0.2) * spec, 1.0);
}
)";

struct Minimal {
  GLuint vao = 0, vbo = 0, ibo = 0;
  GLsizei indexCount = 0;
  dm::ShaderProgram prog;

  bool init(const dm::Mesh& m) {
    auto p = dm::ShaderProgram::create(
        "minimal", {{dm::ShaderStage::Vertex, kMinimalVs}, {dm::ShaderStage::Fragment, kMinimalFs}});
    if (!p) {
      std::fprintf(stderr, "%s\n", p.error().message().c_str());
      return false;
    }
    prog = std::move(*p);
    std::vector<float> v;
    v.reserve(m.positions.size() * 6);
    for (std::size_t i = 0; i < m.positions.size(); ++i) {
      for (int c = 0; c < 3; ++c) v.push_back(static_cast<float>(m.positions[i][c]));
      for (int c = 0; c < 3; ++c) v.push_back(static_cast<float>(m.normals[i][c]));
    }
    glCreateBuffers(1, &vbo);
    glNamedBufferStorage(vbo, static_cast<GLsizeiptr>(v.size() * sizeof(float)), v.data(), 0);
    glCreateBuffers(1, &ibo);
    glNamedBufferStorage(ibo, static_cast<GLsizeiptr>(m.triangles.size() * sizeof(dm::Triangle)),
                         m.triangles.data(), 0);
    glCreateVertexArrays(1, &vao);
    glVertexArrayVertexBuffer(vao, 0, vbo, 0, 6 * sizeof(float));
    glVertexArrayElementBuffer(vao, ibo);
    for (GLuint a = 0; a < 2; ++a) {
      glEnableVertexArrayAttrib(vao, a);
      glVertexArrayAttribFormat(vao, a, 3, GL_FLOAT, GL_FALSE, a * 3 * sizeof(float));
      glVertexArrayAttribBinding(vao, a, 0);
    }
    indexCount = static_cast<GLsizei>(m.triangles.size() * 3);
    return true;
  }
  void draw(const dm::RenderTarget& rt, const dm::Camera& cam, const dm::Vec3& lightDir) {
    rt.bind();
    rt.clear(dm::Vec4f(0, 0, 0, 1));
    glEnable(GL_DEPTH_TEST);
    glDepthFunc(GL_LESS);
    glEnable(GL_CULL_FACE);
    prog.use();
    prog.set("u_viewProj",
             dm::Mat4f(cam.projectionMatrix(double(rt.width()) / rt.height()) * cam.viewMatrix()));
    prog.set("u_cameraPos", dm::Vec3f(cam.position.cast<float>()));
    prog.set("u_lightDir", dm::Vec3f(lightDir.normalized().cast<float>()));
    prog.set("u_baseColor", dm::Vec3f(0.8f, 0.6f, 0.5f));
    glBindVertexArray(vao);
    glDrawElements(GL_TRIANGLES, indexCount, GL_UNSIGNED_INT, nullptr);
    glBindVertexArray(0);
  }
  ~Minimal() {
    glDeleteVertexArrays(1, &vao);
    glDeleteBuffers(1, &vbo);
    glDeleteBuffers(1, &ibo);
  }
};

// Frames of two programs alternately (a, b, a, b, ...) for `seconds`, so
// that a change in the machine's load during the run hits both alike.
template <class A, class B>
std::pair<std::vector<double>, std::vector<double>> timeInterleaved(A&& a, B&& b, double seconds) {
  a();
  b();
  glFinish();
  std::vector<double> ta, tb;
  const auto start = Clock::now();
  while (ta.size() < 3 || (msSince(start) < 2 * seconds * 1000 && ta.size() < 200)) {
    auto t0 = Clock::now();
    a();
    glFinish();
    ta.push_back(msSince(t0));
    t0 = Clock::now();
    b();
    glFinish();
    tb.push_back(msSince(t0));
  }
  return {ta, tb};
}

template <class F>
std::vector<double> timeFrames(F&& frame, double seconds) {
  frame();  // warm-up: shader variants, first-touch of buffers
  glFinish();
  std::vector<double> ms;
  const auto start = Clock::now();
  while (ms.size() < 3 || (msSince(start) < seconds * 1000 && ms.size() < 200)) {
    const auto t0 = Clock::now();
    frame();
    glFinish();
    ms.push_back(msSince(t0));
  }
  return ms;
}

// Zoomed in, an endoscope's view (eye 2 cm off the surface, 1–6 cm depth
// range) of the 1M-triangle sphere at 1280x720: the mesh drawn whole against
// the same mesh with cluster culling through a dm::MeshBvh of it
// (SceneRenderer::setMeshTree), and the minimal program drawing everything.
bool zoomedIn(dm::SceneRenderer& scene, dm::MaterialId material, const dm::Light& light,
              const dm::RenderSettings& settings, std::size_t maxTriangles, double seconds) {
  const std::size_t n = std::min<std::size_t>(maxTriangles, 1'000'000);
  const dm::Mesh mesh = bumpySphere(n);
  auto whole = scene.addMesh(mesh);
  auto clustered = scene.addMesh(mesh);
  const auto t0 = Clock::now();
  auto tree = dm::MeshBvh::build(mesh);
  const double buildMs = msSince(t0);
  if (!whole || !clustered || !tree || !scene.setMeshTree(*clustered, *tree)) return false;
  Minimal minimal;
  if (!minimal.init(mesh)) return false;
  dm::Camera cam = dm::Camera::lookAt({0.05, 0.03, 0.11}, {0.035, 0.02, 0.085});
  cam.fovYDeg = 40;
  cam.nearPlane = 0.01;
  cam.farPlane = 0.06;
  auto rt = dm::RenderTarget::create({.width = 1280, .height = 720, .samples = 1});
  if (!rt) return false;
  std::size_t drawn = 0;
  bool failed = false;
  auto frame = [&](dm::MeshId id) {
    const dm::DrawItem item{.mesh = id, .material = material};
    auto st = scene.render(*rt, cam, {&item, 1}, {&light, 1}, settings);
    if (!st) failed = true;
    else drawn = st->triangles;
  };
  const double all = median(timeFrames([&] { frame(*whole); }, seconds));
  const double culled = median(timeFrames([&] { frame(*clustered); }, seconds));
  const double mini = median(timeFrames([&] { minimal.draw(*rt, cam, light.direction); }, seconds));
  if (failed) return false;
  std::printf("\nzoomed in, %zu triangles, 1280x720 (cluster culling through a MeshBvh built in %.0f ms):\n"
              "  whole %.2f ms, clustered %.2f ms (%zu triangles drawn), minimal %.2f ms; clustered / minimal %.3f\n",
              mesh.triangleCount(), buildMs, all, culled, drawn, mini, culled / mini);
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  const std::size_t maxTriangles = argc > 1 ? std::strtoull(argv[1], nullptr, 10) : 11'000'000;
  const double seconds = argc > 2 ? std::atof(argv[2]) : 3.0;
  dm::log::setLevel(dm::log::Level::Warn);
  auto ctx = dm::GlContext::create();
  if (!ctx) {
    std::fprintf(stderr, "render_mesh_bench: %s\n", ctx.error().message().c_str());
    return 1;
  }
  std::printf("context: %s, %s, EGL %s platform\n", (*ctx)->info().glRenderer.c_str(),
              (*ctx)->info().glVersion.c_str(), dm::toString((*ctx)->info().platform));
  auto scene = dm::SceneRenderer::create();
  if (!scene) {
    std::fprintf(stderr, "render_mesh_bench: %s\n", scene.error().message().c_str());
    return 1;
  }
  const dm::Vec3 lightDir(-0.4, -0.7, -0.6);
  const dm::Light light = dm::Light::directional(lightDir, 1.0f);
  auto material = scene->addMaterial(
      {.model = dm::ShadingModel::BlinnPhong, .baseColor = dm::Vec4f(0.8f, 0.6f, 0.5f, 1)});
  if (!material) return 1;
  dm::Camera cam = dm::Camera::lookAt({0.12, 0.08, 0.3}, {0, 0, 0});
  cam.fovYDeg = 40;
  cam.nearPlane = 0.05;
  cam.farPlane = 2;
  dm::RenderSettings settings;
  settings.shadows = false;

  std::printf("\n%-10s %-10s %12s %12s %8s %14s\n", "triangles", "size", "ours ms", "minimal ms", "ratio",
              "ours Mtri/s");
  const std::pair<int, int> sizes[] = {{1280, 720}, {1920, 1080}};
  struct Readback {
    int w, h;
    double syncMs, pboMs;
  };
  std::vector<Readback> readbacks;
  for (std::size_t n : {std::size_t{100'000}, std::size_t{1'000'000}, std::size_t{10'000'000}}) {
    if (n > maxTriangles) continue;
    const dm::Mesh mesh = bumpySphere(n);
    auto meshId = scene->addMesh(mesh);
    if (!meshId) {
      std::fprintf(stderr, "%s\n", meshId.error().message().c_str());
      return 1;
    }
    Minimal minimal;
    if (!minimal.init(mesh)) return 1;
    const dm::DrawItem item{.mesh = *meshId, .material = *material};
    for (auto [w, h] : sizes) {
      auto rt = dm::RenderTarget::create({.width = w, .height = h, .samples = 1});
      if (!rt) return 1;
      bool failed = false;
      const auto [ours, mini] = timeInterleaved(
          [&] {
            if (!scene->render(*rt, cam, {&item, 1}, {&light, 1}, settings)) failed = true;
          },
          [&] { minimal.draw(*rt, cam, lightDir); }, seconds);
      if (failed) return 1;
      const double o = median(ours), m = median(mini);
      std::printf("%-10zu %4dx%-5d %12.2f %12.2f %8.3f %14.1f\n", mesh.triangleCount(), w, h, o, m, o / m,
                  double(mesh.triangleCount()) / (o * 1e3));
      std::fflush(stdout);
      if (n == 100'000) {
        // Read-back: a frame of the small scene, then the colour copy.
        std::vector<double> sync, pbo;
        for (int i = 0; i < 12; ++i) {
          (void)scene->render(*rt, cam, {&item, 1}, {&light, 1}, settings);
          glFinish();
          const auto t0 = Clock::now();
          auto img = rt->readColor();
          if (i > 1) sync.push_back(msSince(t0));
        }
        auto ring = dm::AsyncReadback::create(w, h, 3);
        if (!ring) return 1;
        for (int i = 0; i < 12; ++i) {
          (void)scene->render(*rt, cam, {&item, 1}, {&light, 1}, settings);
          glFinish();
          const auto t0 = Clock::now();
          (void)ring->request(*rt);
          if (ring->pending() > 1) (void)ring->wait();
          if (i > 1) pbo.push_back(msSince(t0));
        }
        readbacks.push_back({w, h, median(sync), median(pbo)});
      }
    }
    (void)scene->removeMesh(*meshId);
  }
  std::printf("\nread-back per frame (ms, rendering thread): %-10s %10s %10s %8s\n", "size", "sync",
              "PBO ring", "ratio");
  for (const auto& r : readbacks)
    std::printf("%44s%4dx%-5d %10.2f %10.2f %8.3f\n", "", r.w, r.h, r.syncMs, r.pboMs, r.pboMs / r.syncMs);
  return zoomedIn(*scene, *material, light, settings, maxTriangles, seconds) ? 0 : 1;
}
