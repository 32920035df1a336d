// dmedit — the scene and resource editor (Dear ImGui on GLFW).
//
//   dmedit [SCENE.json] [--size WxH] [--screenshot PNG [--frames N]]
//
// Panels: "Scene" lists the resources (type, source, size once loaded),
// materials, objects, volume views, lights and cameras, and adds or removes
// objects; "Inspector" edits the selection (an object's pose, scale,
// material and flags; a material's colours, shading and haptic
// coefficients; a volume view's mode, transfer function and slice; a
// light); "View" draws the scene with DMRenderer's SceneView — headless
// EGL, read back and shown as a texture — from an orbit camera (drag:
// orbit, right-drag: pan, wheel: zoom) or one of the scene's cameras;
// "Volume" shows a volume resource slice by slice. File > Save / Save As
// writes the scene (every edit is validated first: see document.hpp);
// Edit > Undo / Redo. Errors of a refused edit appear under the inspector
// with their JSON path.
//
// --screenshot draws N frames (default 5), writes the window's pixels to
// PNG and exits: the test that runs dmedit under Xvfb checks that picture.
// Exit codes: 0 done, 1 failure (message on stderr), 2 bad command line.
#include <dm/core/log.hpp>
#include <dm/io/image_io.hpp>
#include <dm/io/scene_resources.hpp>
#include <dm/renderer/context.hpp>
#include <dm/renderer/render_target.hpp>
#include <dm/renderer/scene_view.hpp>

#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>
#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>
#include <CLI/CLI.hpp>
#include <backends/imgui_impl_glfw.h>
#include <backends/imgui_impl_opengl3.h>
#include <imgui.h>
#include <imgui_stdlib.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <numbers>
#include <optional>
#include <string>
#include <vector>

#include "document.hpp"

namespace {

namespace fs = std::filesystem;
using dm::Vec3;

struct Options {
  std::string scene;
  std::string size = "1280x800";
  std::string screenshot;
  int frames = 5;
};

// What the inspector shows.
struct Selection {
  enum Kind { None, Resource, Material, Object, Volume, Light, Camera } kind = None;
  std::string name;
  std::size_t index = 0;
};

// The orbit camera of the View panel.
struct Orbit {
  Vec3 target = Vec3::Zero();
  double distance = 0.5, yaw = 0.6, pitch = 0.3;  // m, rad
  dm::Camera camera() const {
    const Vec3 eye = target + distance * Vec3(std::cos(pitch) * std::cos(yaw), std::cos(pitch) * std::sin(yaw),
                                              std::sin(pitch));
    dm::Camera c = dm::Camera::lookAt(eye, target, Vec3::UnitZ());
    c.nearPlane = std::max(1e-3, distance * 0.01);
    c.farPlane = distance * 20 + 1;
    return c;
  }
};

// An RGBA8 GL texture of the window's context, resized on upload.
struct Texture {
  GLuint id = 0;
  int width = 0, height = 0;
  void upload(const dm::Image& image) {
    if (!id) glGenTextures(1, &id);
    glBindTexture(GL_TEXTURE_2D, id);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    glPixelStorei(GL_UNPACK_ROW_LENGTH,
                  static_cast<GLint>(image.strideBytes() / static_cast<std::size_t>(image.channels())));
    const GLenum format = image.channels() == 4 ? GL_RGBA : image.channels() == 3 ? GL_RGB : GL_RED;
    glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, image.width(), image.height(), 0, format, GL_UNSIGNED_BYTE,
                 image.data());
    glPixelStorei(GL_UNPACK_ROW_LENGTH, 0);
    if (image.channels() == 1) {
      const GLint swizzle[] = {GL_RED, GL_RED, GL_RED, GL_ONE};
      glTexParameteriv(GL_TEXTURE_2D, GL_TEXTURE_SWIZZLE_RGBA, swizzle);
    }
    width = image.width(), height = image.height();
  }
  ImTextureID handle() const { return reinterpret_cast<ImTextureID>(static_cast<std::intptr_t>(id)); }
};

// The scene renderer on its own headless EGL context; the window's context
// is released while it draws.
class Viewport {
 public:
  explicit Viewport(std::unique_ptr<dm::GlContext> egl) : egl_(std::move(egl)) {}

