// The OpenIGTLink session layer against the reference library (OpenIGTLink
// 1.11) over real sockets:
//  * reference igtl::ClientSocket → our IgtlServer: every type reaches our
//    typed handlers with the values the reference packed, and the
//    reference client unpacks (CRC checked) our answers to GET_TRANS,
//    GET_IMAGE, STT_TDATA, STP_TDATA and the TDATA sent to a subscriber;
//  * our IgtlClient → reference igtl::ServerSocket: the reference unpacks
//    (CRC checked) what we send, and our handlers decode what it sends back.
// COMMAND is not in 1.11; it is tested between our two ends in
// igtl_session_test.cpp.
#include <dm/network/igtl_session.hpp>
#include <dm/network/io_thread.hpp>

#include <gtest/gtest.h>

#include <igtlClientSocket.h>
#include <igtlImageMessage.h>
#include <igtlMessageHeader.h>
#include <igtlPointMessage.h>
#include <igtlPolyDataMessage.h>
#include <igtlPositionMessage.h>
#include <igtlServerSocket.h>
#include <igtlStatusMessage.h>
#include <igtlStringMessage.h>
#include <igtlTrackingDataMessage.h>
#include <igtlTransformMessage.h>
#include <igtl_header.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "../common/eventually.hpp"

namespace {

using namespace std::chrono_literals;
namespace dmi = dm::igtl;
using Bytes = std::vector<std::byte>;
using dm::test::eventually;

// ------------------------------------------------------ reference values ---

// Rotation of the reference TRANSFORM / TDATA, and its translation in mm.
const dm::Mat3 kRotation =
    dm::Quat(Eigen::AngleAxisd(0.9, dm::Vec3(1, -1, 2).normalized())).toRotationMatrix();
const dm::Vec3 kTranslationMm(12.5, -40.0, 300.0);

// Index-to-world of the volumes we send: the rotation, 0.5 × 0.8 × 2 mm voxels.
dm::Affine3 volumeAffine() {
  dm::Affine3 a = dm::Affine3::Identity();
  a.linear() = kRotation * dm::Vec3(0.5e-3, 0.8e-3, 2e-3).asDiagonal();
  a.translation() = kTranslationMm * 1e-3;
  return a;
}

void referenceMatrix(igtl::Matrix4x4& m) {
  igtl::IdentityMatrix(m);
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) m[i][j] = static_cast<float>(kRotation(i, j));
    m[i][3] = static_cast<float>(kTranslationMm(i));
  }
}

igtl::MessageBase::Pointer referenceTransform() {
  auto m = igtl::TransformMessage::New();
  m->SetDeviceName("Tool");
  m->SetTimeStamp(1700000000u, 0x40000000u);
  igtl::Matrix4x4 mat;
  referenceMatrix(mat);
  m->SetMatrix(mat);
  m->Pack();
  return igtl::MessageBase::Pointer(m.GetPointer());
}

const dm::Quat kQuat(Eigen::AngleAxisd(0.3, dm::Vec3(0, 1, 0)));

igtl::MessageBase::Pointer referencePosition() {
  auto m = igtl::PositionMessage::New();
  m->SetDeviceName("Needle");
  m->SetPosition(1.f, 2.f, 3.f);
  m->SetQuaternion(static_cast<float>(kQuat.x()), static_cast<float>(kQuat.y()),
                   static_cast<float>(kQuat.z()), static_cast<float>(kQuat.w()));
  m->Pack();
  return igtl::MessageBase::Pointer(m.GetPointer());
}

// int16 volume 6 × 5 × 4, big-endian, value i * 100 - 5000 at linear index i.
igtl::MessageBase::Pointer referenceVolume() {
  auto m = igtl::ImageMessage::New();
  m->SetDeviceName("CT");
  m->SetDimensions(6, 5, 4);
  m->SetSpacing(0.5f, 0.8f, 2.0f);
  m->SetScalarTypeToInt16();
  m->SetEndian(igtl::ImageMessage::ENDIAN_BIG);
  m->SetOrigin(10.f, 20.f, -30.f);
  m->AllocateScalars();
  auto* px = static_cast<std::uint8_t*>(m->GetScalarPointer());
  for (int i = 0; i < 6 * 5 * 4; ++i) {
    const auto v = static_cast<std::uint16_t>(static_cast<std::int16_t>(i * 100 - 5000));
    px[2 * i] = static_cast<std::uint8_t>(v >> 8);
    px[2 * i + 1] = static_cast<std::uint8_t>(v & 0xFF);
  }
  m->Pack();
  return igtl::MessageBase::Pointer(m.GetPointer());
}

