// dm/io/scene_file.hpp — the scene file (JSON, "dmplatform-scene" version 2;
// version 1 files read unchanged)
// shared by `dmtool render`, the master engine and `dmplatform run`.
//
// parseScene() validates a scene document and turns it into SceneDesc, a
// plain-data description: resources (meshes, volumes — files or generated
// CT-like phantoms —, isosurfaces, analytic shapes, images), materials,
// objects, volume views, lights, cameras, devices, engine settings and
// outputs. Nothing is loaded here: no file but the scene itself is opened,
// no GL, no device. docs/scene-format.md documents every key, type, unit,
// default and range.
//
// Validation runs on dm::ConfigReader, so every problem (missing key, wrong
// type, value out of range, unknown key, dangling reference, duplicate name,
// bad quaternion, unsorted transfer function) is reported at once, each as a
// dm::Error whose `where` is "SOURCE: /json/pointer" and whose hint suggests
// the closest valid name ("did you mean \"skin\"?"). Units are SI (metres,
// seconds, radians) unless a key says otherwise (`fov_y_deg`).
//
// Source paths: a name "mount:rest" uses a dm::FileSystem mount (an unknown
// mount is a parse error); an absolute path is kept; a relative path is
// resolved against the scene file's directory. Whether the file exists is
// checked when it is loaded, not here.
//
// @code
//   std::vector<dm::Error> problems;
//   auto scene = dm::readScene("examples/scenes/head_probe.json", &problems);
//   if (!scene) { std::cerr << dm::formatSceneErrors(problems); return 1; }
// @endcode
#pragma once

#include <dm/core/config.hpp>
#include <dm/core/pose.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/math/phantom.hpp>

#include <array>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace dm {

/// The scene format version this build writes. It reads this one and
/// version 1, a subset: a version-1 file reads unchanged, and keys that
/// version 2 added are errors in it (so an old reader's file never means
/// something else to a new one).
inline constexpr int kSceneFormatVersion = 2;

/// An axis-aligned box, m: in an object's frame (before its scale), or in
/// a volume's world frame (a segment's crop).
struct SceneBox {
  Vec3 min = Vec3::Zero();
  Vec3 max = Vec3::Zero();  ///< ≥ min on every axis

  bool operator==(const SceneBox&) const = default;
};

/// A saw cut of a segment (v2 "cuts"): a plane in the source volume's
/// world frame. Voxels whose centre lies on the normal's side by more than
/// kerf / 2 are kept; the slot of width `kerf` the saw removes is not.
struct SceneCut {
  Vec3 point = Vec3::Zero();    ///< m, on the plane (unless `atCentroid`)
  Vec3 normal = Vec3::UnitZ();  ///< unit: the side kept
  double kerf = 0.0;            ///< m, ≥ 0, ≤ 0.05
  /// "point": "centroid" — the plane passes through the centroid of the
  /// voxels selected before the cuts (after `largest_component`), the
  /// planned cut through the middle of a bone found in the scan.
  bool atCentroid = false;

  bool operator==(const SceneCut&) const = default;
};

/// A segment's "near": only voxels within `distance` of another mask.
struct SceneSegmentNear {
  std::string volume;     ///< a volume on the source's grid: its nonzero voxels
  double distance = 0.0;  ///< m, > 0, ≤ 0.1: between voxel centres (Euclidean, the voxel sizes applied)

  bool operator==(const SceneSegmentNear&) const = default;
};

/// A volume made from another (v2 "segment"): a bone fragment, an organ —
/// the voxels of `volume` selected by value, outside one mask and near
/// another, cropped to `box`, optionally reduced to their largest
/// 26-connected part, cut by saw planes (each side again reduced to its
/// largest part); a U8 0/1 mask on the source's grid (cropped), so its
/// voxels keep their world positions. Planned osteotomies are segments of
/// the patient's CT (or of an MRI with its brain mask: the calvaria are the
/// dark voxels outside the brain and within millimetres of it).
struct SceneSegment {
  enum class Select : std::uint8_t { Above, Below, Label };

  std::string volume;  ///< a volume read from a file or generated (not another segment)
  Select select =
      Select::Above;  ///< "above": value > `value`; "below": value < `value`; "label": value == `value`
  double value = 0.0;
  std::string outside;  ///< a volume on the source's grid: its nonzero voxels are dropped; or empty
  std::optional<SceneSegmentNear> near;  ///< or nullopt
  std::optional<SceneBox>
      box;  ///< world, m: only voxels whose centres lie inside; the grid is cropped to them
  std::vector<SceneCut> cuts;  ///< every cut keeps its normal's side
  bool largestComponent = false;  ///< before the cuts, and after them

  bool operator==(const SceneSegment&) const = default;
};

/// A named resource: something to load or generate once and share.
struct SceneResource {
  enum class Type : std::uint8_t { Mesh, Volume, Isosurface, Shape, Image };
  enum class Shape : std::uint8_t { Sphere, Box, Capsule, Cylinder, Plane, Compound };
  /// One part of a compound shape (v2, "parts"): a sphere, box, capsule or
  /// cylinder of its own size placed by `pose` in the compound's frame.
  struct Part {
    Shape shape = Shape::Sphere;
    double radius = 0.0;              ///< sphere, capsule, cylinder: m, > 0
    Vec3 halfExtents = Vec3::Zero();  ///< box: m, > 0
    double height = 0.0;              ///< capsule, cylinder: m, > 0
    Pose pose;                        ///< part frame → compound frame

    bool operator==(const Part& o) const {
      return shape == o.shape && radius == o.radius && halfExtents == o.halfExtents && height == o.height &&
             pose.p == o.pose.p && pose.q.coeffs() == o.pose.q.coeffs();
    }
  };

  std::string name;
  Type type = Type::Mesh;
  /// Mesh, Volume, Image: the source as written ("mricron:ch2.nii.gz", "tool.stl");
  /// empty for a generated volume.
  std::string source;
  /// The resolved source: the mount's file if it exists (else empty: loading
  /// reports it), an absolute path as is, a relative one under the scene's directory.
  std::filesystem::path path;
  /// Volume (v2, "phantom"): generated, not read — a CT-like scan of a
  /// calvarium in HU (dm/math/phantom.hpp), instead of a source.
  std::optional<CalvariumPhantom> phantom;
  /// Volume (v2, "segment"): made from another volume resource — a bone
  /// fragment cut from a CT — instead of a source.
  std::optional<SceneSegment> segment;
  std::string unit = "m";  ///< Mesh: length unit of the file (dm::metresPerUnit names)
  double scale = 1.0;      ///< Mesh: extra factor after the unit, > 0

