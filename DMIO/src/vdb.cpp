// vdb.cpp — OpenVDB grids <-> dm::Volume. The only translation unit of the
// SDK that includes OpenVDB; every OpenVDB exception is caught here.
#include <dm/core/filesystem.hpp>
#include <dm/io/vdb.hpp>

#include <openvdb/io/File.h>
#include <openvdb/io/GridDescriptor.h>
#include <openvdb/io/Stream.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/Dense.h>
#include <openvdb/tools/SignedFloodFill.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <exception>
#include <istream>
#include <mutex>
#include <new>
#include <span>
#include <streambuf>
#include <string>
#include <system_error>
#include <utility>

#include "format_util.hpp"
#include "isolate.hpp"

namespace dm {
namespace {

constexpr const char* kDenseMin = "dm_dense_min";
constexpr const char* kDenseMax = "dm_dense_max";
constexpr std::uint32_t kMinFileVersion = 213;  // OPENVDB_FILE_VERSION_ROOTNODE_MAP: oldest OpenVDB 10 reads

void initializeOpenVdb() {
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
}

std::string whereOf(const std::string& source, const std::string& grid) {
  return grid.empty() ? source : source + ": grid \"" + grid + "\"";
}

/// Checks the fixed part of the VDB stream header before OpenVDB sees it:
/// magic (int64 0x56444220), file version, library version, offsets flag and
/// UUID must fit in `size` bytes.
Status checkHeader(const unsigned char* head, std::size_t available, std::uint64_t size,
                   const std::string& where) {
  constexpr std::uint64_t kMagic = 0x56444220;
  if (available < 12)
    return fail(ErrorCode::Parse, "not an OpenVDB file: " + std::to_string(size) + " bytes", where,
                "a .vdb file starts with the 8-byte magic 0x56444220");
  std::uint64_t magic = 0;
  std::uint32_t version = 0;
  std::memcpy(&magic, head, 8);
  std::memcpy(&version, head + 8, 4);
  if (magic != kMagic)
    return fail(ErrorCode::Parse, "not an OpenVDB file (bad magic number)", where + " (byte 0)",
                "a .vdb file starts with the 8-byte magic 0x56444220");
  if (version < kMinFileVersion || version > openvdb::OPENVDB_FILE_VERSION)
    return fail(ErrorCode::Version, "unsupported OpenVDB file version " + std::to_string(version),
                where + " (byte 8)",
                "OpenVDB 10 reads file versions " + std::to_string(kMinFileVersion) + " to " +
                    std::to_string(openvdb::OPENVDB_FILE_VERSION));
  // magic, version, library major/minor, offsets flag, [compression flag], UUID.
  const std::uint64_t header = 8 + 4 + 8 + 1 +
                               (version >= openvdb::OPENVDB_FILE_VERSION_SELECTIVE_COMPRESSION &&
                                        version < openvdb::OPENVDB_FILE_VERSION_NODE_MASK_COMPRESSION
                                    ? 1
                                    : 0) +
                               (version >= openvdb::OPENVDB_FILE_VERSION_BOOST_UUID ? 36 : 16);
  if (size < header + 4)
    return fail(ErrorCode::Parse, "truncated OpenVDB file: " + std::to_string(size) + " bytes", where,
                "the header alone needs " + std::to_string(header + 4) + " bytes; the file is cut short");
  return ok();
}

bool isScalarGrid(const openvdb::GridBase& g) {
  return g.isType<openvdb::FloatGrid>() || g.isType<openvdb::DoubleGrid>() ||
         g.isType<openvdb::Int32Grid>() || g.isType<openvdb::Int64Grid>() || g.isType<openvdb::BoolGrid>();
}

VoxelType voxelTypeOf(const openvdb::GridBase& g) {
  return g.isType<openvdb::FloatGrid>() || g.isType<openvdb::BoolGrid>() ? VoxelType::F32 : VoxelType::F64;
}

std::string describe(const openvdb::GridBase& g) {
  std::string s =
      g.getName() + " (" + g.valueType() + ", " + openvdb::GridBase::gridClassToString(g.getGridClass());
  if (auto count = g.getMetadata<openvdb::Int64Metadata>(openvdb::GridBase::META_FILE_VOXEL_COUNT))
    s += ", " + std::to_string(count->value()) + " active voxels";
  else
    s += ", " + std::to_string(g.activeVoxelCount()) + " active voxels";
  return s + ")";
}

/// The grid named `name`, or the first scalar grid when `name` is empty.
Result<openvdb::GridBase::Ptr> pickGrid(const openvdb::GridPtrVec& grids, const std::string& name,
                                        const std::string& source) {
  for (const auto& g : grids)
    if (g && (name.empty() ? isScalarGrid(*g) : g->getName() == name)) return g;
  std::string names;
  for (const auto& g : grids)
    if (g) names += (names.empty() ? "" : ", ") + describe(*g);
  if (names.empty()) names = "none";
  if (name.empty())
    return fail(ErrorCode::Unsupported, "no float, double, int32, int64 or bool grid", source,
                "the file holds: " + names);
  return fail(ErrorCode::NotFound, "no grid named \"" + name + "\"", source, "the file holds: " + names);
}

/// Unites `box` with the box the metadata `lo`, `hi` of `g` record (when
/// both are there and it is not empty).
void expandByRecorded(openvdb::CoordBBox& box, const openvdb::GridBase& g, const char* lo, const char* hi) {
  auto a = g.getMetadata<openvdb::Vec3IMetadata>(lo);
  auto b = g.getMetadata<openvdb::Vec3IMetadata>(hi);
  if (!a || !b) return;
  const openvdb::CoordBBox recorded(openvdb::Coord(a->value()), openvdb::Coord(b->value()));
  if (!recorded.empty()) box.expand(recorded);
}

/// The dense index box to read: the active voxels' box, united with the box
/// writeVdb() recorded. Empty when neither exists.
openvdb::CoordBBox denseBox(const openvdb::GridBase& g) {
  openvdb::CoordBBox box = g.evalActiveVoxelBoundingBox();
  expandByRecorded(box, g, kDenseMin, kDenseMax);
  return box;
}

/// The box a grid's metadata declares before its tree: the active voxels'
/// box a writer recorded (OpenVDB's file_bbox_min/max) united with
/// writeVdb()'s dense box. Empty when it declares none.
openvdb::CoordBBox declaredBox(const openvdb::GridBase& g) {
  openvdb::CoordBBox box;
  expandByRecorded(box, g, openvdb::GridBase::META_FILE_BBOX_MIN, openvdb::GridBase::META_FILE_BBOX_MAX);
  expandByRecorded(box, g, kDenseMin, kDenseMax);
  return box;
}

/// Fails when the dense box (`what`: which one) would exceed maxBytes (or int dims).
Status checkBox(const openvdb::CoordBBox& box, VoxelType type, std::size_t maxBytes, const std::string& where,
                const char* what = "dense") {
  if (box.empty()) return ok();
  const openvdb::Vec3d extent =
      openvdb::Vec3d(box.max().asVec3d()) - box.min().asVec3d() + openvdb::Vec3d(1.0);
  const double bytes = extent[0] * extent[1] * extent[2] * static_cast<double>(voxelBytes(type));
  if (extent[0] > 2147483647.0 || extent[1] > 2147483647.0 || extent[2] > 2147483647.0 ||
      bytes > static_cast<double>(maxBytes))
    return detail::volumeOverBudget(formatString("the grid's %s box %.0f x %.0f x %.0f of %s", what,
                                                 extent[0], extent[1], extent[2], toString(type)),
                                    static_cast<std::uint64_t>(std::min(bytes, 1.8e19)), maxBytes, where,
                                    "VdbReadOptions::maxBytes");
  return ok();
}

/// The grids of a VDB stream with their descriptors and metadata only, no
/// tree read: the header, the file's metadata, then each grid's descriptor,
/// compression flags and metadata, as openvdb::io::Stream reads them. The
/// next grid is reached by the descriptor's end offset, which a seekable
/// writer (io::File) records; in a stream without offsets the first grid's
/// tree comes next, so the pass stops after the first grid.
class GridHeaders : public openvdb::io::Archive {
 public:
  openvdb::GridPtrVec read(std::istream& is, std::size_t size) {
    readHeader(is);
    openvdb::io::StreamMetadata::Ptr meta(new openvdb::io::StreamMetadata);
    openvdb::io::setStreamMetadataPtr(is, meta, /*transfer=*/false);
    openvdb::io::setVersion(is, libraryVersion(), fileVersion());
    openvdb::io::setDataCompression(is, compression());
    openvdb::MetaMap file;
    file.readMeta(is);
    const std::int32_t count = readGridCount(is);
    openvdb::GridPtrVec grids;
    for (std::int32_t i = 0; i < count; ++i) {
      openvdb::io::GridDescriptor gd;
      openvdb::GridBase::Ptr grid = gd.read(is);
      readGridCompression(is);
      grid->readMeta(is);
      grids.push_back(grid);
      // (an offset out of the bytes ends the pass; the full read judges the file)
      if (!inputHasGridOffsets() || gd.getEndPos() <= 0 || static_cast<std::uint64_t>(gd.getEndPos()) > size)
        break;
      gd.seekToEnd(is);
    }
    return grids;
  }
};

template <class GridT, class DenseValue>
void copyDense(const openvdb::GridBase& g, const openvdb::CoordBBox& box, DenseValue* out, bool serial) {
  openvdb::tools::Dense<DenseValue, openvdb::tools::LayoutXYZ> dense(box, out);
  openvdb::tools::copyToDense(static_cast<const GridT&>(g), dense, serial);
}

/// Densifies a fully loaded scalar grid.
/// `serial`: no oneTBB tasks (in the isolated child, whose copy of the
/// parent's task scheduler has no worker threads).
Result<Volume> densify(const openvdb::GridBase& g, std::size_t maxBytes, const std::string& where,
                       bool serial) {
  const openvdb::math::Transform& xform = g.transform();
  if (!xform.isLinear())
    return fail(ErrorCode::Unsupported, "the grid's transform (" + xform.mapType() + ") is not linear", where,
                "frustum and other non-linear transforms are not supported; resample to a linear grid");
  const openvdb::Mat4d m = xform.baseMap()->getAffineMap()->getMat4();
  const openvdb::CoordBBox box = denseBox(g);
  if (box.empty())
    return fail(ErrorCode::Unsupported, "the grid has no active voxels", where,
                "an empty grid has no extent to densify");
  const VoxelType type = voxelTypeOf(g);
  if (Status s = checkBox(box, type, maxBytes, where); !s) return s.error();
  // OpenVDB maps row vectors, world = [i j k 1] · M; dm maps column vectors.
  Affine3 a = Affine3::Identity();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) a.linear()(r, c) = m(c, r);
    a.translation()(r) = m(3, r);
  }
  a = a * Eigen::Translation3d(box.min().x(), box.min().y(), box.min().z());
  const openvdb::Coord dim = box.dim();
  auto v = Volume::create(Vec3i(dim.x(), dim.y(), dim.z()), type, a, maxBytes);
  if (!v) return v.error().within(where);
  if (g.isType<openvdb::FloatGrid>()) {
    copyDense<openvdb::FloatGrid>(g, box, v->data<float>(), serial);
  } else if (g.isType<openvdb::BoolGrid>()) {
    copyDense<openvdb::BoolGrid>(g, box, v->data<float>(), serial);
  } else if (g.isType<openvdb::DoubleGrid>()) {
    copyDense<openvdb::DoubleGrid>(g, box, v->data<double>(), serial);
  } else if (g.isType<openvdb::Int32Grid>()) {
    copyDense<openvdb::Int32Grid>(g, box, v->data<double>(), serial);
  } else if (g.isType<openvdb::Int64Grid>()) {
    copyDense<openvdb::Int64Grid>(g, box, v->data<double>(), serial);
  } else {
    return fail(ErrorCode::Unsupported, "grid of type " + g.valueType() + " is not scalar", where,
                "read a float, double, int32, int64 or bool grid");
  }
  return std::move(*v);
}

