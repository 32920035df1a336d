// Helpers shared by the DMIO file-format tests: byte buffers built by hand,
// files written for a test, and the real data of the mricron-data package.
#pragma once

#include <dm/core/filesystem.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace dm::test {

/// The bytes of `s`.
inline std::vector<std::byte> text(const std::string& s) {
  std::vector<std::byte> b(s.size());
  if (!s.empty()) std::memcpy(b.data(), s.data(), s.size());
  return b;
}

/// The bytes of the values `v`, each in the byte order asked for.
template <class T>
std::vector<std::byte> raw(const std::vector<T>& v, bool bigEndian = false) {
  std::vector<std::byte> b(v.size() * sizeof(T));
  if (!b.empty()) std::memcpy(b.data(), v.data(), b.size());
  if (bigEndian != (std::endian::native == std::endian::big))
    for (std::size_t i = 0; i < b.size(); i += sizeof(T))
      std::reverse(b.begin() + i, b.begin() + i + sizeof(T));
  return b;
}

/// `a` followed by `b`.
inline std::vector<std::byte> operator+(std::vector<std::byte> a, const std::vector<std::byte>& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}

/// True when the one-line message of `e` holds `s`.
inline bool mentions(const dm::Error& e, const std::string& s) { return e.message().find(s) != std::string::npos; }

/// Eight bytes of 1: the voxels of a 2 x 2 x 2 uint8 volume.
inline const std::vector<std::byte> kEight(8, std::byte{1});

inline void writeBytes(const std::filesystem::path& p, const std::vector<std::byte>& b) {
  auto s = writeFileAtomic(p, b.data(), b.size());
  ASSERT_TRUE(s) << s.error();
}

inline void writeText(const std::filesystem::path& p, const std::string& s) {
  std::ofstream f(p, std::ios::binary);
  f << s;
}

/// Resolves a file of the mricron-data package, failing with the package name.
inline std::filesystem::path mricron(const std::string& name) {
  auto p = FileSystem::global().resolve("mricron:" + name);
  if (!p) {
    ADD_FAILURE() << "test data missing: install the Debian package mricron-data (scripts/setup.sh does): "
                  << p.error();
    return {};
  }
  return *p;
}

}  // namespace dm::test