  std::string volume;             ///< Isosurface: name of a Volume resource
  double level = 0.0;             ///< Isosurface: iso value, in the volume's value units
  bool largestComponent = false;  ///< Isosurface: keep only the largest connected component
  int smooth = 0;                 ///< Isosurface: smoothing iterations, 0..100
  /// Isosurface: farthest a vertex may move while smoothing, m (v2,
  /// "smooth_max_displacement"); infinity: unbounded.
  double smoothMaxDisplacement = std::numeric_limits<double>::infinity();
  int downsample = 1;  ///< Isosurface: voxels averaged per axis before extraction, 1..8

  Shape shape = Shape::Sphere;      ///< Shape: which one, centred at its origin, axis +z
  double radius = 0.0;              ///< Sphere, capsule, cylinder: m, > 0
  Vec3 halfExtents = Vec3::Zero();  ///< Box: m, > 0; plane: x, y > 0 and z = 0
  double height = 0.0;              ///< Capsule (between the cap centres), cylinder: m, > 0
  /// Compound (v2): its parts, 1..64; a rigid union (mass from the parts'
  /// volumes, overlaps counted twice).
  std::vector<Part> parts;
  int subdivisions = 3;             ///< Shape tessellation level, 0..8

  bool operator==(const SceneResource&) const = default;
};

/// Contact properties of a touchable surface.
struct SceneHapticMaterial {
  double stiffness = 0.0;        ///< N/m, > 0
  double damping = 0.0;          ///< N·s/m, ≥ 0
  double staticFriction = 0.0;   ///< coefficient, ≥ 0
  double dynamicFriction = 0.0;  ///< coefficient, 0 ≤ dynamic ≤ static

  bool operator==(const SceneHapticMaterial&) const = default;
};

/// Appearance (and optionally haptic contact) of a surface.
struct SceneMaterial {
  enum class Model : std::uint8_t { BlinnPhong, Pbr };

  std::string name;
  Model model = Model::BlinnPhong;
  Vec4 color{0.8, 0.8, 0.8, 1.0};  ///< linear RGBA, each 0..1
  Vec3 specular{0.2, 0.2, 0.2};    ///< Blinn-Phong: linear RGB, 0..1
  double shininess = 32.0;         ///< Blinn-Phong: exponent, 1..10000
  double metallic = 0.0;           ///< PBR: 0..1
  double roughness = 0.5;          ///< PBR: 0..1
  Vec3 emissive = Vec3::Zero();    ///< linear RGB, ≥ 0
  std::string texture;             ///< name of an Image resource, or empty
  std::string normalMap;           ///< name of an Image resource, or empty
  std::string heightMap;           ///< name of an Image resource (red: 1 = surface, 0 = deepest), or empty
  double heightScale = 0.0;        ///< m of relief from height 1 to 0, 0..1; given with heightMap only
  std::optional<SceneHapticMaterial> haptic;

  bool operator==(const SceneMaterial&) const = default;
};

/// Bone that a burr mills (v2 "millable"): the object's mesh as fractional
/// occupancy on a grid (dm::MillableVolume), touched by the burr renderer.
struct SceneMillable {
  double voxelSize = 0.0;   ///< m, > 0, ≤ 0.01: the grid spacing of the voxelized mesh (0 with `volume`)
  double hardness = 0.5e9;  ///< Pa, > 0: Archard hardness (cortical bone ≈ 0.3–0.7 GPa)
  /// A `volume` resource (CT): the bone is its voxels, occupancy
  /// clamp((I − empty) / (full − empty)) (CT's partial-volume law) on the
  /// volume's own grid, instead of the voxelized mesh. Empty: the mesh.
  std::string volume;
  double empty = 0.0;  ///< with `volume`: the intensity of no bone (e.g. soft tissue, HU)
  double full = 0.0;   ///< with `volume`: the intensity of solid bone (> empty)

  bool operator==(const SceneMillable&) const = default;
};

/// A critical structure (nerve, vessel, dura; v2 "critical"): where it lies
/// inside the millable bone's grid it is a forbidden material the burr can
/// remove (a violation, counted), and the burr's distance to it is measured.
struct SceneCritical {
  double hardness = 0.05e9;  ///< Pa, > 0

  bool operator==(const SceneCritical&) const = default;
};

/// Another material of the millable bone (v2 "inclusion"): dentin under
/// enamel, cancellous bone inside cortical; where the object lies inside
/// the bone's grid, the bone has this hardness.
struct SceneInclusion {
  double hardness = 0.5e9;  ///< Pa, > 0

  bool operator==(const SceneInclusion&) const = default;
};

/// A layer of a soft object that a needle goes through (v2 "layers";
/// dm::NeedleLayer), the first at the top (the +z face of the object's rest
/// bounding box), each below the one before.
struct SceneSoftLayer {
  std::string name;
  double thickness = 0.0;      ///< m, > 0; 0 on the last layer (down to the bottom) and with labels
  int label = -1;              ///< with SceneSoft::labels: the label value of the layer's voxels, 0..65535
  double punctureForce = 1.0;  ///< N, ≥ 0: the tip force that breaks the layer's surface (0: none)
  double cuttingForce = 0.3;   ///< N, ≥ 0: the force on the tip while it cuts through the layer
  double friction = 50.0;      ///< N/m, ≥ 0: sliding friction per metre of shaft in the layer

  bool operator==(const SceneSoftLayer&) const = default;
};

/// Soft tissue (v2 "soft"): the object is a deformable body — co-rotational
/// FEM (dm::FemBody) on tetrahedra made from its mesh — that the physics
/// engine steps, the god-object presses (felt at the haptic rate through
/// dm::HapticTissue) and the render engine draws deformed.
struct SceneSoft {
  /// Faces of the object's rest bounding box (object frame) whose nodes are
  /// held in place; face i (in kFaces) is bit 1 << i of fixedFaces.
  static constexpr std::array<std::string_view, 6> kFaces{"-x", "+x", "-y", "+y", "-z", "+z"};

