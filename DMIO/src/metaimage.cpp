#include <dm/core/filesystem.hpp>
#include <dm/io/metaimage.hpp>
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

struct Field {
  std::string value;
  int line = 0;
  std::string name;  // as spelled in the file
};

struct Parsed {
  Vec3i dims = Vec3i::Ones();
  std::int64_t volumes = 1;
  RawElement element = RawElement::U8;
  const char* elementName = "";
  bool msb = false;
  bool compressed = false;
  std::optional<std::uint64_t> compressedSize;
  std::int64_t headerSize = 0;
  Affine3 indexToWorld = Affine3::Identity();
  std::string dataFile;
  int dataLine = 0;
  std::size_t dataOffset = 0;  // byte after the ElementDataFile line
  std::size_t volumeBytes = 0;
};

class HeaderParser {
 public:
  HeaderParser(std::span<const std::byte> bytes, std::string_view source) : bytes_(bytes), source_(source) {}

  Result<Parsed> parse();

 private:
  Error error(const Field& f, const std::string& what, std::string hint = {}) const {
    return fail(ErrorCode::Parse, f.name + " (line " + std::to_string(f.line) + ") " + what, source_,
                std::move(hint));
  }
  const Field* find(std::initializer_list<const char*> names) const {
    for (const char* n : names) {
      auto it = fields_.find(n);
      if (it != fields_.end()) return &it->second;
    }
    return nullptr;
  }
  Result<std::vector<double>> numbers(const Field& f, std::size_t count, bool integral) const;
  Result<bool> boolean(const Field& f) const;

  std::span<const std::byte> bytes_;
  std::string source_;
  std::map<std::string, Field> fields_;
};

Result<std::vector<double>> HeaderParser::numbers(const Field& f, std::size_t count, bool integral) const {
  std::vector<double> out;
  const char* p = f.value.data();
  const char* end = p + f.value.size();
  while (p < end) {
    while (p < end && std::isspace(static_cast<unsigned char>(*p))) ++p;
    if (p == end) break;
    if (out.size() == count)
      return error(f, "has more than " + std::to_string(count) + " values: \"" + shown(f.value) + "\"");
    double v = 0;
    const char* start = p;
    if (*p == '+') ++p;  // from_chars rejects a leading '+'
    auto [next, ec] = std::from_chars(p, end, v);
    if (ec != std::errc() || (next < end && !std::isspace(static_cast<unsigned char>(*next))))
      return error(
          f, "value " + std::to_string(out.size() + 1) + " is not a number: \"" + shown(f.value) + "\"");
    if (!std::isfinite(v))
      return error(f, "value " + std::to_string(out.size() + 1) + " is not finite: \"" +
                          shown(std::string_view(start, static_cast<std::size_t>(next - start))) + "\"");
    if (integral && v != std::floor(v))
      return error(
          f, "value " + std::to_string(out.size() + 1) + " is not an integer: \"" + shown(f.value) + "\"");
    out.push_back(v);
    p = next;
  }
  if (out.size() != count)
    return error(f, "has " + std::to_string(out.size()) + " values, expected " + std::to_string(count));
  return out;
}

Result<bool> HeaderParser::boolean(const Field& f) const {
  const std::string v = lower(f.value);
  if (v == "true" || v == "1") return true;
  if (v == "false" || v == "0") return false;
  return error(f, "is \"" + shown(f.value) + "\"; expected True or False");
}

struct ElementInfo {
  const char* name;
  RawElement element;
  bool supported;
};
constexpr ElementInfo kElements[] = {
    {"MET_UCHAR", RawElement::U8, true},       {"MET_CHAR", RawElement::I8, true},
    {"MET_USHORT", RawElement::U16, true},     {"MET_SHORT", RawElement::I16, true},
    {"MET_UINT", RawElement::U32, true},       {"MET_INT", RawElement::I32, true},
    {"MET_ULONG", RawElement::U32, true},      {"MET_LONG", RawElement::I32, true},
    {"MET_ULONG_LONG", RawElement::U64, true}, {"MET_LONG_LONG", RawElement::I64, true},
    {"MET_FLOAT", RawElement::F32, true},      {"MET_DOUBLE", RawElement::F64, true},
    {"MET_ASCII_CHAR", RawElement::U8, false}, {"MET_STRING", RawElement::U8, false},
    {"MET_OTHER", RawElement::U8, false},
};

