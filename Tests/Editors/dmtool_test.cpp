// dmtool end to end: runs the built executable (DMTOOL_PATH) with
// posix_spawn, captures stdout, stderr and the exit status, and checks the
// numbers it prints against the geometry of the inputs (a unit box, the
// NIfTI sform of Colin27 read independently from the file's header bytes).
// DmtoolAcceptance.InfoOnEveryAssimpModel walks all of assimp-testmodels; it
// is compiled alone (DMTOOL_ACCEPTANCE) into Editors_acceptance_tests, which
// Tests/Editors/CMakeLists.txt labels "acceptance" with its own timeout.
#include <dm/core/filesystem.hpp>
#include <dm/io/mesh_io.hpp>
#include <dm/io/vdb.hpp>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <future>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "dmtool_run.hpp"

namespace {

namespace fs = std::filesystem;
using dmtool_test::describe;
using dmtool_test::parseJson;
using dmtool_test::runTool;
using dmtool_test::TempDir;
using dmtool_test::ToolRun;
using nlohmann::json;

[[maybe_unused]] std::string assimpModel(const char* rel) {
  return (fs::path("/usr/share/assimp/models") / rel).string();
}

// A small volume (91 x 109 x 91 labels at 2 mm) for tests that need any volume.
[[maybe_unused]] std::string smallVolume() {
  auto p = dm::FileSystem::global().resolve("mricron:JHU-WhiteMatter-labels-2mm.nii.gz");
  return p ? p->string() : std::string();
}

[[maybe_unused]] std::string ch2() {
  auto p = dm::FileSystem::global().resolve("mricron:ch2.nii.gz");
  return p ? p->string() : std::string();
}

[[maybe_unused]] double vecDiff(json a, json b) {
  double d = 0;
  for (int i = 0; i < 3; ++i) d = std::max(d, std::abs(a[i].get<double>() - b[i].get<double>()));
  return d;
}

#if !defined(DMTOOL_ACCEPTANCE)

TEST(Dmtool, InfoJsonOfTheUnitBoxMatchesItsGeometry) {
  const ToolRun r = runTool({"info", assimpModel("OBJ/box.obj"), "--json"});
  ASSERT_EQ(r.exitCode, 0) << describe(r);
  json j = parseJson(r);
  EXPECT_EQ(j["kind"], "mesh");
  json& t = j["total"];
  // 8 corners; 6 quads -> 12 triangles; 18 edges; Euler characteristic 2.
  EXPECT_EQ(t["vertices"], 8);
  EXPECT_EQ(t["triangles"], 12);
  EXPECT_EQ(t["edges"], 18);
  EXPECT_EQ(t["eulerCharacteristic"], 2);
  EXPECT_TRUE(t["watertight"].get<bool>());
  EXPECT_TRUE(t["manifold"].get<bool>());
  EXPECT_LT(vecDiff(t["bounds"]["min"], json::array({-0.5, -0.5, -0.5})), 1e-12);
  EXPECT_LT(vecDiff(t["bounds"]["max"], json::array({0.5, 0.5, 0.5})), 1e-12);
  // A box's volume is the product of its extents, its area 2(ab + bc + ca).
  json& size = t["size"];
  const double a = size[0], b = size[1], c = size[2];
  EXPECT_NEAR(t["volume"].get<double>(), a * b * c, 1e-12);
  EXPECT_NEAR(t["area"].get<double>(), 2 * (a * b + b * c + c * a), 1e-12);
  EXPECT_LT(vecDiff(t["centroid"], json::array({0, 0, 0})), 1e-12);
  ASSERT_EQ(j["meshes"].size(), 1u);
  EXPECT_EQ(j["meshes"][0]["triangles"], 12);
  EXPECT_TRUE(r.err.empty()) << r.err;
}

TEST(Dmtool, InfoTextIsHumanReadable) {
  const ToolRun r = runTool({"info", assimpModel("OBJ/box.obj")});
  ASSERT_EQ(r.exitCode, 0) << describe(r);
  EXPECT_NE(r.out.find("triangles  12"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("watertight yes"), std::string::npos) << r.out;
}

// Fields of a NIfTI-1 header read from the decompressed bytes, independently
// of DMIO: dim[1..3] (int16 at 42), pixdim[1..3] (float32 at 80, mm) and the
// sform rows srow_x/y/z (float32[4] at 280, 296, 312; mm).
struct NiftiHeader {
  std::int16_t dim[8];
  float pixdim[8];
  float srow[3][4];
};
bool readNiftiHeader(const std::string& file, NiftiHeader& h) {
  FILE* p = popen(("gzip -dc '" + file + "'").c_str(), "r");
  if (!p) return false;
  std::vector<char> header(348);
  const std::size_t n = std::fread(header.data(), 1, header.size(), p);
  while (std::fgetc(p) != EOF) {
  }
  pclose(p);
  if (n != header.size()) return false;
  std::memcpy(h.dim, header.data() + 40, sizeof h.dim);
  std::memcpy(h.pixdim, header.data() + 76, sizeof h.pixdim);
  std::memcpy(h.srow, header.data() + 280, sizeof h.srow);
  return true;
}

TEST(Dmtool, InfoJsonOfColin27HasItsDimsAndSformInMetres) {
  const std::string file = ch2();
  ASSERT_FALSE(file.empty()) << "mricron-data is not installed";
  const ToolRun r = runTool({"info", "--json", file});
  ASSERT_EQ(r.exitCode, 0) << describe(r);
  json j = parseJson(r);
  EXPECT_EQ(j["kind"], "volume");
  NiftiHeader h;
  ASSERT_TRUE(readNiftiHeader(file, h));
  EXPECT_EQ(j["dims"], json::array({h.dim[1], h.dim[2], h.dim[3]}));
  EXPECT_EQ(j["dims"], json::array({181, 217, 181}));  // Colin27 at 1 mm
  json& m = j["indexToWorld"];
  for (int r0 = 0; r0 < 3; ++r0)
    for (int c = 0; c < 4; ++c)
      EXPECT_NEAR(m[r0][c].get<double>(), 1e-3 * h.srow[r0][c], 1e-9) << r0 << ',' << c;
  EXPECT_EQ(m[3], json::array({0, 0, 0, 1}));
  json spacing = json::array({1e-3 * h.pixdim[1], 1e-3 * h.pixdim[2], 1e-3 * h.pixdim[3]});
  EXPECT_LT(vecDiff(j["spacing"], spacing), 1e-9);
  EXPECT_LE(j["range"][0].get<double>(), j["range"][1].get<double>());
  EXPECT_TRUE(j["datatype"].is_string());
}

TEST(Dmtool, InfoResolvesMountNames) {
  ASSERT_FALSE(ch2().empty()) << "mricron-data is not installed";
  const ToolRun r = runTool({"info", "--json", "mricron:ch2.nii.gz"});
  ASSERT_EQ(r.exitCode, 0) << describe(r);
  EXPECT_EQ(parseJson(r)["dims"], json::array({181, 217, 181}));
}

TEST(Dmtool, ConvertStlToPlyKeepsCountsAndBounds) {
  TempDir tmp;
  const std::string in = assimpModel("STL/Spider_binary.stl");
  const std::string out = (tmp.path / "spider.ply").string();
  const ToolRun c = runTool({"convert", in, out});
  ASSERT_EQ(c.exitCode, 0) << describe(c);
  const ToolRun a = runTool({"info", "--json", in});
  const ToolRun b = runTool({"info", "--json", out});
  ASSERT_EQ(a.exitCode, 0) << describe(a);
  ASSERT_EQ(b.exitCode, 0) << describe(b);
  json ja = parseJson(a)["total"], jb = parseJson(b)["total"];
  EXPECT_EQ(ja["vertices"], jb["vertices"]);
  EXPECT_EQ(ja["triangles"], jb["triangles"]);
  EXPECT_GT(jb["triangles"].get<int>(), 0);
  // STL holds float32, PLY doubles: the positions survive exactly.
  EXPECT_EQ(vecDiff(ja["bounds"]["min"], jb["bounds"]["min"]), 0.0);
  EXPECT_EQ(vecDiff(ja["bounds"]["max"], jb["bounds"]["max"]), 0.0);
}

TEST(Dmtool, ConvertScalesMeshLengthsAndVolume) {
  TempDir tmp;
  const std::string out = (tmp.path / "box2.obj").string();
  const ToolRun c = runTool({"convert", assimpModel("OBJ/box.obj"), out, "--scale", "2"});
  ASSERT_EQ(c.exitCode, 0) << describe(c);
  const ToolRun i = runTool({"info", "--json", out});
  ASSERT_EQ(i.exitCode, 0) << describe(i);
  json t = parseJson(i)["total"];
  EXPECT_LT(vecDiff(t["size"], json::array({2, 2, 2})), 1e-12);
  EXPECT_NEAR(t["volume"].get<double>(), 8.0, 1e-12);  // volume scales with s³
}

TEST(Dmtool, ConvertVolumeScalesTheAffine) {
  const std::string file = smallVolume();
  ASSERT_FALSE(file.empty()) << "mricron-data is not installed";
  TempDir tmp;
  const std::string out = (tmp.path / "labels.nrrd").string();
  const ToolRun c = runTool({"convert", file, out, "--scale", "0.5"});
  ASSERT_EQ(c.exitCode, 0) << describe(c);
  const ToolRun a = runTool({"info", "--json", file});
  const ToolRun b = runTool({"info", "--json", out});
  ASSERT_EQ(b.exitCode, 0) << describe(b);
  json ja = parseJson(a), jb = parseJson(b);
  EXPECT_EQ(ja["dims"], jb["dims"]);
  EXPECT_EQ(ja["range"], jb["range"]);
  for (int r0 = 0; r0 < 3; ++r0)
    for (int col = 0; col < 4; ++col)
      EXPECT_NEAR(jb["indexToWorld"][r0][col].get<double>(), 0.5 * ja["indexToWorld"][r0][col].get<double>(),
                  1e-9);
}

TEST(Dmtool, IsosurfaceOfColin27IsAClosedManifold) {
  const std::string file = ch2();
  ASSERT_FALSE(file.empty()) << "mricron-data is not installed";
  TempDir tmp;
  const std::string out = (tmp.path / "skin.stl").string();
  // iso 40 equals voxel values of this uint8 scan (what people type).
  const ToolRun r = runTool({"isosurface", file, "--iso", "40", "--close-borders", "-o", out, "--json"});
  ASSERT_EQ(r.exitCode, 0) << describe(r);
  json j = parseJson(r);
  EXPECT_TRUE(j["watertight"].get<bool>());
  EXPECT_TRUE(j["manifold"].get<bool>());
  EXPECT_TRUE(j["oriented"].get<bool>());
  // A head holds a few litres.
  ASSERT_TRUE(j["volume"].is_number());
  EXPECT_GT(j["volume"].get<double>(), 1.5e-3);
  EXPECT_LT(j["volume"].get<double>(), 6e-3);
  EXPECT_GT(j["area"].get<double>(), 0.0);
  // The file written holds the mesh reported: a binary STL has an 84-byte
  // header and 50 bytes per triangle.
  EXPECT_EQ(fs::file_size(out), 84u + 50u * j["triangles"].get<std::uintmax_t>());
  // Colin27's head spans about ±90 mm in x around the MNI origin.
  EXPECT_NEAR(j["bounds"]["min"][0].get<double>(), -0.090, 0.005);
  EXPECT_NEAR(j["bounds"]["max"][0].get<double>(), 0.090, 0.005);
}

TEST(Dmtool, IsosurfaceSmoothedWithinItsBoundKeepsTheHead) {
  // The staircase of the 1 mm scan smoothed away with every vertex kept
  // within half a voxel: still a closed manifold, the head's volume within
  // 1 %, and the file read back (welded by position) is the same surface.
  const std::string file = ch2();
  ASSERT_FALSE(file.empty()) << "mricron-data is not installed";
  TempDir tmp;
  const std::string raw = (tmp.path / "raw.ply").string(), smooth = (tmp.path / "smooth.ply").string();
  const ToolRun a = runTool(
      {"isosurface", file, "--iso", "40", "--close-borders", "--largest-component", "-o", raw, "--json"});
  const ToolRun b =
      runTool({"isosurface", file, "--iso", "40", "--close-borders", "--largest-component", "--smooth", "10",
               "--smooth-max-displacement", "0.0005", "-o", smooth, "--json"});
  ASSERT_EQ(a.exitCode, 0) << describe(a);
  ASSERT_EQ(b.exitCode, 0) << describe(b);
  json ja = parseJson(a), jb = parseJson(b);
  EXPECT_GT(ja["components_dropped"].get<int>(), 0);  // specks outside the head
  EXPECT_EQ(jb["triangles"], ja["triangles"]);
  EXPECT_TRUE(jb["watertight"].get<bool>() && jb["manifold"].get<bool>() && jb["oriented"].get<bool>());
  EXPECT_EQ(jb["smooth"]["iterations"], 10);
  EXPECT_LE(jb["smooth"]["max_displacement_m"].get<double>(), 0.0005 * (1 + 1e-9));
  EXPECT_GT(jb["smooth"]["mean_displacement_m"].get<double>(), 0.05e-3);  // the staircase did move
  EXPECT_NEAR(jb["volume"].get<double>(), ja["volume"].get<double>(), 0.01 * ja["volume"].get<double>());
  const ToolRun info = runTool({"info", smooth, "--json"});
  ASSERT_EQ(info.exitCode, 0) << describe(info);
  json ji = parseJson(info);
  ASSERT_EQ(ji["meshes"].size(), 1u) << ji.dump();
  const json& mi = ji["meshes"][0];
  EXPECT_EQ(mi["vertices"], jb["vertices"]);
  EXPECT_TRUE(mi["watertight"].get<bool>() && mi["manifold"].get<bool>() && mi["oriented"].get<bool>());
}

TEST(Dmtool, IsosurfaceMarchingTetrahedraGivesMoreTriangles) {
  const std::string in = smallVolume();
  ASSERT_FALSE(in.empty()) << "mricron-data is not installed";
  TempDir tmp;
  const ToolRun mc =
      runTool({"isosurface", in, "--iso", "0.5", "-o", (tmp.path / "mc.stl").string(), "--json"});
  const ToolRun mt = runTool(
      {"isosurface", in, "--iso", "0.5", "--method", "mt", "-o", (tmp.path / "mt.stl").string(), "--json"});
  ASSERT_EQ(mc.exitCode, 0) << describe(mc);
  ASSERT_EQ(mt.exitCode, 0) << describe(mt);
  json a = parseJson(mc), b = parseJson(mt);
  // Six tetrahedra per cube cut the same surface into more triangles.
  EXPECT_GT(b["triangles"].get<double>(), 1.5 * a["triangles"].get<double>());
  EXPECT_EQ(b["method"], "mt");
  // Both put their vertices on the same crossed grid edges, so the extreme
  // vertices agree to within a voxel (2 mm).
  EXPECT_LT(vecDiff(a["bounds"]["min"], b["bounds"]["min"]), 2e-3);
  EXPECT_LT(vecDiff(a["bounds"]["max"], b["bounds"]["max"]), 2e-3);
}

TEST(Dmtool, ProgressBarOnlyOnATerminalAndMonotone) {
  const std::string file = smallVolume();
  ASSERT_FALSE(file.empty()) << "mricron-data is not installed";
  TempDir tmp;
  const std::vector<std::string> args = {
      "isosurface", file, "--iso", "0.5", "-o", (tmp.path / "wm.stl").string(), "--json"};
  const ToolRun piped = runTool(args);
  ASSERT_EQ(piped.exitCode, 0) << describe(piped);
  EXPECT_TRUE(piped.err.empty()) << piped.err;  // stderr is a pipe: no bar
  const ToolRun tty = runTool(args, 60.0, true);
  ASSERT_EQ(tty.exitCode, 0) << describe(tty);
  EXPECT_EQ(parseJson(tty)["triangles"], parseJson(piped)["triangles"]);  // stdout unaffected
  // The bar redraws "isosurface [###...] NN%" in place: percentages rise to 100.
  std::vector<int> percents;
  for (std::size_t at = tty.err.find("isosurface ["); at != std::string::npos;
       at = tty.err.find("isosurface [", at + 1)) {
    const std::size_t close = tty.err.find(']', at);
    ASSERT_NE(close, std::string::npos);
    percents.push_back(std::atoi(tty.err.c_str() + close + 1));
  }
  ASSERT_FALSE(percents.empty()) << tty.err;
  EXPECT_TRUE(std::is_sorted(percents.begin(), percents.end())) << tty.err;
  EXPECT_EQ(percents.back(), 100);
  EXPECT_LE(percents.size(), 101u);
}

// A UV sphere of radius r centred at the origin (closed, outward CCW), as OBJ.
void writeSphereObj(const fs::path& file, double r, int slices, int stacks) {
  std::ofstream f(file);
  f.precision(17);
  f << "v 0 0 " << r << "\n";
  for (int i = 1; i < stacks; ++i) {
    const double theta = M_PI * i / stacks;
    for (int j = 0; j < slices; ++j) {
      const double phi = 2 * M_PI * j / slices;
      f << "v " << r * std::sin(theta) * std::cos(phi) << ' ' << r * std::sin(theta) * std::sin(phi) << ' '
        << r * std::cos(theta) << "\n";
    }
  }
  f << "v 0 0 " << -r << "\n";
  const auto ring = [&](int i, int j) { return 2 + (i - 1) * slices + (j % slices); };  // 1-based OBJ index
  const int south = 2 + (stacks - 1) * slices;
  for (int j = 0; j < slices; ++j) {
    f << "f 1 " << ring(1, j) << ' ' << ring(1, j + 1) << "\n";
    for (int i = 1; i + 1 < stacks; ++i)
      f << "f " << ring(i, j) << ' ' << ring(i + 1, j) << ' ' << ring(i + 1, j + 1) << ' ' << ring(i, j + 1)
        << "\n";
    f << "f " << ring(stacks - 1, j) << ' ' << south << ' ' << ring(stacks - 1, j + 1) << "\n";
  }
}

TEST(Dmtool, SimplifyKeepsASphereClosedAndWithinMaxError) {
  TempDir tmp;
  constexpr double kR = 0.1, kMaxError = 2e-3;
  const fs::path in = tmp.path / "sphere.obj", out = tmp.path / "sphere_lod.ply";
  writeSphereObj(in, kR, 64, 32);
  const ToolRun r = runTool(
      {"simplify", in.string(), "--ratio", "0.2", "--max-error", "0.002", "-o", out.string(), "--json"});
  ASSERT_EQ(r.exitCode, 0) << describe(r);
  json j = parseJson(r);
  const std::size_t before = j["trianglesBefore"], after = j["trianglesAfter"];
  EXPECT_EQ(before, 2u * 64 * 31);  // two triangles per quad, one per pole fan
  EXPECT_LT(after, before);
  EXPECT_LE(after, before / 5 + 2);
  EXPECT_EQ(j["triangles"], after);
  EXPECT_TRUE(j["watertight"].get<bool>());
  EXPECT_TRUE(j["manifold"].get<bool>());
  EXPECT_EQ(j["genus"], 0);
  EXPECT_LE(j["maxDistance"].get<double>(), kMaxError);
  // The volume of the LOD stays near the ball's 4/3 π r³ (the input
  // polyhedron is inscribed, so within its own sag plus the error bound).
  const double ball = 4.0 / 3.0 * M_PI * kR * kR * kR;
  EXPECT_NEAR(j["volume"].get<double>() / ball, 1.0, 0.05);
  // Every vertex of the written file lies within the error of the sphere
  // (inside by at most the input's sag r(1 − cos(π/32)) plus the error).
  auto lod = dm::readMesh(out);
  ASSERT_TRUE(lod) << lod.error();
  EXPECT_EQ(lod->triangleCount(), after);
  const double sag = kR * (1 - std::cos(M_PI / 32));
  for (const dm::Vec3& p : lod->positions) {
    EXPECT_LE(p.norm(), kR + kMaxError + 1e-9);
    EXPECT_GE(p.norm(), kR - sag - kMaxError - 1e-9);
  }
}

TEST(Dmtool, VoxelizeTheUnitBoxCountsItsInteriorCentres) {
  TempDir tmp;
  const std::string out = (tmp.path / "box.nii.gz").string();
  // Centres on the lattice 0.03·k: |0.03 k| < 0.5 for k = −16..16, and none
  // lies on a face, so exactly 33³ centres are inside.
  const ToolRun r =
      runTool({"voxelize", assimpModel("OBJ/box.obj"), "--voxel-size", "0.03", "-o", out, "--json"});
  ASSERT_EQ(r.exitCode, 0) << describe(r);
  json j = parseJson(r);
  EXPECT_EQ(j["insideVoxels"], 33 * 33 * 33);
  EXPECT_NEAR(j["insideVolume"].get<double>(), std::pow(33 * 0.03, 3), 1e-9);
  EXPECT_EQ(j["datatype"], "uint8");
  EXPECT_EQ(j["range"], json::array({0, 1}));
  // The written file has the same grid.
  const ToolRun i = runTool({"info", "--json", out});
  ASSERT_EQ(i.exitCode, 0) << describe(i);
  json v = parseJson(i);
  EXPECT_EQ(v["dims"], j["dims"]);
  EXPECT_LT(vecDiff(v["spacing"], json::array({0.03, 0.03, 0.03})), 1e-9);
}

// Distance from p to the box [-0.5, 0.5]³ from outside (0 inside).
double distanceToUnitBox(const dm::Vec3& p) {
  return (p.cwiseAbs() - dm::Vec3::Constant(0.5)).cwiseMax(0.0).norm();
}

TEST(Dmtool, VoxelizeSignedDistanceOfTheUnitBox) {
  TempDir tmp;
  constexpr double kH = 0.05;
  for (const char* name : {"box_sdf.nii.gz", "box_sdf.vdb"}) {
    const std::string out = (tmp.path / name).string();
    const ToolRun r = runTool(
        {"voxelize", assimpModel("OBJ/box.obj"), "--voxel-size", "0.05", "--sdf", "-o", out, "--json"});
    ASSERT_EQ(r.exitCode, 0) << name << '\n' << describe(r);
    json j = parseJson(r);
    EXPECT_EQ(j["datatype"], "float32");
    // The centre voxel (0, 0, 0) is 0.5 m from every face: the minimum.
    EXPECT_NEAR(j["range"][0].get<double>(), -0.5, 1e-6);
    // The largest distance is at a corner voxel of the grid (the farther of
    // the first and the last centre), to the nearest box corner.
    const dm::Vec3 first(j["origin"][0].get<double>(), j["origin"][1].get<double>(),
                         j["origin"][2].get<double>());
    const dm::Vec3 last =
        first + kH * dm::Vec3(j["dims"][0].get<double>() - 1, j["dims"][1].get<double>() - 1,
                              j["dims"][2].get<double>() - 1);
    const double farthest = std::max(distanceToUnitBox(first), distanceToUnitBox(last));
    EXPECT_GT(farthest, kH);  // at least the padding is outside
    EXPECT_NEAR(j["range"][1].get<double>(), farthest, 1e-6);
    EXPECT_GT(fs::file_size(out), 0u);
  }
  // The .vdb is a level set: within its narrow band (3 voxels) it holds the
  // distance, e.g. one voxel outside the +x face.
  auto vdb = dm::readVdb(tmp.path / "box_sdf.vdb");
  ASSERT_TRUE(vdb) << vdb.error();
  EXPECT_NEAR(vdb->sampleWorld(dm::Vec3(0.5 + kH, 0, 0)), kH, 1e-6);
  EXPECT_NEAR(vdb->sampleWorld(dm::Vec3(0.5 - kH, 0, 0)), -kH, 1e-6);
}

TEST(Dmtool, MissingFileFailsWithItsNameOnStderrAndNothingOnStdout) {
  for (const char* name : {"/nonexistent/dir/liver.stl", "/nonexistent/dir/head.nii.gz"}) {
    const ToolRun r = runTool({"info", "--json", name});
    EXPECT_EQ(r.exitCode, 1) << describe(r);
    EXPECT_EQ(r.signal, 0);
    EXPECT_TRUE(r.out.empty()) << r.out;
    EXPECT_NE(r.err.find(name), std::string::npos) << r.err;
  }
}

TEST(Dmtool, InfoRefusesAHeaderWhoseDataFileLeavesItsFolder) {
  // issue 37: a MetaImage header naming ../outside/secret.raw made `dmtool
  // info` print that file's bytes as voxel statistics. Now the reference is
  // refused (exit 1, the field and DM_ALLOW_PATH on stderr) unless allowed.
  TempDir tmp;
  fs::create_directories(tmp.path / "case");
  fs::create_directories(tmp.path / "outside");
  std::ofstream(tmp.path / "outside" / "secret.raw", std::ios::binary) << "ABCDEFGH";
  std::ofstream(tmp.path / "case" / "evil.mhd")
      << "NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\nElementDataFile = ../outside/secret.raw\n";
  const std::string header = (tmp.path / "case" / "evil.mhd").string();
  ToolRun r = runTool({"info", "--json", header});
  EXPECT_EQ(r.exitCode, 1) << describe(r);
  EXPECT_TRUE(r.out.empty()) << r.out;
  EXPECT_NE(r.err.find("ElementDataFile (line 4)"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("DM_ALLOW_PATH"), std::string::npos) << r.err;
  // Allowed explicitly, the same header reads the eight voxels 'A'..'H'.
  ASSERT_EQ(::setenv("DM_ALLOW_PATH", (tmp.path / "outside").c_str(), 1), 0);
  r = runTool({"info", "--json", header});
  ::unsetenv("DM_ALLOW_PATH");
  ASSERT_EQ(r.exitCode, 0) << describe(r);
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["dims"], nlohmann::json::array({2, 2, 2}));
  EXPECT_EQ(j["range"][0].get<double>(), 'A') << r.out;
  EXPECT_EQ(j["range"][1].get<double>(), 'H') << r.out;
}

TEST(Dmtool, OperationErrorsExitOne) {
  TempDir tmp;
  // A mesh cannot become a volume file by conversion.
  ToolRun r = runTool({"convert", assimpModel("OBJ/box.obj"), (tmp.path / "box.nii.gz").string()});
  EXPECT_EQ(r.exitCode, 1) << describe(r);
  EXPECT_NE(r.err.find("voxelize"), std::string::npos) << r.err;
  // An unknown output format is refused and nothing is written.
  r = runTool({"convert", assimpModel("OBJ/box.obj"), (tmp.path / "box.xyz").string()});
  EXPECT_EQ(r.exitCode, 1) << describe(r);
  EXPECT_FALSE(fs::exists(tmp.path / "box.xyz"));
  // An iso above every voxel gives no surface.
  if (!smallVolume().empty()) {
    r = runTool({"isosurface", smallVolume(), "--iso", "1e9", "-o", (tmp.path / "none.stl").string()});
    EXPECT_EQ(r.exitCode, 1) << describe(r);
    EXPECT_NE(r.err.find("empty"), std::string::npos) << r.err;
  }
}

TEST(Dmtool, UsageErrorsExitTwo) {
  const std::vector<std::vector<std::string>> bad = {
      {},                                               // no subcommand
      {"frobnicate"},                                   // unknown subcommand
      {"info"},                                         // missing FILE
      {"info", "a.stl", "--bogus"},                     // unknown option
      {"convert", "a.stl", "b.stl", "--scale", "-1"},   // non-positive scale
      {"convert", "a.stl", "b.stl", "--scale", "nan"},  // non-finite scale
      {"isosurface", "v.nii", "-o", "m.stl"},           // missing --iso
      {"isosurface", "v.nii", "--iso", "1", "-o", "m.stl", "--method", "xx"},
      {"isosurface", "v.nii", "--iso", "1", "-o", "m.stl", "--smooth", "101"},
      {"isosurface", "v.nii", "--iso", "1", "-o", "m.stl", "--smooth", "5", "--smooth-max-displacement", "0"},
      {"isosurface", "v.nii", "--iso", "1", "-o", "m.stl", "--smooth-max-displacement",
       "0.001"},  // no --smooth
      {"simplify", "a.stl", "-o", "b.stl", "--ratio", "1.5"},
      {"simplify", "a.stl", "-o", "b.stl", "--ratio", "0"},
      {"simplify", "a.stl", "-o", "b.stl", "--max-error", "-1"},
      {"voxelize", "a.stl", "-o", "b.nii.gz"},                       // missing --voxel-size
      {"voxelize", "a.stl", "-o", "b.nii.gz", "--voxel-size", "0"},  // non-positive size  // bad method
  };
  // Independent runs, so they go in parallel (each one is mostly process start-up).
  std::vector<std::future<ToolRun>> runs;
  for (const auto& args : bad)
    runs.push_back(std::async(std::launch::async, [&args] { return runTool(args); }));
  for (std::size_t i = 0; i < bad.size(); ++i) {
    const ToolRun r = runs[i].get();
    const std::string what = bad[i].empty() ? std::string("(no arguments)") : bad[i][0];
    EXPECT_EQ(r.exitCode, 2) << what << '\n' << describe(r);
    EXPECT_TRUE(r.out.empty()) << what << ": " << r.out;
    EXPECT_FALSE(r.err.empty()) << what;
  }
  const ToolRun help = runTool({"--help"});
  EXPECT_EQ(help.exitCode, 0) << describe(help);
  EXPECT_NE(help.out.find("isosurface"), std::string::npos);
}

#else  // DMTOOL_ACCEPTANCE

// Every number in a JSON value is finite (nlohmann writes NaN/inf as null,
// so a null where a number belongs also fails the caller's checks).
bool allFinite(const json& j) {
  if (j.is_number()) return std::isfinite(j.get<double>());
  if (j.is_array() || j.is_object())
    return std::all_of(j.begin(), j.end(), [](const json& e) { return allFinite(e); });
  return true;
}

// Checks one successful `info --json` of a mesh; returns "" or what is wrong.
std::string checkMeshJson(json j) {  // by value: operator[] on a missing key gives null
  if (!j.is_object() || j["kind"] != "mesh" || !j["meshes"].is_array() || j["meshes"].empty())
    return "not a mesh report";
  if (!allFinite(j)) return "a number is not finite";
  const auto count = [](json& v) { return v.is_number_unsigned() ? v.get<std::size_t>() : 0; };
  std::size_t triangles = 0, vertices = 0;
  for (json m : j["meshes"]) {
    if (count(m["triangles"]) == 0) return "part without triangles";
    if (count(m["vertices"]) < 3) return "part with < 3 vertices";
    triangles += count(m["triangles"]);
    vertices += count(m["vertices"]);
    if (!m["area"].is_number() || !(m["area"].get<double>() >= 0)) return "bad area";
    for (int i = 0; i < 3; ++i)
      if (!m["bounds"]["min"][i].is_number() || !m["bounds"]["max"][i].is_number() ||
          !(m["bounds"]["min"][i].get<double>() <= m["bounds"]["max"][i].get<double>()))
        return "bad bounds";
  }
  json& t = j["total"];
  if (count(t["triangles"]) != triangles) return "total triangles != sum of parts";
  if (count(t["vertices"]) != vertices) return "total vertices != sum of parts";
  if (!t["volume"].is_null() && !(t["volume"].is_number() && t["volume"].get<double>() > 0))
    return "bad volume";
  return {};
}

TEST(DmtoolAcceptance, InfoOnEveryAssimpModel) {
  const fs::path root = "/usr/share/assimp/models";
  if (!fs::is_directory(root)) GTEST_SKIP() << "assimp-testmodels is not installed";
  std::vector<fs::path> files;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(root, ec); !ec && it != fs::recursive_directory_iterator();
       it.increment(ec))
    if (it->is_regular_file() && dm::canReadMesh(it->path())) files.push_back(it->path());
  std::sort(files.begin(), files.end());
  ASSERT_GT(files.size(), 100u);

  struct Outcome {
    fs::path file;
    ToolRun run;
    std::string problem;
  };
  std::vector<Outcome> outcomes(files.size());
  std::atomic<std::size_t> next{0};
  const auto start = std::chrono::steady_clock::now();
  const auto worker = [&] {
    for (std::size_t i = next++; i < files.size(); i = next++) {
      Outcome& o = outcomes[i];
      o.file = files[i];
      o.run = runTool({"info", "--json", o.file.string()}, 60.0);
      if (o.run.timedOut) {
        o.problem = "timed out";
      } else if (o.run.signal != 0) {
        o.problem = "killed by signal " + std::to_string(o.run.signal);
      } else if (o.run.exitCode == 0) {
        json j = json::parse(o.run.out, nullptr, false);
        o.problem = j.is_discarded() ? "stdout is not JSON" : checkMeshJson(j);
      } else if (o.run.exitCode == 1) {
        if (o.run.err.find_first_not_of(" \n") == std::string::npos) o.problem = "exit 1 without a message";
        if (!o.run.out.empty()) o.problem = "exit 1 with output on stdout";
      } else {
        o.problem = "exit code " + std::to_string(o.run.exitCode);
      }
    }
  };
  std::vector<std::thread> pool;
  for (int t = 0; t < 3; ++t) pool.emplace_back(worker);
  for (auto& t : pool) t.join();
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  std::size_t succeeded = 0, failed = 0;
  const Outcome* slowest = &outcomes.front();
  for (const Outcome& o : outcomes) {
    EXPECT_TRUE(o.problem.empty()) << o.file << ": " << o.problem << '\n' << describe(o.run);
    (o.run.exitCode == 0 ? succeeded : failed) += 1;
    if (o.run.seconds > slowest->run.seconds) slowest = &o;
  }
  std::printf(
      "dmtool info on %zu assimp models: %zu succeeded, %zu failed cleanly; %.1f s wall (3 at a time); "
      "slowest %s (%.2f s)\n",
      files.size(), succeeded, failed, wall, slowest->file.c_str(), slowest->run.seconds);
}

#endif  // DMTOOL_ACCEPTANCE

}  // namespace