  double youngsModulus = 0.0;  ///< E, Pa, > 0 (soft tissue: 1e3–1e5)
  double poissonRatio = 0.45;  ///< ν, 0 ≤ ν < 0.5
  double density = 1000.0;     ///< kg/m³, > 0
  double alpha = 0.0;          ///< Rayleigh mass damping, 1/s, ≥ 0 ("damping": {"alpha"})
  double beta = 0.0;           ///< Rayleigh stiffness damping, s, ≥ 0 ("damping": {"beta"})
  /// m, > 0, ≤ 0.05: tetrahedra edge scale. A box shape splits into cubes of
  /// about this size (its faces kept exactly); any other closed mesh is
  /// voxelized at it (a voxel-shaped surface). 0 with `volume`.
  double voxelSize = 0.0;
  /// A volume resource (a segmentation or a scan, "volume"): the tissue is
  /// its voxels whose value is ≥ threshold, on the volume's own grid, instead
  /// of the object's mesh (which static views such as `dmtool render` still
  /// draw). Empty: the mesh.
  std::string volume;
  double threshold = 0.5;  ///< with `volume`: a voxel is tissue from this value up
  /// N/m per boundary node, > 0: the penalty spring that keeps the tissue
  /// out of the static objects that collide ("contact_stiffness"); 0 (not
  /// given): 20·E·voxel_size, a node's own stiffness times 20.
  double contactStiffness = 0.0;
  /// N·s/m per boundary node in contact, ≥ 0: viscous friction across the
  /// contact with the other objects ("contact_friction"; 0: frictionless).
  double contactFriction = 0.0;
  std::uint8_t fixedFaces = 0;
  /// Boxes whose nodes are held too ("fixed_boxes"): where the tissue is
  /// attached (to bone, to a clamp).
  std::vector<SceneBox> fixedBoxes;
  /// Octree grading ("levels", 0..10): 0 a uniform grid; n > 0 cells of up
  /// to 2ⁿ voxels where the occupancy allows, voxel-sized ones in and
  /// around fineRegion (dm::tetMeshHierarchical).
  int levels = 0;
  std::optional<SceneBox>
      fineRegion;  ///< "fine_region", with levels > 0    ///< bit i: kFaces[i] is held ("fixed": ["-z"])
  std::size_t maxTets = 100'000;  ///< a larger model is an error before it is built, ≤ 4,000,000
  /// What a needle meets, top down ("layers"); only with the needle renderer
  /// on this object, and required there.
  std::vector<SceneSoftLayer> layers;
  /// A volume resource of labels ("labels"): each tetrahedron is in the
  /// layer whose label its centroid's voxel has (the volume placed in the
  /// world, the object's pose and scale applied to the tissue), instead of
  /// slabs by thickness. Empty: slabs.
  std::string labels;

  bool operator==(const SceneSoft&) const = default;
};

/// An object's voxels (v2 "voxels"): the occupancy a voxel renderer
/// (bone placement) touches — the voxels of a volume resource with value >
/// threshold, the volume's world frame placed by the object's pose. The
/// object's mesh is what is drawn (an isosurface of the same volume).
struct SceneVoxels {
  std::string volume;      ///< a volume resource (a segment, a label map)
  double threshold = 0.5;  ///< a voxel is occupied above this value

  bool operator==(const SceneVoxels&) const = default;
};

/// v2 "membrane": the object's triangle mesh (at its pose and scale) as a
/// viscoelastic mass–spring membrane (dm::MassSpringBody::fromMesh: a
/// particle per vertex, an element per edge, bend elements across interior
/// edges), stepped implicitly by the physics engine under its gravity and
/// drawn deformed (docs/scene-format.md, "Membranes").
struct SceneMembrane {
  enum class Model { KelvinVoigt, Maxwell };
  double mass = 0.0;       ///< kg, > 0: the whole membrane (each vertex its lumped area's share)
  double stiffness = 0.0;  ///< N/m per edge element, > 0
  double damping = 0.0;    ///< N·s/m per edge element, ≥ 0 (> 0 for Maxwell)
  Model model = Model::KelvinVoigt;
  double bendStiffness = 0.0;  ///< N/m across each interior edge; 0: no bend elements
  double bendDamping = 0.0;    ///< N·s/m, ≥ 0
  double drag = 0.0;           ///< 1/s, ≥ 0: f = −drag·m·v on every particle (the medium)
  bool pinBoundary = false;    ///< the mesh's boundary vertices are held ("pinned": "boundary")
  /// Boxes whose vertices are held ("pinned_boxes"; the object's frame
  /// before its scale, as a soft object's fixed_boxes).
  std::vector<SceneBox> pinnedBoxes;
  /// Coulomb coefficient of its contact with the objects that collide,
  /// static and dynamic (dm::MembraneRigidCoupling), ≥ 0.
  double friction = 0.0;
  double thickness = 0.0;  ///< m, ≥ 0: how far its particles stay off those objects' surfaces

  bool operator==(const SceneMembrane&) const = default;
};

/// A mesh placed in the world.
struct SceneObject {
  std::string name;
  std::string mesh;        ///< a Mesh, Isosurface or Shape resource (touched, simulated, drawn)
  std::string renderMesh;  ///< drawn instead of `mesh` when set (e.g. a coarser skin), or empty
  std::string material;    ///< a material name, or empty for the renderer's default
  Pose pose;               ///< object → world; the quaternion is unit within 1e-9
  double scale = 1.0;      ///< uniform, > 0
  bool visible = true;
  bool haptic = false;                  ///< touchable by haptic renderers
  bool dynamic = false;                 ///< a rigid body moved by the physics engine
  double mass = 0.0;                    ///< kg; dynamic objects give this or `density`; 0 when not given
  double density = 0.0;                 ///< kg/m³ (v2): mass from the shape's volume; 0 when not given
  Vec3 velocity = Vec3::Zero();         ///< m/s, world, initial (v2; dynamic objects)
  Vec3 angularVelocity = Vec3::Zero();  ///< rad/s, world, initial (v2; dynamic objects)
  /// Takes part in rigid contact when the physics engine runs (v2). The
  /// haptics engine's proxy_object never does: it is the tool's picture.
  bool collide = true;
  double friction = 0.5;                  ///< rigid contact: Coulomb μ, 0..10 (v2 "contact")
  double restitution = 0.0;               ///< rigid contact: coefficient of restitution, 0..1 (v2 "contact")
  std::optional<SceneMillable> millable;  ///< v2: bone the burr renderer mills
  std::optional<SceneCritical> critical;  ///< v2: a structure the burr must not reach
  std::optional<SceneInclusion> inclusion;  ///< v2: another material of the millable bone
  std::optional<SceneSoft> soft;            ///< v2: soft tissue the physics engine deforms
  std::optional<SceneMembrane> membrane;    ///< v2: a mass–spring membrane the physics engine deforms
  std::optional<SceneVoxels> voxels;        ///< v2: voxels the bone-placement renderer touches

