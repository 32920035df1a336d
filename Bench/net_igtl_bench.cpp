// OpenIGTLink codec throughput, ours vs the reference library (OpenIGTLink
// 1.11): encode + CRC + decode of TRANSFORM and of a 256×256 uint8 IMAGE, per
// second (best of 5 rounds). Both sides verify the CRC-64 on decode. Links DM::Network and the
// reference library (OpenIGTLink_LIBRARIES, include dir OpenIGTLink_INCLUDE_DIRS).
#include <dm/network/igtl.hpp>

#include <igtlImageMessage.h>
#include <igtlMessageHeader.h>
#include <igtlTransformMessage.h>
#include <igtl_header.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;

// Best of 5 rounds (the machine is shared; the fastest round is the least disturbed).
template <class F>
double perSecond(int iterations, F&& body) {
  body();  // warm-up
  double best = 0;
  for (int round = 0; round < 5; ++round) {
    const auto t0 = Clock::now();
    for (int i = 0; i < iterations; ++i) body();
    best = std::max(best, iterations / std::chrono::duration<double>(Clock::now() - t0).count());
  }
  return best;
}

// Unpacks `sender`'s packed bytes into `receiver` the way a socket reader does.
template <class M>
bool refReceive(igtl::MessageBase* sender, igtl::MessageHeader* header, M* receiver) {
  header->InitPack();
  std::memcpy(header->GetPackPointer(), sender->GetPackPointer(), IGTL_HEADER_SIZE);
  header->Unpack();
  receiver->SetMessageHeader(header);
  receiver->AllocatePack();
  std::memcpy(receiver->GetPackBodyPointer(),
              static_cast<const char*>(sender->GetPackPointer()) + IGTL_HEADER_SIZE,
              static_cast<std::size_t>(receiver->GetPackBodySize()));
  return (receiver->Unpack(1) & igtl::MessageBase::UNPACK_BODY) != 0;
}

volatile double gSink = 0;

}  // namespace

int main() {
  namespace dmi = dm::igtl;
  const dm::Pose pose(dm::Vec3(0.01, 0.02, 0.03), dm::Quat(Eigen::AngleAxisd(0.4, dm::Vec3(0, 0, 1))));
  const dmi::Envelope env{.deviceName = "Tracker"};

  // The reference packs into message objects it reuses; ours appends into a
  // reused buffer (appendTransform) the same way. The allocating form
  // (encodeTransform returns a new vector) is measured as well.
  std::vector<std::byte> buffer;
  const dm::Affine3 affine(pose.isometry().matrix());
  const double oursT = perSecond(50000, [&] {
    buffer.clear();
    if (!dmi::appendTransform(env, affine, buffer)) std::abort();
    auto m = dmi::decodeMessage(buffer);
    gSink = gSink + dmi::decodeTransform(*m)->translation().x();
  });
  const double oursTNew = perSecond(50000, [&] {
    auto bytes = dmi::encodeTransform(env, pose.isometry());
    auto m = dmi::decodeMessage(*bytes);
    gSink = gSink + dmi::decodeTransform(*m)->translation().x();
  });
  igtl::TransformMessage::Pointer tx = igtl::TransformMessage::New();
  igtl::TransformMessage::Pointer rx = igtl::TransformMessage::New();
  igtl::MessageHeader::Pointer hdr = igtl::MessageHeader::New();
  igtl::Matrix4x4 mat;
  igtl::IdentityMatrix(mat);
  mat[0][3] = 10.f;
  tx->SetDeviceName("Tracker");
  const double refT = perSecond(50000, [&] {
    tx->SetMatrix(mat);
    tx->Pack();
    if (!refReceive(tx.GetPointer(), hdr.GetPointer(), rx.GetPointer())) std::abort();
    igtl::Matrix4x4 got;
    rx->GetMatrix(got);
    gSink = gSink + got[0][3];
  });

  auto vol = dm::Volume::create({256, 256, 1}, dm::VoxelType::U8);
  for (std::size_t i = 0; i < vol->voxelCount(); ++i) vol->bytes()[i] = static_cast<std::byte>(i * 7);
  const double oursI = perSecond(500, [&] {
    auto bytes = dmi::encodeVolume(env, *vol);
    auto m = dmi::decodeMessage(*bytes);
    gSink = gSink + static_cast<double>(dmi::decodeVolume(*m)->byteSize());
  });
  igtl::ImageMessage::Pointer itx = igtl::ImageMessage::New();
  igtl::ImageMessage::Pointer irx = igtl::ImageMessage::New();
  itx->SetDeviceName("US");
  itx->SetDimensions(256, 256, 1);
  itx->SetSpacing(1.f, 1.f, 1.f);
  itx->SetScalarTypeToUint8();
  itx->AllocateScalars();
  const double refI = perSecond(500, [&] {
    std::memcpy(itx->GetScalarPointer(), vol->bytes(), vol->byteSize());
    itx->Pack();
    if (!refReceive(itx.GetPointer(), hdr.GetPointer(), irx.GetPointer())) std::abort();
    gSink = gSink + static_cast<double>(static_cast<const std::uint8_t*>(irx->GetScalarPointer())[5]);
  });

  std::printf("OpenIGTLink encode+decode (CRC-64 checked), messages per second\n");
  std::printf("%-24s %14s %14s %8s\n", "message", "DMNetwork", "reference", "ours/ref");
  std::printf("%-24s %14.0f %14.0f %8.2f\n", "TRANSFORM", oursT, refT, oursT / refT);
  std::printf("%-24s %14.0f %14.0f %8.2f\n", "TRANSFORM (new vector)", oursTNew, refT, oursTNew / refT);
  std::printf("%-24s %14.0f %14.0f %8.2f\n", "IMAGE 256x256 uint8", oursI, refI, oursI / refI);
  return 0;
}
