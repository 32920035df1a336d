// scene_fluids.cpp — the scene's particle fluids, stepped by the physics
// engine (scene_fluids.hpp).
#include "scene_fluids.hpp"

#include <dm/io/scene_file.hpp>
#include <dm/io/scene_resources.hpp>
#include <dm/math/mesh_topology.hpp>
#include <dm/physics/fluid_sources.hpp>
#include <dm/physics/sph_boundary.hpp>
#include <dm/physics/sph_fluid.hpp>

#include <algorithm>
#include <string>
#include <vector>

#include "soft_tissue.hpp"

namespace dm {

namespace {

bool open(double t, double start, const std::optional<double>& stop) {
  return t >= start && (!stop || t < *stop);
}

}  // namespace

struct SceneFluids::Impl {
  struct Inlet {
    const SceneFluidInlet* desc;
    FluidInlet inlet;
  };
  struct Tip {
    const SceneFluidSuction* desc;
    FluidSuction suction;
  };
  struct Body {             // a dynamic body the fluid pushes and is pushed by
    std::size_t link = 0;   // in the physics engine's FluidBody list
    std::size_t rigid = 0;  // in the fluid
  };
  struct Tissue {             // a soft object the fluid flows around
    std::size_t soft = 0;     // in SoftTissues
    std::size_t surface = 0;  // in the fluid
    std::vector<Vec3> x, v;   // its nodes in the world, this tick
  };
  struct Fluid {
    const SceneFluid* desc;
    SphFluid fluid;
    FluidRegion region;
    std::vector<Inlet> inlets;
    std::vector<Tip> tips;
    std::vector<Tissue> tissues;
    std::vector<Body> bodies;
    std::unique_ptr<TripleBuffer<std::vector<Vec3>>> drawn;  // positions, physics → render
    bool firstRead = true;
    std::size_t start = 0;  // particles at the start
    std::uint64_t steps = 0;
    double worstDensityError = 0.0;
  };
  std::vector<Fluid> fluids;
  TripleBuffer<FluidToolSample> tool;
  SoftTissues* soft = nullptr;
  std::vector<FluidBody>* links = nullptr;

