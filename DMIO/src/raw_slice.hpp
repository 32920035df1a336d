// Private to DMIO: locating one volume's bytes in the data stream of a
// header-plus-raw format (MetaImage, NRRD), so both readers apply the same
// bounds checks before anything is allocated.
#pragma once

#include <dm/core/result.hpp>

#include <cstddef>
#include <cstdint>
#include <functional>
#include <span>
#include <string>

namespace dm::detail {

/// Builds the format's "data too short" error: `have` bytes found in `what`.
using ShortDataError = std::function<Error(std::uint64_t have, const char* what)>;

/// The `volumeBytes` bytes of volume `index` (of `volumes`) in `stream`.
/// `skip` bytes precede the data, or -1: the data ends the stream (the
/// MetaImage HeaderSize / NRRD byte skip convention). Errors: overflowing
/// sizes, or a stream too short (through `shortData`).
inline Result<std::span<const std::byte>> rawVolumeSlice(std::span<const std::byte> stream, std::int64_t skip,
                                                         std::uint64_t volumes, std::uint64_t volumeBytes,
                                                         std::uint64_t index, const std::string& source,
                                                         const ShortDataError& shortData) {
  const std::uint64_t volStart = index * volumeBytes;  // overflow checked by the callers
  std::uint64_t start;
  if (skip == -1) {
    if (volumeBytes != 0 && volumes > (std::uint64_t{1} << 62) / volumeBytes)
      return fail(ErrorCode::Parse, "total data size overflows", source);
    const std::uint64_t all = volumes * volumeBytes;
    if (all > stream.size()) return shortData(stream.size(), "the data");
    start = stream.size() - all + volStart;
  } else {
    start = static_cast<std::uint64_t>(skip) + volStart;
  }
  if (start > stream.size() || stream.size() - start < volumeBytes)
    return shortData(stream.size(), "the data");
  return stream.subspan(static_cast<std::size_t>(start), static_cast<std::size_t>(volumeBytes));
}

}  // namespace dm::detail