const char* elementTypeName(VoxelType t) {
  switch (t) {
    case VoxelType::U8:
      return "MET_UCHAR";
    case VoxelType::I8:
      return "MET_CHAR";
    case VoxelType::U16:
      return "MET_USHORT";
    case VoxelType::I16:
      return "MET_SHORT";
    case VoxelType::U32:
      return "MET_UINT";
    case VoxelType::I32:
      return "MET_INT";
    case VoxelType::F32:
      return "MET_FLOAT";
    case VoxelType::F64:
      return "MET_DOUBLE";
  }
  return "MET_OTHER";
}

Result<Parsed> HeaderParser::parse() {
  Parsed out;
  // Key = Value lines up to and including ElementDataFile.
  std::size_t pos = 0;
  int line = 0;
  const Field* dataField = nullptr;
  const char* text = reinterpret_cast<const char*>(bytes_.data());
  while (!dataField) {
    if (pos >= bytes_.size())
      return fail(ErrorCode::Parse,
                  "the header ends after " + std::to_string(line) + " lines without an ElementDataFile key",
                  source_, "this is not a MetaImage header, or it is truncated");
    if (pos >= kMaxHeaderBytes)
      return fail(ErrorCode::Parse,
                  "no ElementDataFile key in the first " + std::to_string(kMaxHeaderBytes) + " bytes",
                  source_, "this is not a MetaImage header");
    ++line;
    const std::size_t scanEnd = std::min(bytes_.size(), kMaxHeaderBytes);
    const void* nl = std::memchr(text + pos, '\n', scanEnd - pos);
    const std::size_t eol = nl ? static_cast<std::size_t>(static_cast<const char*>(nl) - text) : scanEnd;
    const std::string_view raw(text + pos, eol - pos);
    pos = eol + 1;
    const std::string_view content = trim(raw);
    if (content.empty()) continue;
    const std::size_t eq = content.find('=');
    if (eq == std::string_view::npos)
      return fail(ErrorCode::Parse,
                  "line " + std::to_string(line) + " is not \"Key = Value\": \"" + shown(content) + "\"",
                  source_, "this is not a MetaImage header, or it is damaged");
    const std::string_view name = trim(content.substr(0, eq));
    const std::string key = lower(name);
    if (key.empty())
      return fail(ErrorCode::Parse, "line " + std::to_string(line) + " has an empty key", source_);
    Field f{std::string(trim(content.substr(eq + 1))), line, std::string(name)};
    if (auto it = fields_.find(key); it != fields_.end())
      return fail(ErrorCode::Parse,
                  "key " + f.name + " appears twice (lines " + std::to_string(it->second.line) + " and " +
                      std::to_string(line) + ")",
                  source_);
    auto [it, inserted] = fields_.emplace(key, std::move(f));
    (void)inserted;
    if (key == "elementdatafile") dataField = &it->second;
  }
  out.dataFile = dataField->value;
  out.dataLine = dataField->line;
  out.dataOffset = std::min(pos, bytes_.size());

  if (const Field* f = find({"objecttype"}); f && lower(f->value) != "image")
    return fail(ErrorCode::Unsupported,
                f->name + " (line " + std::to_string(f->line) + ") is \"" + shown(f->value) +
                    "\"; only Image objects are volumes",
                source_);
  const Field* ndimsF = find({"ndims"});
  if (!ndimsF) return fail(ErrorCode::Parse, "the NDims key is missing", source_);
  auto ndimsV = numbers(*ndimsF, 1, true);
  if (!ndimsV) return std::move(ndimsV).error();
  if ((*ndimsV)[0] < 1 || (*ndimsV)[0] > 4)
    return fail(ErrorCode::Unsupported,
                ndimsF->name + " (line " + std::to_string(ndimsF->line) + ") is " + ndimsF->value +
                    "; volumes have 1 to 4 dimensions",
                source_);
  const auto n = static_cast<std::size_t>((*ndimsV)[0]);
  const std::size_t ns = std::min<std::size_t>(n, 3);  // spatial axes

  const Field* dimF = find({"dimsize"});
  if (!dimF) return fail(ErrorCode::Parse, "the DimSize key is missing", source_);
  auto dimV = numbers(*dimF, n, true);
  if (!dimV) return std::move(dimV).error();
  for (std::size_t i = 0; i < n; ++i) {
    const double d = (*dimV)[i];
    if (d < 1 || d > std::numeric_limits<int>::max())
      return error(*dimF, "value " + std::to_string(i + 1) + " is " + shown(std::to_string(d)) +
                              "; sizes must be 1.." + std::to_string(std::numeric_limits<int>::max()));
    if (i < 3) out.dims[static_cast<int>(i)] = static_cast<int>(d);
  }
  if (n == 4) out.volumes = static_cast<std::int64_t>((*dimV)[3]);

  const Field* typeF = find({"elementtype"});
  if (!typeF) return fail(ErrorCode::Parse, "the ElementType key is missing", source_);
  const ElementInfo* info = nullptr;
  for (const ElementInfo& e : kElements)
    if (lower(typeF->value) == lower(e.name)) info = &e;
  if (!info) return error(*typeF, "is \"" + shown(typeF->value) + "\", not a MetaImage element type");
  if (!info->supported)
    return fail(ErrorCode::Unsupported,
                typeF->name + " (line " + std::to_string(typeF->line) + ") " + info->name +
                    " is not a scalar voxel type",
                source_, "convert to MET_UCHAR, MET_SHORT, MET_FLOAT, ...");
  out.element = info->element;
  out.elementName = info->name;

  if (const Field* f = find({"elementnumberofchannels"})) {
    auto v = numbers(*f, 1, true);
    if (!v) return std::move(v).error();
    if ((*v)[0] != 1)
      return fail(ErrorCode::Unsupported,
                  f->name + " (line " + std::to_string(f->line) + ") is " + f->value +
                      "; only single-channel (scalar) volumes are supported",
                  source_);
  }
  if (const Field* f = find({"binarydata"})) {
    auto b = boolean(*f);
    if (!b) return std::move(b).error();
    if (!*b)
      return fail(
          ErrorCode::Unsupported,
          f->name + " (line " + std::to_string(f->line) + ") is False; ASCII voxel data is not supported",
          source_, "save the image with binary data");
  }
  if (const Field* f = find({"binarydatabyteordermsb", "elementbyteordermsb", "byteordermsb"})) {
    auto b = boolean(*f);
    if (!b) return std::move(b).error();
    out.msb = *b;
  }
  if (const Field* f = find({"compresseddata"})) {
    auto b = boolean(*f);
    if (!b) return std::move(b).error();
    out.compressed = *b;
  }
  if (const Field* f = find({"compresseddatasize"})) {
    auto v = numbers(*f, 1, true);
    if (!v) return std::move(v).error();
    if ((*v)[0] < 0 || (*v)[0] > 9.0e15) return error(*f, "is out of range");
    out.compressedSize = static_cast<std::uint64_t>((*v)[0]);
  }
  if (const Field* f = find({"headersize"})) {
    auto v = numbers(*f, 1, true);
    if (!v) return std::move(v).error();
    if ((*v)[0] < -1 || (*v)[0] > 9.0e15) return error(*f, "is " + f->value + "; must be -1 or a byte count");
    out.headerSize = static_cast<std::int64_t>((*v)[0]);
  }

  // Geometry, LPS millimetres.
  Vec3 spacing = Vec3::Ones();
  if (const Field* f = find({"elementspacing", "elementsize"})) {
    auto v = numbers(*f, n, false);
    if (!v) return std::move(v).error();
    for (std::size_t i = 0; i < ns; ++i) {
      if ((*v)[i] == 0)
        return error(*f, "value " + std::to_string(i + 1) + " is 0; spacing must be non-zero");
      spacing[static_cast<int>(i)] = (*v)[i];
    }
  }
  Vec3 origin = Vec3::Zero();
  if (const Field* f = find({"offset", "position", "origin"})) {
    auto v = numbers(*f, n, false);
    if (!v) return std::move(v).error();
    for (std::size_t i = 0; i < ns; ++i) origin[static_cast<int>(i)] = (*v)[i];
  }
  Mat3 dir = Mat3::Identity();
  const Field* matF = find({"transformmatrix", "rotation", "orientation"});
  if (matF) {
    auto v = numbers(*matF, n * n, false);
    if (!v) return std::move(v).error();
    // ITK: entries [i·n, i·n + n) are the direction of index axis i.
    for (std::size_t i = 0; i < ns; ++i)
      for (std::size_t j = 0; j < ns; ++j) dir(static_cast<int>(j), static_cast<int>(i)) = (*v)[i * n + j];
  }
  Mat3 lin = dir * spacing.asDiagonal();
  if (isSingular(lin)) {
    const std::string where =
        matF ? matF->name + " (line " + std::to_string(matF->line) + ")" : std::string("ElementSpacing");
    return fail(ErrorCode::Parse, where + " gives a singular index-to-world matrix (collinear axes)",
                source_);
  }
  // LPS -> RAS (negate x and y), millimetres -> metres.
  const Vec3 lpsToRas(-1.0, -1.0, 1.0);
  Affine3 a = Affine3::Identity();
  a.linear() = lpsToRas.asDiagonal() * lin * 1e-3;
  a.translation() = lpsToRas.cwiseProduct(origin) * 1e-3;
  if (!a.matrix().allFinite() || isSingular(a.linear()))
    return fail(ErrorCode::Parse, "the geometry is not finite or singular after conversion to metres",
                source_);
  out.indexToWorld = a;

  // Three factors below 2^31 can overflow 64 bits.
  std::uint64_t voxels = 1;
  for (int i = 0; i < 3; ++i) {
    const auto d = static_cast<std::uint64_t>(out.dims[i]);
    if (voxels > (std::uint64_t{1} << 59) / d) return error(*dimF, "gives a voxel count that overflows");
    voxels *= d;
  }
  out.volumeBytes = static_cast<std::size_t>(voxels * rawElementBytes(out.element));
  return out;
}

