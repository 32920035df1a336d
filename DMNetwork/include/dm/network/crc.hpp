// dm/network/crc.hpp — the checksums of our wire formats.
//
// crc64Ecma() is the CRC-64 that OpenIGTLink puts in every header: the
// ECMA-182 polynomial 0x42F0E1EBA9EA3693, MSB first (not reflected), initial
// value 0, no final xor — the same function as the reference library's
// crc64(data, len, 0). crc32c() is CRC-32C (Castagnoli, reflected polynomial
// 0x82F63B78, init and final xor 0xFFFFFFFF), which our own message model
// (dm/network/message.hpp) uses: it detects every burst error up to 32 bits
// and all 1-, 2- and 3-bit errors in messages up to ~2 Gbit.
// Both are table driven (one byte per step), allocation free and may be
// called from real-time threads. Both can be continued across chunks.
//
// @code
//   std::uint64_t c = dm::crc64Ecma(body);                 // one go
//   std::uint32_t k = dm::crc32c(part2, dm::crc32c(part1)); // in chunks
// @endcode
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>

namespace dm {

/// CRC-64/ECMA-182 as OpenIGTLink computes it, continuing from `crc` (0 to
/// start). crc64Ecma("123456789") == 0x6C40DF5F0B497347. O(n), no allocation.
std::uint64_t crc64Ecma(std::span<const std::byte> data, std::uint64_t crc = 0) noexcept;

/// CRC-32C (Castagnoli), continuing from a previous result `crc` (0 to
/// start). crc32c("123456789") == 0xE3069283. O(n), no allocation.
std::uint32_t crc32c(std::span<const std::byte> data, std::uint32_t crc = 0) noexcept;

}  // namespace dm
