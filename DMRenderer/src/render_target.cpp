// render_target.cpp — FBOs, MSAA resolve, synchronous and PBO read-back.
#include <dm/renderer/render_target.hpp>

#include <algorithm>
#include <cstring>
#include <utility>

#include "gl.hpp"

namespace dm {

namespace {

const char* fboStatusName(GLenum s) {
  switch (s) {
    case GL_FRAMEBUFFER_INCOMPLETE_ATTACHMENT:
      return "GL_FRAMEBUFFER_INCOMPLETE_ATTACHMENT";
    case GL_FRAMEBUFFER_INCOMPLETE_MISSING_ATTACHMENT:
      return "GL_FRAMEBUFFER_INCOMPLETE_MISSING_ATTACHMENT";
    case GL_FRAMEBUFFER_UNSUPPORTED:
      return "GL_FRAMEBUFFER_UNSUPPORTED";
    case GL_FRAMEBUFFER_INCOMPLETE_MULTISAMPLE:
      return "GL_FRAMEBUFFER_INCOMPLETE_MULTISAMPLE";
    default:
      return "incomplete framebuffer";
  }
}

}  // namespace

void gl::flipRows(Image& img) {
  const std::size_t row = img.rowBytes();
  std::vector<std::byte> tmp(row);
  for (int y = 0; y < img.height() / 2; ++y) {
    std::byte* a = img.row(y);
    std::byte* b = img.row(img.height() - 1 - y);
    std::memcpy(tmp.data(), a, row);
    std::memcpy(a, b, row);
    std::memcpy(b, tmp.data(), row);
  }
}

Result<RenderTarget> RenderTarget::create(const RenderTargetOptions& options) {
  GLint maxSize = 0, maxSamples = 1;
  glGetIntegerv(GL_MAX_TEXTURE_SIZE, &maxSize);
  glGetIntegerv(GL_MAX_SAMPLES, &maxSamples);
  if (maxSize <= 0)
    return fail(ErrorCode::InvalidArgument, "no OpenGL context is current", "RenderTarget::create",
                "create a dm::GlContext on this thread first");
  if (options.width < 1 || options.height < 1 || options.width > maxSize || options.height > maxSize)
    return fail(
        ErrorCode::InvalidArgument,
        formatString("render target size %dx%d outside 1..%d", options.width, options.height, maxSize),
        "RenderTargetOptions", "use a size the driver supports");
  if (options.samples < 1)
    return fail(ErrorCode::InvalidArgument, formatString("samples is %d", options.samples),
                "RenderTargetOptions::samples", "use 1 for no multisampling");
  RenderTarget t;
  t.opt_ = options;
  t.opt_.samples = std::min(options.samples, std::max(1, maxSamples));
  const GLenum colorFormat = options.srgb ? GL_SRGB8_ALPHA8 : GL_RGBA8;
  glCreateTextures(GL_TEXTURE_2D, 1, &t.colorTex_);
  glTextureStorage2D(t.colorTex_, 1, colorFormat, options.width, options.height);
  glTextureParameteri(t.colorTex_, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
  glTextureParameteri(t.colorTex_, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  glCreateTextures(GL_TEXTURE_2D, 1, &t.depthTex_);
  glTextureStorage2D(t.depthTex_, 1, GL_DEPTH_COMPONENT32F, options.width, options.height);
  glTextureParameteri(t.depthTex_, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTextureParameteri(t.depthTex_, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  glCreateFramebuffers(1, &t.resolveFbo_);
  glNamedFramebufferTexture(t.resolveFbo_, GL_COLOR_ATTACHMENT0, t.colorTex_, 0);
  glNamedFramebufferTexture(t.resolveFbo_, GL_DEPTH_ATTACHMENT, t.depthTex_, 0);
  if (t.opt_.samples > 1) {
    glCreateRenderbuffers(1, &t.msColor_);
    glNamedRenderbufferStorageMultisample(t.msColor_, t.opt_.samples, colorFormat, options.width,
                                          options.height);
    glCreateRenderbuffers(1, &t.msDepth_);
    glNamedRenderbufferStorageMultisample(t.msDepth_, t.opt_.samples, GL_DEPTH_COMPONENT32F, options.width,
                                          options.height);
    glCreateFramebuffers(1, &t.drawFbo_);
    glNamedFramebufferRenderbuffer(t.drawFbo_, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, t.msColor_);
    glNamedFramebufferRenderbuffer(t.drawFbo_, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, t.msDepth_);
  } else {
    t.drawFbo_ = t.resolveFbo_;
  }
  for (GLuint fbo : {t.drawFbo_, t.resolveFbo_}) {
    const GLenum status = glCheckNamedFramebufferStatus(fbo, GL_FRAMEBUFFER);
    if (status != GL_FRAMEBUFFER_COMPLETE)
      return fail(
          ErrorCode::Unsupported, std::string("framebuffer incomplete: ") + fboStatusName(status),
          formatString("RenderTarget %dx%d, %d samples", options.width, options.height, t.opt_.samples),
          "try samples = 1 or srgb = false");
  }
  if (auto s = gl::check("RenderTarget::create"); !s) return s.error();
  return t;
}

RenderTarget::RenderTarget(RenderTarget&& o) noexcept { *this = std::move(o); }

RenderTarget& RenderTarget::operator=(RenderTarget&& o) noexcept {
  if (this != &o) {
    destroy();
    opt_ = o.opt_;
    drawFbo_ = std::exchange(o.drawFbo_, 0u);
    resolveFbo_ = std::exchange(o.resolveFbo_, 0u);
    msColor_ = std::exchange(o.msColor_, 0u);
    msDepth_ = std::exchange(o.msDepth_, 0u);
    colorTex_ = std::exchange(o.colorTex_, 0u);
    depthTex_ = std::exchange(o.depthTex_, 0u);
  }
  return *this;
}

RenderTarget::~RenderTarget() { destroy(); }

void RenderTarget::destroy() noexcept {
  if (drawFbo_ != 0 && drawFbo_ != resolveFbo_) glDeleteFramebuffers(1, &drawFbo_);
  if (resolveFbo_ != 0) glDeleteFramebuffers(1, &resolveFbo_);
  if (msColor_ != 0) glDeleteRenderbuffers(1, &msColor_);
  if (msDepth_ != 0) glDeleteRenderbuffers(1, &msDepth_);
  if (colorTex_ != 0) glDeleteTextures(1, &colorTex_);
  if (depthTex_ != 0) glDeleteTextures(1, &depthTex_);
  drawFbo_ = resolveFbo_ = msColor_ = msDepth_ = colorTex_ = depthTex_ = 0;
}

void RenderTarget::bind() const { bindViewport(0, 0, opt_.width, opt_.height); }

void RenderTarget::bindViewport(int x, int y, int width, int height) const {
  glBindFramebuffer(GL_FRAMEBUFFER, drawFbo_);
  // Callers give the origin top-left like dm::Image; GL's is bottom-left.
  glViewport(x, opt_.height - y - height, width, height);
  if (opt_.srgb)
    glEnable(GL_FRAMEBUFFER_SRGB);
  else
    glDisable(GL_FRAMEBUFFER_SRGB);
}

void RenderTarget::clear(const Vec4f& color) const {
  const float depth = 1.0f;
  // Clears honour GL_FRAMEBUFFER_SRGB like draws: linear in, encoded stored.
  if (opt_.srgb)
    glEnable(GL_FRAMEBUFFER_SRGB);
  else
    glDisable(GL_FRAMEBUFFER_SRGB);
  glClearNamedFramebufferfv(drawFbo_, GL_COLOR, 0, color.data());
  glClearNamedFramebufferfv(drawFbo_, GL_DEPTH, 0, &depth);
}

void RenderTarget::resolve() const {
  if (drawFbo_ == resolveFbo_) return;
  glBlitNamedFramebuffer(drawFbo_, resolveFbo_, 0, 0, opt_.width, opt_.height, 0, 0, opt_.width, opt_.height,
                         GL_COLOR_BUFFER_BIT, GL_NEAREST);
  glBlitNamedFramebuffer(drawFbo_, resolveFbo_, 0, 0, opt_.width, opt_.height, 0, 0, opt_.width, opt_.height,
                         GL_DEPTH_BUFFER_BIT, GL_NEAREST);
}

Result<Image> RenderTarget::readColor() const {
  if (!valid()) return fail(ErrorCode::InvalidArgument, "empty render target", "RenderTarget::readColor");
  resolve();
  auto img = Image::create(opt_.width, opt_.height, 4, PixelType::U8);
  if (!img) return img.error();
  glBindFramebuffer(GL_READ_FRAMEBUFFER, resolveFbo_);
  glBindBuffer(GL_PIXEL_PACK_BUFFER, 0);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, opt_.width, opt_.height, GL_RGBA, GL_UNSIGNED_BYTE, img->data());
  if (auto s = gl::check("RenderTarget::readColor"); !s) return s.error();
  gl::flipRows(*img);
  return img;
}

Result<Image> RenderTarget::readDepth() const {
  if (!valid()) return fail(ErrorCode::InvalidArgument, "empty render target", "RenderTarget::readDepth");
  resolve();
  auto img = Image::create(opt_.width, opt_.height, 1, PixelType::F32);
  if (!img) return img.error();
  glBindFramebuffer(GL_READ_FRAMEBUFFER, resolveFbo_);
  glBindBuffer(GL_PIXEL_PACK_BUFFER, 0);
  glPixelStorei(GL_PACK_ALIGNMENT, 4);
  glReadPixels(0, 0, opt_.width, opt_.height, GL_DEPTH_COMPONENT, GL_FLOAT, img->data());
  if (auto s = gl::check("RenderTarget::readDepth"); !s) return s.error();
  gl::flipRows(*img);
  return img;
}

// ---- AsyncReadback ---------------------------------------------------------

Result<AsyncReadback> AsyncReadback::create(int width, int height, int buffers) {
  if (width < 1 || height < 1 || buffers < 2 || buffers > 8)
    return fail(ErrorCode::InvalidArgument,
                formatString("read-back ring %dx%d with %d buffers", width, height, buffers),
                "AsyncReadback::create", "use a positive size and 2..8 buffers");
  AsyncReadback r;
  r.width_ = width;
  r.height_ = height;
  r.n_ = buffers;
  glCreateBuffers(buffers, r.pbos_);
  const auto bytes = static_cast<GLsizeiptr>(width) * height * 4;
  for (int i = 0; i < buffers; ++i) glNamedBufferStorage(r.pbos_[i], bytes, nullptr, GL_MAP_READ_BIT);
  if (auto s = gl::check("AsyncReadback::create"); !s) return s.error();
  return r;
}

AsyncReadback::AsyncReadback(AsyncReadback&& o) noexcept { *this = std::move(o); }

AsyncReadback& AsyncReadback::operator=(AsyncReadback&& o) noexcept {
  if (this != &o) {
    destroy();
    width_ = o.width_;
    height_ = o.height_;
    n_ = std::exchange(o.n_, 0);
    head_ = std::exchange(o.head_, 0);
    count_ = std::exchange(o.count_, 0);
    for (int i = 0; i < 8; ++i) {
      pbos_[i] = std::exchange(o.pbos_[i], 0u);
      fences_[i] = std::exchange(o.fences_[i], nullptr);
    }
  }
  return *this;
}

AsyncReadback::~AsyncReadback() { destroy(); }

void AsyncReadback::destroy() noexcept {
  for (int i = 0; i < 8; ++i) {
    if (fences_[i] != nullptr) glDeleteSync(static_cast<GLsync>(fences_[i]));
    fences_[i] = nullptr;
  }
  if (n_ > 0) glDeleteBuffers(n_, pbos_);
  n_ = head_ = count_ = 0;
}

Status AsyncReadback::request(const RenderTarget& target) {
  if (target.width() != width_ || target.height() != height_)
    return fail(
        ErrorCode::InvalidArgument,
        formatString("target is %dx%d, ring is %dx%d", target.width(), target.height(), width_, height_),
        "AsyncReadback::request");
  if (count_ == n_)
    return fail(ErrorCode::Busy, formatString("all %d read-back buffers hold frames not yet taken", n_),
                "AsyncReadback::request", "call poll() or wait() first, or create more buffers");
  const int slot = (head_ + count_) % n_;
  target.resolve();
  glBindFramebuffer(GL_READ_FRAMEBUFFER, target.resolveFramebuffer());
  glBindBuffer(GL_PIXEL_PACK_BUFFER, pbos_[slot]);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, width_, height_, GL_RGBA, GL_UNSIGNED_BYTE, nullptr);
  glBindBuffer(GL_PIXEL_PACK_BUFFER, 0);
  fences_[slot] = glFenceSync(GL_SYNC_GPU_COMMANDS_COMPLETE, 0);
  glFlush();
  ++count_;
  return gl::check("AsyncReadback::request");
}

Result<Image> AsyncReadback::take(bool block, bool* ready) {
  *ready = false;
  if (count_ == 0) return fail(ErrorCode::NotFound, "no read-back pending", "AsyncReadback");
  const int slot = head_;
  auto sync = static_cast<GLsync>(fences_[slot]);
  const GLenum r = glClientWaitSync(sync, GL_SYNC_FLUSH_COMMANDS_BIT, block ? GLuint64{10'000'000'000} : 0);
  if (r == GL_TIMEOUT_EXPIRED) {
    if (block) return fail(ErrorCode::Timeout, "read-back did not finish in 10 s", "AsyncReadback::wait");
    return Image();
  }
  if (r == GL_WAIT_FAILED) return fail(ErrorCode::Internal, "glClientWaitSync failed", "AsyncReadback");
  glDeleteSync(sync);
  fences_[slot] = nullptr;
  auto img = Image::create(width_, height_, 4, PixelType::U8);
  if (!img) return img.error();
  const std::size_t row = img->rowBytes();
  const auto* src = static_cast<const std::byte*>(
      glMapNamedBufferRange(pbos_[slot], 0, static_cast<GLsizeiptr>(row) * height_, GL_MAP_READ_BIT));
  if (src == nullptr) return fail(ErrorCode::Internal, "glMapNamedBufferRange failed", "AsyncReadback");
  for (int y = 0; y < height_; ++y)
    std::memcpy(img->row(height_ - 1 - y), src + static_cast<std::size_t>(y) * row, row);
  glUnmapNamedBuffer(pbos_[slot]);
  head_ = (head_ + 1) % n_;
  --count_;
  *ready = true;
  return img;
}

Result<std::optional<Image>> AsyncReadback::poll() {
  bool ready = false;
  auto img = take(false, &ready);
  if (!img) {
    if (img.error().code == ErrorCode::NotFound) return std::optional<Image>();
    return img.error();
  }
  if (!ready) return std::optional<Image>();
  return std::optional<Image>(std::move(*img));
}

Result<Image> AsyncReadback::wait() {
  bool ready = false;
  return take(true, &ready);
}

}  // namespace dm
