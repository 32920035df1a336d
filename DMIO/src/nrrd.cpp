#include <dm/core/filesystem.hpp>
#include <dm/io/nrrd.hpp>
#include <dm/io/volume_io.hpp>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <map>
#include <optional>
#include <string>

#include "format_util.hpp"
#include "gzip.hpp"
#include "raw_slice.hpp"

namespace dm {

namespace {

using detail::checkWritable;
using detail::fmt17;
using detail::isSingular;
using detail::kMaxHeaderBytes;
using detail::lower;
using detail::shown;
using detail::trim;

constexpr int kMaxDimension = 16;

// Lower case with runs of blanks collapsed to one space ("unsigned   char").
std::string normalized(std::string_view s) {
  std::string out;
  bool blank = false;
  for (char c : trim(s)) {
    if (std::isspace(static_cast<unsigned char>(c))) {
      blank = true;
      continue;
    }
    if (blank) out += ' ';
    blank = false;
    out += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  }
  return out;
}

// Whitespace-separated tokens; parenthesised groups and quoted strings stay whole.
std::vector<std::string_view> tokens(std::string_view s) {
  std::vector<std::string_view> out;
  std::size_t i = 0;
  while (i < s.size()) {
    while (i < s.size() && std::isspace(static_cast<unsigned char>(s[i]))) ++i;
    if (i == s.size()) break;
    const std::size_t start = i;
    if (s[i] == '(' || s[i] == '"') {
      const char close = s[i] == '(' ? ')' : '"';
      const std::size_t end = s.find(close, i + 1);
      i = end == std::string_view::npos ? s.size() : end + 1;
    } else {
      while (i < s.size() && !std::isspace(static_cast<unsigned char>(s[i]))) ++i;
    }
    out.push_back(s.substr(start, i - start));
  }
  return out;
}

bool parseNumber(std::string_view t, double& v) {
  if (!t.empty() && t.front() == '+') t.remove_prefix(1);
  const char* b = t.data();
  const char* e = b + t.size();
  auto [next, ec] = std::from_chars(b, e, v);
  return ec == std::errc() && next == e;
}

struct NrrdField {
  std::string value;
  int line = 0;
  std::string name;
};

enum class Encoding { Raw, Gzip, Ascii, Hex };

struct TypeName {
  const char* name;
  RawElement element;
};
constexpr TypeName kTypes[] = {
    {"uchar", RawElement::U8},
    {"unsigned char", RawElement::U8},
    {"uint8", RawElement::U8},
    {"uint8_t", RawElement::U8},
    {"signed char", RawElement::I8},
    {"int8", RawElement::I8},
    {"int8_t", RawElement::I8},
    {"short", RawElement::I16},
    {"short int", RawElement::I16},
    {"signed short", RawElement::I16},
    {"signed short int", RawElement::I16},
    {"int16", RawElement::I16},
    {"int16_t", RawElement::I16},
    {"ushort", RawElement::U16},
    {"unsigned short", RawElement::U16},
    {"unsigned short int", RawElement::U16},
    {"uint16", RawElement::U16},
    {"uint16_t", RawElement::U16},
    {"int", RawElement::I32},
    {"signed int", RawElement::I32},
    {"int32", RawElement::I32},
    {"int32_t", RawElement::I32},
    {"uint", RawElement::U32},
    {"unsigned int", RawElement::U32},
    {"uint32", RawElement::U32},
    {"uint32_t", RawElement::U32},
    {"longlong", RawElement::I64},
    {"long long", RawElement::I64},
    {"long long int", RawElement::I64},
    {"signed long long", RawElement::I64},
    {"signed long long int", RawElement::I64},
    {"int64", RawElement::I64},
    {"int64_t", RawElement::I64},
    {"ulonglong", RawElement::U64},
    {"unsigned long long", RawElement::U64},
    {"unsigned long long int", RawElement::U64},
    {"uint64", RawElement::U64},
    {"uint64_t", RawElement::U64},
    {"float", RawElement::F32},
    {"double", RawElement::F64},
};

const char* typeNameOf(VoxelType t) {
  switch (t) {
    case VoxelType::U8:
      return "uint8";
    case VoxelType::I8:
      return "int8";
    case VoxelType::U16:
      return "uint16";
    case VoxelType::I16:
      return "int16";
    case VoxelType::U32:
      return "uint32";
    case VoxelType::I32:
      return "int32";
    case VoxelType::F32:
      return "float";
    case VoxelType::F64:
      return "double";
  }
  return "uint8";
}

struct SpaceName {
  const char* name;
  const char* abbrev;
  int dimension;
  Vec3 toRas;  // diagonal map from the space's axes to RAS
};
const SpaceName kSpaces[] = {
    {"right-anterior-superior", "ras", 3, {1, 1, 1}},
    {"left-anterior-superior", "las", 3, {-1, 1, 1}},
    {"left-posterior-superior", "lps", 3, {-1, -1, 1}},
    {"right-anterior-superior-time", "rast", 4, {1, 1, 1}},
    {"left-anterior-superior-time", "last", 4, {-1, 1, 1}},
    {"left-posterior-superior-time", "lpst", 4, {-1, -1, 1}},
    {"scanner-xyz", "", 3, {1, 1, 1}},
    {"scanner-xyz-time", "", 4, {1, 1, 1}},
    {"3d-right-handed", "", 3, {1, 1, 1}},
    {"3d-right-handed-time", "", 4, {1, 1, 1}},
};

struct ParsedNrrd {
  Vec3i dims = Vec3i::Ones();
  std::int64_t volumes = 1;
  RawElement element = RawElement::U8;
  std::string typeName;
  Encoding encoding = Encoding::Raw;
  std::endian endian = std::endian::little;
  std::int64_t byteSkip = 0;
  std::int64_t lineSkip = 0;
  Affine3 indexToWorld = Affine3::Identity();
  std::string dataFile;
  int dataLine = 0;
  std::size_t dataOffset = 0;  // start of attached data
  std::uint64_t voxels = 0;    // per volume
  std::size_t volumeBytes = 0;
};

class NrrdHeaderParser {
 public:
  NrrdHeaderParser(std::span<const std::byte> bytes, std::string_view source)
      : bytes_(bytes), source_(source) {}
  Result<ParsedNrrd> parse();

