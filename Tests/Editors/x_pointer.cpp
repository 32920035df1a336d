// x_pointer.cpp — XPointer (x_pointer.hpp) on Xlib.
#include "x_pointer.hpp"

#include <X11/Xlib.h>
#include <X11/Xutil.h>
#include <X11/keysym.h>

#include <chrono>
#include <thread>

namespace dm::test {

namespace {

// The top-level window whose name starts with `prefix`, or 0.
Window findWindow(Display* d, const std::string& prefix) {
  Window root = 0, parent = 0, *children = nullptr;
  unsigned count = 0;
  Window found = 0;
  if (!XQueryTree(d, DefaultRootWindow(d), &root, &parent, &children, &count)) return 0;
  for (unsigned i = 0; i < count && !found; ++i) {
    // WM_NAME's bytes: a UTF-8 title (GLFW's) is COMPOUND_TEXT there, which
    // XFetchName refuses, but an ASCII prefix reads the same in it.
    XTextProperty name{};
    if (XGetWMName(d, children[i], &name) && name.value) {
      const std::string title(reinterpret_cast<const char*>(name.value), name.nitems);
      if (title.rfind(prefix, 0) == 0) found = children[i];
      XFree(name.value);
    }
  }
  if (children) XFree(children);
  return found;
}

}  // namespace

XPointer::XPointer(const std::string& display) : display_(XOpenDisplay(display.c_str())) {}

XPointer::~XPointer() {
  if (display_) XCloseDisplay(static_cast<Display*>(display_));
}

bool XPointer::waitForWindow(const std::string& prefix, double seconds) {
  if (!display_) return false;
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (!(window_ = findWindow(static_cast<Display*>(display_), prefix))) {
    if (std::chrono::steady_clock::now() > end) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return true;
}

void XPointer::warp(int x, int y) {
  if (!display_ || !window_) return;
  XWarpPointer(static_cast<Display*>(display_), None, window_, 0, 0, 0, 0, x, y);
  XFlush(static_cast<Display*>(display_));
}

void XPointer::key(char letter) {
  if (!display_ || !window_) return;
  Display* d = static_cast<Display*>(display_);
  XKeyEvent e{};
  e.display = d;
  e.window = window_;
  e.root = DefaultRootWindow(d);
  e.subwindow = None;
  e.time = CurrentTime;
  e.same_screen = True;
  e.keycode = XKeysymToKeycode(d, XK_a + (letter - 'a'));
  e.type = KeyPress;
  XSendEvent(d, window_, True, KeyPressMask, reinterpret_cast<XEvent*>(&e));
  e.type = KeyRelease;
  XSendEvent(d, window_, True, KeyReleaseMask, reinterpret_cast<XEvent*>(&e));
  XFlush(d);
}

}  // namespace dm::test
