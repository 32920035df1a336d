// dm/network/igtl.hpp — the OpenIGTLink wire format (header versions 1-3),
// mapped to the shared data model.
//
// Every OpenIGTLink message is a 58-byte big-endian header (version u16, type
// char[12], device name char[20], timestamp u64 as seconds.fraction 32.32,
// body size u64, CRC-64/ECMA-182 of the body) followed by the body. From
// header version 2 on, the body starts with a 12-byte extended header
// (extended header size, metadata header size, metadata size, message id)
// and ends with the metadata (a count, per entry key size / value encoding /
// value size, then keys and values); version 3 has the same layout. The
// type-specific "content" sits between. See docs/network.md for what this
// codec accepts and refuses.
//
// Units: OpenIGTLink lengths are millimetres; this codec converts to and from
// the SDK's metres (TRANSFORM/POSITION translations, IMAGE spacing and
// origin, POINT position and radius, POLYDATA points). Frames: OpenIGTLink
// RAS is taken as the world frame (as NIfTI's); LPS images are converted.
//
// Decoding never trusts the buffer: every count and size is checked against
// the bytes present and the limits before anything is allocated; errors
// name the message type, the field and its byte offset from the start of the
// message. The library does not link the reference implementation.
//
// @code
//   auto bytes = dm::igtl::encodeTransform({.deviceName = "Tracker"}, pose.isometry());
//   auto msg = dm::igtl::decodeMessage(*bytes);
//   auto iso = dm::igtl::decodeTransform(*msg);   // metres
// @endcode
#pragma once

#include <dm/core/image.hpp>
#include <dm/core/mesh.hpp>
#include <dm/core/pose.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/core/volume.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace dm::igtl {

inline constexpr std::size_t kHeaderBytes = 58;          ///< fixed header, every version
inline constexpr std::size_t kExtendedHeaderBytes = 12;  ///< extended header, versions 2 and 3
inline constexpr std::size_t kTypeNameBytes = 12;        ///< longest message type name
inline constexpr std::size_t kDeviceNameBytes = 20;      ///< longest device name
inline constexpr std::uint16_t kEncodingUsAscii = 3;     ///< IANA MIBenum of US-ASCII
inline constexpr std::uint16_t kEncodingUtf8 = 106;      ///< IANA MIBenum of UTF-8

/// Header timestamp (upper 32 bits seconds, lower 32 bits fraction of 2^-32 s)
/// from nanoseconds; rounded to the nearest fraction. Negative times give 0.
std::uint64_t timestampFromNanos(std::int64_t ns) noexcept;
/// Nanoseconds from a header timestamp (rounded to the nearest ns).
std::int64_t timestampToNanos(std::uint64_t stamp) noexcept;

/// The fixed 58-byte header, decoded.
struct Header {
  std::uint16_t version = 1;
  std::string type;        ///< up to 12 characters, e.g. "TRANSFORM", "GET_IMAGE"
  std::string deviceName;  ///< up to 20 characters
  std::uint64_t timestamp = 0;
  std::uint64_t bodySize = 0;
  std::uint64_t crc = 0;
};

/// One metadata entry (header version ≥ 2).
struct MetadataEntry {
  std::string key;                            ///< at most 65535 bytes
  std::uint16_t encoding = kEncodingUsAscii;  ///< IANA MIBenum of `value`
  std::string value;                          ///< at most 2^32 - 1 bytes
  bool operator==(const MetadataEntry&) const = default;
};

/// What every encoder needs besides the content.
struct Envelope {
  std::uint16_t version = 1;  ///< 1 (no extended header), 2 or 3
  std::string deviceName;     ///< at most 20 characters
  std::uint64_t timestamp = 0;
  std::uint32_t messageId = 0;          ///< version ≥ 2 only
  std::vector<MetadataEntry> metadata;  ///< version ≥ 2 only
};

/// Limits and checks applied when decoding.
struct DecodeOptions {
  /// Verify the header's CRC-64 over the body. The reference library checks
  /// only when asked (Unpack(1)) and has no exemption for a zero CRC; we
  /// check by default and likewise never exempt 0.
  bool verifyCrc = true;
  std::size_t maxBodyBytes = std::size_t{256} << 20;  ///< 256 MiB
};

/// A decoded message; `content` views the caller's buffer.
struct MessageView {
  Header header;
  std::uint32_t messageId = 0;               ///< version ≥ 2
  std::vector<MetadataEntry> metadata;       ///< version ≥ 2
  std::span<const std::byte> content;        ///< the body without extended header and metadata
  std::size_t contentOffset = kHeaderBytes;  ///< byte offset of content in the message
};

