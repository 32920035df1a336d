// OpenIGTLink codec against the reference library (OpenIGTLink 1.11), in
// process: messages packed by igtl::*Message::Pack() are decoded by ours and
// compared field by field (and byte for byte where both sides produce the
// same bytes); messages encoded by ours are unpacked by the reference with
// its CRC check on (Unpack(1)) and compared. Socket-level interop lives in
// the transport tests.
#include <dm/network/crc.hpp>
#include <dm/network/igtl.hpp>

#include <gtest/gtest.h>

#include <igtlImageMessage.h>
#include <igtlMessageHeader.h>
#include <igtlPointMessage.h>
#include <igtlPolyDataMessage.h>
#include <igtlPositionMessage.h>
#include <igtlSensorMessage.h>
#include <igtlStatusMessage.h>
#include <igtlStringMessage.h>
#include <igtlTrackingDataMessage.h>
#include <igtlTransformMessage.h>
#include <igtlUnit.h>
#include <igtl_header.h>
#include <igtl_unit.h>
#include <igtl_util.h>

#include <cstring>
#include <random>

namespace {

namespace dmi = dm::igtl;
using Bytes = std::vector<std::byte>;

Bytes packed(igtl::MessageBase* m) {
  m->Pack();
  const auto* p = static_cast<const std::byte*>(m->GetPackPointer());
  return Bytes(p, p + m->GetPackSize());
}

// Unpacks our bytes with the reference library, CRC check on.
template <class M>
typename M::Pointer refUnpack(const Bytes& wire) {
  igtl::MessageHeader::Pointer header = igtl::MessageHeader::New();
  header->InitPack();
  std::memcpy(header->GetPackPointer(), wire.data(), IGTL_HEADER_SIZE);
  header->Unpack();
  typename M::Pointer msg = M::New();
  msg->SetMessageHeader(header);
  msg->AllocatePack();
  EXPECT_EQ(static_cast<std::size_t>(msg->GetPackBodySize()), wire.size() - IGTL_HEADER_SIZE);
  std::memcpy(msg->GetPackBodyPointer(), wire.data() + IGTL_HEADER_SIZE, wire.size() - IGTL_HEADER_SIZE);
  const int r = msg->Unpack(1);
  EXPECT_TRUE(r & igtl::MessageBase::UNPACK_BODY) << "reference refused the body (CRC or layout)";
  return msg;
}

// Index of the first differing byte (or the shorter size), for readable failures.
std::size_t firstDiff(const Bytes& a, const Bytes& b) {
  std::size_t i = 0;
  while (i < a.size() && i < b.size() && a[i] == b[i]) ++i;
  return i == a.size() && i == b.size() ? std::size_t(-1) : i;
}
#define EXPECT_SAME_BYTES(a, b) \
  EXPECT_EQ(firstDiff((a), (b)), std::size_t(-1)) << "sizes " << (a).size() << ", " << (b).size()

// Device name and timestamp of a reference message (some reference classes
// stamp the current time in Pack()), for byte-exact comparisons.
dmi::Envelope envOf(const Bytes& ref) {
  auto h = dmi::decodeHeader(ref);
  return h.ok() ? dmi::Envelope{.deviceName = h->deviceName, .timestamp = h->timestamp} : dmi::Envelope{};
}

dmi::MessageView decode(const Bytes& wire) {
  auto m = dmi::decodeMessage(wire);
  EXPECT_TRUE(m.ok()) << (m.ok() ? "" : m.error().message());
  return m.ok() ? *m : dmi::MessageView{};
}

TEST(IgtlInterop, Crc64EqualsTheReference) {
  std::mt19937 rng(1);
  std::uniform_int_distribution<int> any(0, 255);
  for (std::size_t n : {0u, 1u, 7u, 58u, 1000u}) {
    std::vector<unsigned char> d(n);
    for (auto& x : d) x = static_cast<unsigned char>(any(rng));
    EXPECT_EQ(dm::crc64Ecma(std::as_bytes(std::span(d))), crc64(d.data(), n, 0ull)) << n;
  }
}

TEST(IgtlInterop, Transform) {
  igtl::TransformMessage::Pointer ref = igtl::TransformMessage::New();
  ref->SetDeviceName("Tracker");
  ref->SetTimeStamp(12, 0x40000000u);
  const dm::Mat3 r = dm::Quat(Eigen::AngleAxisd(0.9, dm::Vec3(1, -1, 2).normalized())).toRotationMatrix();
  igtl::Matrix4x4 mat;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) mat[i][j] = static_cast<float>(r(i, j));
  mat[0][3] = 12.5f;
  mat[1][3] = -40.f;
  mat[2][3] = 300.f;
  mat[3][0] = mat[3][1] = mat[3][2] = 0.f;
  mat[3][3] = 1.f;
  ref->SetMatrix(mat);
  const Bytes refBytes = packed(ref);

