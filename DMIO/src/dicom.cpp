// DICOM series I/O through DCMTK (dcmdata). Every byte stream is walked and
// bounds-checked by walkFile() before DCMTK sees it, and DCMTK only parses
// the header part (the bytes before the top-level PixelData); the voxels are
// decoded by decodeRawVolume() from the validated span.
#include <dm/core/filesystem.hpp>
#include <dm/core/log.hpp>
#include <dm/io/dicom.hpp>
#include <dm/io/volume_io.hpp>

#include <dcmtk/config/osconfig.h>  // must come first among DCMTK headers
#include <dcmtk/dcmdata/dcdatset.h>
#include <dcmtk/dcmdata/dcdeftag.h>
#include <dcmtk/dcmdata/dcdict.h>
#include <dcmtk/dcmdata/dcfilefo.h>
#include <dcmtk/dcmdata/dcistrmb.h>
#include <dcmtk/dcmdata/dctag.h>
#include <dcmtk/dcmdata/dcuid.h>
#include <dcmtk/dcmdata/dcxfer.h>
#include <dcmtk/oflog/oflog.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <system_error>
#include <variant>
#include <vector>

#include "format_util.hpp"

namespace dm {

namespace {

constexpr std::uint32_t kUndefinedLength = 0xFFFFFFFFu;
constexpr int kMaxNesting = 16;
// Real headers hold hundreds to a few thousand elements; the cap bounds what
// DCMTK allocates (one object per element) for a file of tiny elements.
constexpr std::size_t kMaxElements = 200000;
constexpr const char* kSliceNameFormat = "slice_%05d.dcm";

std::string hex4(std::uint32_t v) {
  char b[8];
  std::snprintf(b, sizeof b, "%04X", static_cast<unsigned>(v & 0xFFFFu));
  return b;
}

std::string tagText(std::uint16_t g, std::uint16_t e) { return "(" + hex4(g) + "," + hex4(e) + ")"; }

// "(0028,0030) PixelSpacing": the tag and its dictionary keyword.
std::string tagLabel(const DcmTagKey& key) {
  DcmTag tag(key);
  return tagText(key.getGroup(), key.getElement()) + " " + tag.getTagName();
}

void initDcmtk() {
  static std::once_flag once;
  std::call_once(once, [] {
    // Malformed input is reported through dm::Error; DCMTK's own warnings
    // would only duplicate it on stderr.
    OFLog::getLogger("dcmtk.dcmdata").setLogLevel(OFLogger::OFF_LOG_LEVEL);
  });
}

// ---------------------------------------------------------------------------
// Structural walk: the bounds checks that make the bytes safe for DCMTK.

struct Syntax {
  std::string uid = UID_LittleEndianImplicitTransferSyntax;
  bool explicitVr = false;
  bool little = true;
  E_TransferSyntax xfer = EXS_LittleEndianImplicit;
};

struct FileLayout {
  Syntax syntax;
  std::size_t datasetStart = 0;
  /// Offset of the top-level (7FE0,0010) element header; npos when absent.
  std::size_t pixelElement = std::string::npos;
  std::size_t pixelValue = 0;
  std::size_t pixelLength = 0;
  bool pixelIsOw = false;
};

struct ElementHeader {
  std::uint16_t group = 0;
  std::uint16_t element = 0;
  char vr[3] = {0, 0, 0};
  std::uint32_t length = 0;
  std::size_t valueStart = 0;
};

bool isKnownVr(const char* vr) {
  static constexpr const char* kVrs[] = {
      "AE", "AS", "AT", "CS", "DA", "DS", "DT", "FL", "FD", "IS", "LO", "LT", "OB", "OD", "OF", "OL", "OV",
      "OW", "PN", "SH", "SL", "SQ", "SS", "ST", "SV", "TM", "UC", "UI", "UL", "UN", "UR", "US", "UT", "UV"};
  for (const char* k : kVrs)
    if (k[0] == vr[0] && k[1] == vr[1]) return true;
  return false;
}

bool hasLongLength(const char* vr) {
  static constexpr const char* kLong[] = {"OB", "OD", "OF", "OL", "OV", "OW", "SQ",
                                          "UC", "UN", "UR", "UT", "SV", "UV"};
  for (const char* k : kLong)
    if (k[0] == vr[0] && k[1] == vr[1]) return true;
  return false;
}

class Walker {
 public:
  Walker(std::span<const std::byte> bytes, std::string source) : b_(bytes), source_(std::move(source)) {}

  std::uint16_t u16(std::size_t at, bool little) const {
    const auto x = static_cast<unsigned>(b_[at]), y = static_cast<unsigned>(b_[at + 1]);
    return static_cast<std::uint16_t>(little ? (x | y << 8) : (y | x << 8));
  }
  std::uint32_t u32(std::size_t at, bool little) const {
    const std::uint32_t lo = u16(at, little), hi = u16(at + 2, little);
    return little ? (lo | hi << 16) : (hi | lo << 16);
  }

  Error error(const std::string& what, std::size_t offset, std::string hint = {}) const {
    return fail(ErrorCode::Parse, what + " at byte offset " + std::to_string(offset), source_,
                hint.empty() ? "the file is truncated or corrupt" : std::move(hint));
  }

  Result<ElementHeader> header(std::size_t pos, std::size_t limit, bool explicitVr, bool little) {
    if (++elements_ > kMaxElements)
      return error("more than " + std::to_string(kMaxElements) + " data elements", pos,
                   "this is not an image header DMPlatform reads");
    if (limit - pos < 8)
      return error("element header cut off (" + std::to_string(limit - pos) + " of 8 bytes)", pos);
    ElementHeader h;
    h.group = u16(pos, little);
    h.element = u16(pos + 2, little);
    if (h.group == 0xFFFE || !explicitVr) {
      h.length = u32(pos + 4, little);
      h.valueStart = pos + 8;
      return h;
    }
    h.vr[0] = static_cast<char>(b_[pos + 4]);
    h.vr[1] = static_cast<char>(b_[pos + 5]);
    if (!isKnownVr(h.vr)) {
      return error("unknown VR '" + shownText(std::string_view(h.vr, 2)) + "' of element " +
                       tagText(h.group, h.element),
                   pos);
    }
    if (hasLongLength(h.vr)) {
      if (limit - pos < 12)
        return error("element header of " + tagText(h.group, h.element) + " cut off", pos);
      h.length = u32(pos + 8, little);
      h.valueStart = pos + 12;
    } else {
      h.length = u16(pos + 6, little);
      h.valueStart = pos + 8;
    }
    return h;
  }