/// Decodes the 58-byte header alone (for a stream reader that then waits for
/// bodySize bytes). Fails on fewer than 58 bytes, a version other than 1-3,
/// or bodySize over options.maxBodyBytes. O(1).
Result<Header> decodeHeader(std::span<const std::byte> bytes, const DecodeOptions& options = {});

/// Decodes one whole message (header + body, extra bytes refused): header,
/// body size, CRC, extended header and metadata. O(n).
/// @code
///   auto m = dm::igtl::decodeMessage(bytes);
///   if (!m) return m.error();
///   if (m->header.type == "TRANSFORM") use(dm::igtl::decodeTransform(*m));
/// @endcode
Result<MessageView> decodeMessage(std::span<const std::byte> bytes, const DecodeOptions& options = {});

/// Builds a message of any type from its content bytes (adds the extended
/// header and metadata for version ≥ 2, computes the CRC). Fails on a type
/// name over 12 or device name over 20 characters, version outside 1-3, or
/// oversized metadata. Used by all typed encoders below.
Result<std::vector<std::byte>> encodeRaw(const Envelope& env, std::string_view type,
                                         std::span<const std::byte> content);
/// Same, appended to `out` (a buffer reused from message to message:
/// no allocation once its capacity suffices). On failure `out` is unchanged.
Status appendRaw(const Envelope& env, std::string_view type, std::span<const std::byte> content,
                 std::vector<std::byte>& out);

// ---- TRANSFORM -----------------------------------------------------------

/// TRANSFORM content (48 bytes: the 3×3 upper-left as columns, then the
/// translation; float32) as a general affine, translation in metres.
Result<Affine3> decodeTransformAffine(const MessageView& m);
/// TRANSFORM as a rigid transform; fails with Parse when the 3×3 part is not
/// a rotation within 1e-4 (scaled or sheared transforms: use the affine form).
/// @code
///   auto iso = dm::igtl::decodeTransform(*msg);
///   if (iso) tool.setPose(dm::Pose(*iso));
/// @endcode
Result<Isometry3> decodeTransform(const MessageView& m);
/// TRANSFORM message from an affine (translation in metres → mm on the wire).
/// @code
///   auto bytes = dm::igtl::encodeTransform({.deviceName = "Probe"}, pose.isometry());
///   if (bytes) socket.send(*bytes);
/// @endcode
Result<std::vector<std::byte>> encodeTransform(const Envelope& env, const Affine3& transform);
/// TRANSFORM message from a rigid transform (translation in metres).
Result<std::vector<std::byte>> encodeTransform(const Envelope& env, const Isometry3& transform);
/// TRANSFORM message appended to `out` (see appendRaw): the form for
/// streaming a tracked tool at a high rate through one reused buffer.
/// @code
///   buffer.clear();
///   if (dm::igtl::appendTransform({.deviceName = "Probe"}, tool.matrix(), buffer))
///   (void)client->send(buffer);
/// @endcode
Status appendTransform(const Envelope& env, const Affine3& transform, std::vector<std::byte>& out);

// ---- POSITION ------------------------------------------------------------

/// POSITION content: position (mm → m) and quaternion (x, y, z, w). Accepts
/// the 12-byte (position only: identity rotation), 24-byte (x, y, z; w
/// recovered ≥ 0) and 28-byte forms. The quaternion is normalised; a zero
/// or non-finite one fails.
Result<Pose> decodePosition(const MessageView& m);
/// POSITION message, 28-byte form.
/// @code
///   auto bytes = dm::igtl::encodePosition({.deviceName = "Needle"}, pose);
/// @endcode
Result<std::vector<std::byte>> encodePosition(const Envelope& env, const Pose& pose);

// ---- IMAGE ---------------------------------------------------------------

/// Default bound on the decoded size of a whole image or volume: 256 MiB.
inline constexpr std::size_t kDefaultMaxImageBytes = std::size_t{256} << 20;

/// The IMAGE header fields that the data model does not carry.
struct ImageInfo {
  int components = 1;  ///< per voxel
  std::uint8_t scalarType =
      3;  ///< OpenIGTLink code: 2 int8, 3 uint8, 4/5 int16/uint16, 6/7 int32/uint32, 10 float32, 11 float64
  bool bigEndian = false;      ///< byte order of the data on the wire
  bool lps = false;            ///< coordinate system on the wire (false: RAS)
  Vec3i size = Vec3i::Zero();  ///< whole image
  Vec3i subOffset = Vec3i::Zero();
  Vec3i subSize = Vec3i::Zero();  ///< the part carried by this message
};

