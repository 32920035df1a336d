#include <dm/core/config.hpp>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <sstream>

namespace dm {

namespace {
std::string escapePointer(std::string_view key) {
  std::string out;
  for (char c : key) {
    if (c == '~')
      out += "~0";
    else if (c == '/')
      out += "~1";
    else
      out += c;
  }
  return out;
}

std::string describe(const Json& j) {
  std::string s = j.dump();
  if (s.size() > 40) s = s.substr(0, 37) + "...";
  return std::string(j.type_name()) + " " + s;
}

std::string formatNumber(double v) {
  std::ostringstream os;
  os << v;
  return os.str();
}
}  // namespace

Config::Config(Json json, std::string source)
    : json_(std::make_shared<const Json>(std::move(json))), source_(std::move(source)) {}

Result<Config> Config::parse(std::string_view text, std::string source) {
  // nlohmann reports the byte of a syntax error only through its exception;
  // it is caught here and never leaves this function.
  Json j;
  std::size_t byte = 0;
  bool bad = false;
  try {
    j = Json::parse(text, nullptr, /*allow_exceptions=*/true, /*ignore_comments=*/true);
  } catch (const Json::parse_error& e) {
    bad = true;
    byte = e.byte;
  } catch (const Json::exception& e) {
    // e.g. out_of_range 406: a number literal beyond double ([1e400]).
    return fail(ErrorCode::Parse, std::string("not valid JSON: ") + e.what(), source,
                "check the numbers and strings of the file");
  }
  if (bad) {
    std::size_t line = 1, col = 1;
    for (std::size_t i = 0; i + 1 < byte && i < text.size(); ++i) {
      if (text[i] == '\n') {
        ++line;
        col = 1;
      } else {
        ++col;
      }
    }
    return fail(
        ErrorCode::Parse, "invalid JSON at line " + std::to_string(line) + ", column " + std::to_string(col),
        source + ": byte " + std::to_string(byte), "check for a missing comma, quote or bracket there");
  }
  return Config(std::move(j), std::move(source));
}

Result<Config> Config::load(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in)
    return fail(ErrorCode::NotFound, "cannot open file", file.string(), "check the path and permissions");
  std::ostringstream ss;
  ss << in.rdbuf();
  if (in.bad()) return fail(ErrorCode::Io, "read failed", file.string());
  return parse(ss.str(), file.string());
}

ConfigReader Config::reader() const { return ConfigReader(*json_, source_); }

const Json& ConfigReader::nullJson() {
  static const Json kNull;
  return kNull;
}

ConfigReader::ConfigReader(const Json& node, std::string source, std::string path)
    : ConfigReader(&node, std::move(source), std::move(path), std::make_shared<Errors>()) {}

ConfigReader::ConfigReader(const Json* node, std::string source, std::string path,
                           std::shared_ptr<Errors> errors)
    : node_(node), source_(std::move(source)), path_(std::move(path)), errors_(std::move(errors)) {}

bool ConfigReader::has(std::string_view key) const { return find(key) != nullptr; }

const Json* ConfigReader::find(std::string_view key) const {
  if (!node_->is_object()) return nullptr;
  auto it = node_->find(key);
  return it == node_->end() ? nullptr : &*it;
}

std::string ConfigReader::pathOf(std::string_view key) const {
  return key.empty() ? (path_.empty() ? "/" : path_) : path_ + "/" + escapePointer(key);
}

void ConfigReader::addError(std::string what, std::string_view key, std::string hint) {
  errors_->list.push_back(
      fail(ErrorCode::InvalidArgument, std::move(what), source_ + ": " + pathOf(key), std::move(hint)));
}

void ConfigReader::typeError(std::string_view key, const char* expected, const Json& got) {
  addError(std::string("expected ") + expected + ", got " + describe(got), key);
}

double ConfigReader::number(std::string_view key, Range range, std::optional<double> fallback) {
  const Json* v = find(key);
  if (!v) {
    if (fallback) return *fallback;
    addError("missing required number", key, "add \"" + std::string(key) + "\": <number>");
    return std::isfinite(range.min) ? range.min : 0.0;
  }
  if (!v->is_number()) {
    typeError(key, "a number", *v);
    return fallback.value_or(0.0);
  }
  const double d = v->get<double>();
  if (!std::isfinite(d) || d < range.min || d > range.max) {
    addError("value " + formatNumber(d) + " is outside [" + formatNumber(range.min) + ", " +
                 formatNumber(range.max) + "]",
             key);
    return fallback.value_or(std::clamp(d, range.min, range.max));
  }
  return d;
}

long long ConfigReader::integer(std::string_view key, Range range, std::optional<long long> fallback) {
  const Json* v = find(key);
  if (!v) {
    if (fallback) return *fallback;
    addError("missing required integer", key, "add \"" + std::string(key) + "\": <integer>");
    return 0;
  }
  if (!v->is_number_integer()) {
    typeError(key, "an integer", *v);
    return fallback.value_or(0);
  }
  const long long i = v->get<long long>();
  if (static_cast<double>(i) < range.min || static_cast<double>(i) > range.max) {
    addError("value " + std::to_string(i) + " is outside [" + formatNumber(range.min) + ", " +
                 formatNumber(range.max) + "]",
             key);
    return fallback.value_or(i);
  }
  return i;
}