Error fromException(const std::exception& e, const std::string& where, bool reading) {
  if (dynamic_cast<const std::bad_alloc*>(&e))
    return fail(ErrorCode::Unsupported,
                reading ? "out of memory reading the grid" : "out of memory writing the grid", where,
                "the grid is too large for this machine");
  if (reading && dynamic_cast<const std::ios_base::failure*>(&e))  // a short read: stream exceptions are on
    return fail(ErrorCode::Parse, "unexpected end of the OpenVDB data", where,
                "the file is truncated, or a length inside it is corrupt");
  // Whatever else OpenVDB throws on a read (IoError, ValueError, ...) comes from the bytes.
  if (reading)
    return fail(ErrorCode::Parse, std::string("corrupt OpenVDB data: ") + e.what(), where,
                "the file is truncated, corrupt or not written by OpenVDB");
  return fail(ErrorCode::Io, std::string("OpenVDB failed writing: ") + e.what(), where,
              "check the disk space and that the directory is writable");
}

/// A read-only std::streambuf over bytes in memory (seekable, no copy).
class SpanBuf : public std::streambuf {
 public:
  explicit SpanBuf(std::span<const std::byte> bytes) {
    char* b = const_cast<char*>(reinterpret_cast<const char*>(bytes.data()));
    setg(b, b, b + bytes.size());
  }