// uint8 2-D image 8 × 6, value x + 10 y.
igtl::MessageBase::Pointer referenceImage2d() {
  auto m = igtl::ImageMessage::New();
  m->SetDeviceName("US");
  m->SetDimensions(8, 6, 1);
  m->SetSpacing(0.2f, 0.2f, 1.f);
  float t[3] = {1, 0, 0}, s[3] = {0, 1, 0}, n[3] = {0, 0, 1};
  m->SetNormals(t, s, n);
  m->SetScalarTypeToUint8();
  m->AllocateScalars();
  auto* px = static_cast<std::uint8_t*>(m->GetScalarPointer());
  for (int y = 0; y < 6; ++y)
    for (int x = 0; x < 8; ++x) px[y * 8 + x] = static_cast<std::uint8_t>(x + 10 * y);
  m->Pack();
  return igtl::MessageBase::Pointer(m.GetPointer());
}

igtl::MessageBase::Pointer referenceStatus() {
  auto m = igtl::StatusMessage::New();
  m->SetDeviceName("Robot");
  m->SetCode(igtl::StatusMessage::STATUS_NOT_FOUND);
  m->SetSubCode(-123456789012LL);
  m->SetErrorName("NoTool");
  m->SetStatusString("tool 3 is not connected");
  m->Pack();
  return igtl::MessageBase::Pointer(m.GetPointer());
}

igtl::MessageBase::Pointer referenceString() {
  auto m = igtl::StringMessage::New();
  m->SetDeviceName("Text");
  m->SetEncoding(106);
  m->SetString("grüß dich");
  m->Pack();
  return igtl::MessageBase::Pointer(m.GetPointer());
}

igtl::MessageBase::Pointer referencePoints() {
  auto m = igtl::PointMessage::New();
  m->SetDeviceName("Plan");
  for (int i = 0; i < 3; ++i) {
    auto e = igtl::PointElement::New();
    e->SetName(("P" + std::to_string(i)).c_str());
    e->SetGroupName("Fiducial");
    e->SetRGBA(static_cast<igtlUint8>(10 * i), 20, 30, 255);
    e->SetPosition(1.f * static_cast<float>(i), -2.f, 3.5f);
    e->SetRadius(1.5f);
    e->SetOwner("CT");
    m->AddPointElement(e);
  }
  m->Pack();
  return igtl::MessageBase::Pointer(m.GetPointer());
}

// The 1 cm corner tetrahedron (mm), faces CCW from outside.
igtl::MessageBase::Pointer referencePolyData() {
  auto m = igtl::PolyDataMessage::New();
  m->SetDeviceName("Tet");
  auto pts = igtl::PolyDataPointArray::New();
  pts->AddPoint(0.f, 0.f, 0.f);
  pts->AddPoint(10.f, 0.f, 0.f);
  pts->AddPoint(0.f, 10.f, 0.f);
  pts->AddPoint(0.f, 0.f, 10.f);
  auto polys = igtl::PolyDataCellArray::New();
  igtlUint32 faces[4][3] = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  for (auto& f : faces) polys->AddCell(3, f);
  m->SetPoints(pts);
  m->SetPolygons(polys);
  m->Pack();
  return igtl::MessageBase::Pointer(m.GetPointer());
}

const double kTetArea = 1.5e-4 + std::sqrt(3.0) / 2.0 * 1e-4;  // m²

std::vector<igtl::MessageBase::Pointer> referenceMessages() {
  return {referenceTransform(), referencePosition(), referenceVolume(), referenceImage2d(),
          referenceStatus(),    referenceString(),   referencePoints(), referencePolyData()};
}

// ------------------------------------------------------ reference socket ---

bool sendRef(igtl::Socket* s, igtl::MessageBase* m) {
  return s->Send(m->GetPackPointer(), m->GetPackSize()) == 1;
}

/// One message read from a reference socket: its header and raw body.
struct Received {
  igtl::MessageHeader::Pointer header;
  std::vector<unsigned char> body;
  std::string type() const { return header ? header->GetDeviceType() : ""; }
  std::string device() const { return header ? header->GetDeviceName() : ""; }
};

