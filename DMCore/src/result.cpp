#include <dm/core/assert.hpp>
#include <dm/core/result.hpp>

#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <ostream>

namespace dm {

namespace detail {
void assertionFailed(const char* kind, const char* expr, const char* msg, const char* file,
                     int line) noexcept {
  std::fprintf(stderr, "%s:%d: %s(%s) failed: %s\n", file, line, kind, expr, msg ? msg : "");
  std::fflush(stderr);
  std::abort();
}
}  // namespace detail

std::string formatString(const char* format, ...) noexcept {
  char buf[512];
  std::va_list args;
  va_start(args, format);
  const int n = std::vsnprintf(buf, sizeof buf, format, args);
  va_end(args);
  try {
    return n < 0 ? std::string() : std::string(buf);
  } catch (...) {  // out of memory for a message: an empty one
    return {};
  }
}

std::string shownText(std::string_view text, std::size_t maxChars) {
  std::string out;
  for (std::size_t i = 0; i < text.size() && i < maxChars; ++i) {
    const auto c = static_cast<unsigned char>(text[i]);
    if (c >= 32 && c < 127) {
      out += static_cast<char>(c);
    } else {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\x%02x", c);
      out += buf;
    }
  }
  if (text.size() > maxChars) out += "...";
  return out;
}

const char* toString(ErrorCode code) noexcept {
  switch (code) {
    case ErrorCode::InvalidArgument:
      return "invalid argument";
    case ErrorCode::NotFound:
      return "not found";
    case ErrorCode::Io:
      return "I/O error";
    case ErrorCode::Parse:
      return "parse error";
    case ErrorCode::Unsupported:
      return "unsupported";
    case ErrorCode::Version:
      return "version mismatch";
    case ErrorCode::Device:
      return "device error";
    case ErrorCode::Network:
      return "network error";
    case ErrorCode::Timeout:
      return "timeout";
    case ErrorCode::Busy:
      return "busy";
    case ErrorCode::Internal:
      return "internal error";
    case ErrorCode::Denied:
      return "denied";
  }
  return "unknown error";
}

std::string Error::message() const {
  std::string s;
  if (!where.empty()) s += where + ": ";
  s += toString(code);
  s += ": ";
  s += what;
  if (!hint.empty()) s += " (" + hint + ")";
  return s;
}

Error combineErrors(std::span<const Error> errors) {
  DM_DEMAND(!errors.empty(), "combineErrors() needs at least one error");
  Error first = errors.front();
  if (errors.size() > 1) {
    first.what +=
        " (and " + std::to_string(errors.size() - 1) + " more problem" + (errors.size() > 2 ? "s" : "") + ":";
    for (std::size_t i = 1; i < errors.size(); ++i) first.what += " [" + errors[i].message() + "]";
    first.what += ")";
  }
  return first;
}

Error Error::within(const std::string& outer) const {
  Error e = *this;
  e.where = where.empty() ? outer : outer + ": " + where;
  return e;
}

std::ostream& operator<<(std::ostream& os, const Error& e) { return os << e.message(); }

}  // namespace dm