 protected:
  pos_type seekoff(off_type off, std::ios_base::seekdir dir, std::ios_base::openmode) override {
    const off_type base = dir == std::ios_base::beg   ? 0
                          : dir == std::ios_base::cur ? gptr() - eback()
                                                      : egptr() - eback();
    const off_type to = base + off;
    if (to < 0 || to > egptr() - eback()) return pos_type(off_type(-1));
    setg(eback(), eback() + to, egptr());
    return pos_type(to);
  }
  pos_type seekpos(pos_type pos, std::ios_base::openmode mode) override {
    return seekoff(off_type(pos), std::ios_base::beg, mode);
  }
};

/// All grids of a VDB stream in memory, fully loaded. Short reads throw
/// (stream exceptions on), so a truncated length field cannot drive OpenVDB
/// through a long loop of failed reads.
openvdb::GridPtrVecPtr loadGrids(std::span<const std::byte> bytes) {
  SpanBuf buf(bytes);
  std::istream is(&buf);
  is.exceptions(std::ios::failbit | std::ios::badbit | std::ios::eofbit);
  openvdb::io::Stream stream(is, false);
  return stream.getGrids();
}

/// The bytes of `file`, after checking the header (see checkHeader).
Result<std::vector<std::byte>> loadFile(const std::filesystem::path& file, std::size_t maxBytes) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(file, ec))
    return fail(ErrorCode::NotFound, "no such file", file.string(), "check the path");
  // A sparse file is rarely larger than its dense grid; allow twice that plus slack.
  const std::size_t limit =
      maxBytes > (std::size_t{1} << 62) ? maxBytes : 2 * maxBytes + (std::size_t{1} << 20);
  auto bytes = readFile(file, limit);
  if (!bytes) return bytes.error();
  if (Status s = checkHeader(reinterpret_cast<const unsigned char*>(bytes->data()), bytes->size(),
                             bytes->size(), file.string());
      !s)
    return s.error();
  return bytes;
}