  // Redraws when the document, the camera or the size changed; returns the
  // picture to upload, or nothing when the last one still holds.
  dm::Result<std::optional<dm::Image>> draw(GLFWwindow* window, const dmedit::SceneDocument& doc,
                                            const dm::SceneResources& resources, const std::string& cameraName,
                                            const Orbit& orbit, int width, int height) {
    const std::string key = std::to_string(doc.revision()) + "|" + cameraName + "|" + std::to_string(width) + "x" +
                            std::to_string(height) + "|" + std::to_string(orbit.yaw) + std::to_string(orbit.pitch) +
                            std::to_string(orbit.distance) + std::to_string(orbit.target.x()) +
                            std::to_string(orbit.target.y()) + std::to_string(orbit.target.z());
    if (key == key_ || width < 16 || height < 16) return std::optional<dm::Image>{};
    glfwMakeContextCurrent(nullptr);
    if (auto s = egl_->makeCurrent(); !s) return s.error();
    auto result = drawCurrent(doc, resources, cameraName, orbit, width, height);
    egl_->release();
    glfwMakeContextCurrent(window);
    if (!result) {
      key_ = key;  // do not retry a failing frame every frame
      return result.error();
    }
    key_ = key;
    return std::optional<dm::Image>(std::move(*result));
  }

  // Frees the GL objects with their context current (before exit).
  void close() {
    if (egl_ && egl_->makeCurrent()) {
      view_.reset();
      target_.reset();
      egl_->release();
    }
  }

 private:
  dm::Result<dm::Image> drawCurrent(const dmedit::SceneDocument& doc, const dm::SceneResources& resources,
                                    const std::string& cameraName, const Orbit& orbit, int width, int height) {
    if (!view_ || revision_ != doc.revision()) {
      view_.reset();
      auto v = dm::SceneView::create(doc.scene(), resources);
      if (!v) return v.error();
      view_ = std::move(*v);
      revision_ = doc.revision();
    }
    if (!target_ || target_->width() != width || target_->height() != height) {
      target_.reset();
      auto t = dm::RenderTarget::create({.width = width, .height = height, .samples = 4});
      if (!t) return t.error();
      target_ = std::move(*t);
    }
    auto stats = cameraName.empty()
                     ? view_->render(*target_, orbit.camera())
                     : view_->render(*target_, cameraName, 0.0);
    if (!stats) return stats.error();
    return target_->readColor();
  }

  std::unique_ptr<dm::GlContext> egl_;
  std::optional<dm::SceneView> view_;
  std::optional<dm::RenderTarget> target_;
  unsigned revision_ = ~0u;
  std::string key_;
};

const char* resourceType(const dm::SceneResource& r) {
  switch (r.type) {
    case dm::SceneResource::Type::Mesh: return "mesh";
    case dm::SceneResource::Type::Volume: return "volume";
    case dm::SceneResource::Type::Isosurface: return "isosurface";
    case dm::SceneResource::Type::Shape: return "shape";
    case dm::SceneResource::Type::Image: return "image";
  }
  return "?";
}

bool editVec3(const char* label, Vec3& v, float speed, const char* format) {
  float f[3] = {static_cast<float>(v.x()), static_cast<float>(v.y()), static_cast<float>(v.z())};
  if (!ImGui::DragFloat3(label, f, speed, 0, 0, format)) return false;
  v = Vec3(f[0], f[1], f[2]);
  return true;
}

bool editColor(const char* label, dm::Vec4& c) {
  float f[4] = {static_cast<float>(c[0]), static_cast<float>(c[1]), static_cast<float>(c[2]),
                static_cast<float>(c[3])};
  if (!ImGui::ColorEdit4(label, f, ImGuiColorEditFlags_Float)) return false;
  c = dm::Vec4(f[0], f[1], f[2], f[3]);
  return true;
}

bool editDouble(const char* label, double& x, float speed, double lo, double hi, const char* format = "%.4g") {
  float f = static_cast<float>(x);
  if (!ImGui::DragFloat(label, &f, speed, static_cast<float>(lo), static_cast<float>(hi), format)) return false;
  x = f;
  return true;
}

class Editor {
 public:
  Editor(dmedit::SceneDocument doc, dm::SceneResources resources, Viewport viewport)
      : doc_(std::move(doc)), resources_(std::move(resources)), viewport_(std::move(viewport)) {
    // Frame the resources: the orbit looks at the meshes' common centre.
    dm::Aabb box;
    for (const auto& o : doc_.scene().objects)
      if (auto m = resources_.mesh(o.mesh))
        for (const Vec3& p : m->positions) box.extend(o.pose.isometry() * (o.scale * p));
    if (!box.isEmpty()) {
      orbit_.target = box.center();
      orbit_.distance = std::max(0.05, 1.6 * box.sizes().norm());
    }
    saveAs_ = doc_.file().string();
  }

