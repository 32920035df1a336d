// render_engine.cpp — scene frames at the render rate, HUD, PNG writer.
#include "render_engine.hpp"

#include <dm/core/log.hpp>
#include <dm/engine/scene_runtime.hpp>
#include <dm/io/image_io.hpp>
#include <dm/io/scene_file.hpp>
#include <dm/io/scene_resources.hpp>
#include <dm/renderer/context.hpp>
#include <dm/renderer/overlay.hpp>
#include <dm/renderer/render_target.hpp>
#include <dm/renderer/scene_view.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <mutex>
#include <thread>

#include "frame_slot.hpp"

namespace dm {

namespace {

// `camera` turned by a live view's orbit (dm::ViewOrbit): the eye about the
// target by yaw about the camera's up and pitch about its right axis (kept
// 5° off the up axis), the distance scaled, eye and target panned.
Camera orbited(Camera camera, const ViewOrbit& o) {
  const Vec3 up = camera.up.normalized();
  Vec3 offset = camera.position - camera.target;
  const double distance = offset.norm();
  offset = Eigen::AngleAxisd(o.yaw, up) * offset;
  const Vec3 right = up.cross(offset).normalized();  // = forward × up, as the camera's
  const double elevation = std::acos(std::clamp(offset.normalized().dot(up), -1.0, 1.0));  // from up
  constexpr double kMargin = 5.0 * 3.14159265358979323846 / 180.0;
  const double turned = std::clamp(elevation - o.pitch, kMargin, 3.14159265358979323846 - kMargin);
  offset = Eigen::AngleAxisd(turned - elevation, right) * offset;  // a positive turn leans it off up
  const Vec3 pan = distance * (o.panRight * right + o.panUp * offset.cross(right).normalized());
  camera.target += pan;
  camera.position = camera.target + o.zoom * offset;
  camera.orthoHeight *= o.zoom;
  return camera;
}

// What a live view needs of the camera a frame was drawn with.
FrameCamera frameCamera(const Camera& c) {
  FrameCamera f;
  f.eye = c.position;
  f.forward = c.forward();
  f.right = c.right();
  f.up = f.right.cross(f.forward);
  f.orthographic = c.projection == Camera::Projection::Orthographic;
  f.tanHalfFovY = std::tan(0.5 * c.fovYDeg * 3.14159265358979323846 / 180.0);
  f.orthoHeight = c.orthoHeight;
  return f;
}

// Writes frames on its own thread so PNG encoding does not hold the render
// rate. Bounded: `block` waits for room, otherwise a full queue drops.
class FrameWriter {
 public:
  FrameWriter(std::filesystem::path dir, bool block) : dir_(std::move(dir)), block_(block) {
    thread_ = std::thread([this] { run(); });
  }
  ~FrameWriter() { finish(); }
  // Returns false when the frame was dropped.
  bool push(std::uint64_t index, Image image) {
    std::unique_lock lock(m_);
    if (queue_.size() >= kCapacity) {
      if (!block_) {
        ++dropped_;
        return false;
      }
      room_.wait(lock, [&] { return queue_.size() < kCapacity; });
    }
    queue_.emplace_back(index, std::move(image));
    ready_.notify_one();
    return true;
  }
  void finish() {
    {
      std::lock_guard lock(m_);
      if (done_) return;
      done_ = true;
    }
    ready_.notify_all();
    if (thread_.joinable()) thread_.join();
  }
  std::uint64_t written() const {
    std::lock_guard lock(m_);
    return written_;
  }
  std::uint64_t dropped() const {
    std::lock_guard lock(m_);
    return dropped_;
  }
  Error error() const {
    std::lock_guard lock(m_);
    return error_;
  }