template <class GridT>
Status writeGrid(const Volume& volume, const std::filesystem::path& file, const VdbWriteOptions& options,
                 const std::string& where) {
  using Value = typename GridT::ValueType;
  const double voxelSize = volume.spacing().maxCoeff();
  const double background = options.levelSet ? options.halfWidthVoxels * voxelSize : 0.0;
  typename GridT::Ptr grid = GridT::create(static_cast<Value>(background));
  grid->setName(options.gridName);
  openvdb::Mat4d m = openvdb::Mat4d::identity();
  const Affine3& a = volume.indexToWorld();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) m(c, r) = a.linear()(r, c);
    m(3, r) = a.translation()(r);
  }
  grid->setTransform(openvdb::math::Transform::createLinearTransform(m));
  auto acc = grid->getAccessor();
  const Vec3i d = volume.dims();
  bool unitRange = true;
  for (int k = 0; k < d.z(); ++k)
    for (int j = 0; j < d.y(); ++j)
      for (int i = 0; i < d.x(); ++i) {
        const double v = volume.valueAt(volume.linearIndex(i, j, k));
        if (options.levelSet ? !(std::abs(v) < background) : std::abs(v) <= options.tolerance) continue;
        unitRange = unitRange && v >= 0 && v <= 1;
        acc.setValue(openvdb::Coord(i, j, k), static_cast<Value>(v));
      }
  if (options.levelSet) {
    grid->setGridClass(openvdb::GRID_LEVEL_SET);
    openvdb::tools::signedFloodFill(grid->tree());
  } else {
    grid->setGridClass(unitRange ? openvdb::GRID_FOG_VOLUME : openvdb::GRID_UNKNOWN);
  }
  grid->insertMeta(kDenseMin, openvdb::Vec3IMetadata(openvdb::Vec3i(0, 0, 0)));
  grid->insertMeta(kDenseMax, openvdb::Vec3IMetadata(openvdb::Vec3i(d.x() - 1, d.y() - 1, d.z() - 1)));

  static std::atomic<unsigned> counter{0};
  std::filesystem::path tmp = file;
  tmp += ".tmp" + std::to_string(::getpid()) + "_" + std::to_string(counter.fetch_add(1));
  try {
    openvdb::io::File out(tmp.string());
    out.write(openvdb::GridCPtrVec{grid});
    out.close();
  } catch (const std::exception& e) {
    std::error_code ignored;
    std::filesystem::remove(tmp, ignored);
    return fromException(e, where, false);
  }
  std::error_code ec;
  std::filesystem::rename(tmp, file, ec);
  if (ec) {
    std::error_code ignored;
    std::filesystem::remove(tmp, ignored);
    return fail(ErrorCode::Io, "cannot rename the temporary file into place: " + ec.message(), where,
                "check that the directory is writable");
  }
  return ok();
}

}  // namespace

