// libFuzzer target: the haply-2diy driver's reading of a board's answer
// (bytes from a USB serial device, so untrusted) and the kinematics of the
// angles it carries. The first byte picks the decoding (the analog pin, the
// port order, the id); the rest is the answer. An answer is accepted only
// at its exact length with the board's id; its angles then give either no
// pose or a finite handle in front of the motors with a finite Jacobian.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>

#include "../../DMIO/drivers/haply_protocol.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const bool analog = data[0] & 1, arm1Second = data[0] & 2;
  const std::uint8_t id = data[0] >> 2;
  dm::driver::haply::Answer answer;
  const bool ok = dm::driver::haply::decodeAnswer(data + 1, size - 1, id, analog, arm1Second, answer);
  const std::size_t expected = 1 + 4 * ((analog ? 1 : 0) + 2);
  if (ok && (size - 1 != expected || data[1] != id)) std::abort();
  if (!ok) return 0;
  const dm::driver::haply::HaplyPose pose =
      dm::driver::haply::haplyPoseOf({}, answer.degrees[0], answer.degrees[1]);
  if (!pose.valid) return 0;
  if (!std::isfinite(pose.x) || !std::isfinite(pose.y) || !(pose.y > 0.0)) std::abort();
  for (const auto& row : pose.jt)
    if (!std::isfinite(row[0]) || !std::isfinite(row[1])) std::abort();
  return 0;
}
