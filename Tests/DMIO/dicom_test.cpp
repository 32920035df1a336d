// Tests for dm/io/dicom.hpp. The reader is checked against files written by
// DCMTK's command-line tools from text dumps (dump2dcm, in all three
// uncompressed transfer syntaxes) and edited with dcmodify, with the expected
// voxels and geometry computed here analytically; the writer is checked by
// a round trip of the Colin27 template (mricron-data) and by dcmdump.
#include <dm/core/filesystem.hpp>
#include <dm/io/dicom.hpp>
#include <dm/io/volume_io.hpp>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <unistd.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "../common/temp_dir.hpp"
#include "file_test_support.hpp"

namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<std::byte>;

using dm::test::TempDir;

bool haveTool(const char* tool) {
  return std::system((std::string("command -v ") + tool + " >/dev/null 2>&1").c_str()) == 0;
}

#define REQUIRE_TOOL(tool) \
  if (!haveTool(tool))     \
  GTEST_SKIP() << tool << " (package dcmtk) is not installed; scripts/setup.sh installs it"

int run(const std::string& cmd) { return std::system((cmd + " >/dev/null 2>&1").c_str()); }

std::string capture(const std::string& cmd) {
  std::string out;
  if (FILE* p = ::popen(cmd.c_str(), "r")) {
    char buf[4096];
    while (std::size_t n = std::fread(buf, 1, sizeof buf, p)) out.append(buf, n);
    ::pclose(p);
  }
  return out;
}

using dm::test::mricron;
using dm::test::writeText;

// DICOM LPS millimetres to the SDK's RAS metres.
dm::Vec3 lpsToRasM(const dm::Vec3& v) { return {-v.x() * 1e-3, -v.y() * 1e-3, v.z() * 1e-3}; }

std::string num(double v) {
  char b[40];
  std::snprintf(b, sizeof b, "%.10g", v);
  return b;
}

// A small volume written by dump2dcm, one file per slice.
struct DumpSeries {
  int nx = 4, ny = 3, nz = 5;
  double rowSpacing = 0.7, columnSpacing = 0.9, gap = 1.3;  // mm
  dm::Vec3 r, c, n, origin{10, -20, 30};                    // LPS
  double slope = 2.5, intercept = -1024;
  std::string seriesUid = "1.2.826.0.1.3680043.10.999.1";

  DumpSeries() {
    // An oblique orientation: 40 degrees about (1, 2, 3).
    const Eigen::Matrix3d rot =
        Eigen::AngleAxisd(40.0 * M_PI / 180.0, dm::Vec3(1, 2, 3).normalized()).matrix();
    r = rot.col(0);
    c = rot.col(1);
    n = rot.col(2);
  }
  int stored(int i, int j, int k) const { return k * 100 + j * 10 + i - 15; }
  dm::Vec3 ipp(int k) const { return origin + k * gap * n; }