  const auto m = decode(refBytes);
  EXPECT_EQ(m.header.deviceName, "Tracker");
  EXPECT_EQ(m.header.timestamp, (12ull << 32) | 0x40000000u);
  auto iso = dmi::decodeTransform(m);
  ASSERT_TRUE(iso.ok()) << iso.error().message();
  EXPECT_TRUE(iso->linear().isApprox(r, 1e-6));
  EXPECT_TRUE(iso->translation().isApprox(dm::Vec3(0.0125, -0.040, 0.300), 1e-7));

  // Ours from the decoded transform reproduces the reference's bytes exactly
  // (float32 mm round-trip through double metres is exact for these values).
  auto affine = dmi::decodeTransformAffine(m);
  auto ours = dmi::encodeTransform({.deviceName = "Tracker", .timestamp = m.header.timestamp}, *affine);
  ASSERT_TRUE(ours.ok());
  EXPECT_SAME_BYTES(*ours, refBytes);

  auto back = refUnpack<igtl::TransformMessage>(*ours);
  igtl::Matrix4x4 got;
  back->GetMatrix(got);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 4; ++j) EXPECT_FLOAT_EQ(got[i][j], mat[i][j]);
  EXPECT_STREQ(back->GetDeviceName(), "Tracker");
}

TEST(IgtlInterop, Position) {
  igtl::PositionMessage::Pointer ref = igtl::PositionMessage::New();
  ref->SetDeviceName("Needle");
  ref->SetPosition(1.f, 2.f, 3.f);
  const dm::Quat q(Eigen::AngleAxisd(0.3, dm::Vec3(0, 1, 0)));
  ref->SetQuaternion(static_cast<float>(q.x()), static_cast<float>(q.y()), static_cast<float>(q.z()),
                     static_cast<float>(q.w()));
  const Bytes refBytes = packed(ref);
  auto pose = dmi::decodePosition(decode(refBytes));
  ASSERT_TRUE(pose.ok()) << pose.error().message();
  EXPECT_TRUE(pose->p.isApprox(dm::Vec3(0.001, 0.002, 0.003), 1e-9));
  EXPECT_LT(pose->q.angularDistance(q), 1e-6);

  const dm::Pose ourPose(dm::Vec3(-0.1, 0.25, 0.5), q);
  auto ours = dmi::encodePosition({.deviceName = "Needle"}, ourPose);
  ASSERT_TRUE(ours.ok());
  auto back = refUnpack<igtl::PositionMessage>(*ours);
  float p[3], quat[4];
  back->GetPosition(p);
  back->GetQuaternion(quat);
  EXPECT_FLOAT_EQ(p[0], -100.f);
  EXPECT_FLOAT_EQ(p[1], 250.f);
  EXPECT_FLOAT_EQ(p[2], 500.f);
  EXPECT_NEAR(quat[1], q.y(), 1e-7);
  EXPECT_NEAR(quat[3], q.w(), 1e-7);
}