  // Walks data elements from `pos` to `limit` (or to an item delimiter when
  // `delimited`); returns the position after the last one. At top level it
  // stops at PixelData and records it in `layout`.
  Result<std::size_t> dataset(std::size_t pos, std::size_t limit, bool explicitVr, bool little, int depth,
                              bool delimited, FileLayout* layout) {
    while (pos < limit) {
      auto h = header(pos, limit, explicitVr, little);
      if (!h) return std::move(h).error();
      const std::string tag = tagText(h->group, h->element);
      if (h->group == 0xFFFE) {
        if (h->element == 0xE00D && delimited) return h->valueStart;
        return error("unexpected item tag " + tag + " in a data set", pos);
      }
      const bool undefined = h->length == kUndefinedLength;
      if (layout != nullptr && h->group == 0x7FE0 && h->element == 0x0010) {
        if (undefined)
          return error(
              "encapsulated (compressed) PixelData in the uncompressed transfer syntax " + layout->syntax.uid,
              pos);
        if (h->length > limit - h->valueStart)
          return error("(7FE0,0010) PixelData declares " + std::to_string(h->length) + " bytes but only " +
                           std::to_string(limit - h->valueStart) + " remain",
                       pos);
        layout->pixelElement = pos;
        layout->pixelValue = h->valueStart;
        layout->pixelLength = h->length;
        layout->pixelIsOw = explicitVr && h->vr[0] == 'O' && h->vr[1] == 'W';
        return pos;  // the rest of the file is not given to DCMTK
      }
      const bool explicitSq = explicitVr && h->vr[0] == 'S' && h->vr[1] == 'Q';
      const bool explicitUn = explicitVr && h->vr[0] == 'U' && h->vr[1] == 'N';
      if (undefined) {
        // DCMTK reads undefined-length SQ in the current syntax, UN as implicit
        // VR little endian items, and any implicit VR element as a sequence.
        if (!explicitSq && !explicitUn && explicitVr)
          return error("undefined length on the non-sequence element " + tag, pos);
        const bool innerExplicit = explicitUn ? false : explicitVr;
        const bool innerLittle = explicitUn ? true : little;
        auto end = sequence(h->valueStart, limit, innerExplicit, innerLittle, depth + 1, true);
        if (!end) return end;
        pos = *end;
        continue;
      }
      if (h->length > limit - h->valueStart)
        return error("element " + tag + " declares " + std::to_string(h->length) + " bytes but only " +
                         std::to_string(limit - h->valueStart) + " remain",
                     pos);
      const std::size_t end = h->valueStart + h->length;
      if (explicitSq || (!explicitVr && looksLikeSequence(*h, little))) {
        auto r = sequence(h->valueStart, end, explicitVr, little, depth + 1, false);
        if (!r) return r;
      }
      pos = end;
    }
    if (delimited) return error("item without an item delimitation (FFFE,E00D)", pos);
    return pos;
  }

 private:
  // In implicit VR DCMTK descends into a defined-length element when its
  // dictionary (public or private, found through the private creator) says
  // SQ. A sequence value is empty or starts with an item tag, so every such
  // value is walked, whatever the dictionary says.
  bool looksLikeSequence(const ElementHeader& h, bool little) const {
    if (DcmTag(DcmTagKey(h.group, h.element)).getEVR() == EVR_SQ) return true;
    return h.length >= 8 && u16(h.valueStart, little) == 0xFFFE && u16(h.valueStart + 2, little) == 0xE000;
  }

  Result<std::size_t> sequence(std::size_t pos, std::size_t limit, bool explicitVr, bool little, int depth,
                               bool delimited) {
    if (depth > kMaxNesting)
      return error("sequences nested deeper than " + std::to_string(kMaxNesting) + " levels", pos);
    while (pos < limit) {
      auto h = header(pos, limit, false, little);  // item tags never carry a VR
      if (!h) return std::move(h).error();
      if (h->group != 0xFFFE)
        return error("expected an item (FFFE,E000) but found " + tagText(h->group, h->element), pos);
      if (h->element == 0xE0DD) {
        if (delimited) return h->valueStart;
        return error("sequence delimiter in a sequence of defined length", pos);
      }
      if (h->element != 0xE000)
        return error("unexpected " + tagText(h->group, h->element) + " in a sequence", pos);
      if (h->length == kUndefinedLength) {
        auto end = dataset(h->valueStart, limit, explicitVr, little, depth, true, nullptr);
        if (!end) return end;
        pos = *end;
        continue;
      }
      if (h->length > limit - h->valueStart)
        return error("item declares " + std::to_string(h->length) + " bytes but only " +
                         std::to_string(limit - h->valueStart) + " remain",
                     pos);
      auto r = dataset(h->valueStart, h->valueStart + h->length, explicitVr, little, depth, false, nullptr);
      if (!r) return r;
      pos = h->valueStart + h->length;
    }
    if (delimited) return error("sequence without a sequence delimitation (FFFE,E0DD)", pos);
    return pos;
  }