  static Status addObjects(Fluid& out, const SceneDesc& scene, const SceneResources& resources,
                           const SoftTissues& soft, std::vector<FluidBody>& links, std::vector<Mesh>& solids);
};

// A fluid's "objects" as its boundaries (scene_fluids.hpp).
// `solids` gets each object's surface in the world (what blocks leave out).
Status SceneFluids::Impl::addObjects(Fluid& out, const SceneDesc& scene, const SceneResources& resources,
                                     const SoftTissues& soft, std::vector<FluidBody>& links,
                                     std::vector<Mesh>& solids) {
  const double d = out.desc->spacing;
  for (std::size_t k = 0; k < out.desc->objects.size(); ++k) {
    const std::string& name = out.desc->objects[k];
    const std::string where = "fluids/" + out.desc->name + "/objects/" + std::to_string(k);
    const SceneObject* o = scene.object(name);
    if (o == nullptr) return fail(ErrorCode::NotFound, "no object \"" + name + "\"", where);
    if (o->soft) {
      const auto& names = soft.names();
      const auto it = std::find(names.begin(), names.end(), name);
      if (it == names.end())
        return fail(ErrorCode::NotFound, "soft object \"" + name + "\" was not built", where);
      Tissue t{.soft = std::size_t(it - names.begin())};
      soft.worldNodes(t.soft, t.x, t.v);
      Mesh mesh;
      mesh.positions = t.x;
      mesh.triangles = soft.boundaryTriangles(t.soft);
      auto samples = BoundarySurface::create(mesh, 0.5 * d, d / 3.0);
      if (!samples) return samples.error().within(where);
      auto id = out.fluid.addSurfaceBoundary(std::move(*samples), t.x);
      if (!id) return id.error().within(where);
      t.surface = *id;
      out.tissues.push_back(std::move(t));
      solids.push_back(std::move(mesh));
      continue;
    }
    auto resource = resources.mesh(o->mesh);
    if (!resource) return fail(ErrorCode::NotFound, "mesh \"" + o->mesh + "\" was not loaded", where);
    Mesh mesh = *resource;
    for (Vec3& p : mesh.positions) p *= o->scale;
    if (o->dynamic) {
      const auto link =
          std::find_if(links.begin(), links.end(), [&](const FluidBody& b) { return b.object == name; });
      if (link == links.end())
        return fail(ErrorCode::NotFound, "dynamic object \"" + name + "\" has no body", where);
      for (Vec3& p : mesh.positions) p = link->objectInBody * p;  // into the body frame
      auto samples = sampleBoundary(mesh, d, d / 3.0);
      if (!samples) return samples.error().within(where);
      auto rigid = out.fluid.addRigidBoundary(*samples, link->pose);
      if (!rigid) return rigid.error().within(where);
      out.bodies.push_back({std::size_t(link - links.begin()), *rigid});
      for (Vec3& p : mesh.positions) p = link->pose * p;
    } else {
      const Isometry3 pose = o->pose.isometry();
      for (Vec3& p : mesh.positions) p = pose * p;
      auto samples = sampleBoundary(mesh, 0.5 * d, d / 3.0);
      if (!samples) return samples.error().within(where);
      out.fluid.addBoundaryParticles(*samples);
    }
    solids.push_back(std::move(mesh));
  }
  return ok();
}

SceneFluids::SceneFluids(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
SceneFluids::~SceneFluids() = default;

Result<std::unique_ptr<SceneFluids>> SceneFluids::build(const SceneDesc& scene,
                                                        const SceneResources& resources, SoftTissues& soft,
                                                        std::vector<FluidBody>& bodies) {
  auto m = std::make_unique<Impl>();
  m->soft = &soft;
  m->links = &bodies;
  const Vec3 gravity = scene.engines.physics ? scene.engines.physics->gravity : Vec3(0, 0, -9.81);
  m->fluids.reserve(scene.fluids.size());
  for (const SceneFluid& f : scene.fluids) {
    const std::string where = "fluids/" + f.name;
    auto fluid = SphFluid::create({.particleSpacing = f.spacing,
                                   .restDensity = f.density,
                                   .viscosity = f.viscosity,
                                   .surfaceTension = f.surfaceTension,
                                   .gravity = gravity});
    if (!fluid) return fluid.error().within(where);
    auto region = FluidRegion::create(f.region.min, f.region.max);
    if (!region) return region.error().within(where + "/region");
    Impl::Fluid out{&f, std::move(*fluid), *region, {}, {}};
    if (f.container) out.fluid.addBoxBoundary(f.container->min, f.container->max);
    std::vector<Mesh> solids;
    if (auto s = Impl::addObjects(out, scene, resources, soft, bodies, solids); !s) return s.error();
    for (const SceneBox& b : f.blocks) out.fluid.addBlock(b.min, b.max);
    if (!solids.empty()) {  // no fluid inside the objects it flows around (bounds first)
      std::vector<Aabb> bounds;
      for (const Mesh& solid : solids) {
        Aabb& box = bounds.emplace_back();
        for (const Vec3& p : solid.positions) box.extend(p);
      }
      out.fluid.removeIf([&](const Vec3& x) {
        for (std::size_t k = 0; k < solids.size(); ++k)
          if (bounds[k].contains(x) && windingNumber(solids[k], x) > 0.5) return true;
        return false;
      });
    }
    out.start = out.fluid.size();
    const std::vector<Vec3> at0(out.fluid.positions().begin(), out.fluid.positions().end());
    out.drawn = std::make_unique<TripleBuffer<std::vector<Vec3>>>(at0);
    for (const SceneFluidInlet& in : f.inlets) {
      auto inlet = FluidInlet::create({.center = in.center,
                                       .normal = in.normal,
                                       .radius = in.radius,
                                       .flowRate = in.flowRate,
                                       .drivingPressure = in.pressure},
                                      out.fluid);
      if (!inlet) return inlet.error().within(where + "/inlets/" + in.name);
      out.inlets.push_back({&in, std::move(*inlet)});
    }
    for (const SceneFluidSuction& s : f.suction) {
      auto tip = FluidSuction::create({.center = s.center, .radius = s.radius, .maxFlowRate = s.flowRate});
      if (!tip) return tip.error().within(where + "/suction/" + s.name);
      out.tips.push_back({&s, std::move(*tip)});
    }
    m->fluids.push_back(std::move(out));
  }
  return std::unique_ptr<SceneFluids>(new SceneFluids(std::move(m)));
}

bool SceneFluids::empty() const noexcept { return impl_->fluids.empty(); }

TripleBuffer<FluidToolSample>& SceneFluids::toolFeed() noexcept { return impl_->tool; }

Status SceneFluids::step(double t, double dt) {
  Impl& m = *impl_;
  for (FluidBody& b : *m.links) b.force = b.torque = Vec3::Zero();
  m.tool.update();
  const FluidToolSample& tool = m.tool.readBuffer();
  for (Impl::Fluid& f : m.fluids) {
    const double reach = f.desc->spacing;
    for (Impl::Inlet& in : f.inlets) {
      if (!open(t, in.desc->start, in.desc->stop)) continue;
      double pressed = 0.0;
      if (tool.valid && (tool.proxy - in.desc->center).norm() <= in.desc->radius + reach)
        pressed = tool.force.norm() / in.inlet.outletArea();
      in.inlet.setAppliedPressure(pressed);
      in.inlet.emit(f.fluid, dt);
    }
    for (Impl::Tip& tip : f.tips) {
      if (!open(t, tip.desc->start, tip.desc->stop)) continue;
      if (tip.desc->atTool) {
        if (!tool.valid) continue;
        tip.suction.setCenter(tool.proxy);
      }
      tip.suction.apply(f.fluid, dt);
    }
    f.region.apply(f.fluid);
    for (Impl::Tissue& tissue : f.tissues) {  // where the FEM step left them
      m.soft->worldNodes(tissue.soft, tissue.x, tissue.v);
      if (auto s = f.fluid.setSurfaceState(tissue.surface, tissue.x, tissue.v); !s)
        return s.error().within("fluids/" + f.desc->name);
    }
    for (const Impl::Body& b : f.bodies) {  // where the world's step left them
      const FluidBody& link = (*m.links)[b.link];
      if (auto s = f.fluid.setRigidState(b.rigid, link.pose, link.linearVelocity, link.angularVelocity); !s)
        return s.error().within("fluids/" + f.desc->name);
    }
    if (auto s = f.fluid.step(dt); !s) return s.error().within("fluids/" + f.desc->name);
    for (const Impl::Tissue& tissue : f.tissues)  // held on the FEM nodes over the next steps
      m.soft->setFluidLoads(tissue.soft, f.fluid.surfaceLoads(tissue.surface));
    for (const Impl::Body& b : f.bodies) {
      FluidBody& link = (*m.links)[b.link];
      link.force += f.fluid.rigidLoad(b.rigid).force;
      link.torque += f.fluid.rigidLoad(b.rigid).torque;
    }
    std::vector<Vec3>& drawn = f.drawn->writeBuffer();  // grows to the high-water mark
    drawn.assign(f.fluid.positions().begin(), f.fluid.positions().end());
    f.drawn->publish();
    ++f.steps;
    f.worstDensityError = std::max(f.worstDensityError, f.fluid.lastStep().maxDensityError);
  }
  return ok();
}

std::size_t SceneFluids::size() const noexcept { return impl_->fluids.size(); }

void SceneFluids::setInletFlowRate(std::size_t k, double m3PerSecond) {
  for (Impl::Fluid& f : impl_->fluids) {
    if (k < f.inlets.size()) {
      f.inlets[k].inlet.setFlowRate(m3PerSecond);
      return;
    }
    k -= f.inlets.size();
  }
}

bool SceneFluids::latestParticles(std::size_t i, std::vector<Vec3>& out) {
  Impl::Fluid& f = impl_->fluids.at(i);
  const bool fresh = f.drawn->update() || f.firstRead;
  f.firstRead = false;
  if (fresh) out = f.drawn->readBuffer();
  return fresh;
}

nlohmann::json SceneFluids::summary() const {
  nlohmann::json list = nlohmann::json::array();
  for (const Impl::Fluid& f : impl_->fluids) {
    const double volume = f.fluid.particleMass() / f.desc->density;
    nlohmann::json inlets = nlohmann::json::array(), tips = nlohmann::json::array();
    std::size_t emitted = 0, taken = 0;
    for (const Impl::Inlet& in : f.inlets) {
      emitted += in.inlet.emittedParticles();
      inlets.push_back({{"name", in.desc->name},
                        {"particles", in.inlet.emittedParticles()},
                        {"volume_m3", in.inlet.emittedVolume()},
                        {"last_flow_rate_m3_s", in.inlet.lastFlowRate()}});
    }
    for (const Impl::Tip& tip : f.tips) {
      taken += tip.suction.removedParticles();
      tips.push_back({{"name", tip.desc->name},
                      {"particles", tip.suction.removedParticles()},
                      {"volume_m3", double(tip.suction.removedParticles()) * volume}});
    }
    const std::size_t left = f.region.removedParticles();
    Vec3 centre = Vec3::Zero();
    for (const Vec3& x : f.fluid.positions()) centre += x;
    if (f.fluid.size() > 0) centre /= double(f.fluid.size());
    list.push_back({{"name", f.desc->name},
                    {"steps", f.steps},
                    {"particles", f.fluid.size()},
                    {"mass_kg", f.fluid.mass()},
                    {"particle_volume_m3", volume},
                    {"start_particles", f.start},
                    {"left_region_particles", left},
                    {"inlets", std::move(inlets)},
                    {"suction", std::move(tips)},
                    {"max_density_error", f.worstDensityError},
                    {"center_of_mass_m", {centre.x(), centre.y(), centre.z()}},
                    {"boundary_objects", f.desc->objects},
                    // start + emitted − taken − left = particles, always
                    {"balanced", f.start + emitted == f.fluid.size() + taken + left}});
  }
  return list;
}

}  // namespace dm