  void close() { viewport_.close(); }

  // One frame of UI; false when the user quit.
  bool frame(GLFWwindow* window) {
    menu(window);
    const ImGuiViewport* vp = ImGui::GetMainViewport();
    const float top = vp->WorkPos.y, w = vp->WorkSize.x, h = vp->WorkSize.y;
    ImGui::SetNextWindowPos(ImVec2(0, top), ImGuiCond_FirstUseEver);
    ImGui::SetNextWindowSize(ImVec2(w * 0.22f, h * 0.6f), ImGuiCond_FirstUseEver);
    scenePanel();
    ImGui::SetNextWindowPos(ImVec2(0, top + h * 0.6f), ImGuiCond_FirstUseEver);
    ImGui::SetNextWindowSize(ImVec2(w * 0.22f, h * 0.4f), ImGuiCond_FirstUseEver);
    volumePanel();
    ImGui::SetNextWindowPos(ImVec2(w * 0.22f, top), ImGuiCond_FirstUseEver);
    ImGui::SetNextWindowSize(ImVec2(w * 0.5f, h), ImGuiCond_FirstUseEver);
    viewPanel(window);
    ImGui::SetNextWindowPos(ImVec2(w * 0.72f, top), ImGuiCond_FirstUseEver);
    ImGui::SetNextWindowSize(ImVec2(w * 0.28f, h), ImGuiCond_FirstUseEver);
    inspector();
    return !quit_;
  }

 private:
  void report(const dm::Status& s) { error_ = s ? std::string() : s.error().message(); }

  void menu(GLFWwindow* window) {
    if (!ImGui::BeginMainMenuBar()) return;
    if (ImGui::BeginMenu("File")) {
      if (ImGui::MenuItem("Save", "Ctrl+S", false, !doc_.file().empty())) report(doc_.save());
      if (ImGui::MenuItem("Save As...")) showSaveAs_ = true;
      if (ImGui::MenuItem("Quit")) quit_ = true;
      ImGui::EndMenu();
    }
    if (ImGui::BeginMenu("Edit")) {
      if (ImGui::MenuItem("Undo", "Ctrl+Z", false, doc_.canUndo())) doc_.undo();
      if (ImGui::MenuItem("Redo", "Ctrl+Y", false, doc_.canRedo())) doc_.redo();
      ImGui::EndMenu();
    }
    ImGui::TextDisabled("%s%s", doc_.file().string().c_str(), doc_.dirty() ? " (edited)" : "");
    ImGui::EndMainMenuBar();
    const ImGuiIO& io = ImGui::GetIO();
    if (io.KeyCtrl && ImGui::IsKeyPressed(ImGui::GetKeyIndex(ImGuiKey_Z))) doc_.undo();
    if (io.KeyCtrl && ImGui::IsKeyPressed(ImGui::GetKeyIndex(ImGuiKey_Y))) doc_.redo();
    if (io.KeyCtrl && glfwGetKey(window, GLFW_KEY_S) == GLFW_PRESS && !saveKeyHeld_) report(doc_.save());
    saveKeyHeld_ = io.KeyCtrl && glfwGetKey(window, GLFW_KEY_S) == GLFW_PRESS;
    if (showSaveAs_) {
      ImGui::OpenPopup("Save As");
      showSaveAs_ = false;
    }
    if (ImGui::BeginPopupModal("Save As", nullptr, ImGuiWindowFlags_AlwaysAutoResize)) {
      ImGui::InputText("file", &saveAs_);
      if (ImGui::Button("Save")) {
        report(doc_.save(saveAs_));
        ImGui::CloseCurrentPopup();
      }
      ImGui::SameLine();
      if (ImGui::Button("Cancel")) ImGui::CloseCurrentPopup();
      ImGui::EndPopup();
    }
  }

  void selectable(Selection::Kind kind, const std::string& name, std::size_t index, const std::string& label) {
    const bool on = selection_.kind == kind && selection_.name == name && selection_.index == index;
    if (ImGui::Selectable(label.c_str(), on)) selection_ = {kind, name, index};
  }