Result<Volume> readVdb(const std::filesystem::path& file, const VdbReadOptions& options) {
  auto bytes = loadFile(file, options.maxBytes);
  if (!bytes) return bytes.error();
  return parseVdb(*bytes, file.string(), options);
}

namespace {

/// Refuses the grid to read when its metadata declares a box over the
/// budget, before any tree is read (OpenVDB allocates a tree as it reads
/// it); a grid the pass cannot reach or that declares nothing is judged by
/// its dense box after the read.
Status checkDeclaredBox(std::span<const std::byte> bytes, const std::string& source,
                        const VdbReadOptions& options) {
  SpanBuf buf(bytes);
  std::istream is(&buf);
  is.exceptions(std::ios::failbit | std::ios::badbit | std::ios::eofbit);
  GridHeaders headers;
  for (const openvdb::GridBase::Ptr& g : headers.read(is, bytes.size()))
    if (g && (options.gridName.empty() ? isScalarGrid(*g) : g->getName() == options.gridName))
      return checkBox(declaredBox(*g), voxelTypeOf(*g), options.maxBytes, whereOf(source, g->getName()),
                      "declared");
  return ok();
}

Result<Volume> parseInProcess(std::span<const std::byte> bytes, const std::string& source,
                              const VdbReadOptions& options, bool serial) {
  std::string where = whereOf(source, options.gridName);
  try {
    if (Status s = checkDeclaredBox(bytes, source, options); !s) return s.error();
    openvdb::GridPtrVecPtr grids = loadGrids(bytes);
    if (!grids) return fail(ErrorCode::Parse, "no grids", source, "the file holds no grid");
    auto picked = pickGrid(*grids, options.gridName, source);
    if (!picked) return picked.error();
    where = whereOf(source, (*picked)->getName());
    return densify(**picked, options.maxBytes, where, serial);
  } catch (const std::exception& e) {
    return fromException(e, where, true);
  } catch (...) {
    return fail(ErrorCode::Parse, "OpenVDB threw an unknown exception while reading", where,
                "the file is truncated, corrupt or not written by OpenVDB");
  }
}

detail::IsolateOptions isolateOptions(const VdbReadOptions& options, std::size_t fileBytes) {
  detail::IsolateOptions iso;
  iso.library = "OpenVDB";
  iso.timeoutSeconds = options.timeoutSeconds;
  // The dense copy, the sparse tree (compressed files expand) and slack.
  iso.memoryBudget =
      2 * std::min(options.maxBytes, std::size_t{1} << 40) + 16 * fileBytes + (std::size_t{1} << 30);
  iso.disableHint =
      "set VdbReadOptions::isolation to Isolation::Fork (single-threaded callers) or Isolation::InProcess "
      "(trusted files)";
  iso.crashHint =
      "the file is corrupt or crafted (OpenVDB allocates the lengths stored in it); check where it came from";
  iso.timeoutHint = "the file is corrupt or very large: check it, or raise VdbReadOptions::timeoutSeconds";
  iso.budgetHint = "the file is corrupt or crafted, or the grid is larger than VdbReadOptions::maxBytes allows";
  return iso;
}

constexpr std::uint64_t kEndMarker = 0x44'4d'56'44'42'45'4e'44ull;

// Child -> parent: ok flag, then an Error or dims, type, affine and voxels.
void sendVolume(detail::FdWriter& w, const Result<Volume>& r) {
  if (!r) {
    w.u64(0);
    w.error(r.error());
    return;
  }
  w.u64(1);
  for (int i = 0; i < 3; ++i) w.u64(static_cast<std::uint64_t>(r->dims()[i]));
  w.u64(static_cast<std::uint64_t>(r->type()));
  const Eigen::Matrix4d m = r->indexToWorld().matrix();
  w.bytes(m.data(), sizeof(double) * 16);
  w.u64(r->byteSize());
  w.bytes(r->bytes(), r->byteSize());
  w.u64(kEndMarker);
}

Result<Volume> receiveVolume(const detail::IsolatedRun& run, const std::string& where, std::size_t maxBytes) {
  detail::ByteReader r(run.bytes);
  auto broken = [&] {
    return fail(ErrorCode::Internal,
                "the OpenVDB process ended (" + run.exitInfo + ") without a complete result", where,
                "the file is corrupt or needs more memory than the reader allows (VdbReadOptions::maxBytes)");
  };
  const std::uint64_t okFlag = r.u64();
  if (!r.ok()) return broken();
  if (okFlag == 0) {
    Error e = r.error();
    if (!r.ok()) return broken();
    return e;
  }
  std::uint64_t d[3];
  for (auto& x : d) x = r.u64();
  const std::uint64_t type = r.u64();
  Eigen::Matrix4d m;
  r.bytes(m.data(), sizeof(double) * 16);
  const std::uint64_t n = r.u64();
  if (!r.ok() || type > static_cast<std::uint64_t>(VoxelType::F64) || n != r.remaining() - sizeof(kEndMarker))
    return broken();
  for (auto x : d)
    if (x == 0 || x > static_cast<std::uint64_t>(std::numeric_limits<int>::max())) return broken();
  // An affine index-to-world map, as densify() makes: finite, last row 0 0 0 1.
  if (!m.allFinite() || m.row(3) != Eigen::RowVector4d(0, 0, 0, 1)) return broken();
  Affine3 a;
  a.matrix() = m;
  auto v = Volume::create(Vec3i(static_cast<int>(d[0]), static_cast<int>(d[1]), static_cast<int>(d[2])),
                          static_cast<VoxelType>(type), a, maxBytes);
  if (!v) return v.error().within(where);
  if (v->byteSize() != n) return broken();
  r.bytes(v->bytes(), v->byteSize());
  if (r.u64() != kEndMarker || !r.ok()) return broken();
  return std::move(*v);
}

}  // namespace

