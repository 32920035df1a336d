// volume_components.cpp — voxel neighbourhoods and connected components
// (see volume_components.hpp).
#include <dm/math/volume_components.hpp>

#include <algorithm>
#include <array>
#include <cstdlib>
#include <limits>
#include <numeric>

namespace dm {

std::span<const Vec3i> neighbourOffsets(Connectivity c) noexcept {
  // Faces, then edges, then corners, so a prefix of 6 / 18 / 26 is each set.
  static const std::array<Vec3i, 26> offsets = [] {
    std::array<Vec3i, 26> o;
    std::size_t n = 0;
    for (int order = 1; order <= 3; ++order)
      for (int dz = -1; dz <= 1; ++dz)
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx)
            if (std::abs(dx) + std::abs(dy) + std::abs(dz) == order) o[n++] = Vec3i(dx, dy, dz);
    return o;
  }();
  return {offsets.data(), static_cast<std::size_t>(c)};
}

Result<Components> labelComponents(const Volume& mask, Connectivity c) {
  constexpr const char* where = "labelComponents";
  if (mask.empty())
    return fail(ErrorCode::InvalidArgument, "the volume is empty", where,
                "pass a volume with at least one voxel");
  const std::size_t n = mask.voxelCount();
  if (n >= std::numeric_limits<std::uint32_t>::max())
    return fail(ErrorCode::Unsupported, formatString("%zu voxels exceed the 32-bit label range", n), where,
                "crop the volume");
  auto labelsVol = Volume::create(mask.dims(), VoxelType::U32, mask.indexToWorld());
  if (!labelsVol) return std::move(labelsVol).error();
  std::uint32_t* label = labelsVol->data<std::uint32_t>();
  constexpr std::uint32_t kUnvisited = std::numeric_limits<std::uint32_t>::max();

  // Union-find over voxel indices; a root is its component's first voxel.
  std::vector<std::uint32_t> parent(n, kUnvisited);
  auto find = [&](std::uint32_t x) {
    while (parent[x] != x) {
      parent[x] = parent[parent[x]];
      x = parent[x];
    }
    return x;
  };
  std::vector<Vec3i> backward;  // neighbours visited before the current voxel
  for (const Vec3i& o : neighbourOffsets(c))
    if (o.z() < 0 || (o.z() == 0 && (o.y() < 0 || (o.y() == 0 && o.x() < 0)))) backward.push_back(o);
  const Vec3i dims = mask.dims();
  std::size_t idx = 0;
  for (int k = 0; k < dims.z(); ++k)
    for (int j = 0; j < dims.y(); ++j)
      for (int i = 0; i < dims.x(); ++i, ++idx) {
        if (mask.valueAt(idx) == 0.0) continue;
        auto self = static_cast<std::uint32_t>(idx);
        parent[idx] = self;
        for (const Vec3i& o : backward) {
          if (!mask.contains(i + o.x(), j + o.y(), k + o.z())) continue;
          const std::size_t nb = mask.linearIndex(i + o.x(), j + o.y(), k + o.z());
          if (parent[nb] == kUnvisited) continue;
          const std::uint32_t a = find(self), b = find(static_cast<std::uint32_t>(nb));
          if (a != b) parent[std::max(a, b)] = std::min(a, b);
        }
      }
  // Provisional labels in order of first voxel, then renumber by size.
  std::vector<std::size_t> sizes;
  for (std::size_t v = 0; v < n; ++v) {
    if (parent[v] == kUnvisited) continue;
    const std::uint32_t r = find(static_cast<std::uint32_t>(v));
    if (r == v) {
      sizes.push_back(0);
      label[v] = static_cast<std::uint32_t>(sizes.size());
    } else {
      label[v] = label[r];
    }
    ++sizes[label[v] - 1];
  }
  std::vector<std::uint32_t> order(sizes.size());
  std::iota(order.begin(), order.end(), 0u);
  std::stable_sort(order.begin(), order.end(),
                   [&](std::uint32_t a, std::uint32_t b) { return sizes[a] > sizes[b]; });
  std::vector<std::uint32_t> remap(sizes.size());
  Components out;
  out.sizes.resize(sizes.size());
  for (std::size_t r = 0; r < order.size(); ++r) {
    remap[order[r]] = static_cast<std::uint32_t>(r + 1);
    out.sizes[r] = sizes[order[r]];
  }
  for (std::size_t v = 0; v < n; ++v)
    if (label[v]) label[v] = remap[label[v] - 1];
  out.labels = std::move(*labelsVol);
  return out;
}

Result<Volume> largestComponent(const Volume& mask, Connectivity c) {
  auto cc = labelComponents(mask, c);
  if (!cc) return std::move(cc).error();
  auto out = Volume::create(mask.dims(), VoxelType::U8, mask.indexToWorld());
  if (!out) return std::move(out).error();
  std::uint8_t* o = out->data<std::uint8_t>();
  const std::uint32_t* l = cc->labels.data<std::uint32_t>();
  for (std::size_t i = 0; i < mask.voxelCount(); ++i) o[i] = l[i] == 1 ? 1 : 0;
  return out;
}

}  // namespace dm