/// Reads one message (bounded by the socket's receive timeout); no header on failure.
Received receiveRef(igtl::Socket* s) {
  Received r;
  auto h = igtl::MessageHeader::New();
  h->InitPack();
  if (s->Receive(h->GetPackPointer(), h->GetPackSize()) != h->GetPackSize()) return r;
  h->Unpack();
  r.body.resize(static_cast<std::size_t>(h->GetBodySizeToRead()));
  if (!r.body.empty() &&
      s->Receive(r.body.data(), static_cast<int>(r.body.size())) != static_cast<int>(r.body.size()))
    return r;
  r.header = h;
  return r;
}

/// Unpacks `r` as M with the CRC check on; null when the reference refuses it.
template <class M>
typename M::Pointer unpackRef(const Received& r) {
  if (!r.header) return nullptr;
  auto m = M::New();
  m->SetMessageHeader(r.header);
  m->AllocatePack();
  if (static_cast<std::size_t>(m->GetPackBodySize()) != r.body.size()) return nullptr;
  if (!r.body.empty()) std::memcpy(m->GetPackBodyPointer(), r.body.data(), r.body.size());
  if ((m->Unpack(1) & igtl::MessageHeader::UNPACK_BODY) == 0) return nullptr;
  return m;
}

// ------------------------------------------------------- our handlers ----

/// What our handlers received, by type.
struct InteropInbox {
  std::mutex mutex;
  std::map<std::string, int> count;
  std::vector<std::pair<std::string, dm::Affine3>> transforms;
  std::uint64_t transformStamp = 0;
  std::vector<dm::Pose> poses;
  std::vector<dm::Volume> volumes;
  std::vector<dm::Image> images;
  std::vector<dmi::StatusInfo> statuses;
  std::vector<dmi::StringInfo> strings;
  std::vector<std::vector<dmi::Point>> points;
  std::vector<dm::Mesh> meshes;
  std::vector<std::pair<std::string, dmi::Query>> queries;  // device, query

  dm::IgtlHandlers handlers() {
    dm::IgtlHandlers h;
    h.onTransform = [this](dm::ConnectionId, const dmi::MessageView& m, const dm::Affine3& v) {
      std::lock_guard lock(mutex);
      transforms.emplace_back(m.header.deviceName, v);
      transformStamp = m.header.timestamp;
      ++count["TRANSFORM"];
    };
    h.onPosition = [this](dm::ConnectionId, const dmi::MessageView& m, const dm::Pose& v) {
      keep(poses, v, m);
    };
    h.onVolume = [this](dm::ConnectionId, const dmi::MessageView& m, const dm::Volume& v) {
      keep(volumes, v, m);
    };
    h.onImage = [this](dm::ConnectionId, const dmi::MessageView&, const dm::Image& v) {
      std::lock_guard lock(mutex);
      images.push_back(v.clone());
    };
    h.onStatus = [this](dm::ConnectionId, const dmi::MessageView& m, const dmi::StatusInfo& v) {
      keep(statuses, v, m);
    };
    h.onString = [this](dm::ConnectionId, const dmi::MessageView& m, const dmi::StringInfo& v) {
      keep(strings, v, m);
    };
    h.onPoints = [this](dm::ConnectionId, const dmi::MessageView& m, const std::vector<dmi::Point>& v) {
      keep(points, v, m);
    };
    h.onPolyData = [this](dm::ConnectionId, const dmi::MessageView& m, const dm::Mesh& v) {
      keep(meshes, v, m);
    };
    h.onQuery = [this](dm::ConnectionId, const dmi::MessageView& m, const dmi::Query& q) {
      std::lock_guard lock(mutex);
      queries.emplace_back(m.header.deviceName, q);
    };
    return h;
  }
  template <class T>
  void keep(std::vector<T>& list, const T& v, const dmi::MessageView& m) {
    std::lock_guard lock(mutex);
    list.push_back(v);
    ++count[m.header.type];
  }
  int total() {
    std::lock_guard lock(mutex);
    int n = static_cast<int>(images.size());
    for (const auto& [type, c] : count) n += c;
    return n;
  }
};