Result<Volume> parseVdb(std::span<const std::byte> bytes, std::string_view sourceName,
                        const VdbReadOptions& options) {
  const std::string source(sourceName);
  if (Status s = checkHeader(reinterpret_cast<const unsigned char*>(bytes.data()), bytes.size(), bytes.size(),
                             source);
      !s)
    return s.error();
  initializeOpenVdb();  // before a fork, so the child does not initialise
  if (options.isolation == Isolation::InProcess) return parseInProcess(bytes, source, options, false);
  const detail::IsolateOptions iso = isolateOptions(options, bytes.size());
  auto run =
      options.isolation == Isolation::Fork
          ? detail::runIsolated(
                [&](detail::FdWriter& w) { sendVolume(w, parseInProcess(bytes, source, options, true)); },
                iso, whereOf(source, options.gridName))
          : detail::runHelper(
                "openvdb-parse",
                [&](detail::FdWriter& w) {
                  w.str(source);
                  w.str(options.gridName);
                  w.u64(options.maxBytes);
                  w.u64(bytes.size());
                  w.bytes(bytes.data(), bytes.size());
                  w.u64(kEndMarker);
                },
                iso, whereOf(source, options.gridName));
  if (!run) return run.error();
  return receiveVolume(*run, whereOf(source, options.gridName), options.maxBytes);
}

