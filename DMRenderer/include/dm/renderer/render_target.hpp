// dm/renderer/render_target.hpp — off-screen colour + depth targets and
// read-back to dm::Image, synchronous or through pixel buffer objects.
//
// A RenderTarget draws into multisampled renderbuffers (when samples > 1)
// and resolves into single-sample textures: colour RGBA8 (sRGB-encoded when
// `srgb`), depth 32-bit float. readColor() resolves and reads the colour
// into an RGBA8 dm::Image with rows top to bottom (GL's are bottom up);
// readDepth() gives window depth in [0, 1] as F32. AsyncReadback reads
// through a ring of pixel buffer objects: request() starts a transfer and
// returns at once, a later poll()/wait() maps it, so the CPU copy of frame N
// overlaps the rendering of frame N+1.
// All calls need the owning GlContext current on the calling thread.
//
// @code
//   auto rt = dm::RenderTarget::create({.width = 640, .height = 480, .samples = 4});
//   rt->bind(); ... draw ...
//   dm::Result<dm::Image> rgba = rt->readColor();
// @endcode
#pragma once

#include <dm/core/image.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <cstdint>
#include <memory>
#include <optional>

namespace dm {

/// A sub-rectangle of a render target in pixels, origin top-left (like
/// dm::Image); where it is optional, width or height 0 means the whole target.
struct Viewport {
  int x = 0, y = 0, width = 0, height = 0;
};

/// Size and format of a RenderTarget.
struct RenderTargetOptions {
  int width = 640;   ///< pixels, 1..GL_MAX_TEXTURE_SIZE
  int height = 480;  ///< pixels, 1..GL_MAX_TEXTURE_SIZE
  int samples = 4;   ///< MSAA samples; 1 = none; clamped to GL_MAX_SAMPLES
  bool srgb = true;  ///< shaders write linear colour, stored sRGB-encoded
};

/// An off-screen framebuffer. Move-only; frees its GL objects on destruction
/// (with its context current).
class RenderTarget {
 public:
  /// Fails on sizes outside 1..GL_MAX_TEXTURE_SIZE or when the driver refuses
  /// the framebuffer (the message names the GL status).
  static Result<RenderTarget> create(const RenderTargetOptions& options);

  RenderTarget() = default;
  RenderTarget(RenderTarget&& o) noexcept;
  RenderTarget& operator=(RenderTarget&& o) noexcept;
  RenderTarget(const RenderTarget&) = delete;
  RenderTarget& operator=(const RenderTarget&) = delete;
  ~RenderTarget();

  int width() const { return opt_.width; }
  int height() const { return opt_.height; }
  int samples() const { return opt_.samples; }
  bool valid() const { return drawFbo_ != 0; }

  /// Binds the draw framebuffer and sets the viewport to the whole target.
  void bind() const;
  /// Binds and sets the viewport to a sub-rectangle (pixels, origin top-left),
  /// for several viewports in one target (stereo side by side, slice views).
  void bindViewport(int x, int y, int width, int height) const;
  /// Clears colour (linear RGBA) and depth of the whole target.
  void clear(const Vec4f& color = Vec4f(0, 0, 0, 1)) const;
  /// Resolves the multisampled buffers into the textures (no-op at 1 sample).
  void resolve() const;

  /// Resolves and reads colour: RGBA8, rows top to bottom.
  Result<Image> readColor() const;
  /// Resolves and reads window depth in [0, 1] (1 = far plane): F32, 1 channel.
  Result<Image> readDepth() const;

  /// GL names for code in DMRenderer that samples the resolved textures.
  std::uint32_t colorTexture() const { return colorTex_; }
  std::uint32_t depthTexture() const { return depthTex_; }
  std::uint32_t drawFramebuffer() const { return drawFbo_; }
  std::uint32_t resolveFramebuffer() const { return resolveFbo_; }

 private:
  void destroy() noexcept;
  RenderTargetOptions opt_;
  std::uint32_t drawFbo_ = 0, resolveFbo_ = 0;
  std::uint32_t msColor_ = 0, msDepth_ = 0;  // renderbuffers when samples > 1
  std::uint32_t colorTex_ = 0, depthTex_ = 0;
};

/// Asynchronous colour read-back through a ring of pixel buffer objects.
class AsyncReadback {
 public:
  /// `buffers` PBOs of width x height RGBA8 (2..8).
  static Result<AsyncReadback> create(int width, int height, int buffers = 3);

  AsyncReadback() = default;
  AsyncReadback(AsyncReadback&& o) noexcept;
  AsyncReadback& operator=(AsyncReadback&& o) noexcept;
  AsyncReadback(const AsyncReadback&) = delete;
  AsyncReadback& operator=(const AsyncReadback&) = delete;
  ~AsyncReadback();

  /// Resolves `target` and starts copying its colour into the next PBO.
  /// Fails (Busy) when every PBO holds a frame not yet taken, or when the
  /// target's size differs from this ring's.
  Status request(const RenderTarget& target);
  /// The oldest requested frame if its transfer has finished, else nullopt.
  Result<std::optional<Image>> poll();
  /// The oldest requested frame, waiting for its transfer; NotFound when
  /// nothing is pending.
  Result<Image> wait();
  /// Frames requested and not yet taken.
  int pending() const { return count_; }

 private:
  Result<Image> take(bool block, bool* ready);
  void destroy() noexcept;
  int width_ = 0, height_ = 0;
  std::uint32_t pbos_[8] = {};
  void* fences_[8] = {};
  int n_ = 0, head_ = 0, count_ = 0;
};

}  // namespace dm