 private:
  Error error(const NrrdField& f, const std::string& what, std::string hint = {},
              ErrorCode code = ErrorCode::Parse) const {
    return fail(code, "field \"" + f.name + "\" (line " + std::to_string(f.line) + ") " + what, source_,
                std::move(hint));
  }
  const NrrdField* find(const char* name) const {
    auto it = fields_.find(name);
    return it == fields_.end() ? nullptr : &it->second;
  }
  Result<std::int64_t> integer(const NrrdField& f, std::int64_t lo, std::int64_t hi) const;
  Result<Vec3> vector(const NrrdField& f, std::string_view token, int components) const;

  std::span<const std::byte> bytes_;
  std::string source_;
  std::map<std::string, NrrdField> fields_;
};

Result<std::int64_t> NrrdHeaderParser::integer(const NrrdField& f, std::int64_t lo, std::int64_t hi) const {
  double v = 0;
  if (!parseNumber(trim(f.value), v) || v != std::floor(v) || v < static_cast<double>(lo) ||
      v > static_cast<double>(hi))
    return error(f, "is \"" + shown(f.value) + "\"; expected an integer in " + std::to_string(lo) + ".." +
                        std::to_string(hi));
  return static_cast<std::int64_t>(v);
}

// "(x,y,z)" with `components` finite entries (only the first three are kept).
Result<Vec3> NrrdHeaderParser::vector(const NrrdField& f, std::string_view token, int components) const {
  if (token.size() < 2 || token.front() != '(' || token.back() != ')')
    return error(f, "has \"" + shown(token) + "\"; expected a vector like (1,0,0)");
  std::string_view inner = token.substr(1, token.size() - 2);
  Vec3 out = Vec3::Zero();
  int n = 0;
  while (true) {
    const std::size_t comma = inner.find(',');
    const std::string_view part = trim(inner.substr(0, comma));
    double v = 0;
    if (!parseNumber(part, v))
      return error(f,
                   "has \"" + shown(token) + "\"; component " + std::to_string(n + 1) + " is not a number");
    if (!std::isfinite(v))
      return error(f, "has \"" + shown(token) + "\"; component " + std::to_string(n + 1) + " is not finite");
    if (n < 3) out[n] = v;
    ++n;
    if (comma == std::string_view::npos) break;
    inner.remove_prefix(comma + 1);
    if (n > kMaxDimension) break;
  }
  if (n != components)
    return error(f, "has \"" + shown(token) + "\" with " + std::to_string(n) + " components; the space has " +
                        std::to_string(components));
  return out;
}

Result<ParsedNrrd> NrrdHeaderParser::parse() {
  ParsedNrrd out;
  const char* text = reinterpret_cast<const char*>(bytes_.data());
  const std::size_t scanEnd = std::min(bytes_.size(), kMaxHeaderBytes);
  std::size_t pos = 0;
  int line = 0;
  bool blankLine = false;
  while (pos < bytes_.size()) {
    if (pos >= kMaxHeaderBytes)
      return fail(ErrorCode::Parse,
                  "no blank line ends the header in the first " + std::to_string(kMaxHeaderBytes) + " bytes",
                  source_, "this is not an NRRD file");
    const void* nl = std::memchr(text + pos, '\n', scanEnd - pos);
    const std::size_t eol = nl ? static_cast<std::size_t>(static_cast<const char*>(nl) - text) : scanEnd;
    std::string_view raw(text + pos, eol - pos);
    pos = std::min(eol + 1, bytes_.size());
    ++line;
    if (!raw.empty() && raw.back() == '\r') raw.remove_suffix(1);
    if (line == 1) {
      if (raw.size() != 8 || raw.substr(0, 7) != "NRRD000" || raw[7] < '1' || raw[7] > '5')
        return fail(ErrorCode::Parse,
                    "the first line (magic) is \"" + shown(raw) + "\"; expected NRRD0001..NRRD0005", source_,
                    "this is not an NRRD file");
      continue;
    }
    if (raw.empty()) {
      blankLine = true;
      break;
    }
    if (raw.front() == '#') continue;
    if (raw.find(":=") != std::string_view::npos) continue;  // key/value pair: not needed
    const std::size_t colon = raw.find(": ");
    if (colon == std::string_view::npos)
      return fail(ErrorCode::Parse,
                  "line " + std::to_string(line) + " is not \"field: value\": \"" + shown(raw) + "\"",
                  source_, "the header is damaged, or a blank line is missing before the data");
    const std::string name(trim(raw.substr(0, colon)));
    const std::string key = normalized(name);
    NrrdField f{std::string(trim(raw.substr(colon + 2))), line, name};
    if (auto it = fields_.find(key); it != fields_.end())
      return fail(ErrorCode::Parse,
                  "field \"" + name + "\" appears twice (lines " + std::to_string(it->second.line) + " and " +
                      std::to_string(line) + ")",
                  source_);
    fields_.emplace(key == "datafile" ? "data file" : key, std::move(f));
  }
  if (line == 0)
    return fail(ErrorCode::Parse, "the file is empty; expected the magic NRRD0001..NRRD0005", source_);
  out.dataOffset = pos;

  const NrrdField* dataF = find("data file");
  if (dataF) {
    out.dataFile = dataF->value;
    out.dataLine = dataF->line;
    const std::vector<std::string_view> t = tokens(dataF->value);
    if (t.empty()) return error(*dataF, "is empty");
    if (t.size() > 1 || lower(t[0]) == "list" || dataF->value.find('%') != std::string::npos)
      return error(*dataF, "names several data files; only one is supported", "merge the files into one",
                   ErrorCode::Unsupported);
  } else if (!blankLine) {
    return fail(
        ErrorCode::Parse,
        "the header ends after " + std::to_string(line) + " lines without a blank line or a data file field",
        source_, "the file is truncated");
  }

  // type
  const NrrdField* typeF = find("type");
  if (!typeF) return fail(ErrorCode::Parse, "the \"type\" field is missing", source_);
  {
    const std::string t = normalized(typeF->value);
    const TypeName* found = nullptr;
    for (const TypeName& tn : kTypes)
      if (t == tn.name) found = &tn;
    if (!found) {
      if (t == "block")
        return error(*typeF, "is \"block\"; only scalar types are supported", {}, ErrorCode::Unsupported);
      return error(*typeF, "is \"" + shown(typeF->value) + "\", not an NRRD scalar type");
    }
    out.element = found->element;
    out.typeName = t;
  }
  const std::size_t eb = rawElementBytes(out.element);

  // dimension, sizes
  const NrrdField* dimF = find("dimension");
  if (!dimF) return fail(ErrorCode::Parse, "the \"dimension\" field is missing", source_);
  auto dimV = integer(*dimF, 1, kMaxDimension);
  if (!dimV) return std::move(dimV).error();
  const int dim = static_cast<int>(*dimV);
  const NrrdField* sizesF = find("sizes");
  if (!sizesF) return fail(ErrorCode::Parse, "the \"sizes\" field is missing", source_);
  std::vector<std::int64_t> sizes;
  for (std::string_view t : tokens(sizesF->value)) {
    double v = 0;
    if (!parseNumber(t, v) || v != std::floor(v) || v < 1 || v > std::numeric_limits<int>::max())
      return error(*sizesF, "has \"" + shown(t) + "\"; sizes must be integers in 1.." +
                                std::to_string(std::numeric_limits<int>::max()));
    sizes.push_back(static_cast<std::int64_t>(v));
    if (static_cast<int>(sizes.size()) > dim) break;
  }
  if (static_cast<int>(sizes.size()) != dim)
    return error(*sizesF, "needs " + std::to_string(dim) + " sizes (dimension " + std::to_string(dim) + ")");

  // encoding, endian, skips
  const NrrdField* encF = find("encoding");
  if (!encF) return fail(ErrorCode::Parse, "the \"encoding\" field is missing", source_);
  {
    const std::string e = normalized(encF->value);
    if (e == "raw")
      out.encoding = Encoding::Raw;
    else if (e == "gzip" || e == "gz")
      out.encoding = Encoding::Gzip;
    else if (e == "ascii" || e == "text" || e == "txt")
      out.encoding = Encoding::Ascii;
    else if (e == "hex")
      out.encoding = Encoding::Hex;
    else if (e == "bzip2" || e == "bz2")
      return error(*encF, "is bzip2, which is not supported", "re-save with gzip or raw encoding (unu save)",
                   ErrorCode::Unsupported);
    else
      return error(*encF, "is \"" + shown(encF->value) + "\"; expected raw, gzip, ascii or hex");
  }
  if (const NrrdField* f = find("endian")) {
    const std::string e = normalized(f->value);
    if (e == "little")
      out.endian = std::endian::little;
    else if (e == "big")
      out.endian = std::endian::big;
    else
      return error(*f, "is \"" + shown(f->value) + "\"; expected little or big");
  } else if (eb > 1 && out.encoding != Encoding::Ascii) {
    return fail(ErrorCode::Parse,
                "the \"endian\" field is missing but type " + out.typeName + " has " + std::to_string(eb) +
                    "-byte values",
                source_);
  }
  if (const NrrdField* f = find("byte skip")) {
    auto v = integer(*f, -1, std::int64_t{1} << 50);
    if (!v) return std::move(v).error();
    out.byteSkip = *v;
    if (out.byteSkip == -1 && out.encoding != Encoding::Raw)
      return error(*f, "is -1, which is only allowed with raw encoding");
  }
  if (const NrrdField* f = find("line skip")) {
    auto v = integer(*f, 0, std::int64_t{1} << 50);
    if (!v) return std::move(v).error();
    out.lineSkip = *v;
  }

  // space
  const SpaceName* space = nullptr;
  int spaceDim = 0;
  const NrrdField* spaceF = find("space");
  if (spaceF) {
    const std::string s = normalized(spaceF->value);
    for (const SpaceName& sn : kSpaces)
      if (s == sn.name || (sn.abbrev[0] && s == sn.abbrev)) space = &sn;
    if (!space) {
      if (s == "3d-left-handed" || s == "3d-left-handed-time")
        return error(*spaceF, "is a left-handed frame, which has no defined mapping to RAS", {},
                     ErrorCode::Unsupported);
      return error(*spaceF, "is \"" + shown(spaceF->value) + "\", not an NRRD space");
    }
    spaceDim = space->dimension;
  }
  if (const NrrdField* f = find("space dimension")) {
    if (spaceF) return error(*f, "cannot be given together with \"space\"");
    auto v = integer(*f, 1, kMaxDimension);
    if (!v) return std::move(v).error();
    spaceDim = static_cast<int>(*v);
  }
  const Vec3 toRas = space ? space->toRas : Vec3(1, 1, 1);

  // Which axes are spatial, and their directions (file space units).
  std::vector<std::optional<Vec3>> dirs(static_cast<std::size_t>(dim));
  const NrrdField* dirF = find("space directions");
  if (dirF) {
    if (spaceDim == 0) return error(*dirF, "needs a \"space\" or \"space dimension\" field");
    const std::vector<std::string_view> t = tokens(dirF->value);
    if (static_cast<int>(t.size()) != dim)
      return error(*dirF,
                   "has " + std::to_string(t.size()) + " entries; dimension is " + std::to_string(dim));
    for (int i = 0; i < dim; ++i) {
      if (lower(t[static_cast<std::size_t>(i)]) == "none") continue;
      auto v = vector(*dirF, t[static_cast<std::size_t>(i)], spaceDim);
      if (!v) return std::move(v).error();
      dirs[static_cast<std::size_t>(i)] = *v;
    }
  } else {
    std::vector<std::string> kinds;
    if (const NrrdField* f = find("kinds")) {
      for (std::string_view t : tokens(f->value)) kinds.push_back(lower(t));
      if (static_cast<int>(kinds.size()) != dim)
        return error(*f,
                     "has " + std::to_string(kinds.size()) + " entries; dimension is " + std::to_string(dim));
    }
    std::vector<double> spacings(static_cast<std::size_t>(dim), 1.0);
    if (const NrrdField* f = find("spacings")) {
      const std::vector<std::string_view> t = tokens(f->value);
      if (static_cast<int>(t.size()) != dim)
        return error(*f, "has " + std::to_string(t.size()) + " entries; dimension is " + std::to_string(dim));
      for (int i = 0; i < dim; ++i) {
        double v = 0;
        if (!parseNumber(t[static_cast<std::size_t>(i)], v))
          return error(*f, "entry " + std::to_string(i + 1) + " \"" + shown(t[static_cast<std::size_t>(i)]) +
                               "\" is not a number");
        if (std::isfinite(v) && v != 0) spacings[static_cast<std::size_t>(i)] = v;
      }
    }
    int spatial = 0;
    for (int i = 0; i < dim && spatial < 3; ++i) {
      const bool domain = kinds.empty() || kinds[static_cast<std::size_t>(i)] == "domain" ||
                          kinds[static_cast<std::size_t>(i)] == "space" ||
                          kinds[static_cast<std::size_t>(i)] == "???" ||
                          kinds[static_cast<std::size_t>(i)] == "none";
      if (!domain) continue;
      Vec3 d = Vec3::Zero();
      d[spatial] = spacings[static_cast<std::size_t>(i)];
      dirs[static_cast<std::size_t>(i)] = d;
      ++spatial;
    }
  }
  int spatialAxes = 0;
  int lastSpatial = -1;
  for (int i = 0; i < dim; ++i)
    if (dirs[static_cast<std::size_t>(i)]) ++spatialAxes, lastSpatial = i;
  if (spatialAxes == 0)
    return fail(ErrorCode::Unsupported, "the file has no spatial axes", source_,
                "give space directions (or kinds domain) for the image axes");
  if (spatialAxes > 3)
    return error(dirF ? *dirF : *sizesF,
                 "gives " + std::to_string(spatialAxes) + " spatial axes; at most 3 supported", {},
                 ErrorCode::Unsupported);
  std::uint64_t volumes = 1;
  Mat3 lin = Mat3::Zero();
  int col = 0;
  for (int i = 0; i < dim; ++i) {
    const auto n = static_cast<std::uint64_t>(sizes[static_cast<std::size_t>(i)]);
    if (dirs[static_cast<std::size_t>(i)]) {
      out.dims[col] = static_cast<int>(n);
      lin.col(col) = *dirs[static_cast<std::size_t>(i)];
      ++col;
      continue;
    }
    if (i < lastSpatial && n > 1)
      return error(
          dirF ? *dirF : *sizesF,
          "makes axis " + std::to_string(i) + " (size " + std::to_string(n) +
              ") non-spatial before a spatial axis: multi-component voxels (vectors, colours, tensors) "
              "are not supported",
          "split the components into separate scalar volumes", ErrorCode::Unsupported);
    if (volumes > (std::uint64_t{1} << 40) / n) return error(*sizesF, "gives a volume count that overflows");
    volumes *= n;
  }
  out.volumes = static_cast<std::int64_t>(volumes);

  Vec3 origin = Vec3::Zero();
  if (const NrrdField* f = find("space origin")) {
    if (spaceDim == 0) return error(*f, "needs a \"space\" or \"space dimension\" field");
    const std::vector<std::string_view> t = tokens(f->value);
    if (t.size() != 1) return error(*f, "must be one vector like (0,0,0)");
    auto v = vector(*f, t[0], spaceDim);
    if (!v) return std::move(v).error();
    origin = *v;
  }
  // Space units per world component; NRRD's default for anatomical spaces is mm.
  Vec3 unit = Vec3::Constant(1e-3);
  if (const NrrdField* f = find("space units")) {
    const std::vector<std::string_view> t = tokens(f->value);
    if (static_cast<int>(t.size()) != std::max(spaceDim, 1))
      return error(*f,
                   "has " + std::to_string(t.size()) + " entries; the space has " + std::to_string(spaceDim));
    for (int j = 0; j < std::min(spaceDim, 3); ++j) {
      std::string_view u = t[static_cast<std::size_t>(j)];
      if (u.size() >= 2 && u.front() == '"' && u.back() == '"') u = u.substr(1, u.size() - 2);
      const std::string ul = lower(trim(u));
      if (ul == "mm" || ul.empty())
        unit[j] = 1e-3;
      else if (ul == "m" || ul == "meter" || ul == "meters" || ul == "metre" || ul == "metres")
        unit[j] = 1.0;
      else if (ul == "cm")
        unit[j] = 1e-2;
      else if (ul == "um" || ul == "micron" || ul == "microns" || ul == "\xc2\xb5m")
        unit[j] = 1e-6;
      else
        return error(*f, "has unit \"" + shown(u) + "\"; expected mm, m, cm or um");
    }
  }
  // File space -> RAS metres: scale each world component, then flip axes.
  const Vec3 rowScale = toRas.cwiseProduct(unit);
  lin = rowScale.asDiagonal() * lin;
  origin = rowScale.cwiseProduct(origin);
  // Missing index axes (fewer than three spatial ones) get 1 mm directions
  // orthogonal to the existing ones.
  for (int c = spatialAxes; c < 3; ++c) {
    Vec3 d;
    if (c == 1) {
      const Vec3 a = lin.col(0).normalized();
      d = a.unitOrthogonal();
    } else {
      d = lin.col(0).cross(lin.col(1)).normalized();
    }
    lin.col(c) = d * 1e-3;
  }
  if (!lin.allFinite() || isSingular(lin))
    return fail(ErrorCode::Parse,
                std::string(dirF ? "field \"space directions\" (line " + std::to_string(dirF->line) + ")"
                                 : "field \"spacings\"") +
                    " gives a singular or non-finite index-to-world matrix",
                source_);
  out.indexToWorld.linear() = lin;
  out.indexToWorld.translation() = origin;

  std::uint64_t voxels = 1;
  for (int i = 0; i < 3; ++i) {
    const auto d = static_cast<std::uint64_t>(out.dims[i]);
    if (voxels > (std::uint64_t{1} << 59) / d) return error(*sizesF, "gives a voxel count that overflows");
    voxels *= d;
  }
  out.voxels = voxels;
  out.volumeBytes = static_cast<std::size_t>(voxels * eb);
  return out;
}

int hexValue(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

Result<Volume> loadNrrdData(const ParsedNrrd& p, std::span<const std::byte> stream, const std::string& source,
                            const NrrdReadOptions& options) {
  if (options.volumeIndex < 0 || options.volumeIndex >= p.volumes)
    return fail(ErrorCode::InvalidArgument,
                "volumeIndex " + std::to_string(options.volumeIndex) + " is out of range: the file holds " +
                    std::to_string(p.volumes) + " volume(s)",
                source);
  // Checked once the data is known to be there (raw, text) or before inflating it.
  const Status withinLimit =
      p.volumeBytes <= options.maxBytes
          ? ok()
          : Status(detail::volumeOverBudget(
                "sizes " + std::to_string(p.dims.x()) + "x" + std::to_string(p.dims.y()) + "x" +
                    std::to_string(p.dims.z()) + " of " + p.typeName,
                p.volumeBytes, options.maxBytes, source, "NrrdReadOptions::maxBytes"));
  const auto index = static_cast<std::uint64_t>(options.volumeIndex);
  if (index != 0 && p.volumeBytes > (std::uint64_t{1} << 62) / index)
    return fail(ErrorCode::Parse, "data offset of volume " + std::to_string(index) + " overflows", source);
  const std::uint64_t volStart = index * p.volumeBytes;
  auto shortData = [&](std::uint64_t have, const char* what) {
    return fail(ErrorCode::Parse,
                std::string(what) + " holds " + std::to_string(have) + " bytes, but sizes " +
                    std::to_string(p.dims.x()) + "x" + std::to_string(p.dims.y()) + "x" +
                    std::to_string(p.dims.z()) +
                    (p.volumes > 1 ? " (up to volume " + std::to_string(index) + ")" : std::string()) +
                    " of " + p.typeName + " need " + std::to_string(volStart + p.volumeBytes) +
                    (p.byteSkip > 0 ? " after byte skip " + std::to_string(p.byteSkip) : std::string()),
                source, "the data is truncated, or sizes/type/byte skip are wrong");
  };

  // line skip: whole lines before the data, in every encoding.
  for (std::int64_t l = 0; l < p.lineSkip; ++l) {
    const void* nl = std::memchr(stream.data(), '\n', stream.size());
    if (!nl)
      return fail(ErrorCode::Parse,
                  "line skip " + std::to_string(p.lineSkip) + " runs past the end of the data", source);
    stream = stream.subspan(static_cast<std::size_t>(static_cast<const std::byte*>(nl) - stream.data()) + 1);
  }
  RawVoxelFormat fmt;
  fmt.element = p.element;
  fmt.byteOrder = p.endian;
  const auto skip = static_cast<std::uint64_t>(std::max<std::int64_t>(p.byteSkip, 0));

  switch (p.encoding) {
    case Encoding::Raw: {
      auto slice = detail::rawVolumeSlice(stream, p.byteSkip, static_cast<std::uint64_t>(p.volumes),
                                          p.volumeBytes, index, source, shortData);
      if (!slice) return std::move(slice).error();
      if (!withinLimit) return withinLimit.error();
      return decodeRawVolume(*slice, p.dims, fmt, p.indexToWorld, source, options.maxBytes);
    }
    case Encoding::Gzip: {
      if (!withinLimit) return withinLimit.error();
      // byte skip and earlier volumes are decompressed and discarded, not kept.
      auto data = detail::inflate(stream, p.volumeBytes, source, static_cast<std::size_t>(skip + volStart));
      if (!data) return std::move(data).error();
      if (data->size() < p.volumeBytes) return shortData(volStart + data->size(), "the decompressed data");
      return decodeRawVolume(*data, p.dims, fmt, p.indexToWorld, source, options.maxBytes);
    }
    case Encoding::Hex: {
      if (skip > stream.size()) return shortData(0, "the hex data");
      stream = stream.subspan(static_cast<std::size_t>(skip));
      const std::uint64_t need = volStart + p.volumeBytes;
      // Two digits per byte: refuse before allocating if the text is too short.
      if (stream.size() / 2 < need) return shortData(stream.size() / 2, "the hex data");
      if (!withinLimit) return withinLimit.error();
      std::vector<std::byte> bytes(p.volumeBytes);
      std::uint64_t produced = 0;
      int high = -1;
      for (std::size_t i = 0; i < stream.size() && produced < need; ++i) {
        const char c = static_cast<char>(stream[i]);
        if (std::isspace(static_cast<unsigned char>(c))) continue;
        const int v = hexValue(c);
        if (v < 0)
          return fail(ErrorCode::Parse,
                      "hex data has a non-hex character '" + shown(std::string_view(&c, 1)) +
                          "' at data byte " + std::to_string(i),
                      source);
        if (high < 0) {
          high = v;
          continue;
        }
        if (produced >= volStart)
          bytes[static_cast<std::size_t>(produced - volStart)] = std::byte(high * 16 + v);
        ++produced;
        high = -1;
      }
      if (produced < need) return shortData(produced, "the hex data");
      return decodeRawVolume(bytes, p.dims, fmt, p.indexToWorld, source, options.maxBytes);
    }
    case Encoding::Ascii: {
      if (skip > stream.size())
        return fail(ErrorCode::Parse, "byte skip runs past the end of the data", source);
      stream = stream.subspan(static_cast<std::size_t>(skip));
      const std::uint64_t needValues = (index + 1) * p.voxels;
      // Each value takes at least one character and one separator.
      if (stream.size() / 2 + 1 < needValues)
        return fail(ErrorCode::Parse,
                    "ascii data of " + std::to_string(stream.size()) + " bytes cannot hold the " +
                        std::to_string(needValues) + " values sizes need",
                    source, "the data is truncated, or sizes are wrong");
      if (!withinLimit) return withinLimit.error();
      VoxelType vt;
      switch (p.element) {
        case RawElement::U8:
          vt = VoxelType::U8;
          break;
        case RawElement::I8:
          vt = VoxelType::I8;
          break;
        case RawElement::U16:
          vt = VoxelType::U16;
          break;
        case RawElement::I16:
          vt = VoxelType::I16;
          break;
        case RawElement::U32:
          vt = VoxelType::U32;
          break;
        case RawElement::I32:
          vt = VoxelType::I32;
          break;
        case RawElement::F32:
          vt = VoxelType::F32;
          break;
        default:
          vt = VoxelType::F64;
          break;
      }
      auto v = Volume::create(p.dims, vt, p.indexToWorld, options.maxBytes);
      if (!v) {
        Error e = std::move(v).error();
        e.where = source;
        return e;
      }
      const char* c = reinterpret_cast<const char*>(stream.data());
      const char* end = c + stream.size();
      const std::uint64_t first = index * p.voxels;
      for (std::uint64_t n = 0; n < needValues; ++n) {
        while (c < end && (std::isspace(static_cast<unsigned char>(*c)) || *c == ',')) ++c;
        if (c == end)
          return fail(ErrorCode::Parse,
                      "ascii data ends after " + std::to_string(n) + " values; sizes need " +
                          std::to_string(needValues),
                      source, "the data is truncated, or sizes are wrong");
        const char* tokEnd = c;
        while (tokEnd < end && !std::isspace(static_cast<unsigned char>(*tokEnd)) && *tokEnd != ',') ++tokEnd;
        double value = 0;
        if (!parseNumber(std::string_view(c, static_cast<std::size_t>(tokEnd - c)), value))
          return fail(ErrorCode::Parse,
                      "ascii value " + std::to_string(n) + " \"" +
                          shown(std::string_view(c, static_cast<std::size_t>(tokEnd - c))) +
                          "\" is not a number",
                      source);
        if (n >= first) v->setValueAt(static_cast<std::size_t>(n - first), value);
        c = tokEnd;
      }
      return v;
    }
  }
  return fail(ErrorCode::Internal, "unknown encoding", source);
}

}  // namespace

Result<Volume> parseNrrd(std::span<const std::byte> bytes, std::string_view sourceName,
                         const NrrdReadOptions& options) {
  const std::string source(sourceName);
  auto p = NrrdHeaderParser(bytes, source).parse();
  if (!p) return std::move(p).error();
  if (!p->dataFile.empty())
    return fail(ErrorCode::InvalidArgument,
                "the header names a detached data file \"" + shown(p->dataFile) + "\" (line " +
                    std::to_string(p->dataLine) + "); parseNrrd reads only attached data",
                source, "use readNrrd with the header's path");
  return loadNrrdData(*p, bytes.subspan(p->dataOffset), source, options);
}

Result<Volume> readNrrd(const std::filesystem::path& file, const NrrdReadOptions& options) {
  const std::string source = file.string();
  auto bytes = readFile(file, std::numeric_limits<std::size_t>::max());
  if (!bytes) return std::move(bytes).error();
  auto p = NrrdHeaderParser(*bytes, source).parse();
  if (!p) return std::move(p).error();
  if (p->dataFile.empty())
    return loadNrrdData(*p, std::span<const std::byte>(*bytes).subspan(p->dataOffset), source, options);
  const std::string field = "data file (line " + std::to_string(p->dataLine) + ") of " + source;
  auto dataPath = FileSystem::global().confine(file.parent_path(), p->dataFile, field);
  if (!dataPath) return std::move(dataPath).error();
  auto data = readFile(*dataPath, std::numeric_limits<std::size_t>::max());
  if (!data) {
    Error e = std::move(data).error();
    e.what = field + ": " + e.what;
    return e;
  }
  return loadNrrdData(*p, *data, dataPath->string(), options);
}

namespace {

std::string vec(const Vec3& v) { return "(" + fmt17(v.x()) + "," + fmt17(v.y()) + "," + fmt17(v.z()) + ")"; }

std::string nrrdHeaderText(const Volume& v, bool gzip, const std::string& dataFile) {
  const Mat3 lin = v.indexToWorld().linear() * 1e3;  // RAS mm
  const Vec3 origin = v.indexToWorld().translation() * 1e3;
  std::string h =
      "NRRD0004\n# Complete NRRD file format specification at:\n"
      "# http://teem.sourceforge.net/nrrd/format.html\n";
  h += std::string("type: ") + typeNameOf(v.type()) + "\n";
  h += "dimension: 3\nspace: right-anterior-superior\n";
  h += "sizes: " + std::to_string(v.dims().x()) + " " + std::to_string(v.dims().y()) + " " +
       std::to_string(v.dims().z()) + "\n";
  h += "space directions: " + vec(lin.col(0)) + " " + vec(lin.col(1)) + " " + vec(lin.col(2)) + "\n";
  h += "kinds: domain domain domain\nendian: little\n";
  h += std::string("encoding: ") + (gzip ? "gzip" : "raw") + "\n";
  h += "space units: \"mm\" \"mm\" \"mm\"\n";
  h += "space origin: " + vec(origin) + "\n";
  if (!dataFile.empty()) h += "data file: " + dataFile + "\n";
  h += "\n";
  return h;
}

Result<std::vector<std::byte>> nrrdPayload(const Volume& v, bool gzip) {
  std::vector<std::byte> raw(v.bytes(), v.bytes() + v.byteSize());
  if constexpr (std::endian::native == std::endian::big) {
    const std::size_t w = voxelBytes(v.type());
    for (std::size_t i = 0; w > 1 && i < raw.size(); i += w)
      std::reverse(raw.begin() + i, raw.begin() + i + w);
  }
  if (!gzip) return raw;
  return detail::deflate(raw, detail::CompressFormat::Gzip);
}

}  // namespace

Result<std::vector<std::byte>> encodeNrrd(const Volume& v, const NrrdWriteOptions& options) {
  if (auto s = checkWritable(v, "writeNrrd"); !s) return std::move(s).error();
  auto data = nrrdPayload(v, options.gzip);
  if (!data) return std::move(data).error();
  const std::string h = nrrdHeaderText(v, options.gzip, {});
  std::vector<std::byte> out(h.size() + data->size());
  std::memcpy(out.data(), h.data(), h.size());
  std::memcpy(out.data() + h.size(), data->data(), data->size());
  return out;
}

Status writeNrrd(const Volume& v, const std::filesystem::path& file, const NrrdWriteOptions& options) {
  const std::string ext = lower(file.extension().string());
  if (ext == ".nrrd") {
    auto bytes = encodeNrrd(v, options);
    if (!bytes) return std::move(bytes).error().within(file.string());
    return writeFileAtomic(file, bytes->data(), bytes->size());
  }
  if (ext != ".nhdr")
    return fail(ErrorCode::InvalidArgument, "an NRRD file name must end in .nrrd or .nhdr", file.string());
  if (auto s = checkWritable(v, file.string()); !s) return s;
  auto data = nrrdPayload(v, options.gzip);
  if (!data) return std::move(data).error().within(file.string());
  const std::string dataName = file.stem().string() + (options.gzip ? ".raw.gz" : ".raw");
  if (auto s = writeFileAtomic(file.parent_path() / dataName, data->data(), data->size()); !s) return s;
  const std::string h = nrrdHeaderText(v, options.gzip, dataName);
  return writeFileAtomic(file, h.data(), h.size());
}

}  // namespace dm