bool ConfigReader::boolean(std::string_view key, std::optional<bool> fallback) {
  const Json* v = find(key);
  if (!v) {
    if (fallback) return *fallback;
    addError("missing required boolean", key, "add \"" + std::string(key) + "\": true or false");
    return false;
  }
  if (!v->is_boolean()) {
    typeError(key, "true or false", *v);
    return fallback.value_or(false);
  }
  return v->get<bool>();
}

std::string ConfigReader::string(std::string_view key, std::optional<std::string> fallback) {
  const Json* v = find(key);
  if (!v) {
    if (fallback) return *fallback;
    addError("missing required string", key, "add \"" + std::string(key) + "\": \"...\"");
    return {};
  }
  if (!v->is_string()) {
    typeError(key, "a string", *v);
    return fallback.value_or(std::string());
  }
  return v->get<std::string>();
}

std::string ConfigReader::oneOf(std::string_view key, std::initializer_list<std::string_view> choices,
                                std::optional<std::string> fallback) {
  const bool present = has(key);
  std::string s = string(key, fallback);
  if (!present || (find(key) && !find(key)->is_string())) return s;
  if (std::find(choices.begin(), choices.end(), s) != choices.end()) return s;
  std::string list;
  for (auto c : choices) list += (list.empty() ? "" : ", ") + std::string(c);
  const std::string near = closestMatch(s, choices);
  addError("\"" + s + "\" is not one of: " + list, key, near.empty() ? "" : "did you mean \"" + near + "\"?");
  return fallback.value_or(choices.size() ? std::string(*choices.begin()) : std::string());
}

std::vector<double> ConfigReader::numbers(std::string_view key, std::size_t count,
                                          std::optional<std::vector<double>> fallback) {
  const Json* v = find(key);
  if (!v) {
    if (fallback) return *fallback;
    addError("missing required array of " + std::to_string(count) + " numbers", key);
    return std::vector<double>(count, 0.0);
  }
  if (!v->is_array() || v->size() != count) {
    typeError(key, ("an array of " + std::to_string(count) + " numbers").c_str(), *v);
    return fallback.value_or(std::vector<double>(count, 0.0));
  }
  std::vector<double> out(count, 0.0);
  for (std::size_t i = 0; i < count; ++i) {
    const Json& e = (*v)[i];
    if (!e.is_number() || !std::isfinite(e.get<double>())) {
      // The element's pointer is key/i: escape the key alone, not the '/'.
      errors_->list.push_back(fail(ErrorCode::InvalidArgument, "expected a finite number, got " + describe(e),
                                   source_ + ": " + pathOf(key) + "/" + std::to_string(i)));
      continue;
    }
    out[i] = e.get<double>();
  }
  return out;
}

ConfigReader ConfigReader::child(std::string_view key, bool required) {
  const Json* v = find(key);
  if (!v) {
    if (required) addError("missing required section", key, "add \"" + std::string(key) + "\": { ... }");
    return ConfigReader(&nullJson(), source_, pathOf(key), errors_);
  }
  if (!v->is_object() && !v->is_array()) {
    typeError(key, "an object or array", *v);
    return ConfigReader(&nullJson(), source_, pathOf(key), errors_);
  }
  return ConfigReader(v, source_, pathOf(key), errors_);
}

ConfigReader ConfigReader::at(std::size_t i) {
  if (!node_->is_array() || i >= node_->size()) {
    addError("no element " + std::to_string(i), std::to_string(i));
    return ConfigReader(&nullJson(), source_, pathOf(std::to_string(i)), errors_);
  }
  return ConfigReader(&(*node_)[i], source_, pathOf(std::to_string(i)), errors_);
}

void ConfigReader::knownKeys(std::initializer_list<std::string_view> keys) {
  knownKeys(std::span<const std::string_view>(keys.begin(), keys.size()));
}

void ConfigReader::knownKeys(std::span<const std::string_view> keys) {
  if (!node_->is_object()) return;
  for (auto it = node_->begin(); it != node_->end(); ++it) {
    if (std::find(keys.begin(), keys.end(), it.key()) != keys.end()) continue;
    const std::string near = closestMatch(it.key(), keys);
    addError("unknown key \"" + it.key() + "\"", it.key(),
             near.empty() ? "remove it" : "did you mean \"" + near + "\"?");
  }
}

Status ConfigReader::status() const {
  if (errors_->list.empty()) return ok();
  return combineErrors(errors_->list);
}

std::size_t editDistance(std::string_view a, std::string_view b) {
  std::vector<std::size_t> prev(b.size() + 1), cur(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) prev[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    cur[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const bool same = std::tolower(static_cast<unsigned char>(a[i - 1])) ==
                        std::tolower(static_cast<unsigned char>(b[j - 1]));
      cur[j] = std::min({prev[j] + 1, cur[j - 1] + 1, prev[j - 1] + (same ? 0 : 1)});
    }
    std::swap(prev, cur);
  }
  return prev[b.size()];
}

std::string closestMatch(std::string_view word, std::initializer_list<std::string_view> candidates) {
  return closestMatch(word, std::span<const std::string_view>(candidates.begin(), candidates.size()));
}

std::string closestMatch(std::string_view word, std::span<const std::string_view> candidates) {
  std::string best;
  std::size_t bestD = std::max<std::size_t>(2, word.size() / 3) + 1;
  for (auto c : candidates) {
    const std::size_t d = editDistance(word, c);
    if (d < bestD) {
      bestD = d;
      best = std::string(c);
    }
  }
  return best;
}

}  // namespace dm