  bool operator==(const SceneObject& o) const;
};

/// One control point of a volume transfer function.
struct SceneTransferPoint {
  double value = 0.0;        ///< in the volume's value units
  Vec4 rgba = Vec4::Zero();  ///< linear colour and opacity, 0..1

  bool operator==(const SceneTransferPoint&) const = default;
};

/// A volume shown directly (ray casting or a slice).
struct SceneVolume {
  enum class Mode : std::uint8_t { Composite, Mip, Slice };
  enum class Axis : std::uint8_t { Axial, Coronal, Sagittal };

  std::string name;
  std::string volume;  ///< a Volume resource
  Mode mode = Mode::Composite;
  /// Values strictly increasing, ≥ 2 points; empty: the renderer's grey ramp.
  std::vector<SceneTransferPoint> transferFunction;
  Axis sliceAxis = Axis::Axial;  ///< Slice mode: axial ⟂ z, coronal ⟂ y, sagittal ⟂ x (world)
  double slicePosition = 0.0;    ///< Slice mode: world coordinate along that axis, m
  bool visible = true;

  bool operator==(const SceneVolume&) const = default;
};

/// A light source.
struct SceneLight {
  enum class Type : std::uint8_t { Directional, Point, Spot };

  Type type = Type::Directional;
  Vec3 direction{0.0, 0.0, -1.0};  ///< Directional, spot: unit, world, the way the light travels
  Vec3 position = Vec3::Zero();    ///< Point, spot: m, world
  Vec3 color{1.0, 1.0, 1.0};       ///< linear RGB, 0..1
  double intensity = 1.0;          ///< ≥ 0, multiplies color
  double range = 0.0;              ///< Point, spot: m, ≥ 0 (0: no cut-off)
  double innerConeDeg = 20.0;      ///< Spot: full intensity inside, degrees, 0 < inner ≤ outer
  double outerConeDeg = 30.0;      ///< Spot: no light outside, degrees, ≤ 90
  bool shadows = false;

  bool operator==(const SceneLight&) const = default;
};

/// One key of a camera path.
struct SceneCameraKey {
  double t = 0.0;  ///< s, strictly increasing along the path
  Vec3 position = Vec3::Zero();
  Vec3 target = Vec3::Zero();

  bool operator==(const SceneCameraKey&) const = default;
};

/// A view of the scene.
struct SceneCamera {
  enum class Projection : std::uint8_t { Perspective, Orthographic };

  std::string name;
  Projection projection = Projection::Perspective;
  double fovYDeg = 45.0;     ///< Perspective: vertical field of view, degrees, (0, 180)
  double orthoHeight = 0.3;  ///< Orthographic: height of the view, m, > 0
  Vec3 position = Vec3::Zero();
  Vec3 target = Vec3::Zero();
  Vec3 up{0.0, 0.0, 1.0};            ///< not parallel to target − position
  double near = 0.01;                ///< m, > 0
  double far = 10.0;                 ///< m, > near
  std::string track;                 ///< an object whose origin the camera aims at, or empty
  std::vector<SceneCameraKey> path;  ///< empty: a fixed camera
  bool stereo = false;
  double eyeSeparation = 0.064;  ///< Stereo: m, > 0
  double convergence = 0.5;      ///< Stereo: distance of zero parallax, m, > 0

  bool operator==(const SceneCamera&) const = default;
};

/// A haptic device served in this process to the tele-operation stream
/// (DMNetwork's TeleopDevice + TeleopDeviceBridge): the console side of a
/// tele-operation link, which another device — net-haptic with
/// "device": "@NAME" — reaches over the network.
struct SceneDeviceServe {
  std::string listen = "127.0.0.1:0";  ///< "address:port" to bind; port 0: any free port
  double timeout = 0.1;                ///< s without a force from the simulator before the output is zeroed
  double waveImpedance = 0.0;          ///< N·s/m; > 0: wave-variable mode (net-haptic's wave_impedance too)

  bool operator==(const SceneDeviceServe&) const = default;
};

/// An input/output device opened through a driver.
struct SceneDevice {
  std::string name;
  std::string driver;            ///< registered driver name, e.g. "sim-haptic"
  Json config = Json::object();  ///< driver parameters: strings, numbers, booleans or arrays of them
  /// Config keys that name files ("file": a path to follow, a recording),
  /// resolved like resource sources (relative to the scene, confined to the
  /// allowed folders); deviceParams() passes these resolved paths.
  std::map<std::string, std::filesystem::path, std::less<>> files;
  /// Served to the tele-operation stream (haptic devices). A config string
  /// "@NAME" of another device stands for the address a served device NAME
  /// listens on, filled in when the scene runs.
  std::optional<SceneDeviceServe> serve;

  bool operator==(const SceneDevice&) const = default;
};

/// The burr of the burr renderer (v2 "burr"): its cutting part and model
/// (dm::BurrOptions; stiffness and damping come from the milled object's
/// haptic material).
struct SceneBurr {
  enum class Shape : std::uint8_t { Sphere, Cylinder };

