// dm/renderer/context.hpp — a headless OpenGL 4.5 core context over EGL.
//
// No window system is involved: the context renders into off-screen targets
// (dm/renderer/render_target.hpp). Two EGL platforms are supported:
//   - Device: EGL_EXT_platform_device, one EGL device per GPU (NVIDIA, or
//     Mesa's DRM render nodes); chosen by Auto when a hardware device exists.
//   - Surfaceless: EGL_MESA_platform_surfaceless, Mesa's llvmpipe on the CPU;
//     chosen by Auto when no hardware device answers.
// The environment variable DM_EGL_PLATFORM (auto, device, surfaceless) and
// DM_EGL_DEVICE (0-based device index) override ContextOptions::platform and
// ::deviceIndex, so a CI job can pin the platform without code changes.
// When neither platform gives a 4.5 core context, create() fails with a
// message naming what is missing (library, extension, version) and the
// Debian packages that provide it.
//
// A context is current on one thread at a time: create() makes it current
// on the calling thread; makeCurrent() moves it to another thread after
// release() on the first. Every GL object (RenderTarget, ShaderProgram,
// MeshRenderer, ...) must be used and destroyed while its context is current.
//
// @code
//   auto ctx = dm::GlContext::create();                 // Auto platform
//   if (!ctx) { std::cerr << ctx.error() << '\n'; return 1; }
//   std::printf("%s\n", (*ctx)->info().renderer.c_str());  // "llvmpipe (LLVM 15.0.6, 256 bits)"
// @endcode
#pragma once

#include <dm/core/result.hpp>

#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace dm {

/// Which EGL platform a context runs on.
enum class EglPlatform : unsigned char {
  Auto,         ///< a hardware EGL device if there is one, else surfaceless
  Device,       ///< EGL_EXT_platform_device (GPU drivers, Mesa render nodes)
  Surfaceless,  ///< EGL_MESA_platform_surfaceless (llvmpipe on the CPU)
};

/// "auto", "device" or "surfaceless".
const char* toString(EglPlatform p) noexcept;

/// Parses "auto", "device" or "surfaceless" (case-sensitive); the error names
/// the accepted values.
Result<EglPlatform> parseEglPlatform(std::string_view text);

/// How to create a context. The environment overrides these (see the file
/// comment) unless `ignoreEnvironment` is set.
struct ContextOptions {
  EglPlatform platform = EglPlatform::Auto;
  int deviceIndex = -1;      ///< Device platform: which EGL device; -1 = first hardware one
  bool debugOutput = false;  ///< KHR_debug messages go to dm::log (debug context)
  bool ignoreEnvironment = false;
};

/// What a context runs on, for logs and reports.
struct ContextInfo {
  EglPlatform platform = EglPlatform::Auto;  ///< the platform actually used
  int deviceIndex = -1;                      ///< EGL device index on the Device platform
  std::string eglVendor;                     ///< EGL_VENDOR, e.g. "Mesa Project", "NVIDIA"
  std::string eglVersion;                    ///< EGL_VERSION, e.g. "1.5"
  std::string glVendor;                      ///< GL_VENDOR
  std::string glRenderer;                    ///< GL_RENDERER, e.g. "llvmpipe (LLVM 15.0.6, 256 bits)"
  std::string glVersion;                     ///< GL_VERSION, e.g. "4.5 (Core Profile) Mesa 22.3.6"
  bool software = false;                     ///< true on llvmpipe/softpipe
  int maxSamples = 1;                        ///< GL_MAX_SAMPLES
  int maxTextureSize = 0;                    ///< GL_MAX_TEXTURE_SIZE
  int max3dTextureSize = 0;                  ///< GL_MAX_3D_TEXTURE_SIZE
};

/// One EGL device as enumerated by EGL_EXT_device_enumeration.
struct EglDeviceInfo {
  int index = 0;
  std::string extensions;  ///< EGL device extensions (EGL_MESA_device_software marks llvmpipe)
  std::string drmNode;     ///< DRM device file when the driver names one, else empty
  bool software = false;
};

/// The EGL devices this machine offers (empty when EGL_EXT_device_enumeration
/// is missing). Creates no context.
std::vector<EglDeviceInfo> listEglDevices();

/// An EGL display + OpenGL 4.5 core context with no surface.
class GlContext {
 public:
  /// Creates the context and makes it current on the calling thread.
  /// Fails with a message naming the missing platform, extension or version.
  static Result<std::unique_ptr<GlContext>> create(const ContextOptions& options = {});

  GlContext(const GlContext&) = delete;
  GlContext& operator=(const GlContext&) = delete;
  ~GlContext();

  /// Makes the context current on the calling thread.
  Status makeCurrent();
  /// Detaches the context from the calling thread.
  void release();
  /// True when this context is current on the calling thread.
  bool isCurrent() const;

  const ContextInfo& info() const { return info_; }
  /// True when the GL implementation reports `name` (e.g. "GL_KHR_debug").
  bool hasGlExtension(std::string_view name) const;

 private:
  GlContext() = default;
  struct Egl;
  std::unique_ptr<Egl> egl_;
  ContextInfo info_;
  std::vector<std::string> glExtensions_;
};

}  // namespace dm