// Loads the voxels from `stream` (the bytes after the header for LOCAL, or
// the whole data file).
Result<Volume> loadData(const Parsed& p, std::span<const std::byte> stream, const std::string& source,
                        const MetaImageReadOptions& options) {
  if (options.volumeIndex < 0 || options.volumeIndex >= p.volumes)
    return fail(ErrorCode::InvalidArgument,
                "volumeIndex " + std::to_string(options.volumeIndex) + " is out of range: the image holds " +
                    std::to_string(p.volumes) + " volume(s)",
                source);
  // Checked once the data is known to be there (raw) or before inflating it.
  const Status withinLimit =
      p.volumeBytes <= options.maxBytes
          ? ok()
          : Status(detail::volumeOverBudget(
                "DimSize " + std::to_string(p.dims.x()) + "x" + std::to_string(p.dims.y()) + "x" +
                    std::to_string(p.dims.z()) + " of " + p.elementName,
                p.volumeBytes, options.maxBytes, source, "MetaImageReadOptions::maxBytes"));
  const auto index = static_cast<std::uint64_t>(options.volumeIndex);
  if (index != 0 && p.volumeBytes > (std::uint64_t{1} << 62) / index)
    return fail(ErrorCode::Parse, "data offset of volume " + std::to_string(index) + " overflows", source);
  const std::uint64_t volStart = index * p.volumeBytes;
  RawVoxelFormat fmt;
  fmt.element = p.element;
  fmt.byteOrder = p.msb ? std::endian::big : std::endian::little;
  auto shortData = [&](std::uint64_t have, const char* what) {
    return fail(ErrorCode::Parse,
                std::string(what) + " holds " + std::to_string(have) + " bytes, but DimSize " +
                    std::to_string(p.dims.x()) + "x" + std::to_string(p.dims.y()) + "x" +
                    std::to_string(p.dims.z()) +
                    (p.volumes > 1 ? " (up to volume " + std::to_string(index) + ")" : std::string()) +
                    " of " + p.elementName + " needs " + std::to_string(volStart + p.volumeBytes) +
                    (p.headerSize > 0 ? " after HeaderSize " + std::to_string(p.headerSize) : std::string()),
                source, "the data is truncated, or DimSize/ElementType/HeaderSize are wrong");
  };
  if (p.compressed) {
    if (p.headerSize < 0)
      return fail(ErrorCode::Parse, "HeaderSize = -1 cannot be combined with CompressedData = True", source);
    if (static_cast<std::uint64_t>(p.headerSize) > stream.size()) return shortData(stream.size(), "the data");
    std::span<const std::byte> c = stream.subspan(static_cast<std::size_t>(p.headerSize));
    if (p.compressedSize && *p.compressedSize < c.size())
      c = c.first(static_cast<std::size_t>(*p.compressedSize));
    if (!withinLimit) return withinLimit.error();
    // Earlier volumes are decompressed and discarded, not kept.
    auto data = detail::inflate(c, p.volumeBytes, source, static_cast<std::size_t>(volStart));
    if (!data) return std::move(data).error();
    if (data->size() < p.volumeBytes) return shortData(volStart + data->size(), "the decompressed data");
    return decodeRawVolume(*data, p.dims, fmt, p.indexToWorld, source, options.maxBytes);
  }
  auto slice = detail::rawVolumeSlice(stream, p.headerSize, static_cast<std::uint64_t>(p.volumes),
                                      p.volumeBytes, index, source, shortData);
  if (!slice) return std::move(slice).error();
  if (!withinLimit) return withinLimit.error();
  return decodeRawVolume(*slice, p.dims, fmt, p.indexToWorld, source, options.maxBytes);
}