/// Checks that our decoded values equal what the reference builders packed.
void expectReferenceValues(InteropInbox& in) {
  std::lock_guard lock(in.mutex);
  ASSERT_EQ(in.transforms.size(), 1u);
  EXPECT_EQ(in.transforms[0].first, "Tool");
  EXPECT_TRUE(in.transforms[0].second.linear().isApprox(kRotation, 1e-6));
  EXPECT_TRUE(in.transforms[0].second.translation().isApprox(kTranslationMm * 1e-3, 1e-7));
  EXPECT_EQ(in.transformStamp, (1700000000ull << 32) | 0x40000000u);

  ASSERT_EQ(in.poses.size(), 1u);
  EXPECT_TRUE(in.poses[0].p.isApprox(dm::Vec3(0.001, 0.002, 0.003), 1e-7));
  EXPECT_LT(in.poses[0].q.angularDistance(kQuat), 1e-6);

  // The 3-D volume and the 2-D image (1 component: also a 1-slice volume).
  ASSERT_EQ(in.volumes.size(), 2u);
  const dm::Volume& v = in.volumes[0];
  EXPECT_EQ(v.dims(), dm::Vec3i(6, 5, 4));
  EXPECT_EQ(v.type(), dm::VoxelType::I16);
  for (int i = 0; i < 6 * 5 * 4; ++i) ASSERT_EQ(v.valueAt(static_cast<std::size_t>(i)), i * 100 - 5000) << i;
  EXPECT_TRUE(v.spacing().isApprox(dm::Vec3(0.5e-3, 0.8e-3, 2e-3), 1e-6));
  EXPECT_TRUE((v.indexToWorld() * dm::Vec3(2.5, 2, 1.5)).isApprox(dm::Vec3(0.010, 0.020, -0.030), 1e-6));
  ASSERT_EQ(in.images.size(), 1u);
  const dm::Image& img = in.images[0];
  EXPECT_EQ(img.width(), 8);
  EXPECT_EQ(img.height(), 6);
  for (int y = 0; y < 6; ++y)
    for (int x = 0; x < 8; ++x) ASSERT_EQ(img.at<std::uint8_t>(x, y), x + 10 * y);

  ASSERT_EQ(in.statuses.size(), 1u);
  EXPECT_EQ(in.statuses[0], (dmi::StatusInfo{.code = igtl::StatusMessage::STATUS_NOT_FOUND,
                                             .subcode = -123456789012LL,
                                             .errorName = "NoTool",
                                             .message = "tool 3 is not connected"}));
  ASSERT_EQ(in.strings.size(), 1u);
  EXPECT_EQ(in.strings[0], (dmi::StringInfo{.encoding = 106, .text = "grüß dich"}));

  ASSERT_EQ(in.points.size(), 1u);
  ASSERT_EQ(in.points[0].size(), 3u);
  for (int i = 0; i < 3; ++i) {
    const dmi::Point& p = in.points[0][static_cast<std::size_t>(i)];
    EXPECT_EQ(p.name, "P" + std::to_string(i));
    EXPECT_EQ(p.group, "Fiducial");
    EXPECT_EQ(p.rgba, (std::array<std::uint8_t, 4>{static_cast<std::uint8_t>(10 * i), 20, 30, 255}));
    EXPECT_TRUE(p.position.isApprox(dm::Vec3(0.001 * i, -0.002, 0.0035), 1e-7));
    EXPECT_NEAR(p.radius, 0.0015, 1e-9);
    EXPECT_EQ(p.owner, "CT");
  }
  ASSERT_EQ(in.meshes.size(), 1u);
  EXPECT_EQ(in.meshes[0].vertexCount(), 4u);
  EXPECT_EQ(in.meshes[0].triangleCount(), 4u);
  EXPECT_NEAR(in.meshes[0].surfaceArea(), kTetArea, 1e-12);
}

// ---------------------------------------------- reference client → ours ---

TEST(IgtlSessionInterop, ReferenceClientMessagesReachOurTypedHandlers) {
  dm::IoThread net;
  ASSERT_TRUE(net.start().ok());
  InteropInbox in;
  auto server = dm::IgtlServer::listen(net, {}, in.handlers());
  ASSERT_TRUE(server.ok());
  auto ref = igtl::ClientSocket::New();
  ASSERT_EQ(ref->ConnectToServer("127.0.0.1", (*server)->port()), 0);
  for (auto& m : referenceMessages()) ASSERT_TRUE(sendRef(ref, m));
  // 8 messages, the 1-component 2-D image reaching two handlers.
  ASSERT_TRUE(eventually([&] { return in.total() == 9; }));
  expectReferenceValues(in);
  const dm::IgtlStats s = (*server)->stats();
  EXPECT_EQ(s.messagesIn, 8u);
  EXPECT_EQ(s.typedDecodeFailures, 0u);
  EXPECT_EQ(s.malformed, 0u);
  ref->CloseSocket();
}