Status writeVdb(const Volume& volume, const std::filesystem::path& file, const VdbWriteOptions& options) {
  const std::string where = whereOf(file.string(), options.gridName);
  if (volume.empty()) return fail(ErrorCode::InvalidArgument, "the volume is empty", where);
  if (options.gridName.empty())
    return fail(ErrorCode::InvalidArgument, "empty grid name", where, "name the grid, e.g. \"density\"");
  if (options.levelSet) {
    if (volume.type() != VoxelType::F32 && volume.type() != VoxelType::F64)
      return fail(
          ErrorCode::InvalidArgument,
          std::string("a level set needs a float signed distance volume, not ") + toString(volume.type()),
          where, "voxelize with signedDistance = true");
    if (!(options.halfWidthVoxels > 0) || !std::isfinite(options.halfWidthVoxels))
      return fail(ErrorCode::InvalidArgument, "halfWidthVoxels is " + std::to_string(options.halfWidthVoxels),
                  where, "give a positive narrow-band half width, e.g. 3");
  } else if (!(options.tolerance >= 0) || !std::isfinite(options.tolerance)) {
    return fail(ErrorCode::InvalidArgument, "tolerance is " + std::to_string(options.tolerance), where,
                "give 0 or a positive tolerance");
  }
  initializeOpenVdb();
  try {
    if (volume.type() == VoxelType::F64) return writeGrid<openvdb::DoubleGrid>(volume, file, options, where);
    return writeGrid<openvdb::FloatGrid>(volume, file, options, where);
  } catch (const std::exception& e) {
    return fromException(e, where, false);
  }
}

Result<std::vector<std::string>> listVdbGrids(const std::filesystem::path& file) {
  const std::string source = file.string();
  auto bytes = loadFile(file, Volume::kDefaultMaxBytes);
  if (!bytes) return bytes.error();
  initializeOpenVdb();
  const auto list = [&]() -> Result<std::vector<std::string>> {
    try {
      openvdb::GridPtrVecPtr grids = loadGrids(*bytes);
      std::vector<std::string> out;
      if (grids)
        for (const auto& g : *grids)
          if (g) out.push_back(describe(*g));
      return out;
    } catch (const std::exception& e) {
      return fromException(e, source, true);
    } catch (...) {
      return fail(ErrorCode::Parse, "OpenVDB threw an unknown exception", source,
                  "the file is truncated, corrupt or not written by OpenVDB");
    }
  };
  return list();
}

}  // namespace dm

namespace dm::detail {

void prepareOpenVdb() { initializeOpenVdb(); }

Result<Volume> volumeFromResult(const std::vector<char>& bytes, std::size_t maxBytes,
                                const std::string& where) {
  IsolatedRun run;
  run.bytes = bytes;
  run.exitInfo = "exit status 0";
  return receiveVolume(run, where, maxBytes);
}

// The helper's side of an isolated parse: source name, grid name, maxBytes
// and the file's bytes in, the volume out as sendVolume() writes it. A fresh
// process, so OpenVDB may use its oneTBB tasks here.
void openVdbParseJob(ByteReader& r, FdWriter& w) {
  const std::string source = r.str();
  VdbReadOptions o;
  o.gridName = r.str();
  o.maxBytes = static_cast<std::size_t>(r.u64());
  o.isolation = Isolation::InProcess;  // this is the isolated process
  const std::uint64_t n = r.u64();
  std::vector<std::byte> bytes;
  if (r.ok() && n <= r.remaining()) {
    bytes.resize(static_cast<std::size_t>(n));
    r.bytes(bytes.data(), bytes.size());
  } else {
    r.markBroken();
  }
  if (r.u64() != kEndMarker || !r.ok()) {
    sendVolume(w, fail(ErrorCode::Internal, "the OpenVDB helper got an incomplete request",
                       whereOf(source, o.gridName), "please report this"));
    return;
  }
  initializeOpenVdb();
  sendVolume(w, parseInProcess(bytes, source, o, false));
}

}  // namespace dm::detail