  // The dump text of slice k; `edit` may change a line before it is written.
  std::string dump(int k) const {
    std::ostringstream d;
    d << "(0008,0016) UI =SecondaryCaptureImageStorage\n"
      << "(0008,0018) UI [1.2.826.0.1.3680043.10.999.2." << k + 1 << "]\n"
      << "(0008,0060) CS [OT]\n"
      << "(0020,000e) UI [" << seriesUid << "]\n"
      << "(0020,0013) IS [" << (7 * k) % nz + 1 << "]\n"  // scrambled InstanceNumber
      << "(0020,0032) DS [" << num(ipp(k).x()) << "\\" << num(ipp(k).y()) << "\\" << num(ipp(k).z()) << "]\n"
      << "(0020,0037) DS [" << num(r.x()) << "\\" << num(r.y()) << "\\" << num(r.z()) << "\\" << num(c.x())
      << "\\" << num(c.y()) << "\\" << num(c.z()) << "]\n"
      << "(0028,0002) US 1\n"
      << "(0028,0004) CS [MONOCHROME2]\n"
      << "(0028,0010) US " << ny << "\n"
      << "(0028,0011) US " << nx << "\n"
      << "(0028,0030) DS [" << num(rowSpacing) << "\\" << num(columnSpacing) << "]\n"
      << "(0028,0100) US 16\n(0028,0101) US 16\n(0028,0102) US 15\n(0028,0103) US 1\n"
      << "(0028,1052) DS [" << num(intercept) << "]\n"
      << "(0028,1053) DS [" << num(slope) << "]\n"
      << "(7fe0,0010) OW ";
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        char h[8];
        std::snprintf(h, sizeof h, "%04x",
                      static_cast<unsigned>(static_cast<std::uint16_t>(stored(i, j, k))));
        d << ((i | j) ? "\\" : "") << h;
      }
    d << "\n";
    return d.str();
  }

  // Writes the slices into `dir` under names whose order differs from the
  // slice order, cycling through explicit LE, explicit BE and implicit LE.
  void write(const fs::path& dir) const {
    static const char* kSyntax[] = {"+te", "+tb", "+ti"};
    for (int k = 0; k < nz; ++k) {
      const fs::path txt = dir / ("dump" + std::to_string(k) + ".txt");
      writeText(txt, dump(k));
      const std::string name = "img" + std::to_string((3 * k + 2) % nz) + ".dcm";
      ASSERT_EQ(
          run("dump2dcm " + std::string(kSyntax[k % 3]) + " " + txt.string() + " " + (dir / name).string()),
          0);
      fs::remove(txt);
    }
  }

  dm::Affine3 expectedAffine() const {
    dm::Affine3 a = dm::Affine3::Identity();
    a.linear().col(0) = lpsToRasM(r * columnSpacing);
    a.linear().col(1) = lpsToRasM(c * rowSpacing);
    a.linear().col(2) = lpsToRasM(n * gap);
    a.translation() = lpsToRasM(origin);
    return a;
  }
};

void expectAffineNear(const dm::Affine3& got, const dm::Affine3& want, double tol) {
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c)
      EXPECT_NEAR(got.matrix()(r, c), want.matrix()(r, c), tol) << "(" << r << "," << c << ")";
}

// A small int16 volume with a plain axis-aligned affine, for the bad-input tests.
dm::Volume smallVolume() {
  dm::Affine3 a = dm::Affine3::Identity();
  a.linear() = dm::Vec3(0.8e-3, 0.6e-3, 2e-3).asDiagonal();
  a.translation() = dm::Vec3(0.01, -0.02, 0.03);
  auto v = dm::Volume::create({5, 4, 6}, dm::VoxelType::I16, a);
  DM_DEMAND(v.ok(), "smallVolume");
  for (int k = 0; k < 6; ++k)
    for (int j = 0; j < 4; ++j)
      for (int i = 0; i < 5; ++i) v->setValue(i, j, k, 100 * k + 10 * j + i - 200);
  return std::move(v).value();
}

void expectErrorMentions(const dm::Error& e, const std::string& where, const std::string& text) {
  EXPECT_NE(e.message().find(where), std::string::npos) << e.message();
  EXPECT_NE(e.message().find(text), std::string::npos) << e.message();
}

// ------------------------------------------------------------- round trips

TEST(Dicom, Ch2SeriesLoadsBackToSameVoxelsAndGeometry) {
  const fs::path path = mricron("ch2.nii.gz");
  ASSERT_FALSE(path.empty());
  auto v = dm::readVolume(path);
  ASSERT_TRUE(v) << v.error();
  ASSERT_EQ(v->type(), dm::VoxelType::U8);
  TempDir dir("ch2");
  const fs::path series = dir / "series";
  auto s = dm::writeDicomSeries(*v, series);
  ASSERT_TRUE(s) << s.error();
  EXPECT_EQ(std::distance(fs::directory_iterator(series), fs::directory_iterator()), v->dims().z());

  auto back = dm::readDicomSeries(series);
  ASSERT_TRUE(back) << back.error();
  ASSERT_EQ(back->dims(), v->dims());
  ASSERT_EQ(back->type(), dm::VoxelType::U8);
  EXPECT_EQ(std::memcmp(back->bytes(), v->bytes(), v->byteSize()), 0);
  expectAffineNear(back->indexToWorld(), v->indexToWorld(), 1e-9);
  for (const dm::Vec3& ijk : {dm::Vec3(0, 0, 0), dm::Vec3(90, 108, 90), dm::Vec3(13, 77, 41)}) {
    const dm::Vec3 a = v->indexToWorld() * ijk, b = back->indexToWorld() * ijk;
    EXPECT_LT((a - b).norm(), 1e-9) << ijk.transpose();
  }

  // A single file reads its own series; one slice from memory is that slice.
  auto viaFile = dm::readDicomSeries(series / "slice_00010.dcm");
  ASSERT_TRUE(viaFile) << viaFile.error();
  EXPECT_EQ(viaFile->dims(), v->dims());
  auto bytes = dm::readFile(series / "slice_00045.dcm");
  ASSERT_TRUE(bytes) << bytes.error();
  auto slice = dm::parseDicomSlice(*bytes, "slice_00045.dcm");
  ASSERT_TRUE(slice) << slice.error();
  ASSERT_EQ(slice->dims(), dm::Vec3i(v->dims().x(), v->dims().y(), 1));
  const std::size_t plane = std::size_t(v->dims().x()) * v->dims().y();
  EXPECT_EQ(std::memcmp(slice->bytes(), v->bytes() + 45 * plane, plane), 0);
  const dm::Vec3 p = v->indexToWorld() * dm::Vec3(3, 4, 45);
  EXPECT_LT((slice->indexToWorld() * dm::Vec3(3, 4, 0) - p).norm(), 1e-9);
}

