// x_pointer.hpp — the X pointer (and keys) of a test's virtual display
// moved over (sent to) a program's window (the live view's mouse tests), with Xlib kept in its own
// file (x_pointer.cpp: its macros would break the other sources of a batch).
#pragma once

#include <string>

namespace dm::test {

class XPointer {
 public:
  explicit XPointer(const std::string& display);
  ~XPointer();
  XPointer(const XPointer&) = delete;
  XPointer& operator=(const XPointer&) = delete;
  /// Waits up to `seconds` for a top-level window whose name starts with
  /// `prefix`; false when none came.
  bool waitForWindow(const std::string& prefix, double seconds);
  /// The pointer to (x, y) of that window (pixels from its top-left corner).
  void warp(int x, int y);
  /// A press and release of the key of `letter` ('a'..'z') sent to that window.
  void key(char letter);

 private:
  void* display_ = nullptr;
  unsigned long window_ = 0;
};

}  // namespace dm::test