TEST(IgtlInterop, ImageBothWays) {
  // Reference → ours: int16 volume with oblique axes.
  igtl::ImageMessage::Pointer ref = igtl::ImageMessage::New();
  ref->SetDeviceName("CT");
  ref->SetDimensions(6, 5, 4);
  ref->SetSpacing(0.5f, 0.8f, 2.0f);
  ref->SetScalarTypeToInt16();
  ref->SetEndian(igtl::ImageMessage::ENDIAN_BIG);
  const dm::Mat3 axes = dm::Quat(Eigen::AngleAxisd(0.5, dm::Vec3(0, 0, 1))).toRotationMatrix();
  float t[3], s[3], n[3];
  for (int i = 0; i < 3; ++i) {
    t[i] = static_cast<float>(axes(i, 0));
    s[i] = static_cast<float>(axes(i, 1));
    n[i] = static_cast<float>(axes(i, 2));
  }
  ref->SetNormals(t, s, n);
  ref->SetOrigin(10.f, 20.f, -30.f);
  ref->AllocateScalars();
  auto* px = static_cast<std::uint8_t*>(ref->GetScalarPointer());
  for (int i = 0; i < 6 * 5 * 4; ++i) {  // big-endian int16 value i * 100 - 5000
    const auto v = static_cast<std::uint16_t>(static_cast<std::int16_t>(i * 100 - 5000));
    px[2 * i] = static_cast<std::uint8_t>(v >> 8);
    px[2 * i + 1] = static_cast<std::uint8_t>(v & 0xFF);
  }
  auto vol = dmi::decodeVolume(decode(packed(ref)));
  ASSERT_TRUE(vol.ok()) << vol.error().message();
  EXPECT_EQ(vol->dims(), dm::Vec3i(6, 5, 4));
  EXPECT_EQ(vol->type(), dm::VoxelType::I16);
  EXPECT_EQ(vol->value(0, 0, 0), -5000);
  EXPECT_EQ(vol->value(5, 4, 3), 119 * 100 - 5000);
  EXPECT_TRUE(vol->spacing().isApprox(dm::Vec3(0.5e-3, 0.8e-3, 2e-3), 1e-6));
  // The reference's origin is the volume centre: index (2.5, 2, 1.5).
  EXPECT_TRUE((vol->indexToWorld() * dm::Vec3(2.5, 2, 1.5)).isApprox(dm::Vec3(0.010, 0.020, -0.030), 1e-6));
  EXPECT_TRUE((vol->indexToWorld().linear().col(0).normalized()).isApprox(axes.col(0), 1e-6));

  // Ours → reference: float32 volume, little-endian on the wire.
  auto mine = dm::Volume::create({4, 3, 2}, dm::VoxelType::F32, vol->indexToWorld());
  ASSERT_TRUE(mine.ok());
  for (std::size_t i = 0; i < mine->voxelCount(); ++i)
    mine->setValueAt(i, 0.25 * static_cast<double>(i) - 1.0);
  auto ours = dmi::encodeVolume({.deviceName = "Mine"}, *mine);
  ASSERT_TRUE(ours.ok());
  auto back = refUnpack<igtl::ImageMessage>(*ours);
  int d[3];
  back->GetDimensions(d);
  EXPECT_EQ(d[0], 4);
  EXPECT_EQ(d[2], 2);
  EXPECT_EQ(back->GetScalarType(), igtl::ImageMessage::TYPE_FLOAT32);
  EXPECT_EQ(back->GetEndian(), igtl::ImageMessage::ENDIAN_LITTLE);
  float sp[3], org[3];
  back->GetSpacing(sp);
  back->GetOrigin(org);
  EXPECT_NEAR(sp[1], 0.8f, 1e-5);
  const dm::Vec3 centre = mine->indexToWorld() * dm::Vec3(1.5, 1, 0.5) * 1000.0;
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(org[i], centre(i), 1e-3);
  EXPECT_EQ(std::memcmp(back->GetScalarPointer(), mine->bytes(), mine->byteSize()), 0);
}