TEST(Dicom, WrittenGeometryIsLpsMillimetresPerDcmdump) {
  REQUIRE_TOOL("dcmdump");
  const dm::Volume v = smallVolume();
  TempDir dir("dump");
  ASSERT_TRUE(dm::writeDicomSeries(v, dir / "s"));
  // Slice 2 of origin (10, -20, 30) mm RAS with a 2 mm k step: LPS (-10, 20, 34).
  const std::string out =
      capture("dcmdump +P 0020,0032 +P 0028,0030 +P 0020,0037 " + (dir / "s" / "slice_00002.dcm").string());
  EXPECT_NE(out.find("[-10\\20\\34]"), std::string::npos) << out;
  EXPECT_NE(out.find("[0.6\\0.8]"), std::string::npos) << out;  // row spacing (j) \ column spacing (i)
  EXPECT_NE(out.find("[-1\\0\\0\\0\\-1\\0]"), std::string::npos) << out;
}

TEST(Dicom, FloatVolumeIsQuantisedToInt16WithinHalfASlopeStep) {
  dm::Affine3 mm = dm::Affine3::Identity();
  mm.linear() *= 1e-3;
  auto v = dm::Volume::create({7, 5, 3}, dm::VoxelType::F32, mm);
  ASSERT_TRUE(v);
  for (std::size_t i = 0; i < v->voxelCount(); ++i)
    v->setValueAt(i, -3.7 + 15.9 * std::sin(0.37 * double(i)) * 0.5 + 4);
  const auto [lo, hi] = v->range();
  TempDir dir("float");
  ASSERT_TRUE(dm::writeDicomSeries(*v, dir.path(), {.overwrite = true}));
  auto back = dm::readDicomSeries(dir.path());
  ASSERT_TRUE(back) << back.error();
  ASSERT_EQ(back->type(), dm::VoxelType::F32);
  const double step = (hi - lo) / 65535.0;
  for (std::size_t i = 0; i < v->voxelCount(); ++i)
    ASSERT_NEAR(back->valueAt(i), v->valueAt(i), 0.5 * step * 1.001 + 1e-6 * std::abs(v->valueAt(i))) << i;

  // Integral int32 values inside int16's range are written exactly.
  auto w = dm::Volume::create({3, 3, 2}, dm::VoxelType::I32);
  ASSERT_TRUE(w);
  for (std::size_t i = 0; i < w->voxelCount(); ++i) w->setValueAt(i, -32768.0 + 3800.0 * double(i));
  TempDir dir2("int32");
  ASSERT_TRUE(dm::writeDicomSeries(*w, dir2 / "s"));
  auto wb = dm::readDicomSeries(dir2 / "s");
  ASSERT_TRUE(wb) << wb.error();
  EXPECT_EQ(wb->type(), dm::VoxelType::I16);
  for (std::size_t i = 0; i < w->voxelCount(); ++i) EXPECT_EQ(wb->valueAt(i), w->valueAt(i));
}