TEST(IgtlSessionInterop, ReferenceClientQueriesAreAnsweredByOurServer) {
  dm::IoThread net;
  ASSERT_TRUE(net.start().ok());
  InteropInbox in;
  auto server = dm::IgtlServer::listen(net, {}, in.handlers());
  ASSERT_TRUE(server.ok());
  auto ref = igtl::ClientSocket::New();
  ASSERT_EQ(ref->ConnectToServer("127.0.0.1", (*server)->port()), 0);
  ref->SetReceiveTimeout(5000);

  // GET_TRANS before anything is published: a TRANSFORM with no body.
  auto getTrans = igtl::GetTransformMessage::New();
  getTrans->SetDeviceName("Tool");
  getTrans->Pack();
  ASSERT_TRUE(sendRef(ref, getTrans));
  Received r = receiveRef(ref);
  ASSERT_TRUE(r.header);
  EXPECT_EQ(r.type(), "TRANSFORM");
  EXPECT_EQ(r.device(), "Tool");
  EXPECT_TRUE(r.body.empty());

  // Published: the reference unpacks it (CRC on) with our values.
  dm::Affine3 t = dm::Affine3::Identity();
  t.linear() = kRotation;
  t.translation() = kTranslationMm * 1e-3;
  ASSERT_TRUE((*server)->publish(dmi::encodeTransform({.deviceName = "Tool"}, t).value()).ok());
  ASSERT_TRUE(sendRef(ref, getTrans));
  auto trans = unpackRef<igtl::TransformMessage>(receiveRef(ref));
  ASSERT_TRUE(trans);
  EXPECT_STREQ(trans->GetDeviceName(), "Tool");
  igtl::Matrix4x4 got;
  trans->GetMatrix(got);
  igtl::Matrix4x4 expected;
  referenceMatrix(expected);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 4; ++j) EXPECT_FLOAT_EQ(got[i][j], expected[i][j]) << i << ", " << j;

  // GET_IMAGE of a published float32 volume.
  auto vol = dm::Volume::create({4, 3, 2}, dm::VoxelType::F32, volumeAffine());
  ASSERT_TRUE(vol.ok());
  for (std::size_t i = 0; i < vol->voxelCount(); ++i) vol->setValueAt(i, 0.25 * static_cast<double>(i) - 1.0);
  ASSERT_TRUE((*server)->publish(dmi::encodeVolume({.deviceName = "CT"}, *vol).value()).ok());
  auto getImage = igtl::GetImageMessage::New();
  getImage->SetDeviceName("CT");
  getImage->Pack();
  ASSERT_TRUE(sendRef(ref, getImage));
  auto image = unpackRef<igtl::ImageMessage>(receiveRef(ref));
  ASSERT_TRUE(image);
  int d[3];
  image->GetDimensions(d);
  EXPECT_EQ(d[0], 4);
  EXPECT_EQ(d[1], 3);
  EXPECT_EQ(d[2], 2);
  EXPECT_EQ(image->GetScalarType(), igtl::ImageMessage::TYPE_FLOAT32);
  float spacing[3];
  image->GetSpacing(spacing);
  EXPECT_NEAR(spacing[0], 0.5f, 1e-5);
  EXPECT_NEAR(spacing[1], 0.8f, 1e-5);
  EXPECT_NEAR(spacing[2], 2.0f, 1e-5);
  EXPECT_EQ(std::memcmp(image->GetScalarPointer(), vol->bytes(), vol->byteSize()), 0);

  // STT_TDATA: subscribed, answered RTS_TDATA status 0.
  auto stt = igtl::StartTrackingDataMessage::New();
  stt->SetDeviceName("Tracker");
  stt->SetResolution(0);
  stt->SetCoordinateName("Patient");
  stt->Pack();
  ASSERT_TRUE(sendRef(ref, stt));
  Received rts = receiveRef(ref);
  EXPECT_EQ(rts.type(), "RTS_TDATA");
  EXPECT_EQ(rts.device(), "Tracker");
  auto rtsMsg = unpackRef<igtl::RTSTrackingDataMessage>(rts);
  ASSERT_TRUE(rtsMsg);
  EXPECT_EQ(rtsMsg->GetStatus(), igtl::RTSTrackingDataMessage::STATUS_SUCCESS);

  // A TDATA published now reaches the subscriber, CRC intact.
  auto tdata = igtl::TrackingDataMessage::New();
  tdata->SetDeviceName("Tracker");
  auto element = igtl::TrackingDataElement::New();
  element->SetName("Stylus");
  element->SetType(igtl::TrackingDataElement::TYPE_6D);
  igtl::Matrix4x4 stylus;
  referenceMatrix(stylus);
  element->SetMatrix(stylus);
  tdata->AddTrackingDataElement(element);
  tdata->Pack();
  auto fan = (*server)->publish({static_cast<const std::byte*>(tdata->GetPackPointer()),
                                 static_cast<std::size_t>(tdata->GetPackSize())});
  ASSERT_TRUE(fan.ok());
  EXPECT_EQ(fan->sent, 1u);
  auto tdataBack = unpackRef<igtl::TrackingDataMessage>(receiveRef(ref));
  ASSERT_TRUE(tdataBack);
  ASSERT_EQ(tdataBack->GetNumberOfTrackingDataElements(), 1);
  igtl::TrackingDataElement::Pointer e;
  tdataBack->GetTrackingDataElement(0, e);
  EXPECT_STREQ(e->GetName(), "Stylus");
  igtl::Matrix4x4 m;
  e->GetMatrix(m);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 4; ++j) EXPECT_FLOAT_EQ(m[i][j], stylus[i][j]);

  // STP_TDATA: answered RTS_TDATA status 0; later publishes are not sent.
  auto stp = igtl::StopTrackingDataMessage::New();
  stp->SetDeviceName("Tracker");
  stp->Pack();
  ASSERT_TRUE(sendRef(ref, stp));
  auto stopped = unpackRef<igtl::RTSTrackingDataMessage>(receiveRef(ref));
  ASSERT_TRUE(stopped);
  EXPECT_EQ(stopped->GetStatus(), igtl::RTSTrackingDataMessage::STATUS_SUCCESS);
  EXPECT_EQ((*server)
                ->publish({static_cast<const std::byte*>(tdata->GetPackPointer()),
                           static_cast<std::size_t>(tdata->GetPackSize())})
                ->sent,
            0u);
  auto getStatus = igtl::GetStatusMessage::New();
  getStatus->Pack();
  ASSERT_TRUE(sendRef(ref, getStatus));
  EXPECT_EQ(receiveRef(ref).type(), "STATUS");  // the next message is the answer, not a TDATA

  // Our onQuery saw the reference's queries with their fields.
  ASSERT_TRUE(eventually([&] {
    std::lock_guard lock(in.mutex);
    return in.queries.size() == 6;
  }));
  {
    std::lock_guard lock(in.mutex);
    ASSERT_EQ(in.queries.size(), 6u);
    EXPECT_EQ(in.queries[0].second, (dmi::Query{.kind = dmi::QueryKind::Get, .dataType = "TRANS"}));
    EXPECT_EQ(in.queries[3].first, "Tracker");
    EXPECT_EQ(in.queries[3].second, (dmi::Query{.kind = dmi::QueryKind::Start,
                                                .dataType = "TDATA",
                                                .resolutionMs = 0,
                                                .coordinateName = "Patient"}));
    EXPECT_EQ(in.queries[4].second.kind, dmi::QueryKind::Stop);
  }
  EXPECT_EQ((*server)->stats().queriesAnswered, 6u);
  ref->CloseSocket();
}