  std::span<const std::byte> b_;
  std::string source_;
  std::size_t elements_ = 0;
};

std::string trimmed(std::string s) {
  while (!s.empty() && (s.back() == ' ' || s.back() == '\0')) s.pop_back();
  std::size_t i = 0;
  while (i < s.size() && s[i] == ' ') ++i;
  return s.substr(i);
}

Result<Syntax> syntaxOf(const std::string& uid, const std::string& source) {
  Syntax s;
  s.uid = uid;
  if (uid == UID_LittleEndianImplicitTransferSyntax) {
    s.explicitVr = false;
    s.xfer = EXS_LittleEndianImplicit;
  } else if (uid == UID_LittleEndianExplicitTransferSyntax) {
    s.explicitVr = true;
    s.xfer = EXS_LittleEndianExplicit;
  } else if (uid == UID_BigEndianExplicitTransferSyntax) {
    s.explicitVr = true;
    s.little = false;
    s.xfer = EXS_BigEndianExplicit;
  } else {
    const DcmXfer x(uid.c_str());
    const std::string name = x.getXfer() == EXS_Unknown ? std::string("unknown") : x.getXferName();
    return fail(ErrorCode::Unsupported,
                "transfer syntax " + name + " (" + uid + ") is not supported; only uncompressed little/big " +
                    "endian syntaxes are read",
                source, "decompress first, e.g. `dcmdjpeg in.dcm out.dcm`, `dcmdrle` or `dcmconv +te`");
  }
  return s;
}

// Why a byte stream is not DICOM at all (directory scans skip such files).
struct NotDicom {
  std::string reason;
};

// Finds the meta header and transfer syntax and walks the data set up to the
// top-level PixelData. Returns NotDicom when the bytes do not start like a
// DICOM file.
Result<std::variant<FileLayout, NotDicom>> walkFile(std::span<const std::byte> bytes,
                                                    const std::string& source) {
  initDcmtk();
  Walker w(bytes, source);
  FileLayout layout;
  std::size_t pos = 0;
  const auto at = [&](std::size_t i) { return static_cast<char>(bytes[i]); };
  const bool preamble =
      bytes.size() >= 132 && at(128) == 'D' && at(129) == 'I' && at(130) == 'C' && at(131) == 'M';
  if (preamble) pos = 132;
  const bool meta = bytes.size() >= pos + 6 && w.u16(pos, true) == 0x0002 &&
                    isKnownVr(std::array<char, 3>{at(pos + 4), at(pos + 5), 0}.data());
  if (!meta) {
    // A bare data set (no Part 10 header) starts with a group 0008 element;
    // without a meta header the data set is little endian, explicit VR when
    // its first element carries a VR.
    if (!preamble && (bytes.size() < 8 || w.u16(0, true) != 0x0008))
      return std::variant<FileLayout, NotDicom>(NotDicom{"no 'DICM' at byte 128 and no data set start"});
    layout.syntax.explicitVr =
        bytes.size() >= pos + 6 && isKnownVr(std::array<char, 3>{at(pos + 4), at(pos + 5), 0}.data());
    if (layout.syntax.explicitVr) {
      layout.syntax.uid = UID_LittleEndianExplicitTransferSyntax;
      layout.syntax.xfer = EXS_LittleEndianExplicit;
    }
  }
  if (meta) {
    std::string uid;
    while (pos + 4 <= bytes.size() && w.u16(pos, true) == 0x0002) {
      auto h = w.header(pos, bytes.size(), true, true);
      if (!h) return std::move(h).error();
      if (h->length == kUndefinedLength || h->length > bytes.size() - h->valueStart)
        return w.error("meta header element " + tagText(h->group, h->element) + " declares " +
                           std::to_string(h->length) + " bytes but only " +
                           std::to_string(bytes.size() - h->valueStart) + " remain",
                       pos);
      if (h->element == 0x0010)
        uid = trimmed(std::string(reinterpret_cast<const char*>(bytes.data() + h->valueStart), h->length));
      pos = h->valueStart + h->length;
    }
    if (uid.empty())
      return fail(ErrorCode::Parse, "missing (0002,0010) TransferSyntaxUID in the meta header", source,
                  "the file meta information is incomplete");
    auto s = syntaxOf(uid, source);
    if (!s) return std::move(s).error();
    layout.syntax = *s;
  }
  layout.datasetStart = pos;
  auto end = w.dataset(pos, bytes.size(), layout.syntax.explicitVr, layout.syntax.little, 0, false, &layout);
  if (!end) return std::move(end).error();
  return std::variant<FileLayout, NotDicom>(layout);
}

// ---------------------------------------------------------------------------
// Header fields through DCMTK.

struct SliceHeader {
  std::string file;  ///< for messages
  std::string seriesUid;
  std::string sopClassUid;
  int rows = 0, columns = 0;
  int bitsAllocated = 0, bitsStored = 0, highBit = 0;
  bool isSigned = false;
  std::array<double, 6> iop{};
  Vec3 ipp = Vec3::Zero();  ///< LPS mm
  double rowSpacing = 0, columnSpacing = 0;
  double slope = 1, intercept = 0;
  std::optional<double> spacingBetweenSlices, sliceThickness;
  FileLayout layout;
  std::size_t fileBytes = 0;
};

class HeaderReader {
 public:
  HeaderReader(DcmDataset& ds, std::string source) : ds_(ds), source_(std::move(source)) {}

  Error missing(const DcmTagKey& key) const {
    return fail(ErrorCode::Parse, "missing " + tagLabel(key), source_,
                "the file is not a single-frame image with patient geometry");
  }
  Error bad(const DcmTagKey& key, const std::string& why) const {
    return fail(ErrorCode::Parse, tagLabel(key) + " " + why, source_, "the header is corrupt");
  }

  Result<int> us(const DcmTagKey& key, std::optional<int> fallback = std::nullopt) const {
    Uint16 v = 0;
    if (ds_.findAndGetUint16(key, v).good()) return static_cast<int>(v);
    if (!ds_.tagExists(key) && fallback) return *fallback;
    return ds_.tagExists(key) ? bad(key, "is not a valid US value") : missing(key);
  }

  Result<std::vector<double>> ds(const DcmTagKey& key, std::size_t count, bool required) const {
    std::vector<double> out;
    if (!ds_.tagExists(key)) {
      if (required) return missing(key);
      return out;
    }
    for (std::size_t i = 0; i < count; ++i) {
      Float64 v = 0;
      if (ds_.findAndGetFloat64(key, v, static_cast<unsigned long>(i)).bad())
        return bad(key, "needs " + std::to_string(count) + " numeric values");
      if (!std::isfinite(v)) return bad(key, "value " + std::to_string(i + 1) + " is not finite");
      out.push_back(v);
    }
    return out;
  }

  std::string str(const DcmTagKey& key) const {
    OFString s;
    if (ds_.findAndGetOFStringArray(key, s).bad()) return {};
    return trimmed(s.c_str());
  }

