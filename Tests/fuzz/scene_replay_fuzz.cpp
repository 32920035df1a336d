// libFuzzer target: a recording's bytes turned into a replay
// (dm::parseRecording, then dm::loadReplay: the header's JSON, the recorded
// scene, the haptic states) and two force traces compared
// (dm::compareForceTraces on the input split at its first NUL) — never a
// crash; what loads has a haptics engine driven by replay-haptic and a
// positive duration.
#include <dm/io/recorder.hpp>
#include <dm/io/scene_replay.hpp>

#include <cstdint>
#include <cstdlib>
#include <string_view>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (auto rec = dm::parseRecording({data, size}, "fuzz.dmrec"))
    if (auto r = dm::loadReplay(*rec, "fuzz.dmrec")) {
      const dm::SceneDevice* d =
          r->scene.engines.haptics ? r->scene.device(r->scene.engines.haptics->device) : nullptr;
      if (d == nullptr || d->driver != "replay-haptic" || !(r->duration > 0.0) || r->records == 0)
        std::abort();
    }
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  const std::size_t cut = text.find('\0');
  if (cut != std::string_view::npos)
    if (auto c = dm::compareForceTraces(text.substr(0, cut), text.substr(cut + 1)))
      if (c->identical > c->compared) std::abort();
  return 0;
}