  Shape shape = Shape::Sphere;
  double radius = 0.0;            ///< m, > 0, ≤ 0.05
  double halfLength = 0.0;        ///< m, cylinder only: > 0, ≤ 0.05, along the tool's z
  double rpm = 80000.0;           ///< 0..500000 (dental turbines run 300k–450k)
  double wear = 0.1;              ///< Archard wear coefficient, 0..10
  double walk = 0.3;              ///< tangential / normal force of the spinning burr, 0..10
  double vibration = 0.05;        ///< vibration force / normal force, 0..10
  double vibrationHz = 160.0;     ///< ≥ 0, below half the haptic rate
  double warningDistance = 1e-3;  ///< m, 0..0.1: nearer a critical structure counts as time within the margin

  bool operator==(const SceneBurr&) const = default;
};

/// The punch of the punch renderer (v2 "punch"): a rigid indenter bonded to
/// the soft object `object` — its FEM nodes within `region` (world, at
/// rest) move with the tool's displacement from its first pose, and the
/// hand feels the force the tissue puts on them (a flat-punch indentation
/// test, a clamp or a grasper's jaws holding tissue).
struct ScenePunch {
  std::string object;  ///< a soft object's name
  SceneBox region;     ///< m, world, at the objects' rest poses

  bool operator==(const ScenePunch&) const = default;
};

/// The needle of the needle renderer (v2 "needle"; dm::NeedleOptions and
/// dm::HapticNeedleOptions): where it sits on the device and how it couples
/// to the tissue. The tip's spring on a membrane is the tissue material's
/// haptic stiffness.
struct SceneNeedle {
  double length = 0.1;  ///< m, > 0, ≤ 1: shaft behind the tip
  double radius = 0.0;  ///< m, 0 (straight) or > 0: a curved needle's arc, length ≤ 1.5·π·radius
  double couplingSpacing = 2e-3;   ///< m, > 0, ≤ length: track length per coupling point
  double acrossStiffness = 400.0;  ///< N/m, > 0: a coupling point across the shaft
  double alongStiffness = 400.0;   ///< N/m, > 0: a coupling point along the shaft while it sticks
  Vec3 tip = Vec3::Zero();         ///< m, device frame: the tip
  Vec3 axis = -Vec3::UnitZ();      ///< device frame, unit: the shaft at the tip, handle → tip
  Vec3 normal = Vec3::UnitX();     ///< device frame, unit: toward a curved needle's centre (⊥ axis)
  double maxTorque = 0.0;          ///< N·m, ≥ 0: torque sent to the hand (0: a 3-DOF device)

  bool operator==(const SceneNeedle&) const = default;
};

/// The VPS renderer's tool and settings (v2 "vps"; dm::VpsRenderer,
/// dm::VpsOptions): a rigid tool sampled as a point shell, the touched
/// objects as voxel models, the tool tied to the device by a 6-DOF virtual
/// coupling.
struct SceneVps {
  std::string tool;           ///< a mesh, shape or isosurface resource: the tool, in the device's frame
  double pointSpacing = 0.0;  ///< m, ≥ 0 (0: the tool's largest extent / 20)
  double voxelSize = 0.0;     ///< m, ≥ 0 (0: each object's largest extent / 128)
  double couplingStiffness = 500.0;       ///< N/m, > 0
  double couplingDamping = 5.0;           ///< N·s/m, ≥ 0
  double couplingAngularStiffness = 1.0;  ///< N·m/rad, > 0
  double couplingAngularDamping = 2e-3;   ///< N·m·s/rad, ≥ 0
  double mass = 0.05;                     ///< kg, > 0: the tool body
  double referenceContacts = 10.0;        ///< ≥ 1: Nref of the stiffness rule
  double maxPointDepth = 2e-3;            ///< m, > 0
  double brakeDistance = 0.5e-3;          ///< m, ≥ 0
  double brakeDamping = 20.0;             ///< N·s/m, ≥ 0
  double maxTorque = 1.0;                 ///< N·m, > 0: torque to the hand
  int substeps = 1;                       ///< 1..64

  bool operator==(const SceneVps&) const = default;
};

/// The sphere-tree renderer's tool and settings (v2 "sphere_tree";
/// dm::SphereTree6DofRenderer, dm::SphereTree6DofOptions): tool and touched
/// objects as octree sphere trees with surface patches, the tool's
/// configuration the constrained minimiser of its distance to the handle,
/// the force a 6-DOF spring between the two.
struct SceneSphereTree {
  std::string tool;               ///< a mesh, shape or isosurface resource: the tool, in the device's frame
  int levels = 6;                 ///< 2..10: the objects' trees (leaves at levels − 1)
  int toolLevels = 5;             ///< 2..10: the tool's tree
  int toolLevel = 4;              ///< 0..toolLevels − 1: the tool level that collides
  double stiffness = 1000.0;      ///< N/m, > 0: the linear spring to the handle
  double angularStiffness = 0.0;  ///< N·m/rad, ≥ 0 (0: stiffness · I / m)
  double mass = 0.1;              ///< kg, > 0
  double inertia = 0.0;           ///< kg·m², ≥ 0 (0: a solid ball of the tool's root radius)
  int maxConstraints = 256;       ///< 1..65536
  int solverIterations = 60;      ///< 1..10000
  int linearizations = 3;         ///< 1..16
  double marginEpsilon = 1e-4;    ///< m, ≥ 0
  double maxStep = 0.02;          ///< m, > 0
  double surfaceTolerance = 0.1;  ///< ≥ 0: patches within this share of a node's radius (0: spheres only)

  bool operator==(const SceneSphereTree&) const = default;
};

/// The bone-placement renderer's fragment and settings (v2
/// "bone_placement"; dm::BonePlacementRenderer, dm::BonePlacementOptions):
/// a voxel bone fragment, held by the hand through a 6-DOF virtual
/// coupling, placed against the touched object's voxels with impulses.
struct SceneBonePlacement {
  /// A volume resource: the moving fragment's voxels (value > threshold).
  /// Its world frame is the fragment's frame: at the device pose identity
  /// the fragment lies where the volume puts it.
  std::string fragment;
  double threshold = 0.5;
  double couplingStiffness = 300.0;       ///< N/m, > 0
  double couplingDamping = 2.0;           ///< N·s/m, ≥ 0
  double couplingAngularStiffness = 0.3;  ///< N·m/rad, > 0
  double couplingAngularDamping = 1e-3;   ///< N·m·s/rad, ≥ 0
  double mass = 0.0;                      ///< kg, ≥ 0 (0: voxels × voxel volume × density)
  double density = 1900.0;                ///< kg/m³, > 0 (cortical bone)
  int maxContacts = 1024;                 ///< 1..4096 deepest voxel pairs kept per tick
  int iterations = 8;                     ///< 1..100 Gauss–Seidel passes
  int contactLevel = 0;                   ///< 0..4: levels above the voxels whose cells touch (0: voxels)
  double slop = -1.0;      ///< m, ≥ 0 ("slop"); negative (not given): face-adjacent voxels' resting overlap
  double baumgarte = 0.2;  ///< 0..1
  double maxTorque = 1.0;  ///< N·m, > 0: torque to the hand
  /// The planned pose of the fragment (its frame → world; "target_pose"):
  /// summary.json reports the alignment error against it. Default: where
  /// the volume puts it (the anatomy).
  Pose target;

