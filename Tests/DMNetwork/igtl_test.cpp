// OpenIGTLink codec on its own: CRC-64 known answer, COMMAND against bytes
// built by hand from the v3 specification, v2/v3 extended header and
// metadata, unit and frame conversions checked against geometry, and every
// bounds check of the decoder (sizes, counts, indices, CRC).
#include <dm/network/crc.hpp>
#include <dm/network/igtl.hpp>

#include <gtest/gtest.h>

#include <array>
#include <bit>
#include <cstring>
#include <limits>
#include <random>

#include "network_test_support.hpp"

namespace {

namespace igtl = dm::igtl;
using Bytes = std::vector<std::byte>;

void be(Bytes& b, std::uint64_t v, int n) {
  for (int i = n - 1; i >= 0; --i) b.push_back(static_cast<std::byte>((v >> (8 * i)) & 0xFF));
}
void str(Bytes& b, const std::string& s, std::size_t n) {
  for (std::size_t i = 0; i < n; ++i) b.push_back(static_cast<std::byte>(i < s.size() ? s[i] : 0));
}
void f32(Bytes& b, float f) {
  std::uint32_t u;
  std::memcpy(&u, &f, 4);
  be(b, u, 4);
}
// A complete message: 58-byte header around `body`, CRC-64 computed independently of encodeRaw.
Bytes frame(std::uint16_t version, const std::string& type, const std::string& device, const Bytes& body) {
  Bytes m;
  be(m, version, 2);
  str(m, type, 12);
  str(m, device, 20);
  be(m, 0x0000000580000000ull, 8);  // 5.5 s
  be(m, body.size(), 8);
  be(m, dm::crc64Ecma(body), 8);
  m.insert(m.end(), body.begin(), body.end());
  return m;
}

using dm::test::ascii;

TEST(IgtlCrc64, MatchesTheEcma182CheckValue) {
  EXPECT_EQ(dm::crc64Ecma(ascii("123456789")), 0x6C40DF5F0B497347ull);
  const Bytes all = ascii("123456789");
  EXPECT_EQ(dm::crc64Ecma(std::span(all).subspan(3), dm::crc64Ecma(std::span(all).first(3))),
            0x6C40DF5F0B497347ull);
}

TEST(IgtlTimestamp, IsSecondsDotFraction32) {
  EXPECT_EQ(igtl::timestampFromNanos(5'500'000'000), 0x0000000580000000ull);
  EXPECT_EQ(igtl::timestampToNanos(0x0000000580000000ull), 5'500'000'000);
  for (std::int64_t ns : {1LL, 999'999'999LL, 1'234'567'891'234LL})
    EXPECT_NEAR(static_cast<double>(igtl::timestampToNanos(igtl::timestampFromNanos(ns))),
                static_cast<double>(ns), 1.0);
}

// COMMAND (protocol v3, header version 2): extended header, the body of
// COMMAND_ID u32, COMMAND_NAME char[128], ENCODING u16, LENGTH u32, COMMAND
// bytes, then one metadata entry — all laid out by hand from the spec.
Bytes handBuiltCommand() {
  const std::string xml = "<Command Name=\"Start\" />";
  Bytes content;
  be(content, 42, 4);
  str(content, "Start", 128);
  be(content, 106, 2);
  be(content, xml.size(), 4);
  for (char c : xml) content.push_back(static_cast<std::byte>(c));
  const std::string key = "Status", value = "OK";
  Bytes body;
  be(body, 12, 2);                         // extended header size
  be(body, 2 + 8, 2);                      // metadata header size: count + one index entry
  be(body, key.size() + value.size(), 4);  // metadata size
  be(body, 7, 4);                          // message id
  body.insert(body.end(), content.begin(), content.end());
  be(body, 1, 2);  // index count
  be(body, key.size(), 2);
  be(body, 3, 2);  // US-ASCII
  be(body, value.size(), 4);
  str(body, key, key.size());
  str(body, value, value.size());
  return frame(2, "COMMAND", "Robot", body);
}

TEST(IgtlCommand, DecodesHandBuiltV3BytesAndEncodesThemByteExactly) {
  const Bytes wire = handBuiltCommand();
  auto m = igtl::decodeMessage(wire);
  ASSERT_TRUE(m.ok()) << m.error().message();
  EXPECT_EQ(m->header.version, 2);
  EXPECT_EQ(m->header.type, "COMMAND");
  EXPECT_EQ(m->header.deviceName, "Robot");
  EXPECT_EQ(m->messageId, 7u);
  ASSERT_EQ(m->metadata.size(), 1u);
  EXPECT_EQ(m->metadata[0], (igtl::MetadataEntry{"Status", 3, "OK"}));
  EXPECT_EQ(m->contentOffset, 58u + 12u);
  auto c = igtl::decodeCommand(*m);
  ASSERT_TRUE(c.ok()) << c.error().message();
  EXPECT_EQ(c->id, 42u);
  EXPECT_EQ(c->name, "Start");
  EXPECT_EQ(c->encoding, 106);
  EXPECT_EQ(c->content, "<Command Name=\"Start\" />");

  igtl::Envelope env{.version = 2,
                     .deviceName = "Robot",
                     .timestamp = 0x0000000580000000ull,
                     .messageId = 7,
                     .metadata = {{"Status", 3, "OK"}}};
  auto enc = igtl::encodeCommand(env, *c);
  ASSERT_TRUE(enc.ok());
  EXPECT_EQ(*enc, wire);
  // Version 3 headers have the same layout.
  env.version = 3;
  auto v3 = igtl::encodeCommand(env, *c, "RTS_COMMAND");
  ASSERT_TRUE(v3.ok());
  auto m3 = igtl::decodeMessage(*v3);
  ASSERT_TRUE(m3.ok());
  EXPECT_EQ(m3->header.version, 3);
  EXPECT_EQ(igtl::decodeCommand(*m3).value(), *c);
}

TEST(IgtlCommand, RefusesLengthsPastTheBody) {
  Bytes content;
  be(content, 1, 4);
  str(content, "X", 128);
  be(content, 3, 2);
  be(content, 1000, 4);  // claims 1000 bytes, none follow
  const Bytes mWire = frame(1, "COMMAND", "d", content);
  auto m = igtl::decodeMessage(mWire);
  ASSERT_TRUE(m.ok());
  auto c = igtl::decodeCommand(*m);
  ASSERT_FALSE(c.ok());
  EXPECT_NE(c.error().message().find("byte 192"), std::string::npos) << c.error().message();  // 58 + 134
}

TEST(IgtlHeader, MetadataSizesMustAddUp) {
  Bytes wire = handBuiltCommand();
  wire[58 + 7] = std::byte{9};  // metadata size 8 → 9
  // Fix the CRC so the metadata check itself is exercised.
  const std::uint64_t crc = dm::crc64Ecma(std::span(wire).subspan(58));
  for (int i = 0; i < 8; ++i)
    wire[50 + static_cast<std::size_t>(i)] = static_cast<std::byte>(crc >> (56 - 8 * i));
  auto m = igtl::decodeMessage(wire);
  ASSERT_FALSE(m.ok());
  EXPECT_NE(m.error().message().find("metadata"), std::string::npos);
}

TEST(IgtlHeader, RefusesBadVersionsSizesAndCrc) {
  auto wire = igtl::encodeString({.deviceName = "s"}, {.text = "hello"});
  ASSERT_TRUE(wire.ok());
  EXPECT_TRUE(igtl::decodeMessage(*wire).ok());
  Bytes w = *wire;
  w[1] = std::byte{4};
  EXPECT_EQ(igtl::decodeMessage(w).error().code, dm::ErrorCode::Version);
  w = *wire;
  w[60] ^= std::byte{1};
  auto e = igtl::decodeMessage(w);
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.error().message().find("CRC"), std::string::npos);
  EXPECT_TRUE(igtl::decodeMessage(w, {.verifyCrc = false}).ok());
  EXPECT_FALSE(igtl::decodeMessage(std::span(*wire).first(wire->size() - 1)).ok());
  EXPECT_FALSE(igtl::decodeMessage(std::span(*wire).first(20)).ok());
  // A body size far beyond the limit fails from the header alone.
  w = *wire;
  for (int i = 42; i < 50; ++i) w[static_cast<std::size_t>(i)] = std::byte{0x7F};
  auto h = igtl::decodeHeader(std::span(w).first(58));
  ASSERT_FALSE(h.ok());
  EXPECT_EQ(h.error().code, dm::ErrorCode::Unsupported);
  // Names longer than the fields are refused on encode.
  EXPECT_FALSE(igtl::encodeString({.deviceName = std::string(21, 'x')}, {}).ok());
  EXPECT_FALSE(igtl::encodeRaw({}, "ABCDEFGHIJKLM", {}).ok());
  EXPECT_FALSE(igtl::encodeRaw({.version = 1, .messageId = 3}, "STRING", {}).ok());
}

TEST(IgtlTransform, ConvertsMillimetresToMetresAndKeepsTheRotation) {
  const dm::Pose pose(dm::Vec3(0.1, -0.2, 0.3),
                      dm::Quat(Eigen::AngleAxisd(0.7, dm::Vec3(1, 2, 3).normalized())));
  auto wire = igtl::encodeTransform({.deviceName = "Tool"}, pose.isometry());
  ASSERT_TRUE(wire.ok());
  // Translation on the wire: float32 mm at content bytes 36..47.
  const std::byte* t = wire->data() + 58 + 36;
  std::uint32_t u = 0;
  for (int i = 0; i < 4; ++i) u = (u << 8) | std::to_integer<std::uint32_t>(t[i]);
  float mm;
  std::memcpy(&mm, &u, 4);
  EXPECT_FLOAT_EQ(mm, 100.0f);
  auto m = igtl::decodeMessage(*wire);
  ASSERT_TRUE(m.ok());
  auto iso = igtl::decodeTransform(*m);
  ASSERT_TRUE(iso.ok());
  EXPECT_TRUE(iso->isApprox(pose.isometry(), 1e-6));
  // A scaled matrix is an affine, not a pose.
  dm::Affine3 scaled = dm::Affine3::Identity();
  scaled.linear() *= 2.0;
  auto sw = igtl::encodeTransform({}, scaled);
  auto sm = igtl::decodeMessage(*sw);
  EXPECT_FALSE(igtl::decodeTransform(*sm).ok());
  EXPECT_TRUE(igtl::decodeTransformAffine(*sm)->isApprox(scaled));
  EXPECT_FALSE(igtl::decodePosition(*sm).ok());  // wrong type
}

TEST(IgtlPosition, AcceptsTheThreeBodySizes) {
  const dm::Quat q(Eigen::AngleAxisd(1.1, dm::Vec3(0, 0, 1)));
  Bytes body;
  for (float v : {10.f, 20.f, 30.f}) f32(body, v);
  const Bytes m12Wire = frame(1, "POSITION", "p", body);
  auto m12 = igtl::decodeMessage(m12Wire);
  EXPECT_TRUE(igtl::decodePosition(*m12)->q.isApprox(dm::Quat::Identity()));
  EXPECT_TRUE(igtl::decodePosition(*m12)->p.isApprox(dm::Vec3(0.01, 0.02, 0.03)));
  for (double v : {q.x(), q.y(), q.z()}) f32(body, static_cast<float>(v));
  const Bytes m24Wire = frame(1, "POSITION", "p", body);
  auto m24 = igtl::decodeMessage(m24Wire);
  EXPECT_TRUE(igtl::decodePosition(*m24)->q.isApprox(q, 1e-6));
  f32(body, static_cast<float>(q.w()));
  const Bytes m28Wire = frame(1, "POSITION", "p", body);
  auto m28 = igtl::decodeMessage(m28Wire);
  EXPECT_TRUE(igtl::decodePosition(*m28)->q.isApprox(q, 1e-6));
  body.resize(20);
  EXPECT_FALSE(igtl::decodePosition(*igtl::decodeMessage(frame(1, "POSITION", "p", body))).ok());
}

TEST(IgtlImage, VolumeGeometryRoundTripsAndOriginIsTheCentre) {
  dm::Affine3 a = dm::Affine3::Identity();
  a.linear() = dm::Quat(Eigen::AngleAxisd(0.4, dm::Vec3(0, 1, 0))).toRotationMatrix() *
               dm::Vec3(0.5e-3, 0.75e-3, 2e-3).asDiagonal();
  a.translation() = dm::Vec3(-0.05, 0.02, 0.1);
  auto vol = dm::Volume::create({5, 4, 3}, dm::VoxelType::I16, a);
  ASSERT_TRUE(vol.ok());
  for (std::size_t i = 0; i < vol->voxelCount(); ++i)
    vol->setValueAt(i, static_cast<double>(i) * 37.0 - 900.0);
  auto wire = igtl::encodeVolume({.deviceName = "CT"}, *vol);
  ASSERT_TRUE(wire.ok());
  auto m = igtl::decodeMessage(*wire);
  ASSERT_TRUE(m.ok());
  // The wire's origin (content bytes 48..59) is the world position of index (2, 1.5, 1), in mm.
  const dm::Vec3 centre = a * dm::Vec3(2, 1.5, 1) * 1000.0;
  for (int r = 0; r < 3; ++r) {
    const std::byte* p = m->content.data() + 48 + 4 * r;
    std::uint32_t u = 0;
    for (int i = 0; i < 4; ++i) u = (u << 8) | std::to_integer<std::uint32_t>(p[i]);
    float f;
    std::memcpy(&f, &u, 4);
    EXPECT_NEAR(f, centre(r), 1e-3);
  }
  auto back = igtl::decodeVolume(*m);
  ASSERT_TRUE(back.ok()) << back.error().message();
  EXPECT_EQ(back->dims(), vol->dims());
  EXPECT_EQ(back->type(), dm::VoxelType::I16);
  EXPECT_TRUE(back->indexToWorld().matrix().isApprox(a.matrix(), 1e-6));
  EXPECT_EQ(std::memcmp(back->bytes(), vol->bytes(), vol->byteSize()), 0);
}

/// An IMAGE body header (v1 layout, 72 bytes): scalar type, endianness (1 big),
/// coordinates (1 RAS, 2 LPS), size, the 12 floats of the orientation and
/// origin, and the sub-volume offset and size.
Bytes imageHeader(int scalarType, int endian, int coordinates, std::array<int, 3> size,
                  std::array<float, 12> matrix, std::array<int, 3> subOffset, std::array<int, 3> subSize) {
  Bytes c;
  be(c, 1, 2);
  c.push_back(std::byte{1});
  c.push_back(static_cast<std::byte>(scalarType));
  c.push_back(static_cast<std::byte>(endian));
  c.push_back(static_cast<std::byte>(coordinates));
  for (int v : size) be(c, static_cast<std::uint64_t>(v), 2);
  for (float v : matrix) f32(c, v);
  for (int v : subOffset) be(c, static_cast<std::uint64_t>(v), 2);
  for (int v : subSize) be(c, static_cast<std::uint64_t>(v), 2);
  return c;
}

TEST(IgtlImage, HonoursBigEndianDataLpsAndSubVolumes) {
  // 3x2x1 uint16, big-endian, LPS, carrying only the sub-volume x = 1..2, y = 1.
  Bytes c = imageHeader(5, 1, 2, {3, 2, 1}, {2, 0, 0, 0, 2, 0, 0, 0, 2, 10, 20, 30}, {1, 1, 0}, {2, 1, 1});
  be(c, 0x1234, 2);
  be(c, 0xABCD, 2);
  const Bytes mWire = frame(1, "IMAGE", "US", c);
  auto m = igtl::decodeMessage(mWire);
  ASSERT_TRUE(m.ok());
  auto v = igtl::decodeVolume(*m);
  ASSERT_TRUE(v.ok()) << v.error().message();
  EXPECT_EQ(v->value(1, 1, 0), 0x1234);
  EXPECT_EQ(v->value(2, 1, 0), 0xABCD);
  EXPECT_EQ(v->value(0, 0, 0), 0);
  // LPS (10, 20, 30) mm centre → RAS (−10, −20, 30); x, y axes flip too.
  const dm::Vec3 centreRas = v->indexToWorld() * dm::Vec3(1, 0.5, 0);
  EXPECT_TRUE(centreRas.isApprox(dm::Vec3(-0.010, -0.020, 0.030), 1e-9));
  EXPECT_TRUE(v->indexToWorld().linear().isApprox(dm::Vec3(-2e-3, -2e-3, 2e-3).asDiagonal().toDenseMatrix()));
  // As a 2-D image as well.
  auto img = igtl::decodeImage(*m);
  ASSERT_TRUE(img.ok()) << img.error().message();
  EXPECT_EQ(img->at<std::uint16_t>(2, 1), 0xABCD);
  // One byte short of the sub-volume is refused before any allocation.
  c.pop_back();
  const Bytes badWire = frame(1, "IMAGE", "US", c);
  auto bad = igtl::decodeMessage(badWire);
  auto e = igtl::decodeVolume(*bad);
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.error().message().find("byte 130"), std::string::npos) << e.error().message();  // 58 + 72
}

TEST(IgtlImage, HugeDimensionsAreRefusedByTheBodySize) {
  const Bytes c = imageHeader(11, 2, 1, {65535, 65535, 65535}, {1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1},
                              {0, 0, 0}, {65535, 65535, 65535});
  const Bytes mWire = frame(1, "IMAGE", "x", c);
  auto m = igtl::decodeMessage(mWire);
  ASSERT_TRUE(m.ok());
  EXPECT_FALSE(igtl::decodeVolume(*m).ok());
  // A one-voxel sub-volume of a 4000³ image must not allocate the whole image.
  Bytes sub =
      imageHeader(3, 2, 1, {4000, 4000, 4000}, {1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0}, {0, 0, 0}, {1, 1, 1});
  sub.push_back(std::byte{7});
  const Bytes msWire = frame(1, "IMAGE", "x", sub);
  auto ms = igtl::decodeMessage(msWire);
  ASSERT_TRUE(ms.ok());
  ASSERT_TRUE(igtl::decodeImageInfo(*ms).ok());
  auto e = igtl::decodeVolume(*ms);
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.error().message().find("limit"), std::string::npos) << e.error().message();
}

TEST(IgtlPolyData, TriangulatesPolygonsAndStripsWithConsistentWinding) {
  // A unit square in z = 0 (mm), as one quad and as a strip: both must give
  // two triangles whose normals point +z and whose area is 1 mm².
  Bytes pts;
  for (float v : {0.f, 0.f, 0.f, 1.f, 0.f, 0.f, 1.f, 1.f, 0.f, 0.f, 1.f, 0.f}) f32(pts, v);
  auto build = [&](bool strip) {
    Bytes c;
    const std::vector<std::uint32_t> cell =
        strip ? std::vector<std::uint32_t>{4, 0, 1, 3, 2} : std::vector<std::uint32_t>{4, 0, 1, 2, 3};
    const std::uint32_t h[10] = {
        4, 0, 0, 0, 0, strip ? 0u : 1u, strip ? 0u : 20u, strip ? 1u : 0u, strip ? 20u : 0u, 0};
    for (auto v : h) be(c, v, 4);
    c.insert(c.end(), pts.begin(), pts.end());
    for (auto v : cell) be(c, v, 4);
    return frame(1, "POLYDATA", "skin", c);
  };
  for (bool strip : {false, true}) {
    const Bytes mWire = build(strip);
    auto m = igtl::decodeMessage(mWire);
    ASSERT_TRUE(m.ok());
    auto mesh = igtl::decodePolyData(*m);
    ASSERT_TRUE(mesh.ok()) << mesh.error().message();
    ASSERT_EQ(mesh->triangleCount(), 2u);
    EXPECT_NEAR(mesh->surfaceArea(), 1e-6, 1e-12);
    for (std::size_t t = 0; t < 2; ++t) EXPECT_TRUE(mesh->faceNormal(t).isApprox(dm::Vec3(0, 0, 1))) << strip;
  }
}

TEST(IgtlPolyData, RefusesBadIndicesCountsAndOtherCellKinds) {
  Bytes c;
  const std::uint32_t h[10] = {3, 0, 0, 0, 0, 1, 16, 0, 0, 0};
  for (auto v : h) be(c, v, 4);
  for (int k = 0; k < 9; ++k) f32(c, static_cast<float>(k));
  Bytes good = c;
  for (std::uint32_t v : {3u, 0u, 1u, 2u}) be(good, v, 4);
  EXPECT_TRUE(igtl::decodePolyData(*igtl::decodeMessage(frame(1, "POLYDATA", "m", good))).ok());
  Bytes badIndex = c;
  for (std::uint32_t v : {3u, 0u, 1u, 3u}) be(badIndex, v, 4);
  auto e = igtl::decodePolyData(*igtl::decodeMessage(frame(1, "POLYDATA", "m", badIndex)));
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.error().message().find("out of range"), std::string::npos);
  Bytes badCount = c;
  for (std::uint32_t v : {0xFFFFFFFFu, 0u, 1u, 2u}) be(badCount, v, 4);
  EXPECT_FALSE(igtl::decodePolyData(*igtl::decodeMessage(frame(1, "POLYDATA", "m", badCount))).ok());
  Bytes manyPoints;
  const std::uint32_t h2[10] = {0x10000000, 0, 0, 0, 0, 0, 0, 0, 0, 0};
  for (auto v : h2) be(manyPoints, v, 4);
  EXPECT_FALSE(igtl::decodePolyData(*igtl::decodeMessage(frame(1, "POLYDATA", "m", manyPoints))).ok());
  Bytes lines;
  const std::uint32_t h3[10] = {2, 0, 0, 1, 12, 0, 0, 0, 0, 0};
  for (auto v : h3) be(lines, v, 4);
  for (int k = 0; k < 6; ++k) f32(lines, 0.f);
  for (std::uint32_t v : {2u, 0u, 1u}) be(lines, v, 4);
  auto l = igtl::decodePolyData(*igtl::decodeMessage(frame(1, "POLYDATA", "m", lines)));
  ASSERT_FALSE(l.ok());
  EXPECT_EQ(l.error().code, dm::ErrorCode::Unsupported);
}