  void scenePanel() {
    ImGui::Begin("Scene");
    const dm::SceneDesc& s = doc_.scene();
    if (ImGui::TreeNodeEx("Resources", ImGuiTreeNodeFlags_DefaultOpen)) {
      for (const auto& r : s.resources)
        selectable(Selection::Resource, r.name, 0, r.name + "  (" + resourceType(r) + ")");
      ImGui::TreePop();
    }
    if (ImGui::TreeNodeEx("Materials", ImGuiTreeNodeFlags_DefaultOpen)) {
      for (const auto& m : s.materials) selectable(Selection::Material, m.name, 0, m.name);
      ImGui::TreePop();
    }
    if (ImGui::TreeNodeEx("Objects", ImGuiTreeNodeFlags_DefaultOpen)) {
      for (const auto& o : s.objects) selectable(Selection::Object, o.name, 0, o.name + (o.visible ? "" : " (hidden)"));
      ImGui::TreePop();
    }
    if (!s.volumes.empty() && ImGui::TreeNodeEx("Volume views", ImGuiTreeNodeFlags_DefaultOpen)) {
      for (const auto& v : s.volumes) selectable(Selection::Volume, v.name, 0, v.name);
      ImGui::TreePop();
    }
    if (ImGui::TreeNodeEx("Lights", ImGuiTreeNodeFlags_DefaultOpen)) {
      for (std::size_t i = 0; i < s.lights.size(); ++i)
        selectable(Selection::Light, "", i, dm::formatString("light %zu", i));
      ImGui::TreePop();
    }
    if (ImGui::TreeNodeEx("Cameras", ImGuiTreeNodeFlags_DefaultOpen)) {
      for (const auto& c : s.cameras) selectable(Selection::Camera, c.name, 0, c.name);
      ImGui::TreePop();
    }
    ImGui::Separator();
    // Place a new object: a drawable resource at the orbit's target.
    std::vector<const char*> meshes;
    for (const auto& r : s.resources)
      if (r.type != dm::SceneResource::Type::Volume && r.type != dm::SceneResource::Type::Image)
        meshes.push_back(r.name.c_str());
    if (!meshes.empty()) {
      newMesh_ = std::clamp(newMesh_, 0, static_cast<int>(meshes.size()) - 1);
      ImGui::Combo("resource", &newMesh_, meshes.data(), static_cast<int>(meshes.size()));
      ImGui::InputText("name", &newName_);
      if (ImGui::Button("Place object")) {
        dm::SceneObject o;
        o.name = newName_;
        o.mesh = meshes[static_cast<std::size_t>(newMesh_)];
        o.pose = dm::Pose(orbit_.target, dm::Quat::Identity());
        const auto s2 = doc_.addObject(o);
        report(s2);
        if (s2) selection_ = {Selection::Object, o.name, 0};
      }
    }
    ImGui::End();
  }

  void inspector() {
    ImGui::Begin("Inspector");
    const dm::SceneDesc& s = doc_.scene();
    switch (selection_.kind) {
      case Selection::None: ImGui::TextWrapped("Select a resource, material, object, volume view, light or camera."); break;
      case Selection::Resource: resourceInspector(s); break;
      case Selection::Material:
        if (const dm::SceneMaterial* m = s.material(selection_.name)) materialInspector(*m);
        break;
      case Selection::Object:
        if (const dm::SceneObject* o = s.object(selection_.name)) objectInspector(*o);
        break;
      case Selection::Volume:
        if (const dm::SceneVolume* v = s.volume(selection_.name)) volumeInspector(*v);
        break;
      case Selection::Light:
        if (selection_.index < s.lights.size()) lightInspector(s.lights[selection_.index]);
        break;
      case Selection::Camera:
        if (const dm::SceneCamera* c = s.camera(selection_.name)) {
          ImGui::Text("camera %s", c->name.c_str());
          ImGui::Text("position %.3f %.3f %.3f m", c->position.x(), c->position.y(), c->position.z());
          ImGui::Text("target   %.3f %.3f %.3f m", c->target.x(), c->target.y(), c->target.z());
          if (ImGui::Button("Look through it")) viewCamera_ = c->name;
        }
        break;
    }
    if (!error_.empty()) {
      ImGui::Separator();
      ImGui::PushStyleColor(ImGuiCol_Text, ImVec4(1.0f, 0.45f, 0.4f, 1.0f));
      ImGui::TextWrapped("%s", error_.c_str());
      ImGui::PopStyleColor();
    }
    ImGui::End();
  }