 private:
  DcmDataset& ds_;
  std::string source_;
};

Result<SliceHeader> readHeader(std::span<const std::byte> bytes, const FileLayout& layout,
                               const std::string& source) {
  // Only the validated header part: DCMTK never sees the pixel data or
  // anything after it.
  const std::size_t end = layout.pixelElement == std::string::npos ? bytes.size() : layout.pixelElement;
  DcmInputBufferStream in;
  in.setBuffer(bytes.data() + layout.datasetStart, static_cast<offile_off_t>(end - layout.datasetStart));
  in.setEos();
  DcmDataset dataset;
  dataset.transferInit();
  const OFCondition cond = dataset.read(in, layout.syntax.xfer, EGL_noChange, DCM_MaxReadLength);
  dataset.transferEnd();
  if (cond.bad())
    return fail(ErrorCode::Parse, std::string("DCMTK could not parse the header: ") + cond.text(), source,
                "the file is corrupt");
  if (layout.pixelElement == std::string::npos)
    return fail(ErrorCode::Parse, "missing (7FE0,0010) PixelData", source, "the file holds no image");

  HeaderReader r(dataset, source);
  SliceHeader h;
  h.file = source;
  h.layout = layout;
  h.fileBytes = bytes.size();
  h.seriesUid = r.str(DCM_SeriesInstanceUID);
  h.sopClassUid = r.str(DCM_SOPClassUID);

  if (auto frames = r.str(DCM_NumberOfFrames); !frames.empty() && std::atol(frames.c_str()) > 1)
    return fail(ErrorCode::Unsupported,
                tagLabel(DCM_NumberOfFrames) + " is " + frames + "; multi-frame files are not supported",
                source, "convert to single-frame slices, e.g. with `dcm2niix` or `emf2sf`");
  auto samples = r.us(DCM_SamplesPerPixel, 1);
  if (!samples) return std::move(samples).error();
  if (*samples != 1)
    return fail(
        ErrorCode::Unsupported,
        tagLabel(DCM_SamplesPerPixel) + " is " + std::to_string(*samples) + "; only grey images are read",
        source, "convert colour images to MONOCHROME2 first");
  if (const std::string pi = r.str(DCM_PhotometricInterpretation);
      !pi.empty() && pi != "MONOCHROME1" && pi != "MONOCHROME2")
    return fail(ErrorCode::Unsupported,
                tagLabel(DCM_PhotometricInterpretation) + " is " + pi + "; only MONOCHROME1/2 are read",
                source);

  auto rows = r.us(DCM_Rows);
  if (!rows) return std::move(rows).error();
  auto cols = r.us(DCM_Columns);
  if (!cols) return std::move(cols).error();
  if (*rows == 0) return r.bad(DCM_Rows, "is 0");
  if (*cols == 0) return r.bad(DCM_Columns, "is 0");
  h.rows = *rows;
  h.columns = *cols;
  auto bitsAllocated = r.us(DCM_BitsAllocated);
  if (!bitsAllocated) return std::move(bitsAllocated).error();
  if (*bitsAllocated != 8 && *bitsAllocated != 16 && *bitsAllocated != 32)
    return fail(ErrorCode::Unsupported,
                tagLabel(DCM_BitsAllocated) + " is " + std::to_string(*bitsAllocated) +
                    "; only 8, 16 and 32 are read",
                source);
  h.bitsAllocated = *bitsAllocated;
  auto bitsStored = r.us(DCM_BitsStored, h.bitsAllocated);
  if (!bitsStored) return std::move(bitsStored).error();
  if (*bitsStored < 1 || *bitsStored > h.bitsAllocated)
    return r.bad(DCM_BitsStored, "is " + std::to_string(*bitsStored) + " with BitsAllocated " +
                                     std::to_string(h.bitsAllocated));
  h.bitsStored = *bitsStored;
  auto highBit = r.us(DCM_HighBit, h.bitsStored - 1);
  if (!highBit) return std::move(highBit).error();
  if (*highBit < h.bitsStored - 1 || *highBit >= h.bitsAllocated)
    return r.bad(DCM_HighBit,
                 "is " + std::to_string(*highBit) + " with BitsStored " + std::to_string(h.bitsStored));
  h.highBit = *highBit;
  auto rep = r.us(DCM_PixelRepresentation);
  if (!rep) return std::move(rep).error();
  if (*rep > 1) return r.bad(DCM_PixelRepresentation, "is " + std::to_string(*rep) + " (0 or 1 expected)");
  h.isSigned = *rep == 1;

  auto spacing = r.ds(DCM_PixelSpacing, 2, true);
  if (!spacing) return std::move(spacing).error();
  if ((*spacing)[0] <= 0 || (*spacing)[1] <= 0) return r.bad(DCM_PixelSpacing, "must be positive");
  h.rowSpacing = (*spacing)[0];
  h.columnSpacing = (*spacing)[1];
  auto iop = r.ds(DCM_ImageOrientationPatient, 6, true);
  if (!iop) return std::move(iop).error();
  const Vec3 rc((*iop)[0], (*iop)[1], (*iop)[2]), cc((*iop)[3], (*iop)[4], (*iop)[5]);
  if (std::abs(rc.norm() - 1) > 1e-3 || std::abs(cc.norm() - 1) > 1e-3 || std::abs(rc.dot(cc)) > 1e-3)
    return r.bad(DCM_ImageOrientationPatient, "is not two orthogonal unit vectors");
  // Normalise away the rounding of the decimal strings.
  const Vec3 rn = rc.normalized();
  const Vec3 cn = (cc - rn * rn.dot(cc)).normalized();
  h.iop = {rn.x(), rn.y(), rn.z(), cn.x(), cn.y(), cn.z()};
  auto ipp = r.ds(DCM_ImagePositionPatient, 3, true);
  if (!ipp) return std::move(ipp).error();
  h.ipp = Vec3((*ipp)[0], (*ipp)[1], (*ipp)[2]);

  auto slope = r.ds(DCM_RescaleSlope, 1, false);
  if (!slope) return std::move(slope).error();
  auto intercept = r.ds(DCM_RescaleIntercept, 1, false);
  if (!intercept) return std::move(intercept).error();
  if (!slope->empty()) {
    if ((*slope)[0] == 0) return r.bad(DCM_RescaleSlope, "is 0");
    h.slope = (*slope)[0];
  }
  if (!intercept->empty()) h.intercept = (*intercept)[0];
  auto between = r.ds(DCM_SpacingBetweenSlices, 1, false);
  if (between && !between->empty() && (*between)[0] > 0) h.spacingBetweenSlices = (*between)[0];
  auto thickness = r.ds(DCM_SliceThickness, 1, false);
  if (thickness && !thickness->empty() && (*thickness)[0] > 0) h.sliceThickness = (*thickness)[0];

  const std::uint64_t need =
      std::uint64_t(h.rows) * std::uint64_t(h.columns) * std::uint64_t(h.bitsAllocated / 8);
  if (layout.pixelLength < need)
    return fail(ErrorCode::Parse,
                "(7FE0,0010) PixelData has " + std::to_string(layout.pixelLength) + " bytes but " +
                    std::to_string(h.rows) + " Rows x " + std::to_string(h.columns) + " Columns x " +
                    std::to_string(h.bitsAllocated / 8) + " bytes need " + std::to_string(need),
                source, "the file is truncated or (0028,0010) Rows / (0028,0011) Columns are wrong");
  return h;
}

Result<SliceHeader> parseSliceBytes(std::span<const std::byte> bytes, const std::string& source) {
  auto walked = walkFile(bytes, source);
  if (!walked) return std::move(walked).error();
  if (const auto* nd = std::get_if<NotDicom>(&*walked))
    return fail(ErrorCode::Parse, "not a DICOM file: " + nd->reason, source);
  return readHeader(bytes, std::get<FileLayout>(*walked), source);
}

Vec3 normalOf(const SliceHeader& h) {
  return Vec3(h.iop[0], h.iop[1], h.iop[2]).cross(Vec3(h.iop[3], h.iop[4], h.iop[5]));
}

// LPS mm columns (i, j, k steps) and origin to the SDK's RAS metres.
Affine3 lpsMmToRasM(const Vec3& stepI, const Vec3& stepJ, const Vec3& stepK, const Vec3& origin) {
  const Vec3 flip(-1e-3, -1e-3, 1e-3);
  Affine3 a = Affine3::Identity();
  a.linear().col(0) = flip.cwiseProduct(stepI);
  a.linear().col(1) = flip.cwiseProduct(stepJ);
  a.linear().col(2) = flip.cwiseProduct(stepK);
  a.translation() = flip.cwiseProduct(origin);
  return a;
}

Affine3 sliceAffine(const SliceHeader& h, const Vec3& stepK) {
  const Vec3 r(h.iop[0], h.iop[1], h.iop[2]), c(h.iop[3], h.iop[4], h.iop[5]);
  return lpsMmToRasM(r * h.columnSpacing, c * h.rowSpacing, stepK, h.ipp);
}

RawElement elementOf(const SliceHeader& h) {
  switch (h.bitsAllocated) {
    case 8:
      return h.isSigned ? RawElement::I8 : RawElement::U8;
    case 16:
      return h.isSigned ? RawElement::I16 : RawElement::U16;
    default:
      return h.isSigned ? RawElement::I32 : RawElement::U32;
  }
}

// Decodes one slice's voxels (nx×ny×1) from the file bytes scanned into `h`,
// masking BitsStored and applying the rescale.
Result<Volume> decodeSlice(std::span<const std::byte> bytes, const SliceHeader& h, const Vec3& stepK,
                           std::size_t maxBytes) {
  const std::size_t cells = std::size_t(h.rows) * std::size_t(h.columns);
  const std::size_t cellBytes = std::size_t(h.bitsAllocated / 8);
  std::span<const std::byte> raw = bytes.subspan(h.layout.pixelValue, cells * cellBytes);
  std::vector<std::byte> fixed;
  const bool little = h.layout.syntax.little;
  const bool swapPairs = !little && h.layout.pixelIsOw && h.bitsAllocated == 8;
  const bool mask = h.bitsStored < h.bitsAllocated;
  if (swapPairs || mask) {
    if (cells * cellBytes > maxBytes)
      return detail::volumeOverBudget("the slice of " + std::to_string(h.columns) + "x" +
                                          std::to_string(h.rows) + " voxels of " + std::to_string(cellBytes) +
                                          " bytes",
                                      cells * cellBytes, maxBytes, h.file, "DicomReadOptions::maxBytes");
    fixed.assign(raw.begin(), raw.end());
    if (swapPairs)  // 8-bit OW data in big endian is stored as swapped 16-bit words
      for (std::size_t i = 0; i + 1 < fixed.size(); i += 2) std::swap(fixed[i], fixed[i + 1]);
    if (mask) {
      const int shift = h.highBit + 1 - h.bitsStored;
      const std::uint32_t bits = (h.bitsStored >= 32) ? 0xFFFFFFFFu : ((1u << h.bitsStored) - 1u);
      for (std::size_t i = 0; i < cells; ++i) {
        std::byte* p = fixed.data() + i * cellBytes;
        std::uint32_t v = 0;
        for (std::size_t b = 0; b < cellBytes; ++b) {
          const std::size_t at = little ? cellBytes - 1 - b : b;
          v = (v << 8) | static_cast<std::uint32_t>(p[at]);
        }
        v = (v >> shift) & bits;
        if (h.isSigned && (v >> (h.bitsStored - 1)) & 1u) v |= ~bits;  // sign-extend
        for (std::size_t b = 0; b < cellBytes; ++b) {
          const std::size_t at = little ? b : cellBytes - 1 - b;
          p[at] = static_cast<std::byte>((v >> (8 * b)) & 0xFFu);
        }
      }
    }
    raw = fixed;
  }
  RawVoxelFormat format;
  format.element = elementOf(h);
  format.byteOrder = little ? std::endian::little : std::endian::big;
  format.slope = h.slope;
  format.intercept = h.intercept;
  return decodeRawVolume(raw, {h.columns, h.rows, 1}, format, sliceAffine(h, stepK), h.file, maxBytes);
}

Vec3 singleSliceStep(const SliceHeader& h) {
  const double d = h.spacingBetweenSlices ? *h.spacingBetweenSlices
                   : h.sliceThickness     ? *h.sliceThickness
                                          : 1.0;
  return normalOf(h) * d;
}

bool identityRescale(const SliceHeader& h) { return h.slope == 1.0 && h.intercept == 0.0; }

std::string mmText(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.6g mm", v);
  return b;
}

// Checks that `h` agrees with the first slice `f` in everything that must be
// shared by a volume.
Status checkConsistent(const SliceHeader& f, const SliceHeader& h) {
  const auto differ = [&](const DcmTagKey& key, const std::string& a, const std::string& b) {
    return fail(ErrorCode::Parse, tagLabel(key) + " is " + b + " but " + a + " in " + f.file, h.file,
                "the files do not form one volume; pick one series or remove the odd file");
  };
  if (h.rows != f.rows) return differ(DCM_Rows, std::to_string(f.rows), std::to_string(h.rows));
  if (h.columns != f.columns)
    return differ(DCM_Columns, std::to_string(f.columns), std::to_string(h.columns));
  if (h.bitsAllocated != f.bitsAllocated)
    return differ(DCM_BitsAllocated, std::to_string(f.bitsAllocated), std::to_string(h.bitsAllocated));
  if (h.isSigned != f.isSigned)
    return differ(DCM_PixelRepresentation, f.isSigned ? "1" : "0", h.isSigned ? "1" : "0");
  for (int i = 0; i < 6; ++i)
    if (std::abs(h.iop[i] - f.iop[i]) > 1e-4)
      return differ(DCM_ImageOrientationPatient, "different", "different");
  const auto close = [](double a, double b) { return std::abs(a - b) <= 1e-4 * std::max(1.0, std::abs(a)); };
  if (!close(h.rowSpacing, f.rowSpacing) || !close(h.columnSpacing, f.columnSpacing))
    return differ(DCM_PixelSpacing, mmText(f.rowSpacing) + "\\" + mmText(f.columnSpacing),
                  mmText(h.rowSpacing) + "\\" + mmText(h.columnSpacing));
  return ok();
}

Result<Volume> assemble(std::vector<SliceHeader> slices, const DicomReadOptions& options) {
  DM_ASSERT(!slices.empty(), "assemble() needs a slice");
  for (std::size_t i = 1; i < slices.size(); ++i)
    if (auto s = checkConsistent(slices[0], slices[i]); !s) return std::move(s).error();
  const Vec3 n = normalOf(slices[0]);
  std::vector<double> proj(slices.size());
  std::vector<std::size_t> order(slices.size());
  for (std::size_t i = 0; i < slices.size(); ++i) {
    proj[i] = slices[i].ipp.dot(n);
    order[i] = i;
  }
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return proj[a] < proj[b]; });
  const std::size_t nz = slices.size();
  Vec3 stepK = singleSliceStep(slices[order[0]]);
  if (nz > 1) {
    // Gaps are compared with the median gap, so the odd one out is named.
    std::vector<double> gaps(nz - 1);
    for (std::size_t k = 0; k + 1 < nz; ++k) gaps[k] = proj[order[k + 1]] - proj[order[k]];
    std::vector<double> sortedGaps = gaps;
    std::nth_element(sortedGaps.begin(), sortedGaps.begin() + sortedGaps.size() / 2, sortedGaps.end());
    const double typical = sortedGaps[sortedGaps.size() / 2];
    const double tol = std::max(0.01, 0.01 * typical);
    for (std::size_t k = 0; k + 1 < nz; ++k) {
      const SliceHeader& a = slices[order[k]];
      const SliceHeader& b = slices[order[k + 1]];
      if (gaps[k] <= 1e-3)
        return fail(ErrorCode::Parse,
                    "duplicate slice position: (0020,0032) ImagePositionPatient of " + a.file + " and " +
                        b.file + " lie " + mmText(gaps[k]) + " apart along the slice normal",
                    b.file, "the directory holds several volumes of one series (echoes, phases); split them");
      if (std::abs(gaps[k] - typical) > tol)
        return fail(ErrorCode::Parse,
                    "non-uniform slice spacing: (0020,0032) ImagePositionPatient of " + a.file + " and " +
                        b.file + " are " + mmText(gaps[k]) + " apart but the median gap is " +
                        mmText(typical),
                    b.file, "a slice is missing or the series mixes acquisitions");
    }
    stepK = (slices[order.back()].ipp - slices[order.front()].ipp) / double(nz - 1);
    for (std::size_t k = 0; k < nz; ++k) {
      const SliceHeader& s = slices[order[k]];
      const double off = (s.ipp - (slices[order[0]].ipp + double(k) * stepK)).norm();
      if (off > tol)
        return fail(ErrorCode::Parse,
                    "(0020,0032) ImagePositionPatient is " + mmText(off) + " off the line through " +
                        slices[order[0]].file + " and " + slices[order.back()].file,
                    s.file, "the slices are not stacked along one straight line");
    }
  }

