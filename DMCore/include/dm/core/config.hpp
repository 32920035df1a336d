// dm/core/config.hpp — JSON configuration with validation errors that name
// the JSON path.
//
// Config owns a parsed document and where it came from. ConfigReader walks it
// with typed accessors; every problem (missing key, wrong type, value out of
// range, unknown key, unknown enum value) becomes a dm::Error whose `where` is
// "FILE: /json/pointer" and whose hint suggests the closest valid name.
// Readers collect all problems, so a user sees every mistake at once.
//
// @code
//   auto cfg = dm::Config::load("scene.json");            // parse errors: line and column
//   if (!cfg) return cfg.error();
//   dm::ConfigReader r = cfg->reader();
//   double rate = r.child("haptics").number("rate_hz", {.min = 100, .max = 10000}, 1000.0);
//   r.knownKeys({"haptics", "render"});
//   if (auto s = r.status(); !s) return s.error();
// @endcode
#pragma once

#include <dm/core/result.hpp>

#include <nlohmann/json.hpp>

#include <filesystem>
#include <initializer_list>
#include <limits>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace dm {

using Json = nlohmann::json;

/// A parsed JSON document plus its source name (file path or "<string>").
class Config {
 public:
  /// Parses `text`; a syntax error names `source`, line, column and byte.
  static Result<Config> parse(std::string_view text, std::string source = "<string>");
  /// Reads and parses a file; errors name the file.
  static Result<Config> load(const std::filesystem::path& file);

  const Json& json() const { return *json_; }
  const std::string& source() const { return source_; }
  class ConfigReader reader() const;

 private:
  Config(Json json, std::string source);
  std::shared_ptr<const Json> json_;
  std::string source_;
};

/// Numeric constraints for ConfigReader::number / integer (inclusive).
struct Range {
  double min = -std::numeric_limits<double>::infinity();
  double max = std::numeric_limits<double>::infinity();
};

/// Typed, validating view of one JSON object or array inside a Config.
/// Accessors never fail hard: on a problem they record an Error and return
/// the fallback, so parsing can continue and report everything.
class ConfigReader {
 public:
  ConfigReader(const Json& node, std::string source, std::string path = "");

  /// JSON pointer of this node ("" for the root, "/haptics", "/objects/2").
  const std::string& path() const { return path_; }
  const Json& node() const { return *node_; }
  bool has(std::string_view key) const;
  bool isObject() const { return node_->is_object(); }
  bool isArray() const { return node_->is_array(); }
  std::size_t size() const { return node_->size(); }

  /// A number (int or float). Missing: fallback if given, else an error.
  double number(std::string_view key, Range range = {}, std::optional<double> fallback = std::nullopt);
  /// An integer in range.
  long long integer(std::string_view key, Range range = {}, std::optional<long long> fallback = std::nullopt);
  bool boolean(std::string_view key, std::optional<bool> fallback = std::nullopt);
  std::string string(std::string_view key, std::optional<std::string> fallback = std::nullopt);
  /// A string that must be one of `choices`; a wrong one gets "did you mean".
  std::string oneOf(std::string_view key, std::initializer_list<std::string_view> choices,
                    std::optional<std::string> fallback = std::nullopt);
  /// A fixed-size array of numbers, e.g. a 3-vector; missing → fallback.
  std::vector<double> numbers(std::string_view key, std::size_t count,
                              std::optional<std::vector<double>> fallback = std::nullopt);

  /// A nested object or array. Missing and optional → a reader over null
  /// (every accessor then returns its fallback); missing and required → error.
  ConfigReader child(std::string_view key, bool required = false);
  /// Element `i` of an array node.
  ConfigReader at(std::size_t i);
  /// Records an error for every key of this object not in `keys`, with the
  /// closest known key as a suggestion (catches typos like "rate_Hz").
  void knownKeys(std::initializer_list<std::string_view> keys);
  void knownKeys(std::span<const std::string_view> keys);

  /// Records a custom problem at `key` below this node (or at this node).
  void addError(std::string what, std::string_view key = {}, std::string hint = {});

  /// Ok if no problem was recorded by this reader or any child made from it.
  Status status() const;
  /// Every problem recorded, in order.
  const std::vector<Error>& errors() const { return errors_->list; }

 private:
  struct Errors {
    std::vector<Error> list;
  };
  ConfigReader(const Json* node, std::string source, std::string path, std::shared_ptr<Errors> errors);
  const Json* find(std::string_view key) const;
  std::string pathOf(std::string_view key) const;
  void typeError(std::string_view key, const char* expected, const Json& got);

  static const Json& nullJson();
  const Json* node_;
  std::string source_;
  std::string path_;
  std::shared_ptr<Errors> errors_;
};

/// Levenshtein distance, used for "did you mean" suggestions.
std::size_t editDistance(std::string_view a, std::string_view b);
/// The candidate closest to `word`, or "" if none is within a plausible distance.
std::string closestMatch(std::string_view word, std::initializer_list<std::string_view> candidates);
std::string closestMatch(std::string_view word, std::span<const std::string_view> candidates);

}  // namespace dm