  void resourceInspector(const dm::SceneDesc& s) {
    const dm::SceneResource* r = s.resource(selection_.name);
    if (!r) return;
    ImGui::Text("%s: %s", r->name.c_str(), resourceType(*r));
    if (!r->source.empty()) ImGui::TextWrapped("source %s", r->source.c_str());
    if (auto m = resources_.mesh(r->name))
      ImGui::Text("%zu vertices, %zu triangles", m->positions.size(), m->triangleCount());
    if (auto v = resources_.volume(r->name)) {
      ImGui::Text("%d x %d x %d voxels", v->dims().x(), v->dims().y(), v->dims().z());
      if (ImGui::Button("Show slices")) volumeName_ = r->name;
    }
    if (r->type == dm::SceneResource::Type::Isosurface) ImGui::Text("level %g of %s", r->level, r->volume.c_str());
  }

  void objectInspector(dm::SceneObject o) {
    ImGui::Text("object %s", o.name.c_str());
    bool changed = false;
    Vec3 mm = 1e3 * o.pose.p;
    if (editVec3("position (mm)", mm, 0.5f, "%.1f")) o.pose.p = 1e-3 * mm, changed = true;
    Vec3 euler = o.pose.q.toRotationMatrix().eulerAngles(0, 1, 2) * (180.0 / std::numbers::pi);
    if (editVec3("rotation xyz (deg)", euler, 0.5f, "%.1f")) {
      const Vec3 r = euler * (std::numbers::pi / 180.0);
      o.pose.q = dm::AngleAxis(r.x(), Vec3::UnitX()) * dm::AngleAxis(r.y(), Vec3::UnitY()) *
                 dm::AngleAxis(r.z(), Vec3::UnitZ());
      changed = true;
    }
    changed |= editDouble("scale", o.scale, 0.01f, 1e-3, 1e3);
    changed |= ImGui::Checkbox("visible", &o.visible);
    changed |= ImGui::Checkbox("haptic (touchable)", &o.haptic);
    std::vector<const char*> names{"(default)"};
    int current = 0;
    for (const auto& m : doc_.scene().materials) {
      if (m.name == o.material) current = static_cast<int>(names.size());
      names.push_back(m.name.c_str());
    }
    if (ImGui::Combo("material", &current, names.data(), static_cast<int>(names.size()))) {
      o.material = current == 0 ? std::string() : names[static_cast<std::size_t>(current)];
      changed = true;
    }
    // Edits apply when a drag ends, so one drag is one undo step.
    if (changed) pendingObject_ = o;
    if (pendingObject_ && !ImGui::IsMouseDown(ImGuiMouseButton_Left)) {
      report(doc_.setObject(*pendingObject_));
      pendingObject_.reset();
    }
    if (ImGui::Button("Remove object")) {
      const auto st = doc_.removeObject(o.name);
      report(st);
      if (st) selection_ = {};
    }
  }

  void materialInspector(dm::SceneMaterial m) {
    ImGui::Text("material %s (%s)", m.name.c_str(), m.model == dm::SceneMaterial::Model::Pbr ? "PBR" : "Blinn-Phong");
    bool changed = editColor("colour", m.color);
    if (m.model == dm::SceneMaterial::Model::Pbr) {
      changed |= editDouble("metallic", m.metallic, 0.01f, 0, 1);
      changed |= editDouble("roughness", m.roughness, 0.01f, 0, 1);
    } else {
      changed |= editDouble("shininess", m.shininess, 1.0f, 1, 10000);
    }
    if (m.haptic) {
      ImGui::Separator();
      ImGui::TextUnformatted("haptics");
      changed |= editDouble("stiffness (N/m)", m.haptic->stiffness, 10.0f, 1, 1e5);
      changed |= editDouble("damping (N s/m)", m.haptic->damping, 0.05f, 0, 100);
      changed |= editDouble("static friction", m.haptic->staticFriction, 0.01f, 0, 2);
      changed |= editDouble("dynamic friction", m.haptic->dynamicFriction, 0.01f, 0, 2);
    } else if (ImGui::Button("Make touchable")) {
      m.haptic = dm::SceneHapticMaterial{.stiffness = 500, .damping = 0.5, .staticFriction = 0.2, .dynamicFriction = 0.1};
      changed = true;
    }
    if (changed) pendingMaterial_ = m;
    if (pendingMaterial_ && !ImGui::IsMouseDown(ImGuiMouseButton_Left)) {
      report(doc_.setMaterial(*pendingMaterial_));
      pendingMaterial_.reset();
    }
  }