TEST(IgtlInterop, StatusAndStringAreByteExact) {
  igtl::StatusMessage::Pointer st = igtl::StatusMessage::New();
  st->SetDeviceName("Robot");
  st->SetCode(igtl::StatusMessage::STATUS_NOT_FOUND);
  st->SetSubCode(-123456789012LL);
  st->SetErrorName("NoTool");
  st->SetStatusString("tool 3 is not connected");
  const Bytes refStatus = packed(st);
  auto s = dmi::decodeStatus(decode(refStatus));
  ASSERT_TRUE(s.ok()) << s.error().message();
  EXPECT_EQ(s->code, igtl::StatusMessage::STATUS_NOT_FOUND);
  EXPECT_EQ(s->subcode, -123456789012LL);
  EXPECT_EQ(s->errorName, "NoTool");
  EXPECT_EQ(s->message, "tool 3 is not connected");
  EXPECT_SAME_BYTES(dmi::encodeStatus(envOf(refStatus), *s).value(), refStatus);
  auto stBack = refUnpack<igtl::StatusMessage>(dmi::encodeStatus({.deviceName = "Robot"}, *s).value());
  EXPECT_STREQ(stBack->GetStatusString(), "tool 3 is not connected");

  igtl::StringMessage::Pointer str = igtl::StringMessage::New();
  str->SetDeviceName("Text");
  str->SetEncoding(106);
  str->SetString("grüß dich");
  const Bytes refString = packed(str);
  auto t = dmi::decodeString(decode(refString));
  ASSERT_TRUE(t.ok());
  EXPECT_EQ(t->encoding, 106);
  EXPECT_EQ(t->text, "grüß dich");
  EXPECT_SAME_BYTES(dmi::encodeString(envOf(refString), *t).value(), refString);
  auto strBack = refUnpack<igtl::StringMessage>(dmi::encodeString({.deviceName = "Text"}, *t).value());
  EXPECT_STREQ(strBack->GetString(), "grüß dich");
}

TEST(IgtlInterop, Points) {
  igtl::PointMessage::Pointer ref = igtl::PointMessage::New();
  ref->SetDeviceName("Plan");
  for (int i = 0; i < 3; ++i) {
    igtl::PointElement::Pointer e = igtl::PointElement::New();
    e->SetName(("P" + std::to_string(i)).c_str());
    e->SetGroupName("Fiducial");
    e->SetRGBA(static_cast<igtlUint8>(10 * i), 20, 30, 255);
    e->SetPosition(1.f * static_cast<float>(i), -2.f, 3.5f);
    e->SetRadius(1.5f);
    e->SetOwner("CT");
    ref->AddPointElement(e);
  }
  const Bytes refBytes = packed(ref);
  auto pts = dmi::decodePoints(decode(refBytes));
  ASSERT_TRUE(pts.ok()) << pts.error().message();
  ASSERT_EQ(pts->size(), 3u);
  EXPECT_EQ((*pts)[2].name, "P2");
  EXPECT_EQ((*pts)[2].rgba[0], 20);
  EXPECT_TRUE((*pts)[2].position.isApprox(dm::Vec3(0.002, -0.002, 0.0035), 1e-9));
  EXPECT_NEAR((*pts)[0].radius, 0.0015, 1e-9);
  EXPECT_EQ((*pts)[1].owner, "CT");

  auto ours = dmi::encodePoints({.deviceName = "Plan"}, *pts);
  ASSERT_TRUE(ours.ok());
  auto back = refUnpack<igtl::PointMessage>(*ours);
  ASSERT_EQ(back->GetNumberOfPointElement(), 3);
  igtl::PointElement::Pointer e;
  back->GetPointElement(1, e);
  EXPECT_STREQ(e->GetName(), "P1");
  EXPECT_STREQ(e->GetGroupName(), "Fiducial");
  float p[3];
  e->GetPosition(p);
  EXPECT_NEAR(p[0], 1.f, 1e-5);
  EXPECT_NEAR(p[2], 3.5f, 1e-5);
  EXPECT_NEAR(e->GetRadius(), 1.5f, 1e-6);
}