  const SliceHeader& first = slices[order[0]];
  bool anyScaled = false;
  for (const auto& s : slices) anyScaled = anyScaled || !identityRescale(s);
  VoxelType outType;
  switch (elementOf(first)) {
    case RawElement::U8:
      outType = VoxelType::U8;
      break;
    case RawElement::I8:
      outType = VoxelType::I8;
      break;
    case RawElement::U16:
      outType = VoxelType::U16;
      break;
    case RawElement::I16:
      outType = VoxelType::I16;
      break;
    case RawElement::U32:
      outType = VoxelType::U32;
      break;
    default:
      outType = VoxelType::I32;
      break;
  }
  if (anyScaled) outType = first.bitsAllocated <= 16 ? VoxelType::F32 : VoxelType::F64;
  const Vec3i dims(first.columns, first.rows, static_cast<int>(nz));
  const std::size_t sliceVoxels = std::size_t(first.columns) * std::size_t(first.rows);
  const std::size_t vb = voxelBytes(outType);
  if (nz > options.maxBytes / vb / sliceVoxels)
    return detail::volumeOverBudget(
        "the volume " + std::to_string(dims.x()) + "x" + std::to_string(dims.y()) + "x" +
            std::to_string(dims.z()) + " of " + toString(outType),
        std::uint64_t(nz) * vb * sliceVoxels, options.maxBytes, first.file, "DicomReadOptions::maxBytes");
  const Affine3 affine = sliceAffine(first, stepK);
  auto volume = Volume::create(dims, outType, affine, options.maxBytes);
  if (!volume) {
    Error e = std::move(volume).error();
    e.where = first.file;
    return e;
  }
  for (std::size_t k = 0; k < nz; ++k) {
    const SliceHeader& s = slices[order[k]];
    auto bytes = readFile(s.file, options.maxFileBytes);
    if (!bytes) return std::move(bytes).error();
    if (bytes->size() != s.fileBytes)
      return fail(ErrorCode::Io, "the file changed while the series was read", s.file, "read it again");
    auto slice = decodeSlice(*bytes, s, stepK, options.maxBytes);
    if (!slice) return std::move(slice).error();
    const std::size_t base = k * sliceVoxels;
    if (slice->type() == outType) {
      std::memcpy(volume->bytes() + base * vb, slice->bytes(), sliceVoxels * vb);
    } else {  // an unscaled slice among scaled ones: widen (exact for <= 32 bits)
      for (std::size_t i = 0; i < sliceVoxels; ++i) volume->setValueAt(base + i, slice->valueAt(i));
    }
  }
  return volume;
}