  void volumeInspector(dm::SceneVolume v) {
    ImGui::Text("volume view %s of %s", v.name.c_str(), v.volume.c_str());
    bool changed = ImGui::Checkbox("visible", &v.visible);
    int mode = static_cast<int>(v.mode);
    const char* modes[] = {"composite", "mip", "slice"};
    if (ImGui::Combo("mode", &mode, modes, 3)) v.mode = static_cast<dm::SceneVolume::Mode>(mode), changed = true;
    ImGui::Separator();
    ImGui::TextUnformatted("transfer function");
    for (std::size_t i = 0; i < v.transferFunction.size(); ++i) {
      ImGui::PushID(static_cast<int>(i));
      dm::SceneTransferPoint& p = v.transferFunction[i];
      ImGui::SetNextItemWidth(80);
      changed |= editDouble("##value", p.value, 0.5f, -1e9, 1e9, "%.1f");
      ImGui::SameLine();
      changed |= editColor("##rgba", p.rgba);
      ImGui::SameLine();
      if (ImGui::SmallButton("x") && v.transferFunction.size() > 2) {
        v.transferFunction.erase(v.transferFunction.begin() + static_cast<std::ptrdiff_t>(i));
        changed = true;
        ImGui::PopID();
        break;
      }
      ImGui::PopID();
    }
    if (ImGui::Button("Add point") && !v.transferFunction.empty()) {
      dm::SceneTransferPoint p = v.transferFunction.back();
      p.value += 10;
      v.transferFunction.push_back(p);
      changed = true;
    }
    if (v.mode == dm::SceneVolume::Mode::Slice) changed |= editDouble("slice position (m)", v.slicePosition, 1e-3f, -10, 10);
    if (changed) pendingVolume_ = v;
    if (pendingVolume_ && !ImGui::IsMouseDown(ImGuiMouseButton_Left)) {
      report(doc_.setVolume(*pendingVolume_));
      pendingVolume_.reset();
    }
  }

  void lightInspector(dm::SceneLight l) {
    const char* types[] = {"directional", "point", "spot"};
    ImGui::Text("light %zu: %s", selection_.index, types[static_cast<int>(l.type)]);
    bool changed = false;
    if (l.type != dm::SceneLight::Type::Point) changed |= editVec3("direction", l.direction, 0.01f, "%.2f");
    if (l.type != dm::SceneLight::Type::Directional) changed |= editVec3("position (m)", l.position, 0.005f, "%.3f");
    changed |= editDouble("intensity", l.intensity, 0.05f, 0, 100);
    changed |= ImGui::Checkbox("shadows", &l.shadows);
    if (changed) pendingLight_ = l;
    if (pendingLight_ && !ImGui::IsMouseDown(ImGuiMouseButton_Left)) {
      report(doc_.setLight(selection_.index, *pendingLight_));
      pendingLight_.reset();
    }
  }

  void viewPanel(GLFWwindow* window) {
    ImGui::Begin("View");
    std::vector<const char*> cams{"orbit"};
    int current = 0;
    for (const auto& c : doc_.scene().cameras) {
      if (c.name == viewCamera_) current = static_cast<int>(cams.size());
      cams.push_back(c.name.c_str());
    }
    if (ImGui::Combo("camera", &current, cams.data(), static_cast<int>(cams.size())))
      viewCamera_ = current == 0 ? std::string() : cams[static_cast<std::size_t>(current)];
    const ImVec2 avail = ImGui::GetContentRegionAvail();
    const int width = std::max(16, static_cast<int>(avail.x)), height = std::max(16, static_cast<int>(avail.y));
    auto drawn = viewport_.draw(window, doc_, resources_, viewCamera_, orbit_, width, height);
    if (!drawn) {
      viewError_ = drawn.error().message();
    } else if (*drawn) {
      viewError_.clear();
      view_.upload(**drawn);
    }
    if (view_.id) {
      ImGui::Image(view_.handle(), ImVec2(static_cast<float>(view_.width), static_cast<float>(view_.height)));
      if (ImGui::IsItemHovered()) {
        const ImGuiIO& io = ImGui::GetIO();
        if (ImGui::IsMouseDragging(ImGuiMouseButton_Left)) {
          orbit_.yaw -= 0.01 * io.MouseDelta.x;
          orbit_.pitch = std::clamp(orbit_.pitch + 0.01 * io.MouseDelta.y, -1.5, 1.5);
          viewCamera_.clear();
        }
        if (ImGui::IsMouseDragging(ImGuiMouseButton_Right)) {
          const dm::Camera c = orbit_.camera();
          const Vec3 right = c.right(), up = right.cross(c.forward());
          orbit_.target += orbit_.distance * 0.002 * (-io.MouseDelta.x * right + io.MouseDelta.y * up);
          viewCamera_.clear();
        }
        if (io.MouseWheel != 0) orbit_.distance *= std::pow(0.9, io.MouseWheel);
      }
    }
    if (!viewError_.empty()) ImGui::TextWrapped("%s", viewError_.c_str());
    ImGui::End();
  }