// SENSOR: a force in newtons (the scene's network engine publishes the
// haptic force this way) and a unit with a prefix and a negative exponent.
TEST(IgtlInterop, SensorAndUnitAreByteExact) {
  igtl::Unit::Pointer newton = igtl::Unit::New();
  newton->Append(igtl::Unit::SI_DERIVED_NEWTON, 1);
  EXPECT_EQ(newton->Pack(), dmi::kUnitNewton);
  // A unit of several factors goes through the C packer: the reference
  // igtl::Unit::Append (1.11) never advances its count, so each factor
  // overwrites the first.
  igtl_unit_data mmPerS;
  igtl_unit_init(&mmPerS);
  mmPerS.prefix = IGTL_UNIT_PREFIX_MILLI;
  mmPerS.unit[0] = IGTL_UNIT_SI_BASE_METER;
  mmPerS.exp[0] = 1;
  mmPerS.unit[1] = IGTL_UNIT_SI_BASE_SECOND;
  mmPerS.exp[1] = -1;
  const dmi::Unit ours{.prefix = 0xB,
                       .factors = {{{.unit = 0x01, .exponent = 1}, {.unit = 0x03, .exponent = -1}}}};
  EXPECT_EQ(dmi::packUnit(ours).value(), igtl_unit_pack(&mmPerS));
  EXPECT_EQ(dmi::unpackUnit(igtl_unit_pack(&mmPerS)), ours);

  igtl::SensorMessage::Pointer ref = igtl::SensorMessage::New();
  ref->SetDeviceName("Force");
  ref->SetLength(3);
  ref->SetUnit(newton);
  ref->SetValue(0, 0.25);
  ref->SetValue(1, -1.5);
  ref->SetValue(2, 3.0e-3);
  const Bytes refBytes = packed(ref);
  auto v = dmi::decodeSensor(decode(refBytes));
  ASSERT_TRUE(v.ok()) << v.error().message();
  EXPECT_EQ(v->unit, dmi::kUnitNewton);
  EXPECT_EQ(v->data, (std::vector<double>{0.25, -1.5, 3.0e-3}));
  EXPECT_SAME_BYTES(dmi::encodeSensor(envOf(refBytes), *v).value(), refBytes);
  auto back = refUnpack<igtl::SensorMessage>(dmi::encodeSensor({.deviceName = "Force"}, *v).value());
  ASSERT_EQ(back->GetLength(), 3u);
  EXPECT_EQ(back->GetValue(1), -1.5);
  EXPECT_EQ(back->GetUnit(), dmi::kUnitNewton);
}

TEST(IgtlInterop, PolyData) {
  // A tetrahedron in mm, faces CCW from outside, as polygons.
  igtl::PolyDataMessage::Pointer ref = igtl::PolyDataMessage::New();
  ref->SetDeviceName("Tet");
  igtl::PolyDataPointArray::Pointer pts = igtl::PolyDataPointArray::New();
  pts->AddPoint(0.f, 0.f, 0.f);
  pts->AddPoint(10.f, 0.f, 0.f);
  pts->AddPoint(0.f, 10.f, 0.f);
  pts->AddPoint(0.f, 0.f, 10.f);
  igtl::PolyDataCellArray::Pointer polys = igtl::PolyDataCellArray::New();
  igtlUint32 faces[4][3] = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  for (auto& f : faces) polys->AddCell(3, f);
  ref->SetPoints(pts);
  ref->SetPolygons(polys);
  auto mesh = dmi::decodePolyData(decode(packed(ref)));
  ASSERT_TRUE(mesh.ok()) << mesh.error().message();
  ASSERT_EQ(mesh->vertexCount(), 4u);
  ASSERT_EQ(mesh->triangleCount(), 4u);
  // Surface area of the 1 cm corner tetrahedron: 3 · 0.5e-4 + (√3/2)·(√2 cm)²/... = 1.5e-4 + √3/2 · 1e-4.
  EXPECT_NEAR(mesh->surfaceArea(), 1.5e-4 + std::sqrt(3.0) / 2.0 * 1e-4, 1e-12);
  const dm::Vec3 centroid(0.0025, 0.0025, 0.0025);
  for (std::size_t f = 0; f < 4; ++f) {
    const dm::Vec3 c = (mesh->positions[mesh->triangles[f][0]] + mesh->positions[mesh->triangles[f][1]] +
                        mesh->positions[mesh->triangles[f][2]]) /
                       3.0;
    EXPECT_GT(mesh->faceNormal(f).dot(c - centroid), 0.0) << "face " << f << " points inward";
  }

  auto ours = dmi::encodePolyData({.deviceName = "Tet"}, *mesh);
  ASSERT_TRUE(ours.ok());
  auto back = refUnpack<igtl::PolyDataMessage>(*ours);
  ASSERT_EQ(back->GetPoints()->GetNumberOfPoints(), 4);
  float p[3];
  back->GetPoints()->GetPoint(3, p);
  EXPECT_NEAR(p[2], 10.f, 1e-5);
  ASSERT_EQ(back->GetPolygons()->GetNumberOfCells(), 4u);
  igtlUint32 cell[3];
  back->GetPolygons()->GetCell(3, cell);
  EXPECT_EQ(cell[0], 1u);
  EXPECT_EQ(cell[1], 2u);
  EXPECT_EQ(cell[2], 3u);
}

