// Voxel models, sparse storage: an OpenVDB FloatGrid narrow-band level set
// (toSparse(), toDense(), voxel access); see dm/collide/voxel_model.hpp.
// The only DMCollide source that includes OpenVDB (it compiles slowly).
#include <dm/collide/voxel_model.hpp>

#include <openvdb/openvdb.h>
#include <openvdb/tools/SignedFloodFill.h>
#include <openvdb/tree/ValueAccessor.h>

#include <algorithm>
#include <cmath>
#include <exception>
#include <mutex>
#include <new>
#include <string>
#include <utility>

namespace dm {

struct VoxelModel::SparseGrid {
  openvdb::FloatGrid::Ptr grid;
};

namespace {

// Non-registering accessor: cheap to construct on the stack per query, no
// allocation and no lock (the registered kind inserts itself into a
// concurrent map of the tree).
using ConstAccessor = openvdb::tree::ValueAccessor<const openvdb::FloatTree, false>;

void initializeVdb() {
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
}

openvdb::math::Transform::Ptr transformOf(const Affine3& indexToWorld) {
  // OpenVDB matrices act on row vectors: the transpose of Eigen's.
  openvdb::Mat4d m = openvdb::Mat4d::identity();
  const Eigen::Matrix4d e = indexToWorld.matrix();
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) m(r, c) = e(c, r);
  return openvdb::math::Transform::createLinearTransform(m);
}

}  // namespace

float VoxelModel::sparseValue(int i, int j, int k) const noexcept {
  ConstAccessor acc(sparse_->grid->constTree());
  return acc.getValue(openvdb::Coord(i, j, k));
}

void VoxelModel::sparseCorners(int i, int j, int k, int di, int dj, int dk, float out[8]) const noexcept {
  ConstAccessor acc(sparse_->grid->constTree());
  for (int c = 0; c < 8; ++c)
    out[c] =
        acc.getValue(openvdb::Coord(i + ((c & 1) ? di : 0), j + ((c & 2) ? dj : 0), k + ((c & 4) ? dk : 0)));
}

std::size_t VoxelModel::sparseBytes() const noexcept {
  return static_cast<std::size_t>(sparse_->grid->memUsage());
}

Result<std::shared_ptr<const VoxelModel>> VoxelModel::toSparse(double bandWidth) const {
  const std::string where = "dm::VoxelModel::toSparse";
  const Vec3 s = indexToWorld_.linear().colwise().norm().transpose();
  if (!std::isfinite(bandWidth) || bandWidth < s.maxCoeff())
    return fail(ErrorCode::InvalidArgument,
                "band width " + std::to_string(bandWidth) + " m is below the largest voxel spacing " +
                    std::to_string(s.maxCoeff()) + " m",
                where + ": bandWidth", "use at least one voxel, typically three (3 × spacing)");
  const double band = std::min(bandWidth, band_);
  try {
    initializeVdb();
    auto grid = openvdb::FloatGrid::create(static_cast<float>(band));
    grid->setTransform(transformOf(indexToWorld_));
    grid->setGridClass(openvdb::GRID_LEVEL_SET);
    grid->setName("voxel-model");
    {
      auto acc = grid->getAccessor();
      if (storage_ == VoxelStorage::Sparse) {
        for (auto it = sparse_->grid->cbeginValueOn(); it; ++it)
          if (std::abs(*it) < band) acc.setValue(it.getCoord(), *it);
      } else {
        std::size_t idx = 0;
        for (int k = 0; k < dims_.z(); ++k)
          for (int j = 0; j < dims_.y(); ++j)
            for (int i = 0; i < dims_.x(); ++i, ++idx)
              if (std::abs(distance_[idx]) < band) acc.setValue(openvdb::Coord(i, j, k), distance_[idx]);
      }
    }
    // Inactive voxels and tiles take −band inside and +band outside.
    openvdb::tools::signedFloodFill(grid->tree());
    grid->tree().prune();
    std::shared_ptr<VoxelModel> m(new VoxelModel());
    m->storage_ = VoxelStorage::Sparse;
    m->dims_ = dims_;
    m->indexToWorld_ = indexToWorld_;
    m->band_ = band;
    m->lipschitz_ = lipschitz_;  // clamping never steepens the field
    m->occupiedCount_ = occupiedCount_;
    m->sparse_ = std::make_shared<const SparseGrid>(SparseGrid{std::move(grid)});
    m->finish();
    return std::shared_ptr<const VoxelModel>(std::move(m));
  } catch (const std::bad_alloc&) {
    return fail(ErrorCode::Internal, "out of memory building the OpenVDB grid", where, "use a narrower band");
  } catch (const std::exception& e) {
    return fail(ErrorCode::Internal, std::string("OpenVDB: ") + e.what(), where, "please report");
  }
}

Result<std::shared_ptr<const VoxelModel>> VoxelModel::toDense() const {
  const std::string where = "dm::VoxelModel::toDense";
  try {
    const std::size_t n = static_cast<std::size_t>(dims_.x()) * static_cast<std::size_t>(dims_.y()) *
                          static_cast<std::size_t>(dims_.z());
    std::vector<float> d;
    std::vector<std::uint64_t> occ;
    if (storage_ == VoxelStorage::Dense) {
      d = distance_;
      occ = occupancy_;
    } else {
      d.resize(n);
      occ.assign((n + 63) / 64, 0);
      ConstAccessor acc(sparse_->grid->constTree());
      std::size_t idx = 0;
      for (int k = 0; k < dims_.z(); ++k)
        for (int j = 0; j < dims_.y(); ++j)
          for (int i = 0; i < dims_.x(); ++i, ++idx) {
            d[idx] = acc.getValue(openvdb::Coord(i, j, k));
            if (d[idx] < 0) occ[idx >> 6] |= std::uint64_t{1} << (idx & 63);
          }
    }
    auto m = denseFrom(dims_, indexToWorld_, std::move(d), std::move(occ), band_);
    if (!m) return m.error();
    return std::shared_ptr<const VoxelModel>(std::move(*m));
  } catch (const std::bad_alloc&) {
    return fail(ErrorCode::Internal, "out of memory", where, "use a coarser model");
  } catch (const std::exception& e) {
    return fail(ErrorCode::Internal, std::string("OpenVDB: ") + e.what(), where, "please report");
  }
}

}  // namespace dm
