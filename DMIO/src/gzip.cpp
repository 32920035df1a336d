#include "gzip.hpp"

#include <zlib.h>

#include <algorithm>
#include <climits>
#include <string>

namespace dm::detail {

bool isGzip(std::span<const std::byte> bytes) noexcept {
  return bytes.size() >= 2 && bytes[0] == std::byte{0x1f} && bytes[1] == std::byte{0x8b};
}

namespace {
// zlib counts in uInt; feed and drain in pieces that fit.
constexpr std::size_t kMaxChunk = std::size_t{1} << 30;
}  // namespace

Result<std::vector<std::byte>> inflate(std::span<const std::byte> compressed, std::size_t maxOutput,
                                       std::string_view source, std::size_t skip) {
  std::vector<std::byte> out;
  if (maxOutput == 0 || compressed.empty()) return out;

  z_stream zs{};
  // 15 + 32: accept both zlib and gzip headers, detected automatically.
  if (inflateInit2(&zs, 15 + 32) != Z_OK)
    return fail(ErrorCode::Internal, "zlib inflateInit2 failed", std::string(source));

  // Skipped output goes through a small scratch buffer. Kept output starts
  // small and doubles (deflate expands at most ~1032:1, so a lying header
  // cannot make us allocate much more than the stream really holds).
  std::vector<std::byte> scratch(skip > 0 ? std::min(skip, std::size_t{1} << 16) : 0);
  std::size_t skipped = 0;
  std::size_t produced = 0;
  std::size_t consumed = 0;
  auto* in = reinterpret_cast<const Bytef*>(compressed.data());
  Error error;
  bool failed = false;
  for (;;) {
    const bool skipping = skipped < skip;
    if (!skipping && produced == out.size()) {
      if (produced == maxOutput) break;
      const std::size_t initial =
          std::min(maxOutput, std::max<std::size_t>(std::size_t{1} << 16, compressed.size() * 4));
      out.resize(produced == 0 ? initial : (produced > maxOutput / 2 ? maxOutput : produced * 2));
    }
    if (zs.avail_in == 0) {
      if (consumed == compressed.size()) {
        failed = true;
        error = fail(ErrorCode::Parse,
                     "compressed data is truncated (stream ends after " + std::to_string(consumed) +
                         " compressed bytes, " + std::to_string(skipped + produced) + " bytes decompressed)",
                     std::string(source), "the file was probably cut short; download or copy it again");
        break;
      }
      const std::size_t n = std::min(kMaxChunk, compressed.size() - consumed);
      zs.next_in = const_cast<Bytef*>(in + consumed);
      zs.avail_in = static_cast<uInt>(n);
      consumed += n;
    }
    const std::size_t room =
        skipping ? std::min(scratch.size(), skip - skipped) : std::min(kMaxChunk, out.size() - produced);
    zs.next_out = reinterpret_cast<Bytef*>(skipping ? scratch.data() : out.data() + produced);
    zs.avail_out = static_cast<uInt>(room);
    const int rc = ::inflate(&zs, Z_NO_FLUSH);
    (skipping ? skipped : produced) += room - zs.avail_out;
    if (rc == Z_STREAM_END) {
      // Concatenated gzip members (e.g. from pigz or `cat a.gz b.gz`) continue the data.
      const std::size_t offset = consumed - zs.avail_in;
      if (offset + 2 <= compressed.size() && isGzip(compressed.subspan(offset))) {
        if (inflateReset(&zs) != Z_OK) {
          failed = true;
          error = fail(ErrorCode::Internal, "zlib inflateReset failed", std::string(source));
          break;
        }
        continue;
      }
      break;
    }
    if (rc == Z_BUF_ERROR) continue;  // needs more input or more output; the loop supplies it
    if (rc != Z_OK) {
      failed = true;
      const std::size_t offset = consumed - zs.avail_in;
      error = fail(ErrorCode::Parse,
                   std::string("corrupt compressed data at compressed byte ") + std::to_string(offset) +
                       ": " + (zs.msg ? zs.msg : "zlib error " + std::to_string(rc)),
                   std::string(source), "the file is damaged or not gzip/zlib data");
      break;
    }
  }
  inflateEnd(&zs);
  if (failed) return error;
  out.resize(produced);
  out.shrink_to_fit();
  return out;
}

Result<std::vector<std::byte>> deflate(std::span<const std::byte> data, CompressFormat format, int level) {
  z_stream zs{};
  const int windowBits = format == CompressFormat::Gzip ? 15 + 16 : 15;
  if (deflateInit2(&zs, std::clamp(level, 0, 9), Z_DEFLATED, windowBits, 8, Z_DEFAULT_STRATEGY) != Z_OK)
    return fail(ErrorCode::Internal, "zlib deflateInit2 failed", "deflate");
  std::vector<std::byte> out(std::max<std::size_t>(64, data.size() / 2 + 64));
  std::size_t produced = 0;
  std::size_t consumed = 0;
  int rc = Z_OK;
  while (rc != Z_STREAM_END) {
    if (zs.avail_in == 0 && consumed < data.size()) {
      const std::size_t n = std::min(kMaxChunk, data.size() - consumed);
      zs.next_in = const_cast<Bytef*>(reinterpret_cast<const Bytef*>(data.data() + consumed));
      zs.avail_in = static_cast<uInt>(n);
      consumed += n;
    }
    if (produced == out.size()) out.resize(out.size() * 2);
    const std::size_t room = std::min(kMaxChunk, out.size() - produced);
    zs.next_out = reinterpret_cast<Bytef*>(out.data() + produced);
    zs.avail_out = static_cast<uInt>(room);
    const int flush = (consumed == data.size()) ? Z_FINISH : Z_NO_FLUSH;
    rc = ::deflate(&zs, flush);
    produced += room - zs.avail_out;
    if (rc == Z_STREAM_ERROR) {
      deflateEnd(&zs);
      return fail(ErrorCode::Internal, "zlib deflate failed", "deflate");
    }
  }
  deflateEnd(&zs);
  out.resize(produced);
  return out;
}

}  // namespace dm::detail