/// IMAGE header fields, checked (sizes, scalar type, that the data fits the body).
Result<ImageInfo> decodeImageInfo(const MessageView& m);
/// IMAGE with one component as a Volume: the data converted to host order,
/// the matrix (columns = axis × spacing, origin = volume centre at index
/// (size − 1) / 2, mm) turned into the index-to-world affine in metres (LPS
/// flipped to RAS). A sub-volume is placed into a zero-filled whole volume,
/// so the whole volume (not only the bytes carried) must fit in `maxBytes`;
/// a larger one fails before anything is allocated.
/// @code
///   auto vol = dm::igtl::decodeVolume(*msg);
///   if (vol) renderer.show(*vol);
/// @endcode
Result<Volume> decodeVolume(const MessageView& m, std::size_t maxBytes = kDefaultMaxImageBytes);
/// IMAGE with size z = 1 as a 2-D Image: 1-4 components of uint8, uint16 or
/// float32 (the pixel types of dm::Image); other scalar types fail with
/// Unsupported. Geometry is dropped; use decodeVolume() to keep it. The
/// whole image must fit in `maxBytes`.
Result<Image> decodeImage(const MessageView& m, std::size_t maxBytes = kDefaultMaxImageBytes);
/// IMAGE message from a Volume (any voxel type; dims ≤ 65535; little-endian
/// data, RAS, 1 component, whole volume).
/// @code
///   auto bytes = dm::igtl::encodeVolume({.deviceName = "CT"}, volume);
/// @endcode
Result<std::vector<std::byte>> encodeVolume(const Envelope& env, const Volume& volume);
/// IMAGE message from a 2-D Image (size z = 1, identity orientation,
/// `spacing` in metres per pixel, image centre at the origin).
Result<std::vector<std::byte>> encodeImage(const Envelope& env, const Image& image, double spacing = 1e-3);

// ---- STATUS, STRING, COMMAND -----------------------------------------------

/// STATUS content.
struct StatusInfo {
  std::uint16_t code = 1;  ///< 1 OK, 2 unknown error, 3 panic, 4 not found, ... (spec list)
  std::int64_t subcode = 0;
  std::string errorName;  ///< at most 20 characters
  std::string message;    ///< any length, no NUL inside
  bool operator==(const StatusInfo&) const = default;
};
/// STATUS content: 30 fixed bytes, then the message up to its NUL (or the body end).
Result<StatusInfo> decodeStatus(const MessageView& m);
/// STATUS message (message sent NUL-terminated; fails on a NUL inside or an error name over 20).
Result<std::vector<std::byte>> encodeStatus(const Envelope& env, const StatusInfo& s);

/// STRING content.
struct StringInfo {
  std::uint16_t encoding = kEncodingUsAscii;
  std::string text;  ///< at most 65535 bytes
  bool operator==(const StringInfo&) const = default;
};
/// STRING content: encoding u16, length u16, bytes; fails on a length past the body.
Result<StringInfo> decodeString(const MessageView& m);
/// STRING message; fails on text over 65535 bytes.
Result<std::vector<std::byte>> encodeString(const Envelope& env, const StringInfo& s);

/// COMMAND content (protocol v3; also the body of RTS_COMMAND).
struct CommandInfo {
  std::uint32_t id = 0;
  std::string name;  ///< at most 128 bytes, e.g. "Start"
  std::uint16_t encoding = kEncodingUtf8;
  std::string content;  ///< usually XML
  bool operator==(const CommandInfo&) const = default;
};
/// COMMAND content: id u32, name char[128], encoding u16, length u32, bytes. Accepts
/// types COMMAND and RTS_COMMAND; fails on a length past the body.
Result<CommandInfo> decodeCommand(const MessageView& m);
/// COMMAND (or RTS_COMMAND) message; `type` is "COMMAND" or "RTS_COMMAND".
Result<std::vector<std::byte>> encodeCommand(const Envelope& env, const CommandInfo& c,
                                             std::string_view type = "COMMAND");

// ---- POINT ---------------------------------------------------------------

/// One POINT element (136 bytes on the wire).
struct Point {
  std::string name;   ///< at most 64 characters
  std::string group;  ///< at most 32, e.g. "Fiducial"
  std::array<std::uint8_t, 4> rgba{0, 0, 0, 255};
  Vec3 position = Vec3::Zero();  ///< m
  double radius = 0;             ///< m
  std::string owner;             ///< at most 20: device name of the owner image
};
/// POINT content: n × 136-byte elements (mm → m); fails on a size not a multiple of 136.
Result<std::vector<Point>> decodePoints(const MessageView& m);
/// POINT message (m → mm); fails on names longer than their fields.
Result<std::vector<std::byte>> encodePoints(const Envelope& env, std::span<const Point> points);

// ---- SENSOR --------------------------------------------------------------

