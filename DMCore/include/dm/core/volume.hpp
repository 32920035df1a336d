// dm/core/volume.hpp — the dense voxel grid of the data model.
//
// A Volume is an nx×ny×nz grid of scalars of one VoxelType, stored x-fastest
// (index = i + nx·(j + ny·k), the NIfTI/DICOM order), plus an affine map from
// voxel index (i, j, k) to world coordinates in metres. It feeds marching
// cubes, ray casting, voxel collision and vision alike. Importers apply the
// file's intensity scaling before storing, so values are physical (e.g. the
// Hounsfield units of CT).
//
// @code
//   auto v = dm::Volume::create({181, 217, 181}, dm::VoxelType::U8, affine);
//   v->setValue(90, 108, 90, 255);
//   dm::Vec3 centre = v->indexToWorld() * dm::Vec3(90, 108, 90);
// @endcode
#pragma once

#include <dm/core/image.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <cstddef>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace dm {

enum class VoxelType : std::uint8_t { U8, I8, U16, I16, U32, I32, F32, F64 };

/// Bytes of one voxel of `t`.
std::size_t voxelBytes(VoxelType t) noexcept;
/// "uint8", "int16", "float32", ...
const char* toString(VoxelType t) noexcept;

/// Maps a C++ scalar type to its VoxelType.
template <class T>
struct VoxelTypeOf;
template <>
struct VoxelTypeOf<std::uint8_t> {
  static constexpr VoxelType value = VoxelType::U8;
};
template <>
struct VoxelTypeOf<std::int8_t> {
  static constexpr VoxelType value = VoxelType::I8;
};
template <>
struct VoxelTypeOf<std::uint16_t> {
  static constexpr VoxelType value = VoxelType::U16;
};
template <>
struct VoxelTypeOf<std::int16_t> {
  static constexpr VoxelType value = VoxelType::I16;
};
template <>
struct VoxelTypeOf<std::uint32_t> {
  static constexpr VoxelType value = VoxelType::U32;
};
template <>
struct VoxelTypeOf<std::int32_t> {
  static constexpr VoxelType value = VoxelType::I32;
};
template <>
struct VoxelTypeOf<float> {
  static constexpr VoxelType value = VoxelType::F32;
};
template <>
struct VoxelTypeOf<double> {
  static constexpr VoxelType value = VoxelType::F64;
};

class Volume {
 public:
  /// Largest volume create() accepts by default: 8 GiB of voxel data.
  static constexpr std::size_t kDefaultMaxBytes = std::size_t{8} << 30;

  Volume() = default;

  /// A zero-filled volume. Fails on non-positive dims, a size that overflows
  /// or exceeds `maxBytes`, or a singular / non-finite affine.
  static Result<Volume> create(const Vec3i& dims, VoxelType type,
                               const Affine3& indexToWorld = Affine3::Identity(),
                               std::size_t maxBytes = kDefaultMaxBytes);

  const Vec3i& dims() const { return dims_; }
  VoxelType type() const { return type_; }
  std::size_t voxelCount() const { return count_; }
  std::size_t byteSize() const { return data_.size(); }
  bool empty() const { return count_ == 0; }

  /// Raw voxel bytes (x fastest). Writable for importers.
  std::byte* bytes() { return data_.data(); }
  const std::byte* bytes() const { return data_.data(); }
  /// Typed access; DM_DEMAND that T matches type().
  template <class T>
  T* data() {
    DM_DEMAND(VoxelTypeOf<T>::value == type_, "Volume::data<T>() with the wrong voxel type");
    return reinterpret_cast<T*>(data_.data());
  }
  template <class T>
  const T* data() const {
    DM_DEMAND(VoxelTypeOf<T>::value == type_, "Volume::data<T>() with the wrong voxel type");
    return reinterpret_cast<const T*>(data_.data());
  }

  std::size_t linearIndex(int i, int j, int k) const {
    DM_ASSERT(contains(i, j, k), "voxel index out of range");
    return static_cast<std::size_t>(i) +
           static_cast<std::size_t>(dims_.x()) *
               (static_cast<std::size_t>(j) +
                static_cast<std::size_t>(dims_.y()) * static_cast<std::size_t>(k));
  }
  bool contains(int i, int j, int k) const {
    return i >= 0 && j >= 0 && k >= 0 && i < dims_.x() && j < dims_.y() && k < dims_.z();
  }
  /// Voxel value as double, whatever the type.
  double value(int i, int j, int k) const { return valueAt(linearIndex(i, j, k)); }
  double valueAt(std::size_t linear) const;
  /// Stores v converted to the voxel type (rounded and saturated for integers).
  void setValue(int i, int j, int k, double v) { setValueAt(linearIndex(i, j, k), v); }
  void setValueAt(std::size_t linear, double v);

  /// Trilinear interpolation at a continuous voxel index; coordinates are
  /// clamped to the grid (edge values extend outward).
  double sampleIndex(const Vec3& ijk) const;
  /// Trilinear interpolation at a world point (m).
  double sampleWorld(const Vec3& world) const { return sampleIndex(worldToIndex_ * world); }
  /// Central-difference gradient in world units (value per metre) at a voxel.
  Vec3 gradientWorld(int i, int j, int k) const;

  const Affine3& indexToWorld() const { return indexToWorld_; }
  const Affine3& worldToIndex() const { return worldToIndex_; }
  /// Fails like create() on a singular or non-finite affine.
  Status setIndexToWorld(const Affine3& a);
  /// Distance between neighbouring voxel centres along i, j, k, in metres.
  Vec3 spacing() const;
  /// World bounds of the voxel centres' hull.
  Aabb worldBounds() const;
  /// Minimum and maximum voxel value. O(n).
  std::pair<double, double> range() const;

 private:
  Vec3i dims_ = Vec3i::Zero();
  VoxelType type_ = VoxelType::U8;
  std::size_t count_ = 0;
  std::vector<std::byte> data_;
  Affine3 indexToWorld_ = Affine3::Identity();
  Affine3 worldToIndex_ = Affine3::Identity();
};

/// One index-space slice of `volume` as a U8 grey picture: the slice ⟂ index
/// axis `axis` (0 = i, 1 = j, 2 = k) at `index` (clamped to the grid);
/// picture x runs along the first remaining axis, picture y along the second
/// with its highest index in the top row (for an LPS/RAS volume: anterior or
/// superior up); values map linearly from [lo, hi] to 0..255, clamped.
/// InvalidArgument for an empty volume, an axis outside 0..2 or hi <= lo.
/// O(slice).
/// @code
///   const auto [lo, hi] = mri.range();
///   auto axial = dm::volumeSlice(mri, 2, mri.dims().z() / 2, lo, hi);
/// @endcode
Result<Image> volumeSlice(const Volume& volume, int axis, int index, double lo, double hi);

}  // namespace dm
