// Helpers shared by the DMCore tests (plugin_test.cpp, resource_test.cpp).
#pragma once

#include <gtest/gtest.h>

#include <string>

namespace dm::test {

/// True if `part` occurs in `s`.
inline bool contains(const std::string& s, const std::string& part) {
  return s.find(part) != std::string::npos;
}

}  // namespace dm::test

/// Expects the text `needle` in `haystack`, printing both when it is missing.
#define EXPECT_HAS(haystack, needle)                      \
  EXPECT_TRUE(::dm::test::contains((haystack), (needle))) \
      << "expected \"" << (needle) << "\" in: " << (haystack)
