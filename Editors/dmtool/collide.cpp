// dmtool collide A B [--pose-a P] [--pose-b P] [--query boolean|contacts|distance]
// [--max-contacts N] [--unit U] [--json]: one narrow-phase query between two
// posed shapes through dm::intersect / dm::collide / dm::distance. A shape is
// a mesh file (any format Assimp reads) or a primitive spec (sphere:r,
// box:hx,hy,hz, capsule:r,halfLength, cylinder:r,halfLength,
// ellipsoid:rx,ry,rz; metres). Poses are "tx ty tz qw qx qy qz": translation
// in metres and a unit quaternion, local → world.
#include <dm/collide/query.hpp>
#include <dm/collide/shapes.hpp>
#include <dm/io/mesh_io.hpp>

#include <Eigen/Geometry>

#include <charconv>
#include <cmath>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include "common.hpp"

namespace dmtool {
namespace {

constexpr const char* kIdentityPose = "0 0 0 1 0 0 0";
constexpr double kUnitTolerance = 1e-6;

struct CollideCliOptions {
  std::string a, b;
  std::string poseA = kIdentityPose, poseB = kIdentityPose;
  std::string query = "boolean";
  int maxContacts = 4;
  std::string unit = "m";
  bool json = false;
};

// Splits `text` at spaces, tabs and commas into finite numbers; false on a
// token that is not one.
bool parseNumbers(const std::string& text, std::vector<double>& out) {
  out.clear();
  std::size_t i = 0;
  while (i < text.size()) {
    while (i < text.size() && (text[i] == ' ' || text[i] == '\t' || text[i] == ',')) ++i;
    if (i == text.size()) break;
    std::size_t j = i;
    while (j < text.size() && text[j] != ' ' && text[j] != '\t' && text[j] != ',') ++j;
    double v = 0;
    const auto [end, ec] = std::from_chars(text.data() + i, text.data() + j, v);
    if (ec != std::errc() || end != text.data() + j || !std::isfinite(v)) return false;
    out.push_back(v);
    i = j;
  }
  return true;
}

// "tx ty tz qw qx qy qz" → pose; the error text (empty when valid) for CLI11.
std::string parsePose(const std::string& text, dm::Isometry3* pose) {
  std::vector<double> v;
  if (!parseNumbers(text, v) || v.size() != 7)
    return "expected 7 finite numbers \"tx ty tz qw qx qy qz\" (metres, unit quaternion), got \"" + text +
           "\"";
  const Eigen::Quaterniond q(v[3], v[4], v[5], v[6]);
  if (std::abs(q.norm() - 1.0) > kUnitTolerance)
    return "quaternion (" + std::to_string(v[3]) + ", " + std::to_string(v[4]) + ", " + std::to_string(v[5]) +
           ", " + std::to_string(v[6]) + ") has norm " + std::to_string(q.norm()) +
           "; give a unit quaternion (qw qx qy qz, norm 1 within 1e-6)";
  if (pose) {
    pose->setIdentity();
    pose->linear() = q.normalized().toRotationMatrix();
    pose->translation() = dm::Vec3(v[0], v[1], v[2]);
  }
  return {};
}

struct PrimitiveKind {
  const char* name;
  std::size_t count;
  const char* parameters;
};
constexpr PrimitiveKind kPrimitives[] = {
    {"sphere", 1, "r"},
    {"box", 3, "hx,hy,hz"},
    {"capsule", 2, "r,halfLength"},
    {"cylinder", 2, "r,halfLength"},
    {"ellipsoid", 3, "rx,ry,rz"},
};

// The primitive kind named before the first ':' of `spec`, or null (a file).
const PrimitiveKind* primitiveKind(const std::string& spec) {
  const std::size_t colon = spec.find(':');
  if (colon == std::string::npos) return nullptr;
  for (const PrimitiveKind& k : kPrimitives)
    if (spec.compare(0, colon, k.name) == 0) return &k;
  return nullptr;
}

// Checks a primitive spec; the error text (empty when valid or a file name).
std::string checkPrimitive(const std::string& spec, dm::ShapePtr* shape) {
  const PrimitiveKind* k = primitiveKind(spec);
  if (!k) return {};
  std::vector<double> v;
  const std::string rest = spec.substr(spec.find(':') + 1);
  bool positive = parseNumbers(rest, v);
  for (double x : v) positive = positive && x > 0;
  if (!positive || v.size() != k->count)
    return "\"" + spec + "\": " + k->name + " takes " + std::to_string(k->count) +
           (k->count == 1 ? " positive number" : " positive numbers") + " in metres (" + k->name + ":" +
           k->parameters + ")";
  if (shape) {
    const std::string name = k->name;
    if (name == "sphere") *shape = std::make_shared<dm::Sphere>(v[0]);
    if (name == "box") *shape = std::make_shared<dm::Box>(dm::Vec3(v[0], v[1], v[2]));
    if (name == "capsule") *shape = std::make_shared<dm::Capsule>(v[0], v[1]);
    if (name == "cylinder") *shape = std::make_shared<dm::Cylinder>(v[0], v[1]);
    if (name == "ellipsoid") *shape = std::make_shared<dm::Ellipsoid>(dm::Vec3(v[0], v[1], v[2]));
  }
  return {};
}

// A primitive from its spec, else the mesh in file `spec` with its BVH.
dm::Result<dm::ShapePtr> loadShape(const std::string& spec, const std::string& unit) {
  dm::ShapePtr shape;
  if (primitiveKind(spec)) {
    checkPrimitive(spec, &shape);  // validated by the parser already
    return shape;
  }
  const std::filesystem::path file = resolveInput(spec);
  dm::MeshImportOptions import;
  import.unit = unit;
  auto mesh = dm::readMesh(file, import);
  if (!mesh) return mesh.error();
  auto made = dm::TriangleMesh::create(std::make_shared<const dm::Mesh>(std::move(*mesh)));
  if (!made) return made.error().within(file.string());
  return dm::ShapePtr(*made);
}

std::string vecText(const dm::Vec3& v) {
  return "(" + std::to_string(v.x()) + ", " + std::to_string(v.y()) + ", " + std::to_string(v.z()) + ")";
}

int runCollide(const CollideCliOptions& o) {
  dm::Isometry3 poseA, poseB;
  parsePose(o.poseA, &poseA);  // validated by the parser already
  parsePose(o.poseB, &poseB);
  auto a = loadShape(o.a, o.unit);
  if (!a) return printError(a.error());
  auto b = loadShape(o.b, o.unit);
  if (!b) return printError(b.error());
  const dm::Status supported = dm::ColliderTable::global().check(**a, **b);

  nlohmann::json j;
  j["query"] = o.query;
  std::string text;
  if (o.query == "distance") {
    const dm::DistanceResult d = dm::distance(**a, poseA, **b, poseB);
    j["distance"] = d.distance;
    j["pointA"] = toJson(d.pointA);
    j["pointB"] = toJson(d.pointB);
    j["supported"] = d.supported && supported.ok();
    text = "distance  " + std::to_string(d.distance) + " m" + (d.distance < 0 ? " (penetrating)" : "") +
           "\n  point A " + vecText(d.pointA) + "\n  point B " + vecText(d.pointB) + '\n';
  } else {
    dm::CollisionRequest request;
    request.contacts = o.query == "contacts";
    request.maxContacts = o.maxContacts;
    dm::CollisionResult r;
    dm::collide(**a, poseA, **b, poseB, request, r);
    j["colliding"] = r.colliding;
    j["supported"] = r.supported && supported.ok();
    text = r.colliding ? "colliding\n" : "not colliding\n";
    if (request.contacts) {
      nlohmann::json contacts = nlohmann::json::array();
      for (const dm::ContactPoint& c : r.contacts) {
        contacts.push_back(
            {{"position", toJson(c.position)}, {"normal", toJson(c.normal)}, {"depth", c.depth}});
        text += "  contact " + vecText(c.position) + " normal " + vecText(c.normal) + " depth " +
                std::to_string(c.depth) + " m\n";
      }
      j["contacts"] = std::move(contacts);
    }
  }
  if (o.json)
    printJson(j);
  else
    std::cout << text;
  if (!supported) return printError(supported.error());
  return kExitOk;
}

}  // namespace

Command addCollideCommand(CLI::App& parent) {
  auto o = std::make_shared<CollideCliOptions>();
  CLI::App* app = parent.add_subcommand(
      "collide", "Narrow-phase query between two posed shapes: boolean, contacts or signed distance");
  app->footer(
      "Shapes: a mesh file (any format Assimp reads) or a primitive in metres,\n"
      "centred at its local origin:\n"
      "  sphere:r   box:hx,hy,hz (half extents)   capsule:r,halfLength (along z)\n"
      "  cylinder:r,halfLength (along z)   ellipsoid:rx,ry,rz\n"
      "Poses: \"tx ty tz qw qx qy qz\", translation in metres and a unit quaternion (norm 1 within 1e-6),\n"
      "mapping the shape's local frame to the world. Results are in the world frame, metres; normals\n"
      "point from A to B; distance < 0 is the penetration depth.\n"
      "JSON: boolean {\"colliding\",\"supported\"}; contacts adds \"contacts\":[{\"position\",\"normal\","
      "\"depth\"}];\n"
      "distance {\"distance\",\"pointA\",\"pointB\",\"supported\"}.");
  const CLI::Validator shapeSpec([](std::string& s) { return checkPrimitive(s, nullptr); }, "SHAPE");
  const CLI::Validator pose([](std::string& s) { return parsePose(s, nullptr); }, "\"tx ty tz qw qx qy qz\"");
  app->add_option("a", o->a, "shape A: mesh file or primitive spec (see below)")
      ->required()
      ->check(shapeSpec);
  app->add_option("b", o->b, "shape B: mesh file or primitive spec")->required()->check(shapeSpec);
  app->add_option("--pose-a", o->poseA, "pose of A: \"tx ty tz qw qx qy qz\" (m, unit quaternion)")
      ->check(pose)
      ->capture_default_str();
  app->add_option("--pose-b", o->poseB, "pose of B, as --pose-a")->check(pose)->capture_default_str();
  app->add_option("--query", o->query, "boolean, contacts or distance")
      ->check(CLI::IsMember({"boolean", "contacts", "distance"}))
      ->capture_default_str();
  app->add_option("--max-contacts", o->maxContacts, "most contacts reported by --query contacts")
      ->check(CLI::Range(1, 1024))
      ->capture_default_str();
  app->add_option("--unit", o->unit, "length unit of mesh files: m, cm, mm, um, inch, ft")
      ->check(CLI::IsMember({"m", "cm", "mm", "um", "inch", "in", "ft"}));
  app->add_flag("--json", o->json, "print one JSON object on stdout");
  return {app, [o] { return runCollide(*o); }};
}

}  // namespace dmtool