bool isLocal(const std::string& dataFile) { return lower(dataFile) == "local"; }

Status checkDataFileName(const Parsed& p, const std::string& source) {
  const std::string l = lower(p.dataFile);
  if (l.empty())
    return fail(ErrorCode::Parse, "ElementDataFile (line " + std::to_string(p.dataLine) + ") is empty",
                source);
  if (l.rfind("list", 0) == 0 || p.dataFile.find('%') != std::string::npos ||
      p.dataFile.find_first_of(" \t") != std::string::npos)
    return fail(ErrorCode::Unsupported,
                "ElementDataFile (line " + std::to_string(p.dataLine) + ") \"" + shown(p.dataFile) +
                    "\" names several slice files; only LOCAL or one data file is supported",
                source, "merge the slices into one file, e.g. with SimpleITK");
  return ok();
}

}  // namespace

Result<Volume> parseMetaImage(std::span<const std::byte> bytes, std::string_view sourceName,
                              const MetaImageReadOptions& options) {
  const std::string source(sourceName);
  auto p = HeaderParser(bytes, source).parse();
  if (!p) return std::move(p).error();
  if (auto s = checkDataFileName(*p, source); !s) return std::move(s).error();
  if (!isLocal(p->dataFile))
    return fail(ErrorCode::InvalidArgument,
                "ElementDataFile (line " + std::to_string(p->dataLine) + ") names a separate file \"" +
                    shown(p->dataFile) + "\"; parseMetaImage reads only LOCAL data",
                source, "use readMetaImage with the header's path");
  return loadData(*p, bytes.subspan(p->dataOffset), source, options);
}