TEST(Dicom, WriterRefusesNonEmptyDirectoryUnlessOverwrite) {
  const dm::Volume v = smallVolume();
  TempDir dir("nonempty");
  writeText(dir / "notes.txt", "keep me");
  auto s = dm::writeDicomSeries(v, dir.path());
  ASSERT_FALSE(s);
  EXPECT_EQ(s.error().code, dm::ErrorCode::InvalidArgument);
  ASSERT_TRUE(dm::writeDicomSeries(v, dir.path(), {.overwrite = true}));
  ASSERT_TRUE(dm::writeDicomSeries(v, dir.path(), {.overwrite = true}));  // replaces its own slices
  auto back = dm::readDicomSeries(dir.path());                            // notes.txt is skipped
  ASSERT_TRUE(back) << back.error();
  EXPECT_EQ(back->dims(), v.dims());
  EXPECT_TRUE(fs::exists(dir / "notes.txt"));
}

// ----------------------------------------------- files written by DCMTK tools

TEST(Dicom, DcmtkDumpSeriesSortedByPositionRescaledAndObliquelyPlaced) {
  REQUIRE_TOOL("dump2dcm");
  const DumpSeries d;
  TempDir dir("dump2dcm");
  d.write(dir.path());
  auto v = dm::readDicomSeries(dir.path());
  ASSERT_TRUE(v) << v.error();
  ASSERT_EQ(v->dims(), dm::Vec3i(d.nx, d.ny, d.nz));
  ASSERT_EQ(v->type(), dm::VoxelType::F32);  // a rescale other than (1, 0)
  for (int k = 0; k < d.nz; ++k)
    for (int j = 0; j < d.ny; ++j)
      for (int i = 0; i < d.nx; ++i)
        ASSERT_EQ(v->value(i, j, k), d.slope * d.stored(i, j, k) + d.intercept) << i << " " << j << " " << k;
  expectAffineNear(v->indexToWorld(), d.expectedAffine(), 1e-11);
  // Voxel (i, j, k) sits at IPP_k + i·columnSpacing·r + j·rowSpacing·c (LPS mm).
  const dm::Vec3 lps = d.ipp(3) + 2 * d.columnSpacing * d.r + 1 * d.rowSpacing * d.c;
  EXPECT_LT((v->indexToWorld() * dm::Vec3(2, 1, 3) - lpsToRasM(lps)).norm(), 1e-11);
}

TEST(Dicom, BitsStoredAreMaskedAndSignExtended) {
  REQUIRE_TOOL("dump2dcm");
  DumpSeries d;
  d.nz = 1;
  d.slope = 1;
  d.intercept = 0;
  std::string text = d.dump(0);
  // 12 bits stored in 16: set garbage in the top 4 bits of every cell.
  text.replace(text.find("(0028,0101) US 16\n(0028,0102) US 15"), 35, "(0028,0101) US 12\n(0028,0102) US 11");
  const std::size_t px = text.find("OW ") + 3;
  for (std::size_t i = px; i < text.size(); i += 5)
    text[i] = (text[i] == 'f' ? 'a' : '5');  // 0x5xxx / 0xaxxx
  TempDir dir("bits");
  writeText(dir / "d.txt", text);
  ASSERT_EQ(run("dump2dcm +te " + (dir / "d.txt").string() + " " + (dir / "x.dcm").string()), 0);
  auto bytes = dm::readFile(dir / "x.dcm");
  ASSERT_TRUE(bytes);
  auto v = dm::parseDicomSlice(*bytes, "x.dcm");
  ASSERT_TRUE(v) << v.error();
  ASSERT_EQ(v->type(), dm::VoxelType::I16);
  for (int j = 0; j < d.ny; ++j)
    for (int i = 0; i < d.nx; ++i) EXPECT_EQ(v->value(i, j, 0), d.stored(i, j, 0)) << i << " " << j;
}

