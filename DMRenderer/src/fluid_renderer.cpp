// fluid_renderer.cpp — screen-space fluid rendering (see the header).
#include <dm/core/assert.hpp>
#include <dm/renderer/fluid_renderer.hpp>
#include <dm/renderer/shader.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <string>
#include <vector>

#include "fluid_shaders.hpp"
#include "gl.hpp"
#include "light_uniforms.hpp"

namespace dm {

namespace {

constexpr int kMaxFluidLights = gl::LightUniforms::kMax;

Status checkLook(const FluidLook& look, double radius, std::size_t lights) {
  const char* where = "FluidRenderer::render";
  if (!(radius > 0.0) || !std::isfinite(radius))
    return fail(ErrorCode::InvalidArgument, formatString("particle radius %g m", radius), where,
                "a positive radius, e.g. half the particle spacing");
  auto finiteNonNegative = [](const Vec3f& v) { return v.allFinite() && (v.array() >= 0.0f).all(); };
  if (!finiteNonNegative(look.color))
    return fail(ErrorCode::InvalidArgument, "FluidLook::color has a negative or non-finite channel", where);
  if (!finiteNonNegative(look.absorption))
    return fail(ErrorCode::InvalidArgument, "FluidLook::absorption has a negative or non-finite channel",
                where, "Beer-Lambert coefficients in 1/m, 0 for a clear channel");
  if (!(look.fresnelF0 >= 0.0f && look.fresnelF0 <= 1.0f))
    return fail(ErrorCode::InvalidArgument, formatString("FluidLook::fresnelF0 %g", double(look.fresnelF0)),
                where, "a reflectance in [0, 1] (water 0.02)");
  if (!(look.specular >= 0.0f) || !std::isfinite(look.specular) || !(look.shininess >= 1.0f) ||
      !std::isfinite(look.shininess))
    return fail(
        ErrorCode::InvalidArgument,
        formatString("FluidLook::specular %g, shininess %g", double(look.specular), double(look.shininess)),
        where, "specular >= 0 and a shininess >= 1");
  if (!std::isfinite(look.refractionPixels))
    return fail(ErrorCode::InvalidArgument, "FluidLook::refractionPixels is not finite", where);
  if (look.smoothingIterations < 0 || look.smoothingIterations > 16)
    return fail(ErrorCode::InvalidArgument,
                formatString("FluidLook::smoothingIterations %d", look.smoothingIterations), where, "0..16");
  if (!(look.smoothingRadius > 0.0f) || !std::isfinite(look.smoothingRadius))
    return fail(ErrorCode::InvalidArgument,
                formatString("FluidLook::smoothingRadius %g", double(look.smoothingRadius)), where,
                "a positive number of particle radii, e.g. 2");
  if (!(look.particleVolume >= 0.0f) || !std::isfinite(look.particleVolume))
    return fail(ErrorCode::InvalidArgument,
                formatString("FluidLook::particleVolume %g", double(look.particleVolume)), where,
                "the volume each particle stands for (spacing cubed), or 0 for its sphere's");
  if (lights > std::size_t(kMaxFluidLights))
    return fail(ErrorCode::InvalidArgument, formatString("%zu lights", lights), where,
                "at most 8 lights light a fluid");
  return ok();
}

// A single-level texture of `format`, nearest sampling, clamped.
GLuint makeTexture(GLenum format, int w, int h) {
  GLuint t = 0;
  glCreateTextures(GL_TEXTURE_2D, 1, &t);
  glTextureStorage2D(t, 1, format, w, h);
  glTextureParameteri(t, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTextureParameteri(t, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  glTextureParameteri(t, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  glTextureParameteri(t, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  return t;
}

GLuint makeFramebuffer(GLuint color, GLuint depth = 0) {
  GLuint f = 0;
  glCreateFramebuffers(1, &f);
  glNamedFramebufferTexture(f, GL_COLOR_ATTACHMENT0, color, 0);
  if (depth != 0) glNamedFramebufferTexture(f, GL_DEPTH_ATTACHMENT, depth, 0);
  return f;
}

}  // namespace

FluidLook FluidLook::fromTransmittance(const Vec3f& transmittance, float depth) {
  FluidLook look;
  look.color = transmittance.cwiseMax(0.0f).cwiseMin(1.0f);
  for (int c = 0; c < 3; ++c)
    look.absorption[c] = -std::log(std::clamp(transmittance[c], 1e-4f, 1.0f)) / depth;
  return look;
}

struct FluidRenderer::Impl {
  ShaderProgram depth, thickness, smoothDepth, smoothThickness, composite;
  GLuint particleVao = 0, emptyVao = 0, positionBuffer = 0;
  std::size_t bufferCapacity = 0;
  std::vector<float> upload;  // positions as floats, reused
  // Buffers the size of the last viewport: raw and smoothed eye depth (the
  // smoothing ping-pongs between smoothA and smoothB), thickness and its
  // blur's scratch, the particles' own depth test, and copies of the
  // target's colour and depth (sampled while drawing into the target).
  int w = 0, h = 0, targetW = 0, targetH = 0;
  GLenum colorFormat = 0;
  GLuint rawDepth = 0, smoothA = 0, smoothB = 0, thick = 0, thickTmp = 0, zbuf = 0;
  GLuint sceneColor = 0, sceneDepth = 0;
  GLuint fboRaw = 0, fboA = 0, fboB = 0, fboThick = 0, fboThickTmp = 0;
  GLuint smoothed = 0;  // whichever of smoothA/smoothB (or rawDepth) the last render ended in

  ~Impl() {
    releaseBuffers();
    releaseSceneCopies();
    if (particleVao != 0) glDeleteVertexArrays(1, &particleVao);
    if (emptyVao != 0) glDeleteVertexArrays(1, &emptyVao);
    if (positionBuffer != 0) glDeleteBuffers(1, &positionBuffer);
  }

  void releaseBuffers() {
    const GLuint fbos[] = {fboRaw, fboA, fboB, fboThick, fboThickTmp};
    glDeleteFramebuffers(5, fbos);
    const GLuint texs[] = {rawDepth, smoothA, smoothB, thick, thickTmp, zbuf};
    glDeleteTextures(6, texs);
    fboRaw = fboA = fboB = fboThick = fboThickTmp = 0;
    rawDepth = smoothA = smoothB = thick = thickTmp = zbuf = smoothed = 0;
    w = h = 0;
  }
  void releaseSceneCopies() {
    const GLuint texs[] = {sceneColor, sceneDepth};
    glDeleteTextures(2, texs);
    sceneColor = sceneDepth = 0;
    targetW = targetH = 0;
  }

  void ensureBuffers(int width, int height) {
    if (width == w && height == h) return;
    releaseBuffers();
    w = width;
    h = height;
    rawDepth = makeTexture(GL_R32F, w, h);
    smoothA = makeTexture(GL_R32F, w, h);
    smoothB = makeTexture(GL_R32F, w, h);
    thick = makeTexture(GL_R32F, w, h);
    thickTmp = makeTexture(GL_R32F, w, h);
    zbuf = makeTexture(GL_DEPTH_COMPONENT32F, w, h);
    fboRaw = makeFramebuffer(rawDepth, zbuf);
    fboA = makeFramebuffer(smoothA);
    fboB = makeFramebuffer(smoothB);
    fboThick = makeFramebuffer(thick);
    fboThickTmp = makeFramebuffer(thickTmp);
  }

  // Copies the target's resolved colour and depth: the passes sample them
  // while the composite draws into the target.
  void copyScene(const RenderTarget& target) {
    GLint format = 0;
    glGetTextureLevelParameteriv(target.colorTexture(), 0, GL_TEXTURE_INTERNAL_FORMAT, &format);
    if (targetW != target.width() || targetH != target.height() || colorFormat != GLenum(format)) {
      releaseSceneCopies();
      targetW = target.width();
      targetH = target.height();
      colorFormat = GLenum(format);
      sceneColor = makeTexture(colorFormat, targetW, targetH);
      sceneDepth = makeTexture(GL_DEPTH_COMPONENT32F, targetW, targetH);
    }
    target.resolve();
    glCopyImageSubData(target.colorTexture(), GL_TEXTURE_2D, 0, 0, 0, 0, sceneColor, GL_TEXTURE_2D, 0, 0, 0,
                       0, targetW, targetH, 1);
    glCopyImageSubData(target.depthTexture(), GL_TEXTURE_2D, 0, 0, 0, 0, sceneDepth, GL_TEXTURE_2D, 0, 0, 0,
                       0, targetW, targetH, 1);
  }

  void uploadPositions(std::span<const Vec3> positions) {
    upload.resize(positions.size() * 3);
    for (std::size_t i = 0; i < positions.size(); ++i)
      for (int k = 0; k < 3; ++k) upload[3 * i + std::size_t(k)] = float(positions[i][k]);
    const std::size_t bytes = upload.size() * sizeof(float);
    if (bytes > bufferCapacity) {
      bufferCapacity = std::max(bytes, 2 * bufferCapacity);
      glNamedBufferData(positionBuffer, GLsizeiptr(bufferCapacity), nullptr, GL_STREAM_DRAW);
    }
    glNamedBufferSubData(positionBuffer, 0, GLsizeiptr(bytes), upload.data());
  }

  Result<Image> read(GLuint tex, const char* what) const {
    if (tex == 0)
      return fail(ErrorCode::InvalidArgument, "nothing rendered yet", std::string("FluidRenderer::") + what);
    auto img = Image::create(w, h, 1, PixelType::F32);
    if (!img) return img.error();
    glBindBuffer(GL_PIXEL_PACK_BUFFER, 0);
    glPixelStorei(GL_PACK_ALIGNMENT, 4);
    glGetTextureImage(tex, 0, GL_RED, GL_FLOAT, GLsizei(img->rowBytes() * std::size_t(h)), img->data());
    if (auto s = gl::check(what); !s) return s.error();
    gl::flipRows(*img);
    return img;
  }
};

FluidRenderer::FluidRenderer() = default;
FluidRenderer::FluidRenderer(FluidRenderer&&) noexcept = default;
FluidRenderer& FluidRenderer::operator=(FluidRenderer&&) noexcept = default;
FluidRenderer::~FluidRenderer() = default;

Result<FluidRenderer> FluidRenderer::create() {
  GLint maxSize = 0;
  glGetIntegerv(GL_MAX_TEXTURE_SIZE, &maxSize);
  if (maxSize <= 0)
    return fail(ErrorCode::InvalidArgument, "no OpenGL context is current", "FluidRenderer::create",
                "create a dm::GlContext on this thread first");
  FluidRenderer r;
  r.impl_ = std::make_unique<Impl>();
  Impl& m = *r.impl_;
  namespace fs = fluid_shaders;
  const std::string depthFs = std::string(fs::kSphereHit) + fs::kDepthFs;
  const std::string thickFs = std::string(fs::kSphereHit) + fs::kThicknessFs;
  struct Spec {
    ShaderProgram* out;
    const char* name;
    const char* vs;
    std::string_view fs;
    const char* depthDefine;
  };
  const Spec specs[] = {
      {&m.depth, "fluid depth", fs::kParticleVs, depthFs, nullptr},
      {&m.thickness, "fluid thickness", fs::kParticleVs, thickFs, nullptr},
      {&m.smoothDepth, "fluid depth smoothing", fs::kFullscreenVs, fs::kSmoothFs, "1"},
      {&m.smoothThickness, "fluid thickness blur", fs::kFullscreenVs, fs::kSmoothFs, "0"},
      {&m.composite, "fluid composite", fs::kFullscreenVs, fs::kCompositeFs, nullptr},
  };
  for (const Spec& s : specs) {
    std::vector<std::pair<std::string, std::string>> defines;
    if (s.depthDefine != nullptr) defines.emplace_back("DEPTH", s.depthDefine);
    auto p =
        ShaderProgram::create(s.name, {{ShaderStage::Vertex, s.vs}, {ShaderStage::Fragment, s.fs}}, defines);
    if (!p) return p.error();
    *s.out = std::move(*p);
  }
  glCreateBuffers(1, &m.positionBuffer);
  glCreateVertexArrays(1, &m.particleVao);
  glVertexArrayVertexBuffer(m.particleVao, 0, m.positionBuffer, 0, 3 * sizeof(float));
  glEnableVertexArrayAttrib(m.particleVao, 0);
  glVertexArrayAttribFormat(m.particleVao, 0, 3, GL_FLOAT, GL_FALSE, 0);
  glVertexArrayAttribBinding(m.particleVao, 0, 0);
  glVertexArrayBindingDivisor(m.particleVao, 0, 1);
  glCreateVertexArrays(1, &m.emptyVao);
  if (auto s = gl::check("FluidRenderer::create"); !s) return s.error();
  return r;
}

Result<FluidRenderStats> FluidRenderer::render(const RenderTarget& target, const Camera& camera,
                                               std::span<const Vec3> positions, double radius,
                                               const FluidLook& look, std::span<const Light> lights,
                                               const Vec3f& ambient, const Viewport& viewport) {
  const char* where = "FluidRenderer::render";
  DM_DEMAND(impl_ != nullptr, "FluidRenderer used after move");
  if (!target.valid()) return fail(ErrorCode::InvalidArgument, "empty render target", where);
  if (auto s = camera.validate(); !s) return s.error().within(where);
  if (auto s = checkLook(look, radius, lights.size()); !s) return s.error();
  if (!ambient.allFinite()) return fail(ErrorCode::InvalidArgument, "ambient light is not finite", where);
  Viewport vp = viewport;
  if (vp.width == 0 || vp.height == 0) vp = Viewport{0, 0, target.width(), target.height()};
  if (vp.x < 0 || vp.y < 0 || vp.width < 0 || vp.height < 0 || vp.x + vp.width > target.width() ||
      vp.y + vp.height > target.height())
    return fail(ErrorCode::InvalidArgument,
                formatString("viewport %d,%d %dx%d outside the %dx%d target", vp.x, vp.y, vp.width, vp.height,
                             target.width(), target.height()),
                where);
  Impl& m = *impl_;
  FluidRenderStats stats{.particles = int(positions.size()), .width = vp.width, .height = vp.height};
  m.ensureBuffers(vp.width, vp.height);
  const float noFluid = 0.0f, far = 1.0f;
  glClearNamedFramebufferfv(m.fboRaw, GL_COLOR, 0, &noFluid);
  glClearNamedFramebufferfv(m.fboRaw, GL_DEPTH, 0, &far);
  glClearNamedFramebufferfv(m.fboThick, GL_COLOR, 0, &noFluid);
  m.smoothed = m.rawDepth;
  if (positions.empty()) return stats;

  const Mat4f view = camera.viewMatrix();
  const Mat4f proj = camera.projectionMatrix(double(vp.width) / double(vp.height));
  const int ortho = camera.projection == Camera::Projection::Orthographic ? 1 : 0;
  // GL's origin is the lower left: the viewport's lower-left pixel.
  const int originX = vp.x, originY = target.height() - vp.y - vp.height;
  const auto r = float(radius);
  const double sphereVolume = 4.0 / 3.0 * std::numbers::pi * radius * radius * radius;
  const auto thicknessScale =
      float(look.particleVolume > 0 ? double(look.particleVolume) / sphereVolume : 1.0);
  const float pixelsPerMetre = proj(1, 1) * float(vp.height) / 2.0f;

  m.copyScene(target);
  m.uploadPositions(positions);
  gl::StateGuard guard;
  glDisable(GL_CULL_FACE);
  glViewport(0, 0, vp.width, vp.height);
  glBindTextureUnit(0, m.sceneDepth);

  // 1. Depth of the nearest sphere.
  glBindVertexArray(m.particleVao);
  for (ShaderProgram* p : {&m.depth, &m.thickness}) {
    p->use();
    p->set("u_view", view);
    p->set("u_proj", proj);
    p->set("u_radius", r);
    p->set("u_ortho", ortho);
    glProgramUniform2i(p->id(), p->location("u_vpOrigin"), originX, originY);
  }
  glBindFramebuffer(GL_FRAMEBUFFER, m.fboRaw);
  glDisable(GL_BLEND);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glDepthMask(GL_TRUE);
  m.depth.use();
  glDrawArraysInstanced(GL_TRIANGLE_STRIP, 0, 4, GLsizei(positions.size()));

  // 2. Thickness: every sphere's chord, summed.
  glBindFramebuffer(GL_FRAMEBUFFER, m.fboThick);
  glDisable(GL_DEPTH_TEST);
  glDepthMask(GL_FALSE);
  glEnable(GL_BLEND);
  glBlendEquation(GL_FUNC_ADD);
  glBlendFunc(GL_ONE, GL_ONE);
  m.thickness.use();
  m.thickness.set("u_thicknessScale", thicknessScale);
  glDrawArraysInstanced(GL_TRIANGLE_STRIP, 0, 4, GLsizei(positions.size()));
  glDisable(GL_BLEND);

  // 3. Smoothing: bilateral over the depth, a Gaussian over the thickness.
  glBindVertexArray(m.emptyVao);
  const float radiusWorld = look.smoothingRadius * r;
  for (ShaderProgram* p : {&m.smoothDepth, &m.smoothThickness}) {
    p->use();
    p->set("u_radiusWorld", radiusWorld);
    p->set("u_pixelsPerMetre", pixelsPerMetre);
    p->set("u_ortho", ortho);
    p->set("u_rangeScale", 0.5f / r);
  }
  auto pass = [&](ShaderProgram& p, GLuint src, GLuint dstFbo, GLuint eyeDepth, int dx, int dy) {
    glBindFramebuffer(GL_FRAMEBUFFER, dstFbo);
    p.use();
    glProgramUniform2i(p.id(), p.location("u_dir"), dx, dy);
    glBindTextureUnit(0, src);
    glBindTextureUnit(1, eyeDepth);
    glDrawArrays(GL_TRIANGLES, 0, 3);
  };
  pass(m.smoothThickness, m.thick, m.fboThickTmp, m.rawDepth, 1, 0);
  pass(m.smoothThickness, m.thickTmp, m.fboThick, m.rawDepth, 0, 1);
  GLuint src = m.rawDepth;
  for (int i = 0; i < look.smoothingIterations; ++i) {
    pass(m.smoothDepth, src, m.fboA, src, 1, 0);
    pass(m.smoothDepth, m.smoothA, m.fboB, m.smoothA, 0, 1);
    src = m.smoothB;
  }
  m.smoothed = src;

  // 4–5. Normals and shading over the target.
  gl::LightUniforms packed;
  packed.pack(lights, view);  // the composite shades in view space
  ShaderProgram& c = m.composite;
  c.use();
  const GLuint id = c.id();
  glProgramUniform2i(id, c.location("u_vpOrigin"), originX, originY);
  c.set("u_proj", proj);
  c.set("u_invProj", Mat4f(proj.cast<double>().inverse().cast<float>()));
  c.set("u_ortho", ortho);
  c.set("u_color", look.color);
  c.set("u_absorption", look.absorption);
  c.set("u_f0", look.fresnelF0);
  c.set("u_specular", look.specular);
  c.set("u_shininess", look.shininess);
  c.set("u_refraction", look.refractionPixels);
  c.set("u_ambient", ambient);
  c.set("u_lightCount", packed.count);
  packed.upload(c);
  glBindTextureUnit(0, m.smoothed);
  glBindTextureUnit(1, m.thick);
  glBindTextureUnit(2, m.sceneColor);
  target.bindViewport(vp.x, vp.y, vp.width, vp.height);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glDepthMask(GL_TRUE);
  glDrawArrays(GL_TRIANGLES, 0, 3);
  if (auto s = gl::check(where); !s) return s.error();
  return stats;
}

Result<Image> FluidRenderer::readRawDepth() const { return impl_->read(impl_->rawDepth, "readRawDepth"); }
Result<Image> FluidRenderer::readSmoothedDepth() const {
  return impl_->read(impl_->smoothed, "readSmoothedDepth");
}
Result<Image> FluidRenderer::readThickness() const { return impl_->read(impl_->thick, "readThickness"); }

}  // namespace dm
