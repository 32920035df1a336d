// context.cpp — EGL display selection and the OpenGL 4.5 core context.
#include <dm/core/log.hpp>
#include <dm/renderer/context.hpp>

#include <EGL/egl.h>
#include <EGL/eglext.h>

#include <cstdlib>
#include <cstring>
#include <mutex>
#include <sstream>

#include "gl.hpp"

#ifndef EGL_PLATFORM_SURFACELESS_MESA
#define EGL_PLATFORM_SURFACELESS_MESA 0x31DD
#endif

namespace dm {

namespace {

constexpr const char* kPackages =
    "apt install libegl1 libegl-mesa0 libgl1-mesa-dri (Mesa) or the GPU vendor's EGL driver";

bool hasToken(const char* list, std::string_view token) {
  if (list == nullptr) return false;
  std::string_view s(list);
  std::size_t pos = 0;
  while (pos < s.size()) {
    const std::size_t end = std::min(s.find(' ', pos), s.size());
    if (s.substr(pos, end - pos) == token) return true;
    pos = end + 1;
  }
  return false;
}

const char* eglErrorName(EGLint e) {
  switch (e) {
    case EGL_SUCCESS:
      return "EGL_SUCCESS";
    case EGL_NOT_INITIALIZED:
      return "EGL_NOT_INITIALIZED";
    case EGL_BAD_ACCESS:
      return "EGL_BAD_ACCESS";
    case EGL_BAD_ALLOC:
      return "EGL_BAD_ALLOC";
    case EGL_BAD_ATTRIBUTE:
      return "EGL_BAD_ATTRIBUTE";
    case EGL_BAD_CONFIG:
      return "EGL_BAD_CONFIG";
    case EGL_BAD_CONTEXT:
      return "EGL_BAD_CONTEXT";
    case EGL_BAD_DISPLAY:
      return "EGL_BAD_DISPLAY";
    case EGL_BAD_MATCH:
      return "EGL_BAD_MATCH";
    case EGL_BAD_PARAMETER:
      return "EGL_BAD_PARAMETER";
    case EGL_BAD_SURFACE:
      return "EGL_BAD_SURFACE";
    default:
      return "EGL error";
  }
}

// Client-extension entry points, resolved once.
struct EglExt {
  PFNEGLQUERYDEVICESEXTPROC queryDevices = nullptr;
  PFNEGLQUERYDEVICESTRINGEXTPROC queryDeviceString = nullptr;
  PFNEGLGETPLATFORMDISPLAYEXTPROC getPlatformDisplay = nullptr;
  std::string clientExtensions;

