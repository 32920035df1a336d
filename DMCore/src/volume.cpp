#include <dm/core/volume.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <type_traits>

namespace dm {

std::size_t voxelBytes(VoxelType t) noexcept {
  switch (t) {
    case VoxelType::U8:
    case VoxelType::I8:
      return 1;
    case VoxelType::U16:
    case VoxelType::I16:
      return 2;
    case VoxelType::U32:
    case VoxelType::I32:
    case VoxelType::F32:
      return 4;
    case VoxelType::F64:
      return 8;
  }
  return 1;
}

const char* toString(VoxelType t) noexcept {
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
      return "float32";
    case VoxelType::F64:
      return "float64";
  }
  return "unknown";
}

namespace {
Status checkAffine(const Affine3& a) {
  if (!a.matrix().allFinite())
    return fail(ErrorCode::InvalidArgument, "index-to-world affine has a NaN or Inf entry", "volume",
                "check the spacing and orientation fields of the source file");
  const double det = a.linear().determinant();
  if (!(std::abs(det) > 1e-30))
    return fail(ErrorCode::InvalidArgument, "index-to-world affine is singular (zero spacing?)", "volume",
                "check the spacing and orientation fields of the source file");
  return ok();
}

template <class T>
T load(const std::byte* p) {
  T v;
  std::memcpy(&v, p, sizeof v);
  return v;
}

template <class T>
void storeConverted(std::byte* p, double v) {
  T out;
  if constexpr (std::is_integral_v<T>) {
    if (std::isnan(v)) v = 0;
    v = std::clamp(std::round(v), static_cast<double>(std::numeric_limits<T>::lowest()),
                   static_cast<double>(std::numeric_limits<T>::max()));
    out = static_cast<T>(v);
  } else {
    out = static_cast<T>(v);
  }
  std::memcpy(p, &out, sizeof out);
}
}  // namespace

Result<Volume> Volume::create(const Vec3i& dims, VoxelType type, const Affine3& indexToWorld,
                              std::size_t maxBytes) {
  if ((dims.array() <= 0).any())
    return fail(ErrorCode::InvalidArgument,
                "dims " + std::to_string(dims.x()) + "x" + std::to_string(dims.y()) + "x" +
                    std::to_string(dims.z()) + " must all be positive",
                "volume");
  std::size_t count = 1;
  for (int a = 0; a < 3; ++a) {
    const auto d = static_cast<std::size_t>(dims[a]);
    if (count > std::numeric_limits<std::size_t>::max() / d)
      return fail(ErrorCode::InvalidArgument, "voxel count overflows", "volume");
    count *= d;
  }
  const std::size_t bytes = voxelBytes(type);
  if (count > maxBytes / bytes)
    return fail(ErrorCode::InvalidArgument,
                std::to_string(dims.x()) + "x" + std::to_string(dims.y()) + "x" + std::to_string(dims.z()) +
                    " " + toString(type) + " voxels exceed the limit of " + std::to_string(maxBytes) +
                    " bytes",
                "volume", "crop or downsample the volume, or raise the limit");
  if (auto s = checkAffine(indexToWorld); !s) return std::move(s).error();
  Volume v;
  v.dims_ = dims;
  v.type_ = type;
  v.count_ = count;
  v.data_.assign(count * bytes, std::byte{0});
  v.indexToWorld_ = indexToWorld;
  v.worldToIndex_ = indexToWorld.inverse();
  return v;
}

Status Volume::setIndexToWorld(const Affine3& a) {
  if (auto s = checkAffine(a); !s) return s;
  indexToWorld_ = a;
  worldToIndex_ = a.inverse();
  return ok();
}

double Volume::valueAt(std::size_t n) const {
  const std::byte* p = data_.data() + n * voxelBytes(type_);
  switch (type_) {
    case VoxelType::U8:
      return load<std::uint8_t>(p);
    case VoxelType::I8:
      return load<std::int8_t>(p);
    case VoxelType::U16:
      return load<std::uint16_t>(p);
    case VoxelType::I16:
      return load<std::int16_t>(p);
    case VoxelType::U32:
      return load<std::uint32_t>(p);
    case VoxelType::I32:
      return load<std::int32_t>(p);
    case VoxelType::F32:
      return load<float>(p);
    case VoxelType::F64:
      return load<double>(p);
  }
  return 0;
}

