// haptics.cpp — haptic rendering for Python: the god-object renderer over
// meshes (dm::GodObjectRenderer) and dmtool probe's vps, sphere-tree and
// burr renderers over a mesh or a volume (dm/haptics/probe_renderers.hpp,
// built as dmtool builds them), ticked one device pose at a time, and
// dmtool probe as a function — a device path (a CSV file or an array of
// rows t, x, y, z[, qw, qx, qy, qz]) replayed through a renderer in
// lockstep (dm::replayDevicePath) into a structured array with forces.csv's
// columns, optionally written as that CSV (the bytes dmtool probe writes).
#include <dm/collide/bvh.hpp>
#include <dm/collide/millable_volume.hpp>
#include <dm/core/filesystem.hpp>
#include <dm/haptics/god_object.hpp>
#include <dm/haptics/probe.hpp>
#include <dm/haptics/probe_renderers.hpp>
#include <dm/io/device_path.hpp>

#include <pybind11/numpy.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "arrays.hpp"
#include "bindings.hpp"

namespace dm::python {

namespace {

// A renderer and what it was built over (the trees stay alive with it).
struct PyRenderer {
  std::unique_ptr<HapticRenderer> renderer;
  GodObjectRenderer* godObject = nullptr;
  std::vector<std::shared_ptr<const MeshBvh>> trees;
  std::shared_ptr<MillableVolume> bone;  // burr: the bone it drills
};

// The environment of dmtool probe's renderers: a Mesh or a Volume.
ProbeEnvironment environmentOf(const py::object& model) {
  if (py::isinstance<Mesh>(model)) return {.mesh = &model.cast<const Mesh&>()};
  if (py::isinstance<Volume>(model)) return {.volume = &model.cast<const Volume&>()};
  raise(fail(ErrorCode::InvalidArgument, "expected a Mesh or a Volume", "model",
             "read one with read_mesh or read_volume, or make one (isosurface, phantom)"));
}

// The material, tool and threshold shared by vps, sphere_tree and burr, checked.
ProbeRendererOptions probeOptions(double stiffness, double damping, double staticFriction,
                                  double dynamicFriction, double toolRadius,
                                  const py::object& tool = py::none(),
                                  const py::object& threshold = py::none()) {
  ProbeRendererOptions o;
  o.material = {.stiffness = stiffness,
                .damping = damping,
                .staticFriction = staticFriction,
                .dynamicFriction = dynamicFriction};
  unwrap(o.material.validate("stiffness/damping/friction"));
  if (!(toolRadius >= 0.0 && toolRadius <= 1.0))
    raise(fail(ErrorCode::InvalidArgument, formatString("tool_radius %g m is outside [0, 1]", toolRadius),
               "tool_radius"));
  o.toolRadius = toolRadius;
  if (!tool.is_none()) o.tool = &tool.cast<const Mesh&>();
  if (!threshold.is_none()) o.threshold = threshold.cast<double>();
  return o;
}

std::shared_ptr<PyRenderer> wrap(Result<std::unique_ptr<HapticRenderer>> r) {
  auto out = std::make_shared<PyRenderer>();
  out->renderer = unwrap(std::move(r));
  return out;
}

py::array_t<double> poseArray(const Isometry3& pose) { return arrayOf(Mat4(pose.matrix())); }

// A device pose: a 4x4 rigid matrix or a position (3 numbers).
Isometry3 devicePoseOf(const py::object& o) {
  const auto a = py::array::ensure(o);
  if (a && a.ndim() == 2) return poseOf(o, "pose");
  Isometry3 pose = Isometry3::Identity();
  pose.translation() = vec3Of(o, "pose");
  return pose;
}

// A device path from a CSV file or an (n, 4) / (n, 8) array of rows t, x,
// y, z[, qw, qx, qy, qz]; an array goes through the CSV parser, so both get
// the same checks (increasing time, finite values, unit quaternions).
DevicePath devicePathOf(const py::object& o) {
  if (py::isinstance<py::str>(o) || py::hasattr(o, "__fspath__"))
    return unwrap(readDevicePathCsv(o.cast<std::filesystem::path>()));
  const auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(o);
  if (!a || a.ndim() != 2 || (a.shape(1) != 4 && a.shape(1) != 8))
    raise(fail(ErrorCode::InvalidArgument, "expected a CSV file or an (n, 4) or (n, 8) array", "path",
               "rows t, x, y, z (s, m) and optionally qw, qx, qy, qz"));
  std::string csv = a.shape(1) == 4 ? "t,x,y,z\n" : "t,x,y,z,qw,qx,qy,qz\n";
  for (py::ssize_t r = 0; r < a.shape(0); ++r) {
    for (py::ssize_t c = 0; c < a.shape(1); ++c) csv += formatString(c == 0 ? "%.17g" : ",%.17g", a.at(r, c));
    csv += '\n';
  }
  return unwrap(parseDevicePathCsv(csv, "path"));
}

// forces.csv's columns (dm::formatProbeCsv), as read_forces() reads them.
py::array samplesArray(const std::vector<ProbeSample>& samples) {
  py::list fields;
  for (const char* name : {"t", "fx", "fy", "fz", "tx", "ty", "tz", "px", "py", "pz", "qw", "qx", "qy", "qz"})
    fields.append(py::make_tuple(name, "<f8"));
  fields.append(py::make_tuple("contacts", "<i8"));
  fields.append(py::make_tuple("penetration", "<f8"));
  const py::dtype dtype = py::dtype::from_args(fields);
  py::array out(dtype, std::vector<py::ssize_t>{py::ssize_t(samples.size())}, std::vector<py::ssize_t>{});
  struct Row {
    double v[14];
    std::int64_t contacts;
    double penetration;
  };
  static_assert(sizeof(Row) == 16 * 8);
  auto* rows = static_cast<Row*>(out.mutable_data());
  for (std::size_t i = 0; i < samples.size(); ++i) {
    const ProbeSample& s = samples[i];
    const Quat q(s.response.proxyPose.rotation());
    const Vec3 p = s.response.proxyPose.translation();
    const double v[14] = {s.t,
                          s.response.force.x(),
                          s.response.force.y(),
                          s.response.force.z(),
                          s.response.torque.x(),
                          s.response.torque.y(),
                          s.response.torque.z(),
                          p.x(),
                          p.y(),
                          p.z(),
                          q.w(),
                          q.x(),
                          q.y(),
                          q.z()};
    std::copy(std::begin(v), std::end(v), rows[i].v);
    rows[i].contacts = s.response.contacts;
    rows[i].penetration = s.response.penetration;
  }
  return out;
}

}  // namespace

void bindHaptics(py::module_& m) {
  py::class_<HapticResponse>(m, "HapticResponse", "What a renderer answered for one tick (world frame).")
      .def_property_readonly(
          "force", [](const HapticResponse& r) { return arrayOf(r.force); }, "N, on the user's hand.")
      .def_property_readonly(
          "torque", [](const HapticResponse& r) { return arrayOf(r.torque); }, "N·m, about the device point.")
      .def_property_readonly(
          "proxy", [](const HapticResponse& r) { return poseArray(r.proxyPose); },
          "4x4 pose of the proxy / tool, where it is drawn.")
      .def_readonly("contacts", &HapticResponse::contacts, "Active constraints or penetrating points.")
      .def_readonly("penetration", &HapticResponse::penetration, "m: how far the device is inside.")
      .def("__repr__", [](const HapticResponse& r) {
        return formatString("<dmplatform.HapticResponse |F| = %.4g N, %d contacts>", r.force.norm(),
                            r.contacts);
      });

  py::class_<PyRenderer, std::shared_ptr<PyRenderer>>(
      m, "HapticRenderer", "A haptic rendering method, ticked from Python one device sample at a time.")
      .def_property_readonly("name", [](const PyRenderer& r) { return std::string(r.renderer->name()); })
      .def_property_readonly("object_count", [](const PyRenderer& r) { return r.renderer->objectCount(); })
      .def(
          "reset", [](PyRenderer& r, const py::object& pose) { r.renderer->reset(devicePoseOf(pose)); },
          py::arg("pose"), "Puts the proxy at the device pose (4x4, or a position) and clears history.")
      .def(
          "tick",
          [](PyRenderer& r, const py::object& pose, const py::object& velocity, double dt) {
            if (!(dt > 0.0) || !std::isfinite(dt))
              raise(fail(ErrorCode::InvalidArgument, formatString("dt %g s", dt), "dt",
                         "a positive time step"));
            HapticInput in;
            in.dt = dt;
            in.devicePose = devicePoseOf(pose);
            if (!velocity.is_none()) in.linearVelocity = vec3Of(velocity, "velocity");
            return r.renderer->tick(in);
          },
          py::arg("pose"), py::arg("velocity") = py::none(), py::arg("dt") = 1e-3,
          "One haptic tick at the device pose (4x4, or a position; world, m) moving at `velocity` (m/s).")
      .def(
          "set_object_pose",
          [](PyRenderer& r, std::size_t i, const py::object& pose) {
            if (i >= r.renderer->objectCount())
              raise(fail(ErrorCode::InvalidArgument,
                         "object " + std::to_string(i) + " of " + std::to_string(r.renderer->objectCount()),
                         "index"));
            r.renderer->setObjectPose(i, poseOf(pose, "pose"));
          },
          py::arg("index"), py::arg("pose"), "Moves object `index` (a rigid 4x4 pose) before the next tick.")
      .def_property_readonly(
          "contact",
          [](const PyRenderer& r) -> py::object {
            if (r.godObject == nullptr || !r.godObject->contact().active) return py::none();
            const GodObjectContact& c = r.godObject->contact();
            py::dict d;
            d["object"] = c.object;
            d["triangle"] = c.triangle;
            d["point"] = arrayOf(c.point);
            d["normal"] = arrayOf(c.normal);
            return d;
          },
          "The god-object's contact of the last tick (object, triangle, point, normal), or None.")
      .def_property_readonly(
          "removed_volume",
          [](const PyRenderer& r) -> py::object {
            if (!r.bone) return py::none();
            return py::float_(r.bone->removedVolume(0));
          },
          "A burr's: m³ of bone drilled away so far; None for other renderers.")
      .def(
          "bone_occupancy",
          [](const PyRenderer& r) -> py::object {
            if (!r.bone) return py::none();
            return py::cast(std::make_shared<Volume>(unwrap(r.bone->occupancyVolume())));
          },
          "A burr's: the drilled bone as a Volume of occupancies in [0, 1] (isosurface at 0.5 for its "
          "surface); "
          "None for other renderers.");

  m.def(
      "god_object",
      [](const py::list& objects, double stiffness, double damping, double staticFriction,
         double dynamicFriction, double proxyRadius, bool forceShading, double maxForce,
         const py::object& poses) {
        auto out = std::make_shared<PyRenderer>();
        std::vector<GodObjectObject> list;
        for (std::size_t i = 0; i < objects.size(); ++i) {
          const py::handle o = objects[i];
          GodObjectObject g;
          if (py::isinstance<MeshBvh>(o)) {
            g.bvh = o.cast<std::shared_ptr<MeshBvh>>();
          } else if (py::isinstance<Mesh>(o)) {
            const Mesh& mesh = o.cast<const Mesh&>();
            g.bvh = std::make_shared<const MeshBvh>(unwrap(released([&] { return MeshBvh::build(mesh); })));
          } else {
            raise(fail(ErrorCode::InvalidArgument, "expected a Mesh or a MeshTree",
                       "objects[" + std::to_string(i) + "]"));
          }
          if (!poses.is_none()) g.pose = poseOf(poses.cast<py::list>()[i], "poses");
          g.material = {.stiffness = stiffness,
                        .damping = damping,
                        .staticFriction = staticFriction,
                        .dynamicFriction = dynamicFriction};
          out->trees.push_back(g.bvh);
          list.push_back(std::move(g));
        }
        if (!poses.is_none() && poses.cast<py::list>().size() != objects.size())
          raise(fail(ErrorCode::InvalidArgument, "one pose per object", "poses"));
        auto r = unwrap(GodObjectRenderer::create(
            std::move(list),
            {.proxyRadius = proxyRadius, .forceShading = forceShading, .maxForce = maxForce}));
        out->godObject = r.get();
        out->renderer = std::move(r);
        return out;
      },
      py::arg("objects"), py::arg("stiffness") = 1000.0, py::arg("damping") = 0.0,
      py::arg("static_friction") = 0.0, py::arg("dynamic_friction") = 0.0, py::arg("proxy_radius") = 0.0,
      py::arg("force_shading") = false, py::arg("max_force") = std::numeric_limits<double>::infinity(),
      py::arg("poses") = py::none(),
      "The god-object renderer (a 3-DOF proxy, or a ball tip of proxy_radius) over meshes or MeshTrees at "
      "their poses (4x4 each; None: identity), one haptic material for all (N/m, N·s/m, friction "
      "coefficients); as `dmtool probe --renderer godobject` builds it.");

  m.def(
      "vps",
      [](const py::object& model, double stiffness, double damping, double staticFriction,
         double dynamicFriction, const py::object& tool, double toolRadius, const py::object& threshold,
         double voxelSize) {
        ProbeRendererOptions o =
            probeOptions(stiffness, damping, staticFriction, dynamicFriction, toolRadius, tool, threshold);
        if (!(voxelSize >= 0.0 && voxelSize <= 1.0))
          raise(fail(ErrorCode::InvalidArgument, formatString("voxel_size %g m is outside [0, 1]", voxelSize),
                     "voxel_size"));
        o.voxelSize = voxelSize;
        const ProbeEnvironment env = environmentOf(model);
        return wrap(released([&] { return makeVpsProbe(env, o); }));
      },
      py::arg("model"), py::arg("stiffness") = 1000.0, py::arg("damping") = 0.0,
      py::arg("static_friction") = 0.0, py::arg("dynamic_friction") = 0.0, py::arg("tool") = py::none(),
      py::arg("tool_radius") = 0.0, py::arg("threshold") = py::none(), py::arg("voxel_size") = 0.0,
      "The voxel point shell renderer (6-DOF): the tool (a Mesh, or a ball of tool_radius, default 2 mm) "
      "sampled into a point shell against the model — a Volume's occupancy above `threshold`, a signed "
      "distance Volume without one, or a Mesh voxelized at voxel_size (default: its largest extent / 128); "
      "the hand feels a virtual coupling of `stiffness` in series with a contact ten times stiffer. As "
      "`dmtool probe --renderer vps` builds it.");

  m.def(
      "sphere_tree",
      [](const py::object& model, double stiffness, double damping, double staticFriction,
         double dynamicFriction, const py::object& tool, double toolRadius, const py::object& threshold,
         int levels, int toolLevel) {
        ProbeRendererOptions o =
            probeOptions(stiffness, damping, staticFriction, dynamicFriction, toolRadius, tool, threshold);
        if (levels < 2 || levels > 10)
          raise(fail(ErrorCode::InvalidArgument, formatString("levels %d is outside [2, 10]", levels),
                     "levels"));
        if (toolLevel < 1 || toolLevel > 8)
          raise(fail(ErrorCode::InvalidArgument, formatString("tool_level %d is outside [1, 8]", toolLevel),
                     "tool_level"));
        o.levels = levels;
        o.toolLevel = toolLevel;
        const ProbeEnvironment env = environmentOf(model);
        return wrap(released([&] { return makeSphereTreeProbe(env, o); }));
      },
      py::arg("model"), py::arg("stiffness") = 1000.0, py::arg("damping") = 0.0,
      py::arg("static_friction") = 0.0, py::arg("dynamic_friction") = 0.0, py::arg("tool") = py::none(),
      py::arg("tool_radius") = 0.0, py::arg("threshold") = py::none(), py::arg("levels") = 6,
      py::arg("tool_level") = 4,
      "The 6-DOF sphere-tree renderer: octree sphere trees of the model (a Mesh, or a Volume solid above "
      "`threshold`; `levels` deep) and of the tool (a Mesh, or a ball of tool_radius, default 2 mm; "
      "colliding "
      "at tool_level), the tool held out by constraints. As `dmtool probe --renderer spheretree` builds it.");

  m.def(
      "burr",
      [](const Volume& volume, double stiffness, double damping, double toolRadius, const py::object& rpm,
         const py::object& boneRange) {
        ProbeRendererOptions o = probeOptions(stiffness, damping, 0.0, 0.0, toolRadius);
        if (!rpm.is_none()) o.rpm = rpm.cast<double>();
        if (!boneRange.is_none()) {
          const auto range = boneRange.cast<std::vector<double>>();
          if (range.size() != 2)
            raise(
                fail(ErrorCode::InvalidArgument, "bone_range takes two values (empty, full)", "bone_range"));
          o.boneRange = std::array<double, 2>{range[0], range[1]};
        }
        auto out = std::make_shared<PyRenderer>();
        out->renderer = unwrap(released([&] { return makeBurrProbe({.volume = &volume}, o, out->bone); }));
        return out;
      },
      py::arg("volume"), py::arg("stiffness") = 1000.0, py::arg("damping") = 0.0,
      py::arg("tool_radius") = 0.0, py::arg("rpm") = py::none(), py::arg("bone_range") = py::none(),
      "A sphere burr of tool_radius (default 2 mm) at `rpm` drilling the volume: a signed distance (negative "
      "inside), or with bone_range the intensities of empty space and of full bone (partial volume between). "
      "Its removed_volume and bone_occupancy tell what it drilled. As `dmtool probe --renderer burr` builds "
      "it.");

  m.def(
      "probe",
      [](PyRenderer& r, const py::object& path, double rateHz, const py::object& out) {
        const DevicePath p = devicePathOf(path);
        auto samples = unwrap(released([&] { return replayDevicePath(*r.renderer, p, rateHz); }));
        if (!out.is_none()) {
          const std::filesystem::path file = out.cast<std::filesystem::path>();
          unwrap(released([&] {
            const std::string csv = formatProbeCsv(samples);
            return writeFileAtomic(file, csv.data(), csv.size());
          }));
        }
        return samplesArray(samples);
      },
      py::arg("renderer"), py::arg("path"), py::arg("rate_hz") = 1000.0, py::arg("out") = py::none(),
      "dmtool probe as a function: replays a device path (a CSV file, or an (n, 4) / (n, 8) array of rows t, "
      "x, y, z[, qw, qx, qy, qz]) through the renderer in lockstep at rate_hz, reset to the first pose; "
      "returns forces.csv's columns as a structured array (read_forces's), and with `out` writes that CSV.");
}

}  // namespace dm::python