  bool operator==(const SceneBonePlacement& o) const;
};

/// The haptic engine: one device rendering contact with objects.
struct SceneHapticsEngine {
  /// `None` ("none", v2): a tool in free space, nothing to touch (no
  /// "objects"); the proxy is the device point, effects such as the
  /// segmentation engine's guidance give the force (dm::FreeSpaceRenderer).
  /// `Punch` ("punch", v2): bonded to a soft object's nodes (its "punch"
  /// block names the object; no "objects").
  enum class Renderer : std::uint8_t { GodObject, Vps, SphereTree, Burr, Needle, BonePlacement, None, Punch };

  double rateHz = 1000.0;  ///< 100..10000
  Renderer renderer = Renderer::GodObject;
  std::string device;                ///< a device name
  std::vector<std::string> objects;  ///< touchable object names, ≥ 1 (none with renderer "none" or "punch")
  double toolRadius = 0.0;           ///< m, 0..0.1 (0: a point)
  Pose devicePose;                   ///< device frame → world
  double maxForce = 0.0;             ///< N, ≥ 0 (0: the device's limit)
  bool forceShading = false;
  std::string proxyObject;        ///< an object whose pose follows the proxy (the tool shown), or empty
  std::optional<SceneBurr> burr;  ///< v2: with renderer "burr" (and only then)
  std::optional<SceneNeedle> needle;  ///< v2: with renderer "needle" (and only then)
  std::optional<SceneVps> vps;        ///< v2: with renderer "vps" (and only then)
  std::optional<SceneSphereTree> sphereTree;  ///< v2: with renderer "sphere-tree" (and only then)
  std::optional<SceneBonePlacement> bonePlacement;  ///< v2: with renderer "bone-placement" (and only then)
  std::optional<ScenePunch> punch;                  ///< v2: with renderer "punch" (and only then)

  bool operator==(const SceneHapticsEngine& o) const;
};

/// The scene file's name of a haptic renderer ("god-object", "burr", …).
std::string_view rendererName(SceneHapticsEngine::Renderer renderer) noexcept;

/// A joint of the physics engine's world (v2 "joints"; docs/scene-format.md,
/// "Joints"; dm::JointDesc): object `a` held to object `b` (the world when
/// `b` is empty) at `anchor`, built from the objects' initial poses. Both are
/// rigid bodies of the world (dynamic, or static and colliding), one at
/// least dynamic.
struct SceneJoint {
  enum class Type { Ball, Hinge, Slider, Fixed };
  std::string name;
  Type type = Type::Ball;
  std::string a;               ///< an object's name
  std::string b;               ///< an object's name, or empty: the world
  Vec3 anchor = Vec3::Zero();  ///< m, world, at the initial poses
  Vec3 axis = Vec3::UnitX();   ///< hinge and slider: unit, world
  bool limited = false;        ///< hinge (rad) and slider (m): "limits" given
  double lower = 0.0, upper = 0.0;

  bool operator==(const SceneJoint&) const = default;
};

/// The physics engine.
struct ScenePhysicsEngine {
  /// v2 "backend": what steps the rigid bodies and joints — the built-in
  /// contact solver ("builtin") or the Open Dynamics Engine ("ode",
  /// dm::OdeWorld). Soft objects and fluids are stepped as they are either way.
  enum class Backend { BuiltIn, Ode };
  /// v2 "ode": ODE's settings (dm::OdeOptions), with the "ode" backend only.
  struct Ode {
    int iterations = 20;        ///< dWorldQuickStep iterations, 1..1000
    double erp = 0.2;           ///< error reduction, (0, 1]
    double cfm = 1e-9;          ///< constraint force mixing, 0..1
    int contactsPerPair = 4;    ///< 1..64
    double surfaceLayer = 0.0;  ///< m, 0..0.01: contacts sink this deep uncorrected (ODE's default 0)

    bool operator==(const Ode&) const = default;
  };

  double rateHz = 1000.0;            ///< 10..10000
  Vec3 gravity{0.0, 0.0, -9.80665};  ///< m/s², world
  bool sleep = false;  ///< v2: bodies at rest fall asleep (dm::ContactSettings::sleep); built-in only
  std::vector<SceneJoint> joints;    ///< v2
  Backend backend = Backend::BuiltIn;  ///< v2
  Ode ode;                             ///< v2

  bool operator==(const ScenePhysicsEngine&) const = default;
};

/// The render engine.
struct SceneRenderEngine {
  double rateHz = 60.0;  ///< 1..240
  std::string camera;    ///< a camera name, or empty for the first camera
  int width = 1280;      ///< pixels, 16..16384
  int height = 720;      ///< pixels, 16..16384
  int samples = 1;       ///< MSAA samples: 1, 2, 4, 8 or 16
  bool hud = true;       ///< v2: time, force and force plot drawn over the written frames
  /// v2 "inset": a second camera's picture in the frame's upper-right
  /// corner (e.g. the endoscope's), or empty for none.
  std::string insetCamera;
  double insetSize = 0.3;  ///< the inset's width and height as fractions of the frame's, 0.1..0.9

  bool operator==(const SceneRenderEngine&) const = default;
};

/// The monitor engine (statistics, traces, console).
struct SceneMonitorEngine {
  double rateHz = 30.0;  ///< 1..1000

  bool operator==(const SceneMonitorEngine&) const = default;
};