Result<Volume> readMetaImage(const std::filesystem::path& file, const MetaImageReadOptions& options) {
  const std::string source = file.string();
  auto bytes = readFile(file, std::numeric_limits<std::size_t>::max());
  if (!bytes) return std::move(bytes).error();
  auto p = HeaderParser(*bytes, source).parse();
  if (!p) return std::move(p).error();
  if (auto s = checkDataFileName(*p, source); !s) return std::move(s).error();
  if (isLocal(p->dataFile))
    return loadData(*p, std::span<const std::byte>(*bytes).subspan(p->dataOffset), source, options);
  const std::string field = "ElementDataFile (line " + std::to_string(p->dataLine) + ") of " + source;
  auto dataPath = FileSystem::global().confine(file.parent_path(), p->dataFile, field);
  if (!dataPath) return std::move(dataPath).error();
  auto data = readFile(*dataPath, std::numeric_limits<std::size_t>::max());
  if (!data) {
    Error e = std::move(data).error();
    e.what = field + ": " + e.what;
    return e;
  }
  return loadData(*p, *data, dataPath->string(), options);
}

namespace {

std::vector<std::byte> littleEndianVoxels(const Volume& v) {
  std::vector<std::byte> out(v.bytes(), v.bytes() + v.byteSize());
  if constexpr (std::endian::native == std::endian::big) {
    const std::size_t w = voxelBytes(v.type());
    for (std::size_t i = 0; w > 1 && i < out.size(); i += w)
      std::reverse(out.begin() + i, out.begin() + i + w);
  }
  return out;
}

std::string headerText(const Volume& v, bool compressed, std::size_t compressedSize,
                       const std::string& dataFile) {
  // RAS metres -> LPS millimetres; directions are the unit columns.
  const Vec3 rasToLps(-1.0, -1.0, 1.0);
  const Mat3 lin = rasToLps.asDiagonal() * v.indexToWorld().linear() * 1e3;
  const Vec3 origin = rasToLps.cwiseProduct(v.indexToWorld().translation()) * 1e3;
  const Vec3 spacing = lin.colwise().norm().transpose();
  std::string h = "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\n";
  h += std::string("CompressedData = ") + (compressed ? "True" : "False") + "\n";
  if (compressed) h += "CompressedDataSize = " + std::to_string(compressedSize) + "\n";
  h += "TransformMatrix =";
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) h += " " + fmt17(lin(j, i) / spacing[i]);
  h += "\nOffset = " + fmt17(origin.x()) + " " + fmt17(origin.y()) + " " + fmt17(origin.z()) + "\n";
  h += "CenterOfRotation = 0 0 0\n";
  h += "ElementSpacing = " + fmt17(spacing.x()) + " " + fmt17(spacing.y()) + " " + fmt17(spacing.z()) + "\n";
  h += "DimSize = " + std::to_string(v.dims().x()) + " " + std::to_string(v.dims().y()) + " " +
       std::to_string(v.dims().z()) + "\n";
  h += std::string("ElementType = ") + elementTypeName(v.type()) + "\n";
  h += "ElementDataFile = " + dataFile + "\n";
  return h;
}

