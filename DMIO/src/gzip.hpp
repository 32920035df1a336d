// gzip.hpp — private zlib wrapper for the volume importers (NIfTI .nii.gz,
// MetaImage CompressedData, NRRD gzip encoding).
//
// Inflation is bounded: the caller states how many output bytes it needs at
// most, and inflation stops there, so a gzip bomb never allocates more than
// the header it came with claimed. The output buffer grows geometrically as
// data actually decompresses, so a lying header does not allocate either.
//
// @code
//   auto raw = dm::detail::inflate(bytes, 352 + nBytes, "head.nii.gz");
//   if (!raw) return std::move(raw).error();
// @endcode
#pragma once

#include <dm/core/result.hpp>

#include <cstddef>
#include <span>
#include <string_view>
#include <vector>

namespace dm::detail {

/// True when `bytes` starts with the gzip magic 1f 8b.
bool isGzip(std::span<const std::byte> bytes) noexcept;

/// Inflates a gzip (one or more concatenated members) or zlib stream (format
/// detected from its first bytes), discards the first `skip` decompressed
/// bytes (through a 64 KiB scratch buffer) and returns at most `maxOutput`
/// of the bytes after them: inflation stops as soon as those are produced,
/// without error. A stream that ends cleanly but early returns fewer bytes;
/// the caller checks the size it needs. Fails with a Parse error naming
/// `source` and the compressed byte offset on corrupt data, or on a
/// truncated stream that ends before `skip + maxOutput` bytes.
/// O(skip + output) time, O(output) memory.
Result<std::vector<std::byte>> inflate(std::span<const std::byte> compressed, std::size_t maxOutput,
                                       std::string_view source, std::size_t skip = 0);

enum class CompressFormat { Gzip, Zlib };

/// Deflates `data` into a gzip or zlib stream at zlib level `level` (0..9).
/// Fails only if zlib runs out of memory.
Result<std::vector<std::byte>> deflate(std::span<const std::byte> data, CompressFormat format, int level = 6);

}  // namespace dm::detail