/// One factor of an OpenIGTLink unit: an SI base or derived unit code
/// (igtl_unit.h: 0x01 metre, 0x02 gram, 0x03 second, 0x0B newton,
/// 0x0C pascal, ...) and its exponent, −7..7.
struct UnitFactor {
  std::uint8_t unit = 0;  ///< 6 bits
  std::int8_t exponent = 0;
  bool operator==(const UnitFactor&) const = default;
};
/// An OpenIGTLink unit unpacked: a prefix code (0 none, 0xB milli, ...) and
/// up to six factors, in the 64-bit packing of igtl_unit_pack (prefix in the
/// top 4 bits, then six 10-bit unit/exponent fields).
struct Unit {
  std::uint8_t prefix = 0;  ///< 4 bits
  std::array<UnitFactor, 6> factors{};
  bool operator==(const Unit&) const = default;
};
/// The packed form; fails on a prefix over 15, a unit code over 63 or an
/// exponent outside −7..7.
Result<std::uint64_t> packUnit(const Unit& unit);
/// The unpacked form of any 64-bit value (every bit pattern is a unit).
Unit unpackUnit(std::uint64_t packed) noexcept;
/// Newtons (N, SI derived unit 0x0B), the unit of a force SENSOR.
inline constexpr std::uint64_t kUnitNewton = std::uint64_t{0x0B} << 54 | std::uint64_t{1} << 50;

/// SENSOR content (protocol v3): an array of float64 readings with a unit.
struct SensorInfo {
  std::uint8_t status = 0;   ///< reserved by the protocol, 0
  std::uint64_t unit = 0;    ///< packed (packUnit), e.g. kUnitNewton
  std::vector<double> data;  ///< at most 255 values
  bool operator==(const SensorInfo&) const = default;
};
/// SENSOR content: length u8, status u8, unit u64, then float64 × length;
/// fails on a length that does not match the body or a non-finite value.
Result<SensorInfo> decodeSensor(const MessageView& m);
/// SENSOR message; fails on more than 255 values or a non-finite one.
/// @code
///   auto f = dm::igtl::encodeSensor({.version = 2, .deviceName = "Force"},
///                                   {.unit = dm::igtl::kUnitNewton, .data = {fx, fy, fz}});
/// @endcode
Result<std::vector<std::byte>> encodeSensor(const Envelope& env, const SensorInfo& s);

// ---- POLYDATA ------------------------------------------------------------

/// POLYDATA as a Mesh: points (mm → m), polygons fan-triangulated (n ≥ 3),
/// triangle strips split into triangles with alternating winding. Vertex
/// and line cells fail with Unsupported (a Mesh has no such cells);
/// attributes are ignored. Indices are checked against the point count.
/// @code
///   auto mesh = dm::igtl::decodePolyData(*msg);
///   if (mesh) resources.add(std::move(*mesh));
/// @endcode
Result<Mesh> decodePolyData(const MessageView& m);
/// POLYDATA message: points (m → mm) and triangles as 3-gons, no attributes. Fails
/// on an invalid mesh (Mesh::validate()).
Result<std::vector<std::byte>> encodePolyData(const Envelope& env, const Mesh& mesh);

// ---- GET_ / STT_ / STP_ / RTS_ ----------------------------------------------

/// The four query prefixes: GET_, STT_ (start), STP_ (stop), RTS_ (ready to send).
enum class QueryKind : std::uint8_t { Get, Start, Stop, Ready };

/// A query message: GET_<T> and STP_<T> (empty bodies), STT_<T> (for TDATA
/// and QTDATA: resolution in ms and coordinate name, 36 bytes; otherwise
/// empty), RTS_<T> (1-byte status, 0 success; RTS_COMMAND is a COMMAND body:
/// use decodeCommand()).
struct Query {
  QueryKind kind = QueryKind::Get;
  std::string dataType;            ///< "IMAGE", "TDATA", ...
  std::uint32_t resolutionMs = 0;  ///< STT_TDATA / STT_QTDATA
  std::string coordinateName;      ///< STT_TDATA / STT_QTDATA, at most 32 characters
  std::uint8_t status = 0;         ///< RTS_: 0 success, 1 error
  bool operator==(const Query&) const = default;
};
/// True for GET_, STT_, STP_ and RTS_ type names.
bool isQueryType(std::string_view type) noexcept;
/// Decodes a GET_/STT_/STP_/RTS_ message; fails on a body the convention does not allow.
Result<Query> decodeQuery(const MessageView& m);
/// Query message of type prefix + dataType (the whole name must fit 12 characters:
/// the reference library uses GET_TRANS for TRANSFORM).
Result<std::vector<std::byte>> encodeQuery(const Envelope& env, const Query& q);

}  // namespace dm::igtl
