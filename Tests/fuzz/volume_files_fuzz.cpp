// libFuzzer target: the volume readers that read files — a header and the
// data file it names (MetaImage .mhd, NRRD .nhdr with detached data, the
// NIfTI .hdr/.img pair), the lookup of that data file next to the header
// and its confinement to the header's folder (a name that leaves it must be
// refused before it is opened). The first byte picks the format, the rest
// is the header and the data split at the first "\n@@DATA@@\n": both are
// written into a private folder as v.mhd / v.nhdr / v.hdr and the data as
// v.raw (v.img for NIfTI), which a header names to reach it. Any input must
// give a Volume or a dm::Error with a message; a file outside the folder is
// never read (a sentinel file beside the folder must never become voxels).
#include <dm/io/metaimage.hpp>
#include <dm/io/nifti.hpp>
#include <dm/io/nrrd.hpp>

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>

namespace {

namespace fs = std::filesystem;

// The sentinel beside the folder: a pattern a volume read from the folder
// could hold only if the input itself holds it.
std::string sentinel() {
  std::string s;
  for (int i = 0; i < 1024; ++i) s += "\xa5\x5a\xc3\x3c";
  return s;
}

// A folder of this process's own, inside a parent that also holds the
// sentinel a header could try to reach with "../outside.raw".
const fs::path& folder() {
  static const fs::path dir = [] {
    const fs::path parent =
        fs::temp_directory_path() / ("dm_volume_files_fuzz_" + std::to_string(::getpid()));
    fs::create_directories(parent / "in");
    std::ofstream(parent / "outside.raw", std::ios::binary) << sentinel();
    std::atexit([] {  // no folder left behind in /tmp
      std::error_code ec;
      fs::remove_all(fs::temp_directory_path() / ("dm_volume_files_fuzz_" + std::to_string(::getpid())), ec);
    });
    return parent / "in";
  }();
  return dir;
}

void write(const fs::path& p, std::string_view bytes) {
  std::ofstream(p, std::ios::binary | std::ios::trunc)
      .write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const std::string_view all(reinterpret_cast<const char*>(data) + 1, size - 1);
  constexpr std::string_view kSplit = "\n@@DATA@@\n";
  const std::size_t at = all.find(kSplit);
  const std::string_view header = all.substr(0, at);
  const std::string_view body =
      at == std::string_view::npos ? std::string_view() : all.substr(at + kSplit.size());
  const fs::path& dir = folder();
  const int format = data[0] % 3;
  const fs::path file = dir / (format == 0 ? "v.mhd" : format == 1 ? "v.nhdr" : "v.hdr");
  write(file, header);
  write(dir / (format == 2 ? "v.img" : "v.raw"), body);
  constexpr std::size_t kMax = std::size_t{64} << 20;
  dm::Result<dm::Volume> v = format == 0   ? dm::readMetaImage(file, {.maxBytes = kMax})
                             : format == 1 ? dm::readNrrd(file, {.maxBytes = kMax})
                                           : dm::readNifti(file, {.maxBytes = kMax});
  if (!v) {
    if (v.error().what.empty()) std::abort();
    return 0;
  }
  // Voxels that are the sentinel's bytes came from outside the folder,
  // unless the input holds them itself.
  static const std::string outside = sentinel();
  const std::string_view got(reinterpret_cast<const char*>(v->bytes()), v->byteSize());
  if (got.size() >= 16 && outside.compare(0, got.size(), got) == 0 &&
      all.find(std::string_view(outside).substr(0, 16)) == std::string_view::npos)
    std::abort();
  return 0;
}