  void volumePanel() {
    ImGui::Begin("Volume");
    std::vector<const char*> names;
    int current = 0;
    for (const auto& [name, v] : resources_.volumes) {
      if (name == volumeName_) current = static_cast<int>(names.size());
      names.push_back(name.c_str());
    }
    if (names.empty()) {
      ImGui::TextDisabled("no volume resource");
      ImGui::End();
      return;
    }
    ImGui::Combo("volume", &current, names.data(), static_cast<int>(names.size()));
    volumeName_ = names[static_cast<std::size_t>(current)];
    const auto v = resources_.volume(volumeName_);
    const char* axes[] = {"sagittal (x)", "coronal (y)", "axial (z)"};
    ImGui::Combo("axis", &sliceAxis_, axes, 3);
    const int n = v->dims()[sliceAxis_];
    if (sliceIndex_ < 0) sliceIndex_ = n / 2;
    ImGui::SliderInt("slice", &sliceIndex_, 0, n - 1);
    const std::string key = volumeName_ + std::to_string(sliceAxis_) + "/" + std::to_string(sliceIndex_);
    if (key != sliceKey_) {
      const auto [lo, hi] = v->range();
      auto img = dm::volumeSlice(*v, sliceAxis_, sliceIndex_, lo, hi > lo ? hi : lo + 1);
      if (img) slice_.upload(*img);
      sliceKey_ = key;
    }
    if (slice_.id) {
      const float s = std::min(ImGui::GetContentRegionAvail().x / static_cast<float>(slice_.width),
                               ImGui::GetContentRegionAvail().y / static_cast<float>(slice_.height));
      ImGui::Image(slice_.handle(), ImVec2(slice_.width * std::max(s, 0.1f), slice_.height * std::max(s, 0.1f)));
    }
    ImGui::End();
  }

  dmedit::SceneDocument doc_;
  dm::SceneResources resources_;
  Viewport viewport_;
  Selection selection_;
  Orbit orbit_;
  Texture view_, slice_;
  std::string viewCamera_, viewError_, error_, volumeName_, sliceKey_, saveAs_, newName_ = "new_object";
  int sliceAxis_ = 2, sliceIndex_ = -1, newMesh_ = 0;
  bool quit_ = false, showSaveAs_ = false, saveKeyHeld_ = false;
  std::optional<dm::SceneObject> pendingObject_;
  std::optional<dm::SceneMaterial> pendingMaterial_;
  std::optional<dm::SceneVolume> pendingVolume_;
  std::optional<dm::SceneLight> pendingLight_;
};

int fail(const std::string& message) {
  std::cerr << "dmedit: " << message << '\n';
  return 1;
}

// The bundled default scene: next to the installed binary or in the source
// tree this was built from (DM_SOURCE_SCENES_DIR, relative to the built
// binary's folder).
fs::path defaultScene() {
  std::error_code ec;
  const auto exe = fs::canonical("/proc/self/exe", ec);
  if (ec) return fs::path(DM_SOURCE_SCENES_DIR) / "head_probe.json";
  const auto installed = exe.parent_path().parent_path() / "share" / "dmplatform" / "scenes" / "head_probe.json";
  if (fs::exists(installed, ec)) return installed;
  return (exe.parent_path() / DM_SOURCE_SCENES_DIR / "head_probe.json").lexically_normal();
}

