// File references inside untrusted files stay in their allowed roots
// (FileSystem::confine, dm/core/filesystem.hpp): MetaImage ElementDataFile,
// NRRD data file, the files of a DICOM series folder, a scene's resource
// sources and the files a mesh names for Assimp to open (an OBJ's mtllib). The file outside the roots is a
// FIFO with no writer: opening it for reading would block, so a reader that returns at all never opened it,
// and a watchdog thread unblocks (and so exposes) one that did.
#include <dm/core/filesystem.hpp>
#include <dm/io/dicom.hpp>
#include <dm/io/mesh_io.hpp>
#include <dm/io/metaimage.hpp>
#include <dm/io/nrrd.hpp>
#include <dm/io/scene_file.hpp>

#include <gtest/gtest.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstring>
#include <fstream>
#include <string>
#include <thread>

#include "../common/temp_dir.hpp"
#include "file_test_support.hpp"

namespace {

namespace fs = std::filesystem;
using dm::test::TempDir;
using dm::test::writeText;

// case/      the folder of the untrusted header or scene
// outside/   a folder that is not an allowed root; secret.raw there is a FIFO
struct Layout {
  TempDir root;
  fs::path caseDir, outside, secret;
  explicit Layout(const std::string& name) : root(name) {
    caseDir = root / "case";
    outside = root / "outside";
    secret = outside / "secret.raw";
    fs::create_directories(caseDir);
    fs::create_directories(outside);
    EXPECT_EQ(::mkfifo(secret.c_str(), 0600), 0) << std::strerror(errno);
  }
};

// Runs `read` (a reader of an untrusted file) and reports whether it opened
// `fifo` for reading: if it has not returned after 3 s, the watchdog opens
// the FIFO for writing (which succeeds only while a reader has it open),
// writes 8 bytes and closes it, so the reader ends and the test fails.
template <class F>
bool opensFifo(const fs::path& fifo, F&& read) {
  std::atomic<bool> done{false}, opened{false};
  std::thread watchdog([&] {
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(3);
    while (!done && std::chrono::steady_clock::now() < until)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    while (!done) {
      const int fd = ::open(fifo.c_str(), O_WRONLY | O_NONBLOCK | O_CLOEXEC);
      if (fd >= 0) {
        opened = true;
        [[maybe_unused]] const ssize_t n = ::write(fd, "LEAKED!!", 8);
        ::close(fd);
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  });
  read();
  done = true;
  watchdog.join();
  return opened;
}

const std::string kMhd = "NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\nElementDataFile = ";
const std::string kNhdr = "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\ndata file: ";
const std::string kEightVoxels = "ABCDEFGH";

void expectDenied(const dm::Result<dm::Volume>& v, const std::string& field) {
  ASSERT_FALSE(v) << "a file outside the allowed roots was read";
  EXPECT_EQ(v.error().code, dm::ErrorCode::Denied) << v.error();
  EXPECT_NE(v.error().message().find(field), std::string::npos) << v.error();
  EXPECT_NE(v.error().hint.find("DM_ALLOW_PATH"), std::string::npos) << v.error();
}

TEST(Confinement, MetaImageDataFileOutsideTheHeadersFolderIsRefused) {
  Layout l("confine_mhd");
  fs::create_symlink(l.secret, l.caseDir / "link.raw");
  fs::create_symlink(l.outside, l.caseDir / "linkdir");
  for (const std::string& ref : {std::string("../outside/secret.raw"), l.secret.string(),
                                 std::string("link.raw"), std::string("linkdir/secret.raw"),
                                 std::string("sub/../../outside/secret.raw")}) {
    SCOPED_TRACE(ref);
    writeText(l.caseDir / "evil.mhd", kMhd + ref + "\n");
    dm::Result<dm::Volume> v = dm::Volume();
    EXPECT_FALSE(opensFifo(l.secret, [&] { v = dm::readMetaImage(l.caseDir / "evil.mhd"); }));
    expectDenied(v, "ElementDataFile (line 4)");
  }
}

TEST(Confinement, DataFilesInsideTheFolderStillLoad) {
  Layout l("confine_inside");
  fs::create_directories(l.caseDir / "data");
  writeText(l.caseDir / "data" / "v.raw", kEightVoxels);
  fs::create_symlink("data/v.raw", l.caseDir / "inside_link.raw");
  for (const std::string& ref : {std::string("data/v.raw"), std::string("inside_link.raw"),
                                 std::string("./data/../data/v.raw"), (l.caseDir / "data" / "v.raw").string()}) {
    SCOPED_TRACE(ref);
    writeText(l.caseDir / "ok.mhd", kMhd + ref + "\n");
    auto v = dm::readMetaImage(l.caseDir / "ok.mhd");
    ASSERT_TRUE(v) << v.error();
    EXPECT_EQ(v->value(1, 1, 1), 'H');
    writeText(l.caseDir / "ok.nhdr", kNhdr + ref + "\n");
    auto n = dm::readNrrd(l.caseDir / "ok.nhdr");
    ASSERT_TRUE(n) << n.error();
    EXPECT_EQ(n->value(1, 0, 0), 'B');
  }
}

TEST(Confinement, AnAllowedRootLetsTheReferenceThrough) {
  Layout l("confine_allow");
  writeText(l.outside / "v.raw", kEightVoxels);
  writeText(l.caseDir / "h.mhd", kMhd + "../outside/v.raw\n");
  auto refused = dm::readMetaImage(l.caseDir / "h.mhd");
  expectDenied(refused, "ElementDataFile");
  dm::FileSystem::global().allowRoot(l.outside);
  auto v = dm::readMetaImage(l.caseDir / "h.mhd");
  dm::FileSystem::global().disallowRoot(l.outside);
  ASSERT_TRUE(v) << v.error();
  EXPECT_EQ(v->value(0, 1, 0), 'C');
  EXPECT_FALSE(dm::readMetaImage(l.caseDir / "h.mhd")) << "disallowRoot did not take the root back";
}

TEST(Confinement, NrrdDataFileOutsideTheHeadersFolderIsRefused) {
  Layout l("confine_nrrd");
  fs::create_symlink(l.secret, l.caseDir / "link.raw");
  for (const std::string& ref : {std::string("../outside/secret.raw"), l.secret.string(), std::string("link.raw")}) {
    SCOPED_TRACE(ref);
    writeText(l.caseDir / "evil.nhdr", kNhdr + ref + "\n");
    dm::Result<dm::Volume> v = dm::Volume();
    EXPECT_FALSE(opensFifo(l.secret, [&] { v = dm::readNrrd(l.caseDir / "evil.nhdr"); }));
    expectDenied(v, "data file (line 6)");
  }
}

TEST(Confinement, VeryLongAndMalformedReferencesAreRefusedCleanly) {
  Layout l("confine_long");
  std::string deep;
  while (deep.size() <= dm::FileSystem::kMaxReferenceBytes) deep += "a/";
  deep += "v.raw";
  const std::string longName(300, 'x');  // one element longer than NAME_MAX
  for (const std::string& ref : {deep, longName + ".raw", "../" + longName + "/../outside/secret.raw"}) {
    SCOPED_TRACE(ref.size());
    writeText(l.caseDir / "long.mhd", kMhd + ref + "\n");
    auto v = dm::readMetaImage(l.caseDir / "long.mhd");
    ASSERT_FALSE(v);
    EXPECT_NE(v.error().message().find("ElementDataFile"), std::string::npos) << v.error();
  }
  auto direct = dm::FileSystem::global().confine(l.caseDir, std::string("a\0b", 3), "field");
  ASSERT_FALSE(direct);
  EXPECT_EQ(direct.error().code, dm::ErrorCode::Denied);
  EXPECT_NE(direct.error().what.find("NUL"), std::string::npos) << direct.error();
  EXPECT_FALSE(dm::FileSystem::global().confine(l.caseDir, "", "field"));
}

TEST(Confinement, DicomSeriesFolderWithAnEscapingSymlinkIsRefused) {
  Layout l("confine_dicom");
  auto vol = dm::Volume::create({3, 2, 2}, dm::VoxelType::I16);
  ASSERT_TRUE(vol);
  ASSERT_TRUE(dm::writeDicomSeries(*vol, l.outside / "series"));
  std::vector<fs::path> slices;
  for (const auto& e : fs::directory_iterator(l.outside / "series")) slices.push_back(e.path());
  ASSERT_EQ(slices.size(), 2u);
  for (const fs::path& s : slices) fs::create_symlink(s, l.caseDir / s.filename());
  auto refused = dm::readDicomSeries(l.caseDir);
  ASSERT_FALSE(refused);
  EXPECT_EQ(refused.error().code, dm::ErrorCode::Denied) << refused.error();
  EXPECT_NE(refused.error().message().find("of the series folder"), std::string::npos) << refused.error();
  // The same series read from its own folder, or through an allowed root.
  EXPECT_TRUE(dm::readDicomSeries(l.outside / "series"));
  dm::FileSystem::global().allowRoot(l.outside);
  auto allowed = dm::readDicomSeries(l.caseDir);
  dm::FileSystem::global().disallowRoot(l.outside);
  ASSERT_TRUE(allowed) << allowed.error();
  EXPECT_EQ(allowed->dims(), dm::Vec3i(3, 2, 2));
}

TEST(Confinement, SceneSourcesOutsideTheScenesFolderAreRefused) {
  Layout l("confine_scene");
  const std::string head = R"({"format": "dmplatform-scene", "version": 1, "resources": {"v": {"type": "volume", "source": ")";
  const std::string tail = "\"}}}";
  std::vector<std::string> refs = {"../outside/secret.raw", l.secret.string()};
  if (fs::is_directory("/usr/share/mricron/templates")) refs.push_back("mricron:../../../../etc/passwd");
  for (const std::string& ref : refs) {
    SCOPED_TRACE(ref);
    writeText(l.caseDir / "scene.json", head + ref + tail);
    auto s = dm::readScene(l.caseDir / "scene.json");
    ASSERT_FALSE(s) << "the scene was accepted";
    EXPECT_NE(s.error().message().find("outside the allowed folders"), std::string::npos) << s.error();
    EXPECT_NE(s.error().message().find("source"), std::string::npos) << s.error();
  }
  writeText(l.caseDir / "scene.json", head + "volumes/brain.nii.gz" + tail);
  auto inside = dm::readScene(l.caseDir / "scene.json");
  ASSERT_TRUE(inside) << inside.error();
  EXPECT_EQ(inside->resources.at(0).path, fs::canonical(l.caseDir) / "volumes" / "brain.nii.gz");
}

// A triangle whose OBJ names a material library: refused when the library
// lies outside the model's folder (by "..", or a symlink that leaves), in-
// process, in the helper program and in a forked child alike, even though
// Assimp goes on without a missing library; loaded when it is inside or
// allowed. An absolute mtllib does not leave: Assimp 5.2's OBJ reader puts
// the model's folder in front of it (it looks for case//tmp/.../secret.raw),
// so the model loads without the library and the file outside is never
// opened. In-process and in the helper the FIFO's watchdog thread catches a
// reader that opened it; a forked import runs without the watchdog thread
// (a fork beside a running thread is what Isolation::Fork cannot make safe:
// under ASan such a child hung on the allocator's lock, held at the fork by
// another thread), and a child that opened the FIFO would block until the
// import's timeout and fail the test.
const std::string kTriangleObj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl skin\nf 1 2 3\n";

dm::Result<dm::Mesh> readWatched(const Layout& l, const fs::path& file, dm::Isolation isolation) {
  dm::MeshImportOptions options;
  options.isolation = isolation;
  options.timeoutSeconds = 30;
  if (isolation == dm::Isolation::Fork) return dm::readMesh(file, options);
  dm::Result<dm::Mesh> m = dm::Mesh();
  EXPECT_FALSE(opensFifo(l.secret, [&] { m = dm::readMesh(file, options); }));
  return m;
}

TEST(Confinement, AMeshsMaterialLibraryOutsideItsFolderIsRefused) {
  Layout l("confine_obj");
  fs::create_symlink(l.secret, l.caseDir / "link.mtl");
  fs::create_symlink(l.outside, l.caseDir / "linkdir");
  for (const dm::Isolation isolation :
       {dm::Isolation::Helper, dm::Isolation::Fork, dm::Isolation::InProcess}) {
    for (const std::string& ref :
         {std::string("../outside/secret.raw"), std::string("link.mtl"), std::string("linkdir/secret.raw"),
          std::string("sub/../../outside/secret.raw")}) {
      SCOPED_TRACE(ref + " (" + dm::toString(isolation) + ")");
      writeText(l.caseDir / "evil.obj", "mtllib " + ref + "\n" + kTriangleObj);
      const dm::Result<dm::Mesh> m = readWatched(l, l.caseDir / "evil.obj", isolation);
      ASSERT_FALSE(m) << "a file outside the allowed roots was asked for and not refused";
      EXPECT_EQ(m.error().code, dm::ErrorCode::Denied) << m.error();
      EXPECT_NE(m.error().message().find("outside the allowed folders"), std::string::npos) << m.error();
      EXPECT_NE(m.error().where.find("evil.obj"), std::string::npos) << m.error();
      EXPECT_NE(m.error().hint.find("DM_ALLOW_PATH"), std::string::npos) << m.error();
    }
    SCOPED_TRACE(std::string("absolute (") + dm::toString(isolation) + ")");
    writeText(l.caseDir / "abs.obj", "mtllib " + l.secret.string() + "\n" + kTriangleObj);
    const dm::Result<dm::Mesh> m = readWatched(l, l.caseDir / "abs.obj", isolation);
    ASSERT_TRUE(m) << m.error();
    EXPECT_EQ(m->triangleCount(), 1u);
  }
}

TEST(Confinement, AMeshsMaterialLibraryInsideOrAllowedLoads) {
  Layout l("confine_obj_ok");
  fs::create_directories(l.caseDir / "mats");
  const std::string mtl = "newmtl skin\nKd 0.8 0.5 0.4\n";
  writeText(l.caseDir / "mats" / "skin.mtl", mtl);
  writeText(l.outside / "skin.mtl", mtl);
  writeText(l.caseDir / "ok.obj", "mtllib mats/skin.mtl\n" + kTriangleObj);
  auto inside = dm::readMesh(l.caseDir / "ok.obj");
  ASSERT_TRUE(inside) << inside.error();
  EXPECT_EQ(inside->triangleCount(), 1u);
  writeText(l.caseDir / "out.obj", "mtllib ../outside/skin.mtl\n" + kTriangleObj);
  auto refused = dm::readMesh(l.caseDir / "out.obj");
  ASSERT_FALSE(refused);
  EXPECT_EQ(refused.error().code, dm::ErrorCode::Denied) << refused.error();
  dm::FileSystem::global().allowRoot(l.outside);
  auto allowed = dm::readMesh(l.caseDir / "out.obj");
  dm::FileSystem::global().disallowRoot(l.outside);
  ASSERT_TRUE(allowed) << allowed.error();
  EXPECT_EQ(allowed->triangleCount(), 1u);
}

}  // namespace