// ---------------------------------------------------------------------------
// Writing.

// The shortest decimal string of at most 16 characters (DS's limit).
std::string dsText(double v) {
  if (v == 0) return "0";
  char b[40];
  for (int p = 17; p >= 1; --p) {
    std::snprintf(b, sizeof b, "%.*g", p, v);
    if (std::strlen(b) <= 16) return b;
  }
  return "0";
}

std::string dsList(std::initializer_list<double> values) {
  std::string s;
  for (double v : values) {
    if (!s.empty()) s += '\\';
    s += dsText(v);
  }
  return s;
}

std::string newUid(const char* root) {
  char uid[100];
  dcmGenerateUniqueIdentifier(uid, root);
  return uid;
}

Error ioError(const std::string& what, const std::filesystem::path& p, const std::error_code& ec) {
  return fail(ErrorCode::Io, what + ": " + ec.message(), p.string(), "check the path and permissions");
}

}  // namespace

Result<Volume> parseDicomSlice(std::span<const std::byte> bytes, std::string_view sourceName,
                               const DicomReadOptions& options) {
  const std::string source(sourceName);
  try {
    auto h = parseSliceBytes(bytes, source);
    if (!h) return std::move(h).error();
    return decodeSlice(bytes, *h, singleSliceStep(*h), options.maxBytes);
  } catch (const std::exception& e) {
    return fail(ErrorCode::Internal, std::string("DCMTK threw: ") + e.what(), source);
  }
}