int run(const Options& o) {
  int width = 0, height = 0;
  if (std::sscanf(o.size.c_str(), "%dx%d", &width, &height) != 2 || width < 320 || height < 240 || width > 8192 ||
      height > 8192)
    return fail("--size " + o.size + ": expected WxH, at least 320x240");
  auto doc = dmedit::SceneDocument::open(o.scene.empty() ? defaultScene() : fs::path(o.scene));
  if (!doc) return fail(doc.error().message());
  std::fprintf(stderr, "dmedit: loading the resources of %s\n", doc->file().string().c_str());
  auto resources = dm::loadSceneResources(doc->scene());
  if (!resources) return fail(resources.error().message());
  auto egl = dm::GlContext::create();
  if (!egl) return fail(egl.error().message());
  (*egl)->release();

  glfwSetErrorCallback([](int code, const char* text) { std::fprintf(stderr, "dmedit: GLFW %d: %s\n", code, text); });
  if (!glfwInit()) return fail("GLFW could not initialize (is DISPLAY set? run under Xvfb for a headless machine)");
  glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
  glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
  glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
  GLFWwindow* window = glfwCreateWindow(width, height, "dmedit", nullptr, nullptr);
  if (!window) {
    glfwTerminate();
    return fail("no window with an OpenGL 3.3 core context");
  }
  glfwMakeContextCurrent(window);
  glfwSwapInterval(o.screenshot.empty() ? 1 : 0);
  IMGUI_CHECKVERSION();
  ImGui::CreateContext();
  ImGui::GetIO().IniFilename = nullptr;  // layout from code, nothing written next to the user's files
  ImGui::StyleColorsDark();
  ImGui_ImplGlfw_InitForOpenGL(window, true);
  ImGui_ImplOpenGL3_Init("#version 330");

  int status = 0;
  {
    Editor editor(std::move(*doc), std::move(*resources), Viewport(std::move(*egl)));
    for (int frame = 0; !glfwWindowShouldClose(window); ++frame) {
      glfwPollEvents();
      ImGui_ImplOpenGL3_NewFrame();
      ImGui_ImplGlfw_NewFrame();
      ImGui::NewFrame();
      const bool keep = editor.frame(window);
      ImGui::Render();
      int fw = 0, fh = 0;
      glfwGetFramebufferSize(window, &fw, &fh);
      glViewport(0, 0, fw, fh);
      glClearColor(0.1f, 0.1f, 0.12f, 1.0f);
      glClear(GL_COLOR_BUFFER_BIT);
      ImGui_ImplOpenGL3_RenderDrawData(ImGui::GetDrawData());
      if (!o.screenshot.empty() && frame + 1 >= o.frames) {
        auto shot = dm::Image::create(fw, fh, 3, dm::PixelType::U8);
        if (!shot) {
          status = fail(shot.error().message());
          break;
        }
        std::vector<std::uint8_t> rows(static_cast<std::size_t>(fw) * fh * 3);
        glPixelStorei(GL_PACK_ALIGNMENT, 1);
        glReadPixels(0, 0, fw, fh, GL_RGB, GL_UNSIGNED_BYTE, rows.data());
        for (int y = 0; y < fh; ++y)  // GL rows bottom-up
          std::copy_n(rows.data() + static_cast<std::size_t>(fh - 1 - y) * fw * 3, static_cast<std::size_t>(fw) * 3,
                      reinterpret_cast<std::uint8_t*>(shot->row(y)));
        if (auto s = dm::writePng(*shot, o.screenshot); !s) status = fail(s.error().message());
        else std::fprintf(stderr, "dmedit: wrote %s (%dx%d)\n", o.screenshot.c_str(), fw, fh);
        break;
      }
      glfwSwapBuffers(window);
      if (!keep) break;
    }
    editor.close();
  }
  ImGui_ImplOpenGL3_Shutdown();
  ImGui_ImplGlfw_Shutdown();
  ImGui::DestroyContext();
  glfwDestroyWindow(window);
  glfwTerminate();
  return status;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{"dmedit: the DMPlatform scene and resource editor"};
  app.add_option("scene", o.scene, "Scene file (default: the bundled head_probe.json)");
  app.add_option("--size", o.size, "Window size WxH (default 1280x800)");
  app.add_option("--screenshot", o.screenshot, "Draw --frames frames, write the window to this PNG and exit");
  app.add_option("--frames", o.frames, "Frames before the screenshot (default 5)")->check(CLI::Range(1, 10000));
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  return run(o);
}