/// v2: the OpenIGTLink server engine: what a running scene publishes to
/// 3D Slicer, PLUS or any OpenIGTLink client (docs/scene-format.md, "igtl").
/// Each name is an OpenIGTLink device name (1..20 characters); an empty one
/// is not published.
struct SceneIgtlEngine {
  double rateHz = 30.0;                    ///< 1..1000
  std::string listen = "127.0.0.1:18944";  ///< "address:port"; port 0: any free port
  std::vector<std::string> allow;          ///< peers allowed (addresses or CIDR blocks); empty: everyone
  std::string tool;                        ///< TRANSFORM of the tool (the haptic proxy), world
  std::string handle;                      ///< TRANSFORM of the device's handle, world
  std::string force;                       ///< SENSOR: the force sent to the hand (N, world x, y, z)
  bool bodies = false;                     ///< TRANSFORM of each dynamic object, named as the object
  std::string image;                       ///< IMAGE: the rendered frames (RGB, 8 bits)
  int waitForClients = 0;                  ///< 0..64: the run starts once this many clients are connected
  double waitTimeout = 30.0;               ///< s, 0.1..3600: then the run fails

  bool operator==(const SceneIgtlEngine&) const = default;
};

/// v2: the vision engine: a DMVision filter graph (docs/vision.md) stepped
/// one frame per tick; its "input" sources get the render engine's frames
/// (a simulated endoscope), its other sources read their own (video files).
struct SceneVisionEngine {
  double rateHz = 15.0;             ///< 1..240
  std::filesystem::path graphFile;  ///< "graph" as a file (resolved like a resource source), or empty
  Json graph;                       ///< "graph" given inline ({"nodes": [...]}), or null
  std::string overlay;  ///< a "texture" sink of the graph the render engine draws over its frames, or empty

  bool operator==(const SceneVisionEngine&) const = default;
};

/// The segmentation engine (v2 "segmentation"; docs/scene-format.md,
/// "Segmentation"): haptic-guided segmentation of a volume resource
/// (dm::HapticSegmentation, DMVision) — `rateHz` times a second it paints the
/// region around the haptics engine's tool point (the device point in the
/// world), and its guidance force, pushing the tool away from edges, is an
/// effect of the haptic loop. The intensity window is `window`, or the mean ±
/// `windowK` standard deviations of the 5×5×5 voxels at `seed`. With
/// `referenceK` the summary's precision is against an adaptive region grown
/// from `seed` over the whole volume (dm::growRegion, 26-connected).
struct SceneSegmentationEngine {
  double rateHz = 20.0;                         ///< 1..1000
  std::string volume;                           ///< a volume resource: the image
  Vec3 seed = Vec3::Zero();                     ///< m, world (the volume's frame): inside its grid
  std::optional<std::array<double, 2>> window;  ///< intensities [lower, upper], lower ≤ upper; or nullopt
  double windowK = 2.5;                         ///< 0.1..10 (without `window`)
  int connectivity = 6;                         ///< 6, 18 or 26
  double minRadius = 1e-3;                      ///< m, 1e-5..0.1
  double maxRadius = 15e-3;                     ///< m, minRadius..0.2
  double edgeSigma = 1e-3;                      ///< m, 0..0.05 (0: no smoothing)
  double edgeThreshold = 0.25;                  ///< (0, 1]
  int rays = 64;                                ///< 6..4096
  double gain = 1e-3;                           ///< N·m, ≥ 0
  double maxForce = 2.0;                        ///< N, 0..100
  bool guidance = true;                         ///< the guidance force in the haptic loop
  std::optional<double> referenceK;             ///< "reference": {"k": ...}, 0.1..10; or nullopt

  bool operator==(const SceneSegmentationEngine&) const = default;
};

/// Which engines run; each is optional.
struct SceneEngines {
  std::optional<SceneHapticsEngine> haptics;
  std::optional<ScenePhysicsEngine> physics;
  std::optional<SceneRenderEngine> render;
  std::optional<SceneMonitorEngine> monitor;
  std::optional<SceneIgtlEngine> igtl;      ///< v2
  std::optional<SceneVisionEngine> vision;  ///< v2
  std::optional<SceneSegmentationEngine> segmentation;  ///< v2

  bool operator==(const SceneEngines&) const = default;
};

/// A script whose callbacks run during the run (v2 "scripts";
/// docs/scene-format.md, "Scripts"; dm/engine/script.hpp): its language is
/// its file's extension (".py": Python), it runs at the rate of the engine
/// it names on a thread of its own, never the haptic one, and its callbacks
/// get `args` as written (a sweep's parameters can set them).
struct SceneScript {
  std::string name;
  std::string source;              ///< as written
  std::filesystem::path path;      ///< resolved and confined like a resource's source
  std::string engine = "monitor";  ///< whose rate: "physics", "monitor", "render", "vision" or "igtl"
  Json args = Json::object();      ///< handed to the script as is

  bool operator==(const SceneScript&) const = default;
};

/// Where a fluid comes in (v2 "fluids"/"inlets"; dm::FluidInlet): a cut
/// vessel (pressure > 0: its rate falls with the pressure on it) or a pump
/// (pressure 0: irrigation), open from `start` to `stop` scene seconds.
struct SceneFluidInlet {
  std::string name;
  Vec3 center = Vec3::Zero();
  Vec3 normal = Vec3(0, 0, 1);  ///< unit: the direction the fluid leaves in
  double radius = 0.0;          ///< m, ≥ 0
  double flowRate = 0.0;        ///< m³/s at zero back pressure
  double pressure = 0.0;        ///< Pa: the vessel's driving pressure; 0 a pump
  double start = 0.0;           ///< s
  std::optional<double> stop;   ///< s; open to the end when absent

  bool operator==(const SceneFluidInlet&) const = default;
};

/// A suction tip (v2 "fluids"/"suction"; dm::FluidSuction): at a fixed
/// centre, or at the haptic tool's proxy ("at": "tool").
struct SceneFluidSuction {
  std::string name;
  double radius = 0.0;         ///< m, > 0
  double flowRate = 0.0;       ///< m³/s, the most it takes
  bool atTool = false;         ///< follows the tool's proxy instead of `center`
  Vec3 center = Vec3::Zero();  ///< when not at the tool
  double start = 0.0;          ///< s
  std::optional<double> stop;  ///< s