Result<Volume> readDicomSeries(const std::filesystem::path& dirOrFile, const DicomReadOptions& options) {
  try {
    std::error_code ec;
    const bool isDir = std::filesystem::is_directory(dirOrFile, ec);
    if (!isDir && !std::filesystem::is_regular_file(dirOrFile, ec))
      return fail(ErrorCode::NotFound, "no such file or directory", dirOrFile.string(),
                  "give a directory of DICOM files or one of its files");
    const std::filesystem::path dir = isDir                             ? dirOrFile
                                      : dirOrFile.parent_path().empty() ? "."
                                                                        : dirOrFile.parent_path();
    std::string wanted = options.seriesUid;
    if (!isDir) {
      auto bytes = readFile(dirOrFile, options.maxFileBytes);
      if (!bytes) return std::move(bytes).error();
      auto h = parseSliceBytes(*bytes, dirOrFile.string());
      if (!h) return std::move(h).error();
      if (!wanted.empty() && wanted != h->seriesUid)
        return fail(ErrorCode::InvalidArgument,
                    "the file belongs to series " + h->seriesUid + ", not the requested " + wanted,
                    dirOrFile.string(), "pass the directory instead, or clear DicomReadOptions::seriesUid");
      wanted = h->seriesUid;
    }

    // The folder is the caller's choice; a symlink in it is someone else's,
    // so it must not lead out of the folder or the allowed roots.
    std::vector<std::filesystem::path> files;
    for (std::filesystem::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
      std::error_code fec;
      if (!it->is_regular_file(fec)) continue;
      if (it->is_symlink(fec)) {
        const std::string name = it->path().filename().string();
        auto real = FileSystem::global().confine(dir, name, "file \"" + shownText(name) + "\" of the series folder " +
                                                                 dir.string());
        if (!real) return std::move(real).error();
      }
      files.push_back(it->path());
    }
    if (ec) return ioError("cannot list the directory", dir, ec);
    std::sort(files.begin(), files.end());

    std::map<std::string, std::vector<SliceHeader>> series;
    for (const auto& file : files) {
      auto bytes = readFile(file, options.maxFileBytes);
      if (!bytes) return std::move(bytes).error();
      auto walked = walkFile(*bytes, file.string());
      if (!walked) return std::move(walked).error();
      if (const auto* nd = std::get_if<NotDicom>(&*walked)) {
        log::debug("DICOM: skipping %s (%s)", file.string().c_str(), nd->reason.c_str());
        continue;
      }
      const FileLayout& layout = std::get<FileLayout>(*walked);
      if (layout.pixelElement == std::string::npos) {
        log::debug("DICOM: skipping %s (no pixel data, e.g. DICOMDIR or a report)", file.string().c_str());
        continue;
      }
      auto h = readHeader(*bytes, layout, file.string());
      if (!h) return std::move(h).error();
      series[h->seriesUid].push_back(std::move(*h));
    }
    if (series.empty())
      return fail(ErrorCode::NotFound, "no DICOM image files in the directory", dir.string(),
                  "non-DICOM files are skipped; point at the folder that holds the .dcm slices");
    std::string listing;
    for (const auto& [uid, s] : series)
      listing += (listing.empty() ? "" : ", ") + (uid.empty() ? std::string("<no SeriesInstanceUID>") : uid) +
                 " (" + std::to_string(s.size()) + " slices)";
    if (wanted.empty() && series.size() > 1)
      return fail(ErrorCode::InvalidArgument,
                  "the directory holds " + std::to_string(series.size()) + " series", dir.string(),
                  "set DicomReadOptions::seriesUid to one of: " + listing);
    auto chosen = wanted.empty() ? series.begin() : series.find(wanted);
    if (chosen == series.end())
      return fail(ErrorCode::NotFound, "no slices of series " + wanted, dir.string(),
                  "the directory holds: " + listing);
    return assemble(std::move(chosen->second), options);
  } catch (const std::exception& e) {
    return fail(ErrorCode::Internal, std::string("exception while reading DICOM: ") + e.what(),
                dirOrFile.string());
  }
}