TEST(IgtlQuery, GetSttStpRtsBodies) {
  auto get = igtl::encodeQuery({.deviceName = "d"}, {.kind = igtl::QueryKind::Get, .dataType = "IMAGE"});
  ASSERT_TRUE(get.ok());
  EXPECT_EQ(get->size(), 58u);
  auto stt = igtl::encodeQuery(
      {}, {.kind = igtl::QueryKind::Start, .dataType = "TDATA", .resolutionMs = 50, .coordinateName = "RAS"});
  ASSERT_TRUE(stt.ok());
  EXPECT_EQ(stt->size(), 58u + 36u);
  auto m = igtl::decodeMessage(*stt);
  EXPECT_EQ(m->header.type, "STT_TDATA");
  auto q = igtl::decodeQuery(*m);
  ASSERT_TRUE(q.ok());
  EXPECT_EQ(q->resolutionMs, 50u);
  EXPECT_EQ(q->coordinateName, "RAS");
  auto rts = igtl::decodeQuery(*igtl::decodeMessage(
      *igtl::encodeQuery({}, {.kind = igtl::QueryKind::Ready, .dataType = "TDATA", .status = 1})));
  ASSERT_TRUE(rts.ok());
  EXPECT_EQ(rts->status, 1);
  EXPECT_FALSE(igtl::decodeQuery(*igtl::decodeMessage(frame(1, "GET_IMAGE", "d", ascii("x")))).ok());
  EXPECT_FALSE(igtl::isQueryType("TRANSFORM"));
}