 private:
  static constexpr std::size_t kCapacity = 8;
  void run() {
    for (;;) {
      std::pair<std::uint64_t, Image> item;
      {
        std::unique_lock lock(m_);
        ready_.wait(lock, [&] { return done_ || !queue_.empty(); });
        if (queue_.empty()) return;
        item = std::move(queue_.front());
        queue_.pop_front();
        room_.notify_one();
      }
      const auto file = dir_ / formatString("frame_%05llu.png", static_cast<unsigned long long>(item.first));
      // zlib level 1: about 6 ms a 640x480 frame against 30 ms at the
      // default, so one writer thread keeps up with 30 Hz.
      Status s = writePng(item.second, file, 1);
      std::lock_guard lock(m_);
      if (s)
        ++written_;
      else if (error_.what.empty())
        error_ = s.error();
    }
  }
  std::filesystem::path dir_;
  bool block_;
  mutable std::mutex m_;
  std::condition_variable ready_, room_;
  std::deque<std::pair<std::uint64_t, Image>> queue_;
  bool done_ = false;
  std::uint64_t written_ = 0, dropped_ = 0;
  Error error_;
  std::thread thread_;
};

class RenderEngine final : public Engine, public RenderEngineHandle {
 public:
  std::string_view name() const noexcept override { return "render"; }

  bool tick(const TickInfo& info) noexcept override {
    try {
      return frame(info);
    } catch (const std::exception& e) {
      error_ = fail(ErrorCode::Internal, e.what(), "render");
      return false;
    }
  }

  Status shutdown() override {
    if (writer_) writer_->finish();
    // Free GL objects with the context current on this (control) thread.
    if (ctx_ && ctx_->makeCurrent()) {
      overlay_ = Overlay();
      target_ = RenderTarget();
      insetTarget_ = RenderTarget();
      view_ = SceneView();
      ctx_->release();
    }
    if (writer_ && !writer_->error().what.empty()) return writer_->error();
    return ok();
  }

  Error error() const override { return error_; }

  std::shared_ptr<Engine> engine() override { return self_.lock(); }

  RenderEngineStats stats() const override {
    RenderEngineStats s = stats_;
    if (writer_) {
      s.framesWritten = writer_->written();
      s.framesDropped = writer_->dropped();
    }
    std::vector<double> t = renderMs_;
    if (!t.empty()) {
      std::sort(t.begin(), t.end());
      s.renderMsP50 = t[t.size() / 2];
      s.renderMsMax = t.back();
    }
    return s;
  }

  // The milled bone's surface: what the burr removed since the last frame
  // (only the changed blocks are remeshed), swapped in before drawing.
  Status updateMillable() {
    if (!feed_.millableSurface) return ok();
    auto changed = feed_.millableSurface(surface_);
    if (!changed) return changed.error().within("engines/render");
    if (*changed) return view_.updateObjectMesh(feed_.millableObject, surface_);
    return ok();
  }

  // The soft objects' deformed surfaces (the physics engine's newest step),
  // swapped in before drawing: in place once the topology is set.
  Status updateSoft() {
    if (!feed_.softSurface) return ok();
    softSurfaces_.resize(feed_.softObjects.size());
    for (std::size_t i = 0; i < feed_.softObjects.size(); ++i)
      if (feed_.softSurface(i, softSurfaces_[i]))
        if (auto s = view_.updateObjectMesh(feed_.softObjects[i], softSurfaces_[i]); !s)
          return s.error().within("engines/render");
    return ok();
  }

  // The fluids' particles (the physics engine's newest step), drawn as
  // spheres half a spacing wide or as a liquid surface.
  Status updateFluids() {
    if (!feed_.fluidParticles) return ok();
    for (std::size_t i = 0; i < feed_.fluids.size(); ++i)
      if (feed_.fluidParticles(i, particles_)) {
        const RenderFeed::FluidLook& f = feed_.fluids[i];
        if (auto s = view_.setParticles(f.name, particles_, f.radius, f.color); !s)
          return s.error().within("engines/render");
      }
    return ok();
  }

  // Each fluid's surface look, once (the spheres need none).
  Status setFluidLooks() {
    for (const RenderFeed::FluidLook& f : feed_.fluids) {
      if (!f.surface) continue;
      dm::FluidLook look;
      look.color = f.color.head<3>();
      look.absorption = f.absorption;
      look.fresnelF0 = f.fresnel;
      look.specular = f.specular;
      look.shininess = f.shininess;
      look.refractionPixels = f.refraction;
      look.smoothingIterations = f.smoothing;
      const double spacing = 2.0 * f.radius;
      look.particleVolume = float(spacing * spacing * spacing);
      if (auto s = view_.setParticleSurface(f.name, look, 0.75 * spacing); !s)
        return s.error().within("engines/render");
    }
    return ok();
  }

