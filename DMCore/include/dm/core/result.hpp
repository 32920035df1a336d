// dm/core/result.hpp — the result type for recoverable failures.
//
// Every operation that can fail because of something outside the program
// (a file, a configuration, a device, the network) returns dm::Result<T>:
// either a value or a dm::Error whose message says what failed, where
// (file, JSON path, byte offset, device) and what to do about it.
// Results never throw; reading value() of an error is a DM_DEMAND failure.
//
// @code
//   dm::Result<dm::Volume> v = loadVolume("head.nii.gz");
//   if (!v) { std::cerr << v.error() << '\n'; return 1; }
//   use(*v);
// @endcode
#pragma once

#include <dm/core/assert.hpp>

#include <cstddef>
#include <cstdint>
#include <iosfwd>
#include <span>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <variant>

namespace dm {

/// Broad category of a failure, for code that branches on it.
enum class ErrorCode : std::uint8_t {
  InvalidArgument,  ///< a value given by the caller is out of its domain
  NotFound,         ///< a file, resource, plugin or key does not exist
  Io,               ///< reading or writing failed
  Parse,            ///< input is malformed (bytes, JSON, header fields)
  Unsupported,      ///< valid input the SDK cannot handle (datatype, version)
  Version,          ///< ABI or format version mismatch
  Device,           ///< a device failed or disappeared
  Network,          ///< a connection failed
  Timeout,          ///< an operation did not finish in time
  Busy,             ///< a resource is in use or a queue is full
  Internal,         ///< a bug in the SDK; please report
  Denied,           ///< not allowed, e.g. a file outside the allowed folders
};

/// Short name of an error code ("parse error", "not found", ...).
const char* toString(ErrorCode code) noexcept;

/// A recoverable failure: what failed, where, and what to do.
struct Error {
  ErrorCode code = ErrorCode::Internal;
  std::string what;   ///< what failed, e.g. "dim[1] is 0"
  std::string where;  ///< file, JSON path, byte offset or device; may be empty
  std::string hint;   ///< what to do; may be empty

  /// "where: what (hint)" — the one-line message shown to users.
  std::string message() const;
  /// Returns a copy whose `where` is prefixed by `outer` ("scene.json: /objects/0").
  Error within(const std::string& outer) const;
};

std::ostream& operator<<(std::ostream& os, const Error& e);

/// One error reporting all of `errors` (non-empty): the first, with the
/// others' messages appended, so a user sees every mistake at once.
Error combineErrors(std::span<const Error> errors);

/// printf into a std::string, for error messages (the format is checked by
/// the compiler; output longer than 511 characters is cut). Not for hot paths.
/// @code
///   return dm::fail(ErrorCode::InvalidArgument, dm::formatString("stiffness is %g N/m", k), where);
/// @endcode
std::string formatString(const char* format, ...) noexcept __attribute__((format(printf, 1, 2)));

/// Untrusted text (a file's field, a name from the network) as an error
/// message may show it: at most `maxChars` characters, then "...", with
/// bytes outside printable ASCII written as \xNN.
std::string shownText(std::string_view text, std::size_t maxChars = 60);

/// Builds an Error; the usual way to fail: `return dm::fail(ErrorCode::Parse, ...)`.
inline Error fail(ErrorCode code, std::string what, std::string where = {}, std::string hint = {}) {
  return Error{code, std::move(what), std::move(where), std::move(hint)};
}

/// Either a T or an Error. [[nodiscard]]: ignoring a failure is a bug.
template <class T>
class [[nodiscard]] Result {
 public:
  static_assert(!std::is_same_v<std::remove_cv_t<T>, Error>, "Result<Error> is ambiguous");
  using value_type = T;

  Result(const T& v) : data_(std::in_place_index<0>, v) {}          // NOLINT(google-explicit-constructor)
  Result(T&& v) : data_(std::in_place_index<0>, std::move(v)) {}    // NOLINT(google-explicit-constructor)
  Result(Error e) : data_(std::in_place_index<1>, std::move(e)) {}  // NOLINT(google-explicit-constructor)
  template <class... Args>
  explicit Result(std::in_place_t, Args&&... args)
      : data_(std::in_place_index<0>, std::forward<Args>(args)...) {}

  bool ok() const noexcept { return data_.index() == 0; }
  explicit operator bool() const noexcept { return ok(); }

  T& value() & {
    demandValue();
    return std::get<0>(data_);
  }
  const T& value() const& {
    demandValue();
    return std::get<0>(data_);
  }
  T&& value() && {
    demandValue();
    return std::get<0>(std::move(data_));
  }
  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }
  T&& operator*() && { return std::move(*this).value(); }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }

  /// The value, or `fallback` on error.
  template <class U>
  T valueOr(U&& fallback) const& {
    return ok() ? std::get<0>(data_) : T(std::forward<U>(fallback));
  }

  const Error& error() const& {
    DM_DEMAND(!ok(), "Result::error() on a value");
    return std::get<1>(data_);
  }
  Error&& error() && {
    DM_DEMAND(!ok(), "Result::error() on a value");
    return std::get<1>(std::move(data_));
  }

 private:
  void demandValue() const {
    if (!ok()) [[unlikely]]
      detail::assertionFailed("DM_DEMAND", "Result::value()", std::get<1>(data_).message().c_str(), __FILE__,
                              __LINE__);
  }
  std::variant<T, Error> data_;
};

/// Success or an Error, for operations with no value.
template <>
class [[nodiscard]] Result<void> {
 public:
  using value_type = void;
  Result() = default;
  Result(Error e) : error_(std::move(e)), ok_(false) {}  // NOLINT(google-explicit-constructor)

  bool ok() const noexcept { return ok_; }
  explicit operator bool() const noexcept { return ok_; }
  const Error& error() const& {
    DM_DEMAND(!ok_, "Result::error() on success");
    return error_;
  }
  Error&& error() && {
    DM_DEMAND(!ok_, "Result::error() on success");
    return std::move(error_);
  }

 private:
  Error error_;
  bool ok_ = true;
};

using Status = Result<void>;

/// Success value for Status-returning functions: `return dm::ok();`.
inline Status ok() { return {}; }

}  // namespace dm