Status writeDicomSeries(const Volume& volume, const std::filesystem::path& dir,
                        const DicomWriteOptions& options) {
  const std::string where = dir.string();
  if (volume.empty()) return fail(ErrorCode::InvalidArgument, "the volume is empty", where);
  const Vec3i dims = volume.dims();
  if (dims.x() > 65535 || dims.y() > 65535)
    return fail(ErrorCode::InvalidArgument,
                "slices larger than 65535 x 65535 do not fit (0028,0010) Rows / (0028,0011) Columns", where);
  // RAS metres to LPS millimetres.
  const Vec3 toLps(-1e3, -1e3, 1e3);
  const Affine3& a = volume.indexToWorld();
  const Vec3 stepI = toLps.cwiseProduct(a.linear().col(0));
  const Vec3 stepJ = toLps.cwiseProduct(a.linear().col(1));
  const Vec3 stepK = toLps.cwiseProduct(a.linear().col(2));
  const Vec3 origin = toLps.cwiseProduct(a.translation());
  const Vec3 r = stepI.normalized(), c = stepJ.normalized();
  if (std::abs(r.dot(c)) > 1e-9)
    return fail(ErrorCode::Unsupported, "the volume's i and j axes are not perpendicular (sheared slices)",
                where, "DICOM's ImageOrientationPatient needs orthogonal rows and columns; resample first");

  // Stored values: unchanged for uint8/uint16/int16, else int16 with rescale.
  struct Encoding {
    int bits = 16;
    bool isSigned = true;
    double slope = 1, intercept = 0;
    bool direct = true;
  } enc;
  const VoxelType t = volume.type();
  if (t == VoxelType::U8) {
    enc.bits = 8;
    enc.isSigned = false;
  } else if (t == VoxelType::U16) {
    enc.isSigned = false;
  } else if (t != VoxelType::I16) {
    enc.direct = false;
    auto [lo, hi] = volume.range();
    if (!std::isfinite(lo) || !std::isfinite(hi))
      return fail(ErrorCode::InvalidArgument, "the volume has non-finite values", where,
                  "replace NaN/Inf first");
    bool integral = lo >= -32768 && hi <= 32767;
    for (std::size_t i = 0; integral && i < volume.voxelCount(); ++i) {
      const double v = volume.valueAt(i);
      integral = std::isfinite(v) && v == std::floor(v);
    }
    for (std::size_t i = 0; !integral && i < volume.voxelCount(); ++i)
      if (!std::isfinite(volume.valueAt(i)))
        return fail(ErrorCode::InvalidArgument, "the volume has non-finite values", where,
                    "replace NaN/Inf first");
    if (!integral) {
      // The strings written are what a reader sees: quantise with them.
      enc.slope = hi > lo ? std::strtod(dsText((hi - lo) / 65535.0).c_str(), nullptr) : 1.0;
      enc.intercept = std::strtod(dsText(lo + 32768.0 * enc.slope).c_str(), nullptr);
      if (!(enc.slope > 0)) enc.slope = 1.0;
    }
  }

  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return ioError("cannot create the directory", dir, ec);
  const bool empty = std::filesystem::is_empty(dir, ec);
  if (ec) return ioError("cannot list the directory", dir, ec);
  if (!empty) {
    if (!options.overwrite)
      return fail(ErrorCode::InvalidArgument, "the directory is not empty", where,
                  "choose an empty directory or set DicomWriteOptions::overwrite");
    for (std::filesystem::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
      const std::string name = it->path().filename().string();
      if (name.rfind("slice_", 0) == 0 && it->path().extension() == ".dcm") {
        std::error_code rec;
        std::filesystem::remove(it->path(), rec);
      }
    }
  }
  if (ec) return ioError("cannot list the directory", dir, ec);

  initDcmtk();
  const std::string study = options.studyUid.empty() ? newUid(SITE_STUDY_UID_ROOT) : options.studyUid;
  const std::string seriesUid = options.seriesUid.empty() ? newUid(SITE_SERIES_UID_ROOT) : options.seriesUid;
  const std::string frame = newUid(SITE_UID_ROOT ".1.5");
  const char* sopClass = options.modality == "CT"   ? UID_CTImageStorage
                         : options.modality == "MR" ? UID_MRImageStorage
                                                    : UID_SecondaryCaptureImageStorage;
  const std::size_t sliceVoxels = std::size_t(dims.x()) * std::size_t(dims.y());
  std::vector<Uint16> words(enc.bits == 16 ? sliceVoxels : 0);
  try {
    for (int k = 0; k < dims.z(); ++k) {
      DcmFileFormat file;
      DcmDataset* ds = file.getDataset();
      const Vec3 ipp = origin + double(k) * stepK;
      const double thickness = stepK.norm();
      OFCondition cond = EC_Normal;
      const auto put = [&](const DcmTagKey& key, const std::string& v) {
        if (cond.good()) cond = ds->putAndInsertString(key, v.c_str());
      };
      const auto putUs = [&](const DcmTagKey& key, int v) {
        if (cond.good()) cond = ds->putAndInsertUint16(key, static_cast<Uint16>(v));
      };
      put(DCM_SOPClassUID, sopClass);
      put(DCM_SOPInstanceUID, newUid(SITE_INSTANCE_UID_ROOT));
      put(DCM_StudyInstanceUID, study);
      put(DCM_SeriesInstanceUID, seriesUid);
      put(DCM_FrameOfReferenceUID, frame);
      put(DCM_Modality, options.modality);
      put(DCM_ConversionType, "WSD");
      put(DCM_SeriesDescription, options.seriesDescription);
      put(DCM_PatientName, options.patientName);
      put(DCM_PatientID, options.patientId);
      put(DCM_SeriesNumber, "1");
      put(DCM_InstanceNumber, std::to_string(k + 1));
      put(DCM_ImagePositionPatient, dsList({ipp.x(), ipp.y(), ipp.z()}));
      put(DCM_ImageOrientationPatient, dsList({r.x(), r.y(), r.z(), c.x(), c.y(), c.z()}));
      put(DCM_PixelSpacing, dsList({stepJ.norm(), stepI.norm()}));  // row spacing \ column spacing
      put(DCM_SliceThickness, dsText(thickness));
      put(DCM_SpacingBetweenSlices, dsText(thickness));
      put(DCM_RescaleSlope, dsText(enc.slope));
      put(DCM_RescaleIntercept, dsText(enc.intercept));
      put(DCM_PhotometricInterpretation, "MONOCHROME2");
      putUs(DCM_SamplesPerPixel, 1);
      putUs(DCM_Rows, dims.y());
      putUs(DCM_Columns, dims.x());
      putUs(DCM_BitsAllocated, enc.bits);
      putUs(DCM_BitsStored, enc.bits);
      putUs(DCM_HighBit, enc.bits - 1);
      putUs(DCM_PixelRepresentation, enc.isSigned ? 1 : 0);
      const std::size_t base = std::size_t(k) * sliceVoxels;
      if (cond.good()) {
        if (enc.bits == 8) {
          cond =
              ds->putAndInsertUint8Array(DCM_PixelData, reinterpret_cast<const Uint8*>(volume.bytes()) + base,
                                         static_cast<unsigned long>(sliceVoxels));
        } else {
          if (enc.direct) {
            std::memcpy(words.data(), volume.bytes() + base * 2, sliceVoxels * 2);
          } else {
            for (std::size_t i = 0; i < sliceVoxels; ++i) {
              const double q = std::round((volume.valueAt(base + i) - enc.intercept) / enc.slope);
              const auto s = static_cast<std::int16_t>(std::clamp(q, -32768.0, 32767.0));
              std::memcpy(&words[i], &s, 2);
            }
          }
          cond = ds->putAndInsertUint16Array(DCM_PixelData, words.data(),
                                             static_cast<unsigned long>(sliceVoxels));
        }
      }
      char name[32];
      std::snprintf(name, sizeof name, kSliceNameFormat, k);
      const std::filesystem::path target = dir / name;
      if (cond.bad())
        return fail(ErrorCode::Internal, std::string("DCMTK could not build the data set: ") + cond.text(),
                    target.string());
      const std::filesystem::path temp = dir / ("." + std::string(name) + ".tmp");
      cond = file.saveFile(temp.string().c_str(), EXS_LittleEndianExplicit);
      if (cond.bad()) {
        std::filesystem::remove(temp, ec);
        return fail(ErrorCode::Io, std::string("cannot write: ") + cond.text(), temp.string(),
                    "check free space and permissions");
      }
      std::filesystem::rename(temp, target, ec);
      if (ec) {
        std::error_code rec;
        std::filesystem::remove(temp, rec);
        return ioError("cannot rename the temporary file into place", target, ec);
      }
    }
  } catch (const std::exception& e) {
    return fail(ErrorCode::Internal, std::string("exception while writing DICOM: ") + e.what(), where);
  }
  return ok();
}

}  // namespace dm