  // A frame while loading, neither counted nor written: the driver compiles
  // the frame's shader variants (llvmpipe JIT-compiles them at the first
  // draw, ~200 ms) and the HUD's atlas and plot here, not in the first
  // real-time period, which would cost the run its first frames.
  Status warmUp() {
    if (auto s = updateMillable(); !s) return s;  // the whole bone's surface, meshed once here
    if (auto s = updateSoft(); !s) return s;      // the tissues at rest
    if (auto s = setFluidLooks(); !s) return s;
    if (auto s = updateFluids(); !s) return s;    // the fluids at the start
    if (auto r = view_.render(target_, camera_, 0.0); !r) return r.error();
    hud(0.0, false, Vec3::Zero());
    overlay_.begin(target_);
    const float values[2] = {0.0f, 1.0f};
    const OverlaySeries series{.values = values};
    (void)overlay_.plot(OverlayRect{0, 0, 64, 32}, {&series, 1}, PlotOptions{});
    if (auto s = overlay_.end(); !s) return s;
    if (auto img = target_.readColor(); !img) return img.error();
    return ok();
  }

  std::weak_ptr<RenderEngine> self_;
  std::unique_ptr<GlContext> ctx_;
  SceneView view_;
  RenderTarget target_;
  Overlay overlay_;
  std::unique_ptr<FrameWriter> writer_;
  RenderFeed feed_;
  std::string camera_;
  std::string insetCamera_;  // a second camera drawn in the upper-right corner, or empty
  RenderTarget insetTarget_;
  SpriteId insetSprite_{};
  ViewOrbit orbit_;       // a live view's turn of camera_
  bool orbited_ = false;  // orbit_ is not the identity: draw camera_ turned (mono)
  std::string proxyObject_;
  int frameEvery_ = 1;
  RenderEngineStats stats_;
  std::vector<double> renderMs_;
  std::vector<float> recent_;
  std::vector<Isometry3> poses_;  // of feed_.movingObjects
  Mesh surface_;                  // the milled object's, as drawn
  std::vector<Mesh> softSurfaces_;  // of feed_.softObjects, as drawn
  std::vector<Vec3> particles_;     // one fluid's, as read
  bool hud_ = true;
  Image overlayImage_;  // the vision overlay's newest image, as uploaded
  std::int64_t overlayFrame_ = -1;
  SpriteId overlaySprite_{};
  Error error_;
  TickTime time_;