TEST(IgtlPoint, RoundTripsInMetresAndChecksTheElementSize) {
  std::vector<igtl::Point> pts{
      {"tip", "Fiducial", {255, 0, 0, 255}, dm::Vec3(0.01, 0.02, -0.03), 0.002, "CT"},
      {"entry", "Landmark", {0, 255, 0, 128}, dm::Vec3(-0.1, 0, 0.05), 0, ""}};
  auto wire = igtl::encodePoints({.deviceName = "plan"}, pts);
  ASSERT_TRUE(wire.ok());
  EXPECT_EQ(wire->size(), 58u + 2 * 136u);
  auto back = igtl::decodePoints(*igtl::decodeMessage(*wire));
  ASSERT_TRUE(back.ok());
  ASSERT_EQ(back->size(), 2u);
  EXPECT_EQ((*back)[0].name, "tip");
  EXPECT_EQ((*back)[1].group, "Landmark");
  EXPECT_EQ((*back)[1].rgba[3], 128);
  EXPECT_TRUE((*back)[0].position.isApprox(pts[0].position, 1e-6));
  EXPECT_NEAR((*back)[0].radius, 0.002, 1e-9);
  EXPECT_EQ((*back)[0].owner, "CT");
  EXPECT_FALSE(igtl::decodePoints(*igtl::decodeMessage(frame(1, "POINT", "p", Bytes(135)))).ok());
}