// ---------------------------------------------- ours → reference server ---

/// What the reference server unpacked from our client, CRC checked.
struct ReferenceSaw {
  std::vector<std::string> types;
  int crcFailures = 0;
  float matrix[3][4] = {};
  float position[3] = {}, quaternion[4] = {};
  int dims[3] = {};
  int scalarType = 0;
  std::vector<std::uint8_t> scalars;
  int statusCode = 0;
  long long subcode = 0;
  std::string errorName, statusString, text;
  int encoding = 0;
  std::vector<std::string> pointNames;
  std::vector<std::array<float, 3>> pointPositions;
  float radius = 0;
  int polyPoints = 0, polyCells = 0;
  float lastPoint[3] = {};
};

TEST(IgtlSessionInterop, OurClientAndTheReferenceServerUnderstandEachOther) {
  auto refServer = igtl::ServerSocket::New();
  ASSERT_EQ(refServer->CreateServer(0), 0);
  const int port = refServer->GetServerPort();
  ASSERT_GT(port, 0);

  constexpr int kOurMessages = 7;
  ReferenceSaw saw;
  std::atomic<bool> done{false};
  std::atomic<bool> sentBack{false};
  std::thread reference([&] {
    igtl::ClientSocket::Pointer s = refServer->WaitForConnection(5000);
    if (!s) return;
    s->SetReceiveTimeout(5000);
    for (int i = 0; i < kOurMessages; ++i) {
      const Received r = receiveRef(s);
      if (!r.header) break;
      saw.types.push_back(r.type());
      const std::string type = r.type();
      if (type == "TRANSFORM") {
        auto m = unpackRef<igtl::TransformMessage>(r);
        if (!m) {
          ++saw.crcFailures;
          continue;
        }
        igtl::Matrix4x4 mat;
        m->GetMatrix(mat);
        for (int a = 0; a < 3; ++a)
          for (int b = 0; b < 4; ++b) saw.matrix[a][b] = mat[a][b];
      } else if (type == "POSITION") {
        auto m = unpackRef<igtl::PositionMessage>(r);
        if (!m) {
          ++saw.crcFailures;
          continue;
        }
        m->GetPosition(saw.position);
        m->GetQuaternion(saw.quaternion);
      } else if (type == "IMAGE") {
        auto m = unpackRef<igtl::ImageMessage>(r);
        if (!m) {
          ++saw.crcFailures;
          continue;
        }
        m->GetDimensions(saw.dims);
        saw.scalarType = m->GetScalarType();
        const auto* p = static_cast<const std::uint8_t*>(m->GetScalarPointer());
        saw.scalars.assign(p, p + m->GetImageSize());
      } else if (type == "STATUS") {
        auto m = unpackRef<igtl::StatusMessage>(r);
        if (!m) {
          ++saw.crcFailures;
          continue;
        }
        saw.statusCode = m->GetCode();
        saw.subcode = m->GetSubCode();
        saw.errorName = m->GetErrorName();
        saw.statusString = m->GetStatusString();
      } else if (type == "STRING") {
        auto m = unpackRef<igtl::StringMessage>(r);
        if (!m) {
          ++saw.crcFailures;
          continue;
        }
        saw.text = m->GetString();
        saw.encoding = m->GetEncoding();
      } else if (type == "POINT") {
        auto m = unpackRef<igtl::PointMessage>(r);
        if (!m) {
          ++saw.crcFailures;
          continue;
        }
        for (int k = 0; k < m->GetNumberOfPointElement(); ++k) {
          igtl::PointElement::Pointer e;
          m->GetPointElement(k, e);
          saw.pointNames.push_back(e->GetName());
          std::array<float, 3> p{};
          e->GetPosition(p.data());
          saw.pointPositions.push_back(p);
          saw.radius = e->GetRadius();
        }
      } else if (type == "POLYDATA") {
        auto m = unpackRef<igtl::PolyDataMessage>(r);
        if (!m) {
          ++saw.crcFailures;
          continue;
        }
        saw.polyPoints = m->GetPoints()->GetNumberOfPoints();
        saw.polyCells = static_cast<int>(m->GetPolygons()->GetNumberOfCells());
        m->GetPoints()->GetPoint(3, saw.lastPoint);
      }
    }
    // And back: every type packed by the reference, to our client.
    bool all = true;
    for (auto& m : referenceMessages()) all = sendRef(s, m) && all;
    sentBack = all;
    eventually([&] { return done.load(); }, 10s);  // keep the socket open until our side has read
    s->CloseSocket();
  });

  dm::IoThread net;
  ASSERT_TRUE(net.start().ok());
  InteropInbox in;
  auto client = dm::IgtlClient::connect(
      net, {.tcp = {.peer = {"127.0.0.1", static_cast<std::uint16_t>(port)}}}, in.handlers());
  ASSERT_TRUE(client.ok());
  ASSERT_TRUE((*client)->waitConnected(5s).ok());

  dm::Affine3 t = dm::Affine3::Identity();
  t.linear() = kRotation;
  t.translation() = kTranslationMm * 1e-3;
  const dm::Pose pose(dm::Vec3(-0.1, 0.25, 0.5), kQuat);
  auto vol = dm::Volume::create({4, 3, 2}, dm::VoxelType::U16, volumeAffine());
  ASSERT_TRUE(vol.ok());
  for (std::size_t i = 0; i < vol->voxelCount(); ++i) vol->setValueAt(i, static_cast<double>(i * 1000));
  const std::vector<dmi::Point> pts{
      {.name = "Entry", .group = "Plan", .position = {0.001, -0.002, 0.0035}, .radius = 0.0015},
      {.name = "Target", .group = "Plan", .position = {0.0, 0.01, 0.02}, .radius = 0.0015}};
  dm::Mesh tet;
  tet.positions = {{0, 0, 0}, {0.01, 0, 0}, {0, 0.01, 0}, {0, 0, 0.01}};
  tet.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  const std::vector<Bytes> ours{
      dmi::encodeTransform({.deviceName = "Tool"}, t).value(),
      dmi::encodePosition({.deviceName = "Needle"}, pose).value(),
      dmi::encodeVolume({.deviceName = "CT"}, *vol).value(),
      dmi::encodeStatus(
          {.deviceName = "Robot"},
          {.code = 4, .subcode = -123456789012LL, .errorName = "NoTool", .message = "tool 3 is gone"})
          .value(),
      dmi::encodeString({.deviceName = "Text"}, {.encoding = 106, .text = "grüß dich"}).value(),
      dmi::encodePoints({.deviceName = "Plan"}, pts).value(),
      dmi::encodePolyData({.deviceName = "Tet"}, tet).value()};
  ASSERT_EQ(ours.size(), static_cast<std::size_t>(kOurMessages));
  for (const Bytes& b : ours) ASSERT_TRUE((*client)->send(b).ok());

  const bool gotAll = eventually([&] { return in.total() == 9; }, 10s);
  done = true;
  reference.join();
  refServer->CloseSocket();
  ASSERT_TRUE(gotAll) << in.total() << " of 9 handler calls";
  EXPECT_TRUE(sentBack.load());

  // The reference read ours, CRC checked, with our values (mm on the wire).
  EXPECT_EQ(saw.types, (std::vector<std::string>{"TRANSFORM", "POSITION", "IMAGE", "STATUS", "STRING",
                                                 "POINT", "POLYDATA"}));
  EXPECT_EQ(saw.crcFailures, 0);
  igtl::Matrix4x4 expected;
  referenceMatrix(expected);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 4; ++j) EXPECT_FLOAT_EQ(saw.matrix[i][j], expected[i][j]) << i << ", " << j;
  EXPECT_FLOAT_EQ(saw.position[0], -100.f);
  EXPECT_FLOAT_EQ(saw.position[1], 250.f);
  EXPECT_FLOAT_EQ(saw.position[2], 500.f);
  EXPECT_NEAR(saw.quaternion[1], kQuat.y(), 1e-7);
  EXPECT_NEAR(saw.quaternion[3], kQuat.w(), 1e-7);
  EXPECT_EQ(saw.dims[0], 4);
  EXPECT_EQ(saw.dims[1], 3);
  EXPECT_EQ(saw.dims[2], 2);
  EXPECT_EQ(saw.scalarType, igtl::ImageMessage::TYPE_UINT16);
  ASSERT_EQ(saw.scalars.size(), vol->byteSize());
  EXPECT_EQ(std::memcmp(saw.scalars.data(), vol->bytes(), vol->byteSize()), 0);
  EXPECT_EQ(saw.statusCode, 4);
  EXPECT_EQ(saw.subcode, -123456789012LL);
  EXPECT_EQ(saw.errorName, "NoTool");
  EXPECT_EQ(saw.statusString, "tool 3 is gone");
  EXPECT_EQ(saw.text, "grüß dich");
  EXPECT_EQ(saw.encoding, 106);
  EXPECT_EQ(saw.pointNames, (std::vector<std::string>{"Entry", "Target"}));
  ASSERT_EQ(saw.pointPositions.size(), 2u);
  EXPECT_NEAR(saw.pointPositions[0][2], 3.5f, 1e-5);
  EXPECT_NEAR(saw.pointPositions[1][1], 10.f, 1e-5);
  EXPECT_NEAR(saw.radius, 1.5f, 1e-6);
  EXPECT_EQ(saw.polyPoints, 4);
  EXPECT_EQ(saw.polyCells, 4);
  EXPECT_NEAR(saw.lastPoint[2], 10.f, 1e-5);

  // Our client decoded what the reference sent back.
  expectReferenceValues(in);
  EXPECT_EQ((*client)->stats().messagesIn, 8u);
  EXPECT_EQ((*client)->stats().typedDecodeFailures, 0u);
}

}  // namespace