TEST(Dicom, SeveralSeriesNeedAUidAndAFilePicksItsOwn) {
  REQUIRE_TOOL("dump2dcm");
  const dm::Volume v = smallVolume();
  TempDir dir("multi");
  ASSERT_TRUE(
      dm::writeDicomSeries(v, dir.path(), {.overwrite = true, .seriesUid = "1.2.826.0.1.3680043.10.999.7"}));
  DumpSeries d;
  d.write(dir.path());
  auto both = dm::readDicomSeries(dir.path());
  ASSERT_FALSE(both);
  EXPECT_EQ(both.error().code, dm::ErrorCode::InvalidArgument);
  EXPECT_NE(both.error().hint.find("1.2.826.0.1.3680043.10.999.7 (6 slices)"), std::string::npos)
      << both.error();
  EXPECT_NE(both.error().hint.find(d.seriesUid + " (5 slices)"), std::string::npos) << both.error();

  dm::DicomReadOptions o;
  o.seriesUid = "1.2.826.0.1.3680043.10.999.7";
  auto mine = dm::readDicomSeries(dir.path(), o);
  ASSERT_TRUE(mine) << mine.error();
  ASSERT_EQ(mine->dims(), v.dims());
  EXPECT_EQ(std::memcmp(mine->bytes(), v.bytes(), v.byteSize()), 0);
  auto theirs = dm::readDicomSeries(dir / "img0.dcm");
  ASSERT_TRUE(theirs) << theirs.error();
  EXPECT_EQ(theirs->dims(), dm::Vec3i(d.nx, d.ny, d.nz));
  o.seriesUid = "9.9.9";
  auto none = dm::readDicomSeries(dir.path(), o);
  ASSERT_FALSE(none);
  EXPECT_EQ(none.error().code, dm::ErrorCode::NotFound);
}

// ---------------------------------------------------------------- bad input

class DicomBad : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::make_unique<TempDir>(::testing::UnitTest::GetInstance()->current_test_info()->name());
    ASSERT_TRUE(dm::writeDicomSeries(smallVolume(), dir_->path(), {.overwrite = true}));
  }
  fs::path file(int k) const {
    char n[32];
    std::snprintf(n, sizeof n, "slice_%05d.dcm", k);
    return dir_->path() / n;
  }
  // dcmodify without backup files, so the directory holds only slices.
  void modify(int k, const std::string& args) {
    ASSERT_EQ(run("dcmodify -nb " + args + " " + file(k).string()), 0) << args;
  }
  dm::Error readError() const {
    auto v = dm::readDicomSeries(dir_->path());
    EXPECT_FALSE(v);
    return v ? dm::Error{} : v.error();
  }
  std::unique_ptr<TempDir> dir_;
};

TEST_F(DicomBad, TruncatedFileNamesFileAndPixelData) {
  fs::resize_file(file(3), fs::file_size(file(3)) - 7);
  const dm::Error e = readError();
  expectErrorMentions(e, file(3).string(), "(7FE0,0010) PixelData");
  // Cut inside the header: the element that runs past the end is named with its offset.
  fs::resize_file(file(3), 400);
  expectErrorMentions(readError(), file(3).string(), "byte offset");
}

TEST_F(DicomBad, MissingPixelSpacing) {
  REQUIRE_TOOL("dcmodify");
  modify(2, "-ea \"(0028,0030)\"");
  expectErrorMentions(readError(), file(2).string(), "missing (0028,0030) PixelSpacing");
}

TEST_F(DicomBad, InconsistentRows) {
  REQUIRE_TOOL("dcmodify");
  modify(4, "-m \"(0028,0010)=2\"");
  expectErrorMentions(readError(), file(4).string(), "(0028,0010) Rows is 2 but 4");
}

TEST_F(DicomBad, DuplicatePositions) {
  REQUIRE_TOOL("dcmodify");
  modify(1, "-m \"(0020,0032)=-10\\\\20\\\\30\"");  // the position of slice 0
  expectErrorMentions(readError(), file(1).string(), "duplicate slice position: (0020,0032)");
}

TEST_F(DicomBad, NonUniformSpacing) {
  REQUIRE_TOOL("dcmodify");
  modify(5, "-m \"(0020,0032)=-10\\\\20\\\\41\"");  // 41 mm instead of 40 mm
  const dm::Error e = readError();
  expectErrorMentions(e, file(5).string(), "non-uniform slice spacing");
  expectErrorMentions(e, file(4).string(), "(0020,0032) ImagePositionPatient");
}

TEST_F(DicomBad, HugeRowsAndColumnsFailWithoutAllocating) {
  REQUIRE_TOOL("dcmodify");
  modify(0, "-m \"(0028,0010)=65535\" -m \"(0028,0011)=65535\" -m \"(0028,0100)=32\"");
  expectErrorMentions(readError(), file(0).string(), "65535 Rows x 65535 Columns x 4 bytes need 17179344900");
  // And the caller's size limit holds for a valid series.
  fs::remove(file(0));
  dm::DicomReadOptions o;
  o.maxBytes = 100;
  auto v = dm::readDicomSeries(dir_->path(), o);
  ASSERT_FALSE(v);
  EXPECT_NE(v.error().message().find("more than the budget of 100 bytes (DicomReadOptions::maxBytes)"),
            std::string::npos)
      << v.error();
}