// SENSOR laid out by hand from the v3 specification: count, status, unit
// (N: code 0x0B with exponent 1 in the first 10-bit field), float64 values.
TEST(IgtlSensor, DecodesHandBuiltBytesAndRefusesBadCounts) {
  Bytes c;
  be(c, 2, 1);
  be(c, 0, 1);
  be(c, (std::uint64_t{0x0B} << 54) | (std::uint64_t{1} << 50), 8);
  for (double v : {1.25, -0.5}) be(c, std::bit_cast<std::uint64_t>(v), 8);
  auto s = igtl::decodeSensor(*igtl::decodeMessage(frame(1, "SENSOR", "Force", c)));
  ASSERT_TRUE(s.ok()) << s.error().message();
  EXPECT_EQ(s->unit, igtl::kUnitNewton);
  EXPECT_EQ(s->data, (std::vector<double>{1.25, -0.5}));
  EXPECT_EQ(igtl::encodeSensor({.deviceName = "Force", .timestamp = 0x0000000580000000ull}, *s).value(),
            frame(1, "SENSOR", "Force", c));
  const igtl::Unit u = igtl::unpackUnit(s->unit);
  EXPECT_EQ(u.factors[0], (igtl::UnitFactor{.unit = 0x0B, .exponent = 1}));
  EXPECT_EQ(u.factors[1], igtl::UnitFactor{});

  Bytes shortBody(c.begin(), c.end() - 1);  // count says 2, 1.875 values follow
  auto bad = igtl::decodeSensor(*igtl::decodeMessage(frame(1, "SENSOR", "Force", shortBody)));
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message().find("2 values"), std::string::npos) << bad.error().message();
  Bytes nan = c;
  const Bytes q = [] {
    Bytes b;
    be(b, std::bit_cast<std::uint64_t>(std::numeric_limits<double>::quiet_NaN()), 8);
    return b;
  }();
  std::copy(q.begin(), q.end(), nan.end() - 8);
  EXPECT_FALSE(igtl::decodeSensor(*igtl::decodeMessage(frame(1, "SENSOR", "Force", nan))).ok());
  EXPECT_FALSE(igtl::encodeSensor({}, {.data = std::vector<double>(256, 0.0)}).ok());
  EXPECT_FALSE(igtl::packUnit({.factors = {{{.unit = 1, .exponent = 8}}}}).ok());
  EXPECT_EQ(
      igtl::unpackUnit(igtl::packUnit({.prefix = 0xC, .factors = {{{.unit = 2, .exponent = -7}}}}).value()),
      (igtl::Unit{.prefix = 0xC, .factors = {{{.unit = 2, .exponent = -7}}}}));
}

TEST(IgtlStatusString, RoundTripAndBounds) {
  const igtl::StatusInfo s{.code = 4, .subcode = -77, .errorName = "NotFound", .message = "no such tool"};
  auto sw = igtl::encodeStatus({}, s);
  ASSERT_TRUE(sw.ok());
  EXPECT_EQ(igtl::decodeStatus(*igtl::decodeMessage(*sw)).value(), s);
  const igtl::StringInfo t{.encoding = 106, .text = "h\xC3\xA9llo"};
  EXPECT_EQ(igtl::decodeString(*igtl::decodeMessage(*igtl::encodeString({}, t))).value(), t);
  Bytes c;
  be(c, 3, 2);
  be(c, 10, 2);
  c.push_back(std::byte{'a'});
  EXPECT_FALSE(igtl::decodeString(*igtl::decodeMessage(frame(1, "STRING", "s", c))).ok());
  EXPECT_FALSE(igtl::encodeString({}, {.text = std::string(70000, 'a')}).ok());
}

}  // namespace
