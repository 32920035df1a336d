// mesh_guards.cpp — the checks a mesh input gets before Assimp sees it
// (mesh_guards.hpp): header promises a file cannot keep, inputs that make
// Assimp 5.2 loop, declared element counts over the import's budget.
#include "mesh_guards.hpp"

#include <algorithm>
#include <cctype>
#include <cstring>
#include <limits>
#include <optional>
#include <vector>

#include "format_util.hpp"

namespace dm::detail {

namespace {

constexpr std::uint64_t kMaxU64 = std::numeric_limits<std::uint64_t>::max();

std::uint64_t satMul(std::uint64_t a, std::uint64_t b) { return b != 0 && a > kMaxU64 / b ? kMaxU64 : a * b; }
std::uint64_t satAdd(std::uint64_t a, std::uint64_t b) { return a > kMaxU64 - b ? kMaxU64 : a + b; }

bool parseCount(std::string_view s, std::size_t& pos, std::uint64_t& value) {
  while (pos < s.size() && std::isspace(static_cast<unsigned char>(s[pos]))) ++pos;
  if (pos >= s.size() || !std::isdigit(static_cast<unsigned char>(s[pos]))) return false;
  value = 0;
  while (pos < s.size() && std::isdigit(static_cast<unsigned char>(s[pos]))) {
    value = satAdd(satMul(value, 10), static_cast<std::uint64_t>(s[pos] - '0'));
    ++pos;
  }
  return true;
}

// The budget refusal every format shares: the figure, the limit, the option.
Status overBudget(std::string_view format, std::uint64_t declared, std::string_view what, std::uint64_t limit,
                  std::string_view limitName, const std::string& where) {
  return fail(ErrorCode::Unsupported,
              std::string(format) + " header declares " + std::to_string(declared) + " " + std::string(what) +
                  ", more than the budget of " + std::to_string(limit) + " (" + std::string(limitName) + ")",
              where, "raise MeshImportOptions::maxTriangles if the model is genuine, or simplify it");
}

Status checkCounts(std::string_view format, std::uint64_t vertices, std::uint64_t faces,
                   std::size_t maxTriangles, const std::string& where) {
  if (faces > maxTriangles)
    return overBudget(format, faces, "faces", maxTriangles, "MeshImportOptions::maxTriangles", where);
  const std::uint64_t vertexLimit = vertexBudget(maxTriangles);
  if (vertices > vertexLimit)
    return overBudget(format, vertices, "vertices", vertexLimit, "3 per allowed triangle, at most 2^32 - 1",
                      where);
  return ok();
}

// OFF: Assimp 5.2's OFF reader trusts the vertex and face counts of the
// header and allocates and loops accordingly (the assimp-testmodels file
// invalid/OutOfMemory.off hangs it). A vertex needs at least 6 bytes
// ("0 0 0\n") and a face at least 2, so counts beyond that are refused.
Status checkOffHeader(const MeshHead& in, std::size_t maxTriangles, const std::string& where) {
  const std::string_view head = in.head;
  std::size_t pos = 0;
  // Skip blank lines and '#' comments.
  for (;;) {
    while (pos < head.size() && std::isspace(static_cast<unsigned char>(head[pos]))) ++pos;
    if (pos < head.size() && head[pos] == '#') {
      while (pos < head.size() && head[pos] != '\n') ++pos;
      continue;
    }
    break;
  }
  std::size_t end = pos;
  while (end < head.size() && !std::isspace(static_cast<unsigned char>(head[end]))) ++end;
  const std::string token = lower(head.substr(pos, end - pos));
  const bool offToken = token.size() >= 3 && token.compare(token.size() - 3, 3, "off") == 0;
  if (!offToken && in.extension != "off") return ok();
  if (offToken) {
    pos = end;
    if (token.find('n') != std::string::npos) {  // nOFF: the dimension comes first
      std::uint64_t dim = 0;
      if (!parseCount(head, pos, dim)) return ok();
    }
  }
  std::uint64_t vertices = 0, faces = 0;
  if (!parseCount(head, pos, vertices) || !parseCount(head, pos, faces))
    return ok();  // the reader reports it
  if (auto s = checkCounts("OFF", vertices, faces, maxTriangles, where); !s) return s;
  if (vertices > in.fileBytes / 6 + 1 || faces > in.fileBytes / 2 + 1)
    return fail(ErrorCode::Parse,
                "OFF header declares " + std::to_string(vertices) + " vertices and " + std::to_string(faces) +
                    " faces, more than a file of " + std::to_string(in.fileBytes) + " bytes can hold",
                where, "the header counts are wrong; fix or re-export the file");
  return ok();
}

// PLY. Assimp 5.2 reads header lines until one starts with the token
// "end_header" and never stops at the end of the input, so a header without
// that line ("end_header" glued to the data, a truncated header) loops
// forever: every input that starts with "ply" (the reader's magic) must have
// an "end_header" line, alone on its line, within the first kMeshHeadBytes.
// The reader then allocates per declared element before it reads one, so
// the counts are held against the budget and against the bytes after the
// header: an element needs at least its binary size (a list: its count),
// or in ASCII two characters per property ("0 ").

struct PlyElement {
  std::string name;
  std::uint64_t count = 0;
  std::optional<std::uint64_t> minBytes = 0;  ///< none: a property type we do not know
};

std::optional<std::uint64_t> plyTypeBytes(std::string_view type) {
  static constexpr std::pair<const char*, std::uint64_t> kTypes[] = {
      {"char", 1},  {"uchar", 1},   {"int8", 1},   {"uint8", 1},  {"short", 2}, {"ushort", 2},
      {"int16", 2}, {"uint16", 2},  {"int", 4},    {"uint", 4},   {"int32", 4}, {"uint32", 4},
      {"float", 4}, {"float32", 4}, {"double", 8}, {"float64", 8}};
  for (const auto& [name, bytes] : kTypes)
    if (type == name) return bytes;
  return std::nullopt;
}

std::vector<std::string_view> words(std::string_view line) {
  std::vector<std::string_view> out;
  std::size_t pos = 0;
  while (pos < line.size()) {
    while (pos < line.size() && std::isspace(static_cast<unsigned char>(line[pos]))) ++pos;
    const std::size_t start = pos;
    while (pos < line.size() && !std::isspace(static_cast<unsigned char>(line[pos]))) ++pos;
    if (pos > start) out.push_back(line.substr(start, pos - start));
  }
  return out;
}

Status checkPlyHeader(const MeshHead& in, std::size_t maxTriangles, const std::string& where) {
  const std::string_view head = in.head;
  if (head.size() < 3 || lower(head.substr(0, 3)) != "ply") return ok();
  const char* hint =
      "the PLY header must end with a line holding only 'end_header'; fix or re-export the file";
  std::vector<PlyElement> elements;
  bool ascii = false, knownFormat = false;
  std::size_t pos = 0;
  std::optional<std::uint64_t> dataStart;
  while (pos < head.size()) {
    const std::size_t eol = head.find('\n', pos);
    const std::string_view line =
        head.substr(pos, eol == std::string_view::npos ? std::string_view::npos : eol - pos);
    if (line.starts_with("end_header")) {
      const std::string_view rest = line.substr(10);
      if (eol == std::string_view::npos || rest.find_first_not_of(" \t\r") != std::string_view::npos)
        return fail(
            ErrorCode::Parse,
            "PLY 'end_header' at byte " + std::to_string(pos) + " is not followed by the end of the line",
            where, hint);
      dataStart = eol + 1;
      break;
    }
    const std::vector<std::string_view> w = words(line);
    if (w.size() >= 2 && w[0] == "format") {
      knownFormat = w[1] == "ascii" || w[1] == "binary_little_endian" || w[1] == "binary_big_endian";
      ascii = w[1] == "ascii";
    } else if (w.size() >= 3 && w[0] == "element") {
      std::size_t at = 0;
      std::uint64_t count = 0;
      if (parseCount(w[2], at, count) && at == w[2].size())
        elements.push_back(PlyElement{std::string(w[1]), count, 0});
      else
        elements.push_back(PlyElement{std::string(w[1]), 0, std::nullopt});
    } else if (w.size() >= 2 && w[0] == "property" && !elements.empty()) {
      std::optional<std::uint64_t>& minBytes = elements.back().minBytes;
      // "property TYPE NAME" or "property list COUNTTYPE ITEMTYPE NAME".
      const std::optional<std::uint64_t> bytes =
          w[1] == "list" ? (w.size() >= 3 ? plyTypeBytes(w[2]) : std::nullopt) : plyTypeBytes(w[1]);
      if (!bytes || !minBytes)
        minBytes.reset();
      else
        *minBytes += ascii ? 2 : *bytes;
    }
    if (eol == std::string_view::npos) break;
    pos = eol + 1;
  }
  if (!dataStart)
    return fail(ErrorCode::Parse,
                std::string("PLY header has no 'end_header' line") +
                    (head.size() == in.fileBytes ? "" : " in its first 64 KiB"),
                where, hint);
  std::uint64_t vertices = 0, faces = 0;
  for (const PlyElement& e : elements) {
    if (e.name == "vertex") vertices = satAdd(vertices, e.count);
    if (e.name == "face") faces = satAdd(faces, e.count);
  }
  if (auto s = checkCounts("PLY", vertices, faces, maxTriangles, where); !s) return s;
  if (!knownFormat) return ok();  // the reader reports it
  // An element without properties still costs the reader an entry (and in
  // ASCII a line): count it as one byte.
  std::uint64_t needed = 0;
  std::string listed;
  for (const PlyElement& e : elements) {
    if (!e.minBytes) return ok();  // a type we do not know: the reader judges
    needed = satAdd(needed, satMul(e.count, std::max<std::uint64_t>(*e.minBytes, 1)));
    listed += (listed.empty() ? "" : ", ") + std::to_string(e.count) + " '" + shown(e.name) + "'";
  }
  const std::uint64_t have = in.fileBytes - std::min<std::uint64_t>(in.fileBytes, *dataStart);
  // ASCII data may end without the last separator.
  if (needed > satAdd(have, ascii ? 1 : 0))
    return fail(ErrorCode::Parse,
                "PLY header declares " + listed + " elements, at least " + std::to_string(needed) +
                    " bytes, but only " + std::to_string(have) + " bytes follow the header",
                where, "the element counts are wrong or the file is truncated; fix or re-export it");
  return ok();
}

// Binary STL: an 80-byte header, the triangle count, 50 bytes a triangle.
// Assimp reads a file as binary STL when the count fits its size.
Status checkStlHeader(const MeshHead& in, std::size_t maxTriangles, const std::string& where) {
  if (in.extension != "stl" || in.head.size() < 84 || in.fileBytes < 84) return ok();
  std::uint32_t count = 0;
  std::memcpy(&count, in.head.data() + 80, sizeof count);  // little-endian, like the machines we run on
  if ((in.fileBytes - 84) / 50 != count) return ok();      // not binary: the ASCII reader's input
  if (count > maxTriangles)
    return overBudget("binary STL", count, "triangles", maxTriangles, "MeshImportOptions::maxTriangles",
                      where);
  return ok();
}

}  // namespace

std::uint64_t vertexBudget(std::size_t maxTriangles) {
  return std::min<std::uint64_t>(satMul(maxTriangles, 3), std::numeric_limits<std::uint32_t>::max());
}

Status checkMeshHead(const MeshHead& in, std::size_t maxTriangles, const std::string& where) {
  if (auto s = checkOffHeader(in, maxTriangles, where); !s) return s;
  if (auto s = checkPlyHeader(in, maxTriangles, where); !s) return s;
  return checkStlHeader(in, maxTriangles, where);
}

// Collada: Assimp 5.2 reads the index list of a <p> element with a loop that
// does not advance over a character other than a digit, sign or blank, and
// grows a vector forever ("<p>0 1 x 2</p>" never returns). Files that look
// like Collada are scanned whole and such lists refused.
bool looksLikeCollada(std::string_view head, bool daeExtension) {
  return daeExtension || lower(head.substr(0, std::min<std::size_t>(head.size(), 4096))).find("<collada") !=
                             std::string::npos;
}

Status checkColladaIndexLists(std::string_view xml, const std::string& where) {
  std::size_t pos = 0;
  while ((pos = xml.find("<p", pos)) != std::string_view::npos) {
    pos += 2;
    if (pos >= xml.size() || (xml[pos] != '>' && !std::isspace(static_cast<unsigned char>(xml[pos]))))
      continue;
    const std::size_t open = xml.find('>', pos);
    if (open == std::string_view::npos) break;
    if (xml[open - 1] == '/') continue;  // <p/>
    const std::size_t close = xml.find("</p>", open);
    if (close == std::string_view::npos) break;  // the XML parser reports it
    const std::string_view list = xml.substr(open + 1, close - open - 1);
    const std::size_t bad = list.find_first_not_of("0123456789+- \t\r\n");
    if (bad != std::string_view::npos)
      return fail(ErrorCode::Parse,
                  "Collada index list <p> at byte " + std::to_string(open + 1) + " contains the character '" +
                      std::string(1, list[bad]) + "' at byte " + std::to_string(open + 1 + bad),
                  where, "index lists hold whitespace-separated integers only; fix or re-export the file");
    pos = close + 4;
  }
  return ok();
}

}  // namespace dm::detail