  bool operator==(const SceneFluidSuction&) const = default;
};

/// A particle fluid of the run (v2 "fluids"; dm::SphFluid), stepped by the
/// physics engine: blood from cuts, irrigation, suction; docs/scene-format.md,
/// "Fluids".
/// How a fluid is drawn (v2 "fluids"/"look"; dm::FluidLook in DMRenderer).
struct SceneFluidLook {
  enum class Style : std::uint8_t {
    Surface,  ///< screen-space fluid: one smoothed, absorbing, refracting surface
    Spheres,  ///< one lit sphere half a spacing wide per particle
  };
  Style style = Style::Surface;
  /// Beer–Lambert coefficients, 1/m per channel; unset: a layer 1 mm thick
  /// transmits the fluid's colour
  std::optional<Vec3> absorption;
  double fresnel = 0.02;     ///< reflectance at normal incidence
  double specular = 1.0;     ///< scale of the lights' highlights
  double shininess = 200.0;  ///< Blinn–Phong exponent of the highlights
  double refraction = 12.0;  ///< pixels the scene behind shifts per unit of the normal's screen tilt
  int smoothing = 3;         ///< bilateral smoothing passes over the surface's depth

  bool operator==(const SceneFluidLook&) const = default;
};

struct SceneFluid {
  std::string name;
  double spacing = 0.004;             ///< m: particle spacing
  double density = 1060.0;            ///< kg/m³ (blood)
  double viscosity = 3.5e-6;          ///< m²/s, kinematic (blood)
  double surfaceTension = 0.0;        ///< Akinci's γ
  Vec3 color{0.35, 0.01, 0.01};       ///< linear RGB: the surface's body colour, or the spheres' (blood)
  SceneFluidLook look;                ///< surface or spheres, and the surface's optics
  std::optional<SceneBox> container;  ///< walls of a box open at the top
  SceneBox region;                    ///< particles leaving it are recycled
  std::vector<SceneBox> blocks;       ///< fluid at the start
  std::vector<SceneFluidInlet> inlets;
  std::vector<SceneFluidSuction> suction;
  /// Objects the fluid flows around, by name: a static one's surface is a
  /// wall, a soft one's (tissue) deforms, pushes the fluid and bears its
  /// loads, a dynamic one floats, sinks and is carried (both two-way).
  std::vector<std::string> objects;

  bool operator==(const SceneFluid&) const = default;
};

/// What a run writes.
struct SceneOutputs {
  std::string directory = "out";  ///< relative to the working directory of the run
  bool frames = false;            ///< rendered frames as PNG
  int frameEvery = 1;             ///< keep every n-th frame, ≥ 1
  bool forces = false;            ///< haptic force trace (CSV)
  bool plot = false;              ///< force plot (PNG)
  bool summary = true;            ///< summary.json
  /// v2: the haptic device's stream as recording.dmrec (crash-safe, as the
  /// run goes), which `dmplatform replay` re-runs in lockstep
  bool recording = false;

  bool operator==(const SceneOutputs&) const = default;
};

/// A whole scene, as plain data. Names are unique within each kind.
struct SceneDesc {
  std::string name;
  std::filesystem::path baseDir;         ///< where relative sources resolve
  std::vector<SceneResource> resources;  ///< sorted by name
  std::vector<SceneMaterial> materials;  ///< sorted by name
  std::vector<SceneObject> objects;      ///< in file order
  std::vector<SceneVolume> volumes;
  std::vector<SceneLight> lights;
  std::vector<SceneCamera> cameras;
  std::vector<SceneDevice> devices;
  SceneEngines engines;
  SceneOutputs outputs;
  std::vector<SceneScript> scripts;  ///< v2, in file order
  std::vector<SceneFluid> fluids;    ///< v2, in file order

  /// Find by name; nullptr when there is none. O(n).
  const SceneResource* resource(std::string_view name) const;
  const SceneMaterial* material(std::string_view name) const;
  const SceneObject* object(std::string_view name) const;
  const SceneVolume* volume(std::string_view name) const;
  const SceneCamera* camera(std::string_view name) const;
  const SceneDevice* device(std::string_view name) const;

  bool operator==(const SceneDesc&) const = default;
};

/// Parses and validates a scene document. `sourceName` names it in errors
/// ("scene.json"); relative sources resolve against `baseDir`. On failure
/// the Error is the first problem with the others appended to its `what`,
/// and `problems` (if given) receives every problem, each with its own
/// where ("SOURCE: /json/pointer", or "SOURCE: byte N" for bad JSON) and
/// hint. Documents nested deeper than 64 levels are refused. O(size).
/// @code
///   auto s = dm::parseScene(text, "scene.json", "/data/scenes");
///   if (!s) return s.error();
///   const dm::SceneObject* skin = s->object("head_skin");
/// @endcode
Result<SceneDesc> parseScene(std::string_view json, std::string_view sourceName,
                             const std::filesystem::path& baseDir, std::vector<Error>* problems = nullptr);

/// Reads a scene file (at most 16 MiB) and parses it with its directory as
/// base; errors name the file. See parseScene().
/// @code
///   auto s = dm::readScene("examples/scenes/head_probe.json");
///   if (!s) { std::cerr << s.error() << '\n'; return 1; }
/// @endcode
Result<SceneDesc> readScene(const std::filesystem::path& file, std::vector<Error>* problems = nullptr);

/// One line per problem ("where: what (hint)\n"), for a console.
std::string formatSceneErrors(const std::vector<Error>& problems);

/// The scene as a version-2 document with every key written out (defaults
/// included); parseScene() of it gives back an equal SceneDesc (baseDir
/// aside, which is not stored).
/// @code
///   std::string text = dm::toJson(scene).dump(2);
/// @endcode
Json toJson(const SceneDesc& scene);

/// A device's config as driver parameters (dm::DeviceParams): strings as
/// they are, numbers in shortest round-trip form, booleans as "1"/"0",
/// arrays joined with commas ([0, 0, -0.004] → "0,0,-0.004"); file keys
/// (SceneDevice::files) as their resolved paths.
std::vector<std::pair<std::string, std::string>> deviceParams(const SceneDevice& device);

}  // namespace dm