TEST(IgtlInterop, Queries) {
  igtl::GetImageMessage::Pointer get = igtl::GetImageMessage::New();
  get->SetDeviceName("CT");
  const Bytes getBytes = packed(get);
  auto q = dmi::decodeQuery(decode(getBytes));
  ASSERT_TRUE(q.ok());
  EXPECT_EQ(q->kind, dmi::QueryKind::Get);
  EXPECT_EQ(q->dataType, "IMAGE");
  EXPECT_SAME_BYTES(dmi::encodeQuery(envOf(getBytes), *q).value(), getBytes);

  igtl::StartTrackingDataMessage::Pointer stt = igtl::StartTrackingDataMessage::New();
  stt->SetDeviceName("Tracker");
  stt->SetResolution(50);
  stt->SetCoordinateName("Patient");
  const Bytes sttBytes = packed(stt);
  auto qs = dmi::decodeQuery(decode(sttBytes));
  ASSERT_TRUE(qs.ok()) << qs.error().message();
  EXPECT_EQ(qs->kind, dmi::QueryKind::Start);
  EXPECT_EQ(qs->resolutionMs, 50u);
  EXPECT_EQ(qs->coordinateName, "Patient");
  EXPECT_SAME_BYTES(dmi::encodeQuery(envOf(sttBytes), *qs).value(), sttBytes);
  auto sttBack =
      refUnpack<igtl::StartTrackingDataMessage>(dmi::encodeQuery({.deviceName = "Tracker"}, *qs).value());
  EXPECT_EQ(sttBack->GetResolution(), 50);
  EXPECT_STREQ(sttBack->GetCoordinateName(), "Patient");

  igtl::StopTrackingDataMessage::Pointer stp = igtl::StopTrackingDataMessage::New();
  stp->SetDeviceName("Tracker");
  const Bytes stpBytes = packed(stp);
  auto qp = dmi::decodeQuery(decode(stpBytes));
  ASSERT_TRUE(qp.ok());
  EXPECT_EQ(qp->kind, dmi::QueryKind::Stop);
  EXPECT_SAME_BYTES(dmi::encodeQuery(envOf(stpBytes), *qp).value(), stpBytes);

  igtl::RTSTrackingDataMessage::Pointer rts = igtl::RTSTrackingDataMessage::New();
  rts->SetDeviceName("Tracker");
  rts->SetStatus(1);
  const Bytes rtsBytes = packed(rts);
  auto qr = dmi::decodeQuery(decode(rtsBytes));
  ASSERT_TRUE(qr.ok()) << qr.error().message();
  EXPECT_EQ(qr->kind, dmi::QueryKind::Ready);
  EXPECT_EQ(qr->status, 1);
  EXPECT_SAME_BYTES(dmi::encodeQuery(envOf(rtsBytes), *qr).value(), rtsBytes);
}

}  // namespace

#undef EXPECT_SAME_BYTES