void Volume::setValueAt(std::size_t n, double v) {
  std::byte* p = data_.data() + n * voxelBytes(type_);
  switch (type_) {
    case VoxelType::U8:
      storeConverted<std::uint8_t>(p, v);
      break;
    case VoxelType::I8:
      storeConverted<std::int8_t>(p, v);
      break;
    case VoxelType::U16:
      storeConverted<std::uint16_t>(p, v);
      break;
    case VoxelType::I16:
      storeConverted<std::int16_t>(p, v);
      break;
    case VoxelType::U32:
      storeConverted<std::uint32_t>(p, v);
      break;
    case VoxelType::I32:
      storeConverted<std::int32_t>(p, v);
      break;
    case VoxelType::F32:
      storeConverted<float>(p, v);
      break;
    case VoxelType::F64:
      storeConverted<double>(p, v);
      break;
  }
}

double Volume::sampleIndex(const Vec3& ijk) const {
  if (empty()) return 0;
  int i0[3];
  double f[3];
  for (int a = 0; a < 3; ++a) {
    const double c = std::clamp(ijk[a], 0.0, static_cast<double>(dims_[a] - 1));
    i0[a] = std::min(static_cast<int>(std::floor(c)), std::max(dims_[a] - 2, 0));
    f[a] = dims_[a] > 1 ? c - i0[a] : 0.0;
  }
  auto at = [&](int di, int dj, int dk) {
    return value(std::min(i0[0] + di, dims_.x() - 1), std::min(i0[1] + dj, dims_.y() - 1),
                 std::min(i0[2] + dk, dims_.z() - 1));
  };
  const double c00 = at(0, 0, 0) * (1 - f[0]) + at(1, 0, 0) * f[0];
  const double c10 = at(0, 1, 0) * (1 - f[0]) + at(1, 1, 0) * f[0];
  const double c01 = at(0, 0, 1) * (1 - f[0]) + at(1, 0, 1) * f[0];
  const double c11 = at(0, 1, 1) * (1 - f[0]) + at(1, 1, 1) * f[0];
  const double c0 = c00 * (1 - f[1]) + c10 * f[1];
  const double c1 = c01 * (1 - f[1]) + c11 * f[1];
  return c0 * (1 - f[2]) + c1 * f[2];
}

Vec3 Volume::gradientWorld(int i, int j, int k) const {
  // Central differences in index space (one-sided at the border), then the
  // chain rule through the affine: grad_world = A^{-T} grad_index.
  Vec3 g;
  const int idx[3] = {i, j, k};
  for (int a = 0; a < 3; ++a) {
    int lo[3] = {i, j, k}, hi[3] = {i, j, k};
    lo[a] = std::max(idx[a] - 1, 0);
    hi[a] = std::min(idx[a] + 1, dims_[a] - 1);
    const int span = hi[a] - lo[a];
    g[a] = span > 0 ? (value(hi[0], hi[1], hi[2]) - value(lo[0], lo[1], lo[2])) / span : 0.0;
  }
  return worldToIndex_.linear().transpose() * g;
}

Vec3 Volume::spacing() const { return indexToWorld_.linear().colwise().norm().transpose(); }

Aabb Volume::worldBounds() const {
  Aabb box;
  if (empty()) return box;
  for (int c = 0; c < 8; ++c) {
    const Vec3 ijk((c & 1) ? dims_.x() - 1 : 0, (c & 2) ? dims_.y() - 1 : 0, (c & 4) ? dims_.z() - 1 : 0);
    box.extend(indexToWorld_ * ijk);
  }
  return box;
}

std::pair<double, double> Volume::range() const {
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (std::size_t n = 0; n < count_; ++n) {
    const double v = valueAt(n);
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
  return {lo, hi};
}

Result<Image> volumeSlice(const Volume& volume, int axis, int index, double lo, double hi) {
  if (volume.voxelCount() == 0) return fail(ErrorCode::InvalidArgument, "the volume is empty", "volumeSlice");
  if (axis < 0 || axis > 2)
    return fail(ErrorCode::InvalidArgument, formatString("axis %d is not 0 (i), 1 (j) or 2 (k)", axis), "volumeSlice");
  if (!(hi > lo))
    return fail(ErrorCode::InvalidArgument, formatString("value window [%g, %g] is empty", lo, hi), "volumeSlice",
                "pass lo < hi, e.g. the volume's range()");
  const Vec3i d = volume.dims();
  const int u = axis == 0 ? 1 : 0, w = axis == 2 ? 1 : 2;  // the picture's x and y axes
  auto img = Image::create(d[u], d[w], 1, PixelType::U8);
  if (!img) return img.error();
  Vec3i p;
  p[axis] = std::clamp(index, 0, d[axis] - 1);
  for (int y = 0; y < d[w]; ++y)
    for (int x = 0; x < d[u]; ++x) {
      p[u] = x;
      p[w] = d[w] - 1 - y;
      img->at<std::uint8_t>(x, y) =
          static_cast<std::uint8_t>(std::clamp(255.0 * (volume.value(p.x(), p.y(), p.z()) - lo) / (hi - lo), 0.0, 255.0));
    }
  return img;
}

}  // namespace dm
