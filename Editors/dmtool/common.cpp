#include "common.hpp"

#include <dm/core/filesystem.hpp>
#include <dm/math/mass_properties.hpp>

#include <cmath>
#include <cstdio>
#include <iostream>
#include <sstream>

namespace dmtool {

int printError(const dm::Error& error) {
  std::cerr << "dmtool: error: " << error.message() << '\n';
  return kExitFailure;
}

void printJson(const nlohmann::json& value) {
  // Replace invalid UTF-8 (file and mesh names) instead of throwing.
  std::cout << value.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace) << '\n';
}

std::filesystem::path resolveInput(const std::string& name) {
  auto resolved = dm::FileSystem::global().resolve(name);
  return resolved ? *resolved : std::filesystem::path(name);
}

nlohmann::json toJson(const dm::Vec3& v) { return nlohmann::json::array({v.x(), v.y(), v.z()}); }

MeshSummary summarize(const dm::Mesh& mesh) {
  MeshSummary s;
  s.name = mesh.name;
  s.topology = dm::analyzeTopology(mesh);
  s.bounds = mesh.bounds();
  s.vertices = mesh.vertexCount();
  if (s.topology.isClosed && s.topology.isManifold && s.topology.isOrientedConsistently) {
    // Fails for inside-out or flat meshes: then there is no solid to report.
    if (auto mp = dm::computeMassProperties(mesh)) {
      s.volume = mp->volume;
      s.centroid = mp->centroid;
    }
  }
  return s;
}

nlohmann::json toJson(const MeshSummary& s) {
  const dm::MeshTopology& t = s.topology;
  nlohmann::json j;
  j["name"] = s.name;
  j["vertices"] = s.vertices;
  j["triangles"] = t.triangles;
  j["edges"] = t.edges;
  j["components"] = t.components;
  j["degenerateTriangles"] = t.degenerateTriangles;
  j["boundaryEdges"] = t.boundaryEdges;
  j["nonManifoldEdges"] = t.nonManifoldEdges;
  j["nonManifoldVertices"] = t.nonManifoldVertices;
  j["watertight"] = t.isClosed;
  j["manifold"] = t.isManifold;
  j["oriented"] = t.isOrientedConsistently;
  j["eulerCharacteristic"] = t.eulerCharacteristic;
  j["genus"] = t.genus ? nlohmann::json(*t.genus) : nlohmann::json(nullptr);
  j["bounds"] = {{"min", toJson(s.bounds.min())}, {"max", toJson(s.bounds.max())}};
  j["size"] = toJson(s.bounds.sizes());
  j["area"] = t.surfaceArea;
  j["volume"] = s.volume ? nlohmann::json(*s.volume) : nlohmann::json(nullptr);
  j["centroid"] = s.centroid ? toJson(*s.centroid) : nlohmann::json(nullptr);
  return j;
}

namespace {

std::string vec(const dm::Vec3& v) {
  char buf[96];
  std::snprintf(buf, sizeof buf, "[%.6g %.6g %.6g]", v.x(), v.y(), v.z());
  return buf;
}

const char* yesNo(bool b) { return b ? "yes" : "no"; }

}  // namespace

std::string toText(const MeshSummary& s) {
  const dm::MeshTopology& t = s.topology;
  std::ostringstream os;
  os << "  vertices   " << s.vertices << "\n  triangles  " << t.triangles << " (" << t.degenerateTriangles
     << " degenerate)\n  bounds     " << vec(s.bounds.min()) << " .. " << vec(s.bounds.max())
     << " m\n  size       " << vec(s.bounds.sizes()) << " m\n  watertight " << yesNo(t.isClosed) << " ("
     << t.boundaryEdges << " boundary edges)\n  manifold   " << yesNo(t.isManifold) << " ("
     << t.nonManifoldEdges << " non-manifold edges, " << t.nonManifoldVertices
     << " non-manifold vertices)\n  oriented   " << yesNo(t.isOrientedConsistently) << "\n  components "
     << t.components << "\n  area       " << t.surfaceArea << " m^2\n";
  if (s.volume)
    os << "  volume     " << *s.volume << " m^3\n  centroid   " << vec(*s.centroid) << " m\n";
  else
    os << "  volume     - (not a closed, consistently oriented manifold)\n";
  return os.str();
}

const CLI::Validator& finiteNumber() {
  static const CLI::Validator v(
      [](std::string& text) -> std::string {
        try {
          std::size_t used = 0;
          const double d = std::stod(text, &used);
          if (used != text.size() || !std::isfinite(d)) return "not a finite number: " + text;
        } catch (const std::exception&) {
          return "not a number: " + text;
        }
        return {};
      },
      "FINITE");
  return v;
}

}  // namespace dmtool