TEST_F(DicomBad, CompressedSyntaxIsNamed) {
  REQUIRE_TOOL("dcmcrle");
  ASSERT_EQ(run("dcmcrle " + file(0).string() + " " + (dir_->path() / "rle.dcm").string()), 0);
  fs::remove(file(0));
  expectErrorMentions(readError(), "rle.dcm", "RLE Lossless");
}

TEST(Dicom, EmptyAndNonDicomDirectoriesAreNotFound) {
  TempDir empty("empty");
  auto e = dm::readDicomSeries(empty.path());
  ASSERT_FALSE(e);
  EXPECT_EQ(e.error().code, dm::ErrorCode::NotFound);
  EXPECT_NE(e.error().where.find(empty.path().string()), std::string::npos);

  TempDir other("other");
  writeText(other / "readme.txt", "not DICOM at all, just a longish text file that is not a data set\n");
  writeText(other / "zeros.bin", std::string(300, '\0'));
  const fs::path nii = mricron("ch2.nii.gz");
  if (!nii.empty()) fs::copy_file(nii, other / "ch2.nii.gz");
  auto o = dm::readDicomSeries(other.path());
  ASSERT_FALSE(o);
  EXPECT_EQ(o.error().code, dm::ErrorCode::NotFound);
  EXPECT_NE(o.error().what.find("no DICOM image files"), std::string::npos) << o.error();

  auto missing = dm::readDicomSeries(other / "nope");
  ASSERT_FALSE(missing);
  EXPECT_EQ(missing.error().code, dm::ErrorCode::NotFound);
}

// A Part 10 header followed by one element whose declared length is hostile.
Bytes hostile(const char vr[2], std::uint32_t length) {
  Bytes b(128, std::byte{0});
  const auto add = [&](std::initializer_list<int> v) {
    for (int x : v) b.push_back(static_cast<std::byte>(x));
  };
  const auto addStr = [&](const std::string& s) {
    for (char ch : s) b.push_back(static_cast<std::byte>(ch));
  };
  addStr("DICM");
  const std::string ts = "1.2.840.10008.1.2.1";  // 19 characters + NUL pad
  add({0x02, 0x00, 0x10, 0x00, 'U', 'I', 20, 0});
  addStr(ts);
  add({0});
  add({0x28, 0x00, 0x10, 0x00, 'U', 'S', 2, 0, 4, 0});  // Rows 4
  add({0x29, 0x00, 0x10, 0x10, vr[0], vr[1], 0, 0});
  add({int(length & 0xFF), int(length >> 8 & 0xFF), int(length >> 16 & 0xFF), int(length >> 24 & 0xFF)});
  add({1, 2, 3, 4});
  return b;
}

TEST(Dicom, HostileDeclaredLengthsFailWithTheirOffset) {
  for (const char* vr : {"OB", "UN", "UT", "SQ"}) {
    const Bytes b = hostile(vr, 0xFFFFFFF0u);
    auto v = dm::parseDicomSlice(b, "<hostile>");
    ASSERT_FALSE(v) << vr;
    EXPECT_EQ(v.error().where, "<hostile>");
    EXPECT_NE(
        v.error().what.find("(0029,1010) declares 4294967280 bytes but only 4 remain at byte offset 170"),
        std::string::npos)
        << vr << ": " << v.error();
  }
  // Undefined length opens a sequence that never ends.
  auto u = dm::parseDicomSlice(hostile("SQ", 0xFFFFFFFFu), "<hostile>");
  ASSERT_FALSE(u);
  EXPECT_NE(u.error().what.find("byte offset"), std::string::npos) << u.error();
  auto junk = dm::parseDicomSlice(Bytes(64, std::byte{0x41}), "<junk>");
  ASSERT_FALSE(junk);
  EXPECT_NE(junk.error().what.find("not a DICOM file"), std::string::npos) << junk.error();
}

}  // namespace

#undef REQUIRE_TOOL