  static const EglExt& get() {
    static const EglExt ext = [] {
      EglExt e;
      const char* client = eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
      e.clientExtensions = client != nullptr ? client : "";
      if (hasToken(client, "EGL_EXT_device_enumeration") || hasToken(client, "EGL_EXT_device_base"))
        e.queryDevices = reinterpret_cast<PFNEGLQUERYDEVICESEXTPROC>(eglGetProcAddress("eglQueryDevicesEXT"));
      if (hasToken(client, "EGL_EXT_device_query") || hasToken(client, "EGL_EXT_device_base"))
        e.queryDeviceString =
            reinterpret_cast<PFNEGLQUERYDEVICESTRINGEXTPROC>(eglGetProcAddress("eglQueryDeviceStringEXT"));
      if (hasToken(client, "EGL_EXT_platform_base"))
        e.getPlatformDisplay =
            reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(eglGetProcAddress("eglGetPlatformDisplayEXT"));
      return e;
    }();
    return ext;
  }
  bool client(std::string_view name) const { return hasToken(clientExtensions.c_str(), name); }
};

// EGL displays are process-wide, one per device, shared by every context on
// it: a display is initialised once and never terminated (eglTerminate would
// pull it from under the other contexts, and Mesa unloads its driver on
// terminate, losing the allocations it still holds). libEGL finalises
// displays at process exit.
std::mutex gDisplayMutex;

std::vector<EGLDeviceEXT> queryDevices() {
  const EglExt& ext = EglExt::get();
  if (ext.queryDevices == nullptr) return {};
  EGLint n = 0;
  if (!ext.queryDevices(0, nullptr, &n) || n <= 0) return {};
  std::vector<EGLDeviceEXT> devices(static_cast<std::size_t>(n));
  if (!ext.queryDevices(n, devices.data(), &n)) return {};
  devices.resize(static_cast<std::size_t>(n));
  return devices;
}

}  // namespace

const char* toString(EglPlatform p) noexcept {
  switch (p) {
    case EglPlatform::Auto:
      return "auto";
    case EglPlatform::Device:
      return "device";
    case EglPlatform::Surfaceless:
      return "surfaceless";
  }
  return "?";
}

Result<EglPlatform> parseEglPlatform(std::string_view text) {
  if (text == "auto") return EglPlatform::Auto;
  if (text == "device") return EglPlatform::Device;
  if (text == "surfaceless") return EglPlatform::Surfaceless;
  return fail(ErrorCode::InvalidArgument, "unknown EGL platform \"" + std::string(text) + "\"",
              "DM_EGL_PLATFORM", "use auto, device or surfaceless");
}

std::vector<EglDeviceInfo> listEglDevices() {
  const EglExt& ext = EglExt::get();
  std::vector<EglDeviceInfo> out;
  const auto devices = queryDevices();
  for (std::size_t i = 0; i < devices.size(); ++i) {
    EglDeviceInfo d;
    d.index = static_cast<int>(i);
    if (ext.queryDeviceString != nullptr) {
      const char* e = ext.queryDeviceString(devices[i], EGL_EXTENSIONS);
      d.extensions = e != nullptr ? e : "";
      if (hasToken(e, "EGL_EXT_device_drm")) {
        const char* node = ext.queryDeviceString(devices[i], EGL_DRM_DEVICE_FILE_EXT);
        d.drmNode = node != nullptr ? node : "";
      }
    }
    d.software = hasToken(d.extensions.c_str(), "EGL_MESA_device_software");
    out.push_back(std::move(d));
  }
  return out;
}

struct GlContext::Egl {
  EGLDisplay display = EGL_NO_DISPLAY;
  EGLContext context = EGL_NO_CONTEXT;
};

namespace {

// Opens `display`, creates a 4.5 core context on it and makes it current.
// On failure releases everything it took and says why.
Result<EGLContext> createOn(EGLDisplay display, const char* platformName, bool debug) {
  {
    // eglInitialize on an initialised display is a no-op; serialised anyway
    // because some drivers are not thread-safe here.
    std::lock_guard lock(gDisplayMutex);
    EGLint major = 0, minor = 0;
    if (!eglInitialize(display, &major, &minor))
      return fail(ErrorCode::Unsupported, std::string("eglInitialize failed: ") + eglErrorName(eglGetError()),
                  platformName, kPackages);
  }
  auto bail = [&](std::string what, std::string hint = {}) -> Error {
    return fail(ErrorCode::Unsupported, std::move(what), platformName, std::move(hint));
  };
  const char* dispExt = eglQueryString(display, EGL_EXTENSIONS);
  if (!hasToken(dispExt, "EGL_KHR_surfaceless_context"))
    return bail("the display lacks EGL_KHR_surfaceless_context (needed to render without a window)",
                "update Mesa or the GPU driver");
  if (!eglBindAPI(EGL_OPENGL_API))
    return bail(std::string("eglBindAPI(EGL_OPENGL_API) failed: ") + eglErrorName(eglGetError()),
                "the EGL driver has no desktop OpenGL; install libgl1-mesa-dri");
  EGLConfig config = nullptr;
  EGLint count = 0;
  const EGLint configAttribs[] = {EGL_RENDERABLE_TYPE, EGL_OPENGL_BIT, EGL_NONE};
  const bool noConfig =
      hasToken(dispExt, "EGL_KHR_no_config_context") || hasToken(dispExt, "EGL_MESA_configless_context");
  if (!noConfig && (!eglChooseConfig(display, configAttribs, &config, 1, &count) || count < 1))
    return bail("no EGL config renders desktop OpenGL",
                "install libgl1-mesa-dri or the GPU vendor's GL driver");
  const EGLint ctxAttribs[] = {EGL_CONTEXT_MAJOR_VERSION,
                               4,
                               EGL_CONTEXT_MINOR_VERSION,
                               5,
                               EGL_CONTEXT_OPENGL_PROFILE_MASK,
                               EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT,
                               EGL_CONTEXT_OPENGL_DEBUG,
                               debug ? EGL_TRUE : EGL_FALSE,
                               EGL_NONE};
  EGLContext ctx =
      eglCreateContext(display, noConfig ? EGL_NO_CONFIG_KHR : config, EGL_NO_CONTEXT, ctxAttribs);
  if (ctx == EGL_NO_CONTEXT)
    return bail(std::string("no OpenGL 4.5 core context: ") + eglErrorName(eglGetError()),
                "the driver must support OpenGL 4.5 core (Mesa >= 20 llvmpipe does)");
  if (!eglMakeCurrent(display, EGL_NO_SURFACE, EGL_NO_SURFACE, ctx)) {
    const EGLint e = eglGetError();
    eglDestroyContext(display, ctx);
    return bail(std::string("eglMakeCurrent failed: ") + eglErrorName(e));
  }
  return ctx;
}

std::string glString(GLenum name) {
  const auto* s = reinterpret_cast<const char*>(glGetString(name));
  return s != nullptr ? s : "";
}

void APIENTRY debugCallback(GLenum, GLenum type, GLuint, GLenum severity, GLsizei, const GLchar* message,
                            const void*) {
  if (severity == GL_DEBUG_SEVERITY_NOTIFICATION) return;
  if (type == GL_DEBUG_TYPE_ERROR)
    log::warn("GL: %s", message);
  else
    log::debug("GL: %s", message);
}

}  // namespace

Result<std::unique_ptr<GlContext>> GlContext::create(const ContextOptions& optionsIn) {
  ContextOptions options = optionsIn;
  if (!options.ignoreEnvironment) {
    if (const char* env = std::getenv("DM_EGL_PLATFORM"); env != nullptr && *env != '\0') {
      auto p = parseEglPlatform(env);
      if (!p) return p.error();
      options.platform = *p;
    }
    if (const char* env = std::getenv("DM_EGL_DEVICE"); env != nullptr && *env != '\0') {
      char* end = nullptr;
      const long v = std::strtol(env, &end, 10);
      if (end == env || *end != '\0' || v < 0 || v > 1024)
        return fail(ErrorCode::InvalidArgument, std::string("DM_EGL_DEVICE is \"") + env + "\"",
                    "DM_EGL_DEVICE", "give a 0-based device index (dmtool render --list-devices shows them)");
      options.deviceIndex = static_cast<int>(v);
    }
  }
  const EglExt& ext = EglExt::get();
  std::vector<std::string> reasons;
  std::unique_ptr<GlContext> self(new GlContext());
  self->egl_ = std::make_unique<Egl>();

  auto tryDevice = [&](bool allowSoftware) -> bool {
    if (ext.getPlatformDisplay == nullptr || !ext.client("EGL_EXT_platform_device")) {
      reasons.push_back("device: EGL_EXT_platform_device is missing");
      return false;
    }
    const auto infos = listEglDevices();
    const auto devices = queryDevices();
    if (devices.empty()) {
      reasons.push_back("device: no EGL device is enumerated");
      return false;
    }
    for (std::size_t i = 0; i < devices.size(); ++i) {
      if (options.deviceIndex >= 0 && static_cast<int>(i) != options.deviceIndex) continue;
      if (options.deviceIndex < 0 && infos[i].software && !allowSoftware) continue;
      EGLDisplay d = ext.getPlatformDisplay(EGL_PLATFORM_DEVICE_EXT, devices[i], nullptr);
      if (d == EGL_NO_DISPLAY) {
        reasons.push_back(formatString("device %zu: no display", i));
        continue;
      }
      auto ctx = createOn(d, "EGL device platform", options.debugOutput);
      if (!ctx) {
        reasons.push_back(formatString("device %zu: %s", i, ctx.error().what.c_str()));
        continue;
      }
      self->egl_->display = d;
      self->egl_->context = *ctx;
      self->info_.platform = EglPlatform::Device;
      self->info_.deviceIndex = static_cast<int>(i);
      return true;
    }
    if (options.deviceIndex >= static_cast<int>(devices.size()))
      reasons.push_back(
          formatString("device: index %d requested, %zu devices", options.deviceIndex, devices.size()));
    else if (options.deviceIndex < 0 && !allowSoftware)
      reasons.push_back("device: no hardware EGL device");
    return false;
  };
  auto trySurfaceless = [&]() -> bool {
    if (ext.getPlatformDisplay == nullptr || !ext.client("EGL_MESA_platform_surfaceless")) {
      reasons.push_back("surfaceless: EGL_MESA_platform_surfaceless is missing (Mesa's libegl-mesa0)");
      return false;
    }
    EGLDisplay d = ext.getPlatformDisplay(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
    if (d == EGL_NO_DISPLAY) {
      reasons.push_back("surfaceless: no display");
      return false;
    }
    auto ctx = createOn(d, "EGL surfaceless platform", options.debugOutput);
    if (!ctx) {
      reasons.push_back("surfaceless: " + ctx.error().what);
      return false;
    }
    self->egl_->display = d;
    self->egl_->context = *ctx;
    self->info_.platform = EglPlatform::Surfaceless;
    return true;
  };

  bool ok = false;
  switch (options.platform) {
    case EglPlatform::Device:
      ok = tryDevice(true);
      break;
    case EglPlatform::Surfaceless:
      ok = trySurfaceless();
      break;
    case EglPlatform::Auto:
      ok = tryDevice(false) || trySurfaceless() || tryDevice(true);
      break;
  }
  if (!ok) {
    std::string what = "no headless OpenGL 4.5 core context";
    for (const auto& r : reasons) what += "; " + r;
    return fail(ErrorCode::Unsupported, std::move(what),
                std::string("EGL platform ") + toString(options.platform), kPackages);
  }

  ContextInfo& info = self->info_;
  const char* v = eglQueryString(self->egl_->display, EGL_VENDOR);
  info.eglVendor = v != nullptr ? v : "";
  v = eglQueryString(self->egl_->display, EGL_VERSION);
  info.eglVersion = v != nullptr ? v : "";
  info.glVendor = glString(GL_VENDOR);
  info.glRenderer = glString(GL_RENDERER);
  info.glVersion = glString(GL_VERSION);
  info.software = info.glRenderer.find("llvmpipe") != std::string::npos ||
                  info.glRenderer.find("softpipe") != std::string::npos;
  glGetIntegerv(GL_MAX_SAMPLES, &info.maxSamples);
  glGetIntegerv(GL_MAX_TEXTURE_SIZE, &info.maxTextureSize);
  glGetIntegerv(GL_MAX_3D_TEXTURE_SIZE, &info.max3dTextureSize);
  GLint n = 0;
  glGetIntegerv(GL_NUM_EXTENSIONS, &n);
  for (GLint i = 0; i < n; ++i) {
    const auto* e = reinterpret_cast<const char*>(glGetStringi(GL_EXTENSIONS, static_cast<GLuint>(i)));
    if (e != nullptr) self->glExtensions_.emplace_back(e);
  }
  if (options.debugOutput && self->hasGlExtension("GL_KHR_debug")) {
    glEnable(GL_DEBUG_OUTPUT);
    glDebugMessageCallback(debugCallback, nullptr);
  }
  log::info("GL context: %s on %s (%s, EGL %s platform)", info.glVersion.c_str(), info.glRenderer.c_str(),
            info.glVendor.c_str(), toString(info.platform));
  return self;
}

GlContext::~GlContext() {
  if (!egl_ || egl_->display == EGL_NO_DISPLAY) return;
  if (eglGetCurrentContext() == egl_->context)
    eglMakeCurrent(egl_->display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
  eglDestroyContext(egl_->display, egl_->context);
}

Status GlContext::makeCurrent() {
  if (!eglMakeCurrent(egl_->display, EGL_NO_SURFACE, EGL_NO_SURFACE, egl_->context))
    return fail(ErrorCode::Busy, std::string("eglMakeCurrent failed: ") + eglErrorName(eglGetError()),
                "GlContext",
                "a context is current on one thread at a time: release() it on the other thread first");
  return ok();
}

void GlContext::release() {
  if (isCurrent()) eglMakeCurrent(egl_->display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
}

bool GlContext::isCurrent() const { return eglGetCurrentContext() == egl_->context; }

bool GlContext::hasGlExtension(std::string_view name) const {
  for (const auto& e : glExtensions_)
    if (e == name) return true;
  return false;
}

namespace gl {

const char* errorName(GLenum e) noexcept {
  switch (e) {
    case GL_NO_ERROR:
      return "GL_NO_ERROR";
    case GL_INVALID_ENUM:
      return "GL_INVALID_ENUM";
    case GL_INVALID_VALUE:
      return "GL_INVALID_VALUE";
    case GL_INVALID_OPERATION:
      return "GL_INVALID_OPERATION";
    case GL_INVALID_FRAMEBUFFER_OPERATION:
      return "GL_INVALID_FRAMEBUFFER_OPERATION";
    case GL_OUT_OF_MEMORY:
      return "GL_OUT_OF_MEMORY";
    case GL_STACK_OVERFLOW:
      return "GL_STACK_OVERFLOW";
    case GL_STACK_UNDERFLOW:
      return "GL_STACK_UNDERFLOW";
    default:
      return "GL error";
  }
}

Status check(const char* what) {
  const GLenum first = glGetError();
  if (first == GL_NO_ERROR) return ok();
  while (glGetError() != GL_NO_ERROR) {
  }
  if (first == GL_OUT_OF_MEMORY)
    return fail(ErrorCode::Io, std::string(what) + ": GL_OUT_OF_MEMORY", "OpenGL",
                "use a smaller render target, volume or mesh");
  return fail(ErrorCode::Internal, std::string(what) + ": " + errorName(first), "OpenGL");
}

}  // namespace gl

}  // namespace dm