 private:
  // One frame with the context current on this thread, released again
  // whatever happens; a failure is kept in error_ and stops the engine.
  bool frame(const TickInfo& info) {
    const auto t0 = std::chrono::steady_clock::now();
    if (!ctx_->isCurrent()) {
      if (auto s = ctx_->makeCurrent(); !s) {
        error_ = s.error();
        return false;
      }
    }
    const Status drawn = draw(time_.seconds(info));  // scene time, also in real time
    ctx_->release();
    if (!drawn) {
      error_ = drawn.error();
      return false;
    }
    renderMs_.push_back(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    return true;
  }

  Status draw(double t) {
    Isometry3 proxy = Isometry3::Identity();
    Vec3 force = Vec3::Zero();
    if (feed_.objectPoses && feed_.objectPoses(poses_))
      for (std::size_t i = 0; i < poses_.size() && i < feed_.movingObjects.size(); ++i)
        if (auto s = view_.setObjectPose(feed_.movingObjects[i], poses_[i]); !s) return s;
    if (auto s = updateMillable(); !s) return s;
    if (auto s = updateSoft(); !s) return s;
    if (auto s = updateFluids(); !s) return s;
    const bool haptics = feed_.haptics && feed_.haptics(proxy, force);
    if (haptics && !proxyObject_.empty())
      if (auto s = view_.setObjectPose(proxyObject_, proxy); !s) return s;
    if (feed_.viewOrbit && feed_.viewOrbit(orbit_)) orbited_ = !(orbit_ == ViewOrbit{});
    Camera drawnWith;  // for a live view (the mono camera of a stereo pair)
    if (orbited_ || feed_.shown) {
      auto cam = view_.camera(camera_, t);
      if (!cam) return cam.error();
      drawnWith = orbited_ ? orbited(*cam, orbit_) : *cam;
    }
    if (orbited_) {
      if (auto r = view_.render(target_, drawnWith); !r) return r.error();
    } else if (auto r = view_.render(target_, camera_, t); !r) {
      return r.error();
    }
    // The camera's view for the engines that stream or filter it, before
    // anything is drawn over it; the written frame is read again only when
    // something was (a frame is never written into once read: both may
    // share it).
    Image view;
    if (feed_.frames) {
      auto img = target_.readColor();
      if (!img) return img.error();
      view = std::move(*img);
      feed_.frames->put(view, t);
    }
    const bool drawnOver = hud_ || feed_.overlay || !insetCamera_.empty();
    if (auto s = drawInset(t); !s) return s;
    if (auto s = drawOver(t, haptics, force); !s) return s;
    const std::uint64_t index = stats_.frames++;
    const bool written = writer_ && index % static_cast<std::uint64_t>(frameEvery_) == 0;
    if ((written || feed_.shown) && (drawnOver || view.empty())) {  // the frame as drawn over
      auto img = target_.readColor();
      if (!img) return img.error();
      view = std::move(*img);
    }
    if (feed_.shown) feed_.shown->put(view, t, frameCamera(drawnWith));
    if (written) writer_->push(index / static_cast<std::uint64_t>(frameEvery_), std::move(view));
    return ok();
  }

  // What is drawn over the camera's view: the HUD (unless the scene turned
  // it off) and the vision overlay, 1:1 in the lower-left corner (halved
  // until it fits in half the view).
  Status drawOver(double t, bool haptics, const Vec3& force) {
    if (!hud_ && !feed_.overlay && insetCamera_.empty())
      return ok();  // (draw() relies on this to reuse its read-back)
    overlay_.begin(target_);
    if (insetSprite_.valid()) {
      const float w = static_cast<float>(insetTarget_.width()), h = static_cast<float>(insetTarget_.height());
      overlay_.sprite(insetSprite_, OverlayRect{static_cast<float>(target_.width()) - w, 0, w, h});
    }
    if (hud_) hudItems(t, haptics, force);
    if (feed_.overlay) {
      std::int64_t frame = -1;
      if (feed_.overlay(overlayImage_, frame) && frame != overlayFrame_) {
        if (!overlaySprite_.valid()) {
          auto id = overlay_.createTexture(overlayImage_, {.srgb = true, .linear = false});
          if (!id) return id.error().within("engines/vision/overlay");
          overlaySprite_ = *id;
        } else if (auto s = overlay_.updateTexture(overlaySprite_, overlayImage_); !s) {
          return s.error().within("engines/vision/overlay");
        }
        overlayFrame_ = frame;
      }
      if (overlaySprite_.valid()) {
        float w = static_cast<float>(overlayImage_.width()), h = static_cast<float>(overlayImage_.height());
        const float maxW = 0.5f * static_cast<float>(target_.width()),
                    maxH = 0.5f * static_cast<float>(target_.height());
        while (w > maxW || h > maxH) w *= 0.5f, h *= 0.5f;
        overlay_.sprite(overlaySprite_, OverlayRect{0, static_cast<float>(target_.height()) - h, w, h});
      }
    }
    return overlay_.end();
  }

  // The inset camera's picture at scene time t, into its sprite (drawn in
  // the upper-right corner by drawOver).
  Status drawInset(double t) {
    if (insetCamera_.empty()) return ok();
    if (auto r = view_.render(insetTarget_, insetCamera_, t); !r)
      return r.error().within("engines/render/inset");
    auto img = insetTarget_.readColor();
    if (!img) return img.error();
    if (!insetSprite_.valid()) {
      auto id = overlay_.createTexture(*img, {.srgb = true, .linear = false});
      if (!id) return id.error().within("engines/render/inset");
      insetSprite_ = *id;
      return ok();
    }
    return overlay_.updateTexture(insetSprite_, *img);
  }

  void hud(double t, bool haptics, const Vec3& force) {
    overlay_.begin(target_);
    hudItems(t, haptics, force);
    if (auto s = overlay_.end(); !s) log::warn("HUD: %s", s.error().message().c_str());
  }

  void hudItems(double t, bool haptics, const Vec3& force) {
    const float w = static_cast<float>(target_.width()), h = static_cast<float>(target_.height());
    const float size = std::clamp(h / 32.0f, 10.0f, 24.0f);
    char line[160];
    if (haptics)
      std::snprintf(line, sizeof line, "t = %6.2f s   |F| = %5.2f N", t, force.norm());
    else
      std::snprintf(line, sizeof line, "t = %6.2f s", t);
    overlay_.text(size * 0.6f, size * 0.5f, line, size, Vec4f(1, 1, 1, 1));
    if (haptics && feed_.recentForce) {
      double seconds = 0;
      feed_.recentForce(recent_, seconds);
      if (recent_.size() >= 2) {
        const OverlayRect frame{w * 0.58f, h * 0.70f, w * 0.40f, h * 0.27f};
        OverlaySeries series{.values = recent_, .color = Vec4f(1.0f, 0.55f, 0.2f, 1), .width = 1.5f};
        PlotOptions opt;
        opt.xMin = static_cast<float>(-seconds);
        opt.xMax = 0;
        opt.yLabel = "|F| N";
        opt.xLabel = "s";
        opt.textSize = std::max(9.0f, size * 0.6f);
        overlay_.plot(frame, {&series, 1}, opt);
      }
    }
  }
};

}  // namespace

Result<std::shared_ptr<RenderEngineHandle>> makeRenderEngine(const SceneDesc& scene,
                                                             const SceneResources& resources, RenderFeed feed,
                                                             const std::filesystem::path& framesDir,
                                                             int frameEvery, bool blockOnWriter) {
  const SceneRenderEngine settings = scene.engines.render.value_or(SceneRenderEngine{});
  auto e = std::make_shared<RenderEngine>();
  e->self_ = e;
  auto ctx = GlContext::create();
  if (!ctx) return ctx.error().within("engines/render");
  e->ctx_ = std::move(*ctx);
  e->stats_.glRenderer = e->ctx_->info().glRenderer;
  e->stats_.eglPlatform = toString(e->ctx_->info().platform);
  auto view = SceneView::create(scene, resources);
  if (!view) return view.error();
  e->view_ = std::move(*view);
  auto target =
      RenderTarget::create({.width = settings.width, .height = settings.height, .samples = settings.samples});
  if (!target) return target.error().within("engines/render");
  e->target_ = std::move(*target);
  auto overlay = Overlay::create();
  if (!overlay) return overlay.error().within("engines/render");
  e->overlay_ = std::move(*overlay);
  e->camera_ = settings.camera;
  if (!settings.insetCamera.empty()) {
    auto inset = RenderTarget::create(
        {.width = std::max(16, static_cast<int>(std::lround(settings.insetSize * settings.width))),
         .height = std::max(16, static_cast<int>(std::lround(settings.insetSize * settings.height))),
         .samples = settings.samples});
    if (!inset) return inset.error().within("engines/render/inset");
    e->insetTarget_ = std::move(*inset);
    e->insetCamera_ = settings.insetCamera;
  }
  if (auto cam = e->view_.camera(e->camera_, 0.0); !cam) return cam.error().within("engines/render/camera");
  if (scene.engines.haptics) e->proxyObject_ = scene.engines.haptics->proxyObject;
  e->hud_ = settings.hud;
  e->feed_ = std::move(feed);
  e->frameEvery_ = std::max(1, frameEvery);
  if (!framesDir.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(framesDir, ec);
    if (ec)
      return fail(ErrorCode::Io, "cannot create the frames folder: " + ec.message(), framesDir.string());
    e->writer_ = std::make_unique<FrameWriter>(framesDir, blockOnWriter);
  }
  if (auto s = e->warmUp(); !s) return s.error().within("engines/render");
  e->ctx_->release();  // the ticking thread makes it current
  return std::shared_ptr<RenderEngineHandle>(e);
}

}  // namespace dm