Result<std::vector<std::byte>> payload(const Volume& v, bool compress) {
  std::vector<std::byte> raw = littleEndianVoxels(v);
  if (!compress) return raw;
  return detail::deflate(raw, detail::CompressFormat::Zlib);
}

}  // namespace

Result<std::vector<std::byte>> encodeMetaImage(const Volume& v, const MetaImageWriteOptions& options) {
  if (auto s = checkWritable(v, "writeMetaImage"); !s) return std::move(s).error();
  auto data = payload(v, options.compress);
  if (!data) return std::move(data).error();
  const std::string h = headerText(v, options.compress, data->size(), "LOCAL");
  std::vector<std::byte> out(h.size() + data->size());
  std::memcpy(out.data(), h.data(), h.size());
  std::memcpy(out.data() + h.size(), data->data(), data->size());
  return out;
}

Status writeMetaImage(const Volume& v, const std::filesystem::path& file,
                      const MetaImageWriteOptions& options) {
  const std::string ext = lower(file.extension().string());
  if (ext == ".mha") {
    auto bytes = encodeMetaImage(v, options);
    if (!bytes) return std::move(bytes).error().within(file.string());
    return writeFileAtomic(file, bytes->data(), bytes->size());
  }
  if (ext != ".mhd")
    return fail(ErrorCode::InvalidArgument, "a MetaImage file name must end in .mha or .mhd", file.string());
  if (auto s = checkWritable(v, file.string()); !s) return s;
  auto data = payload(v, options.compress);
  if (!data) return std::move(data).error().within(file.string());
  const std::string dataName = file.stem().string() + (options.compress ? ".zraw" : ".raw");
  if (auto s = writeFileAtomic(file.parent_path() / dataName, data->data(), data->size()); !s) return s;
  const std::string h = headerText(v, options.compress, data->size(), dataName);
  return writeFileAtomic(file, h.data(), h.size());
}

}  // namespace dm
