// dm/core/types.hpp — Eigen vocabulary shared by the whole SDK.
//
// Simulation scalars are double; only GPU buffers use float (converted at
// upload). Units are SI (m, kg, s, N, N·m) and the world frame is
// right-handed; see units.hpp for conversions.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cstdint>

namespace dm {

using Scalar = double;
using Vec2 = Eigen::Vector2d;
using Vec3 = Eigen::Vector3d;
using Vec4 = Eigen::Vector4d;
using Vec6 = Eigen::Matrix<double, 6, 1>;
using VecX = Eigen::VectorXd;
using Mat3 = Eigen::Matrix3d;
using Mat4 = Eigen::Matrix4d;
using Mat6 = Eigen::Matrix<double, 6, 6>;
using MatX = Eigen::MatrixXd;
using Quat = Eigen::Quaterniond;
using AngleAxis = Eigen::AngleAxisd;
using Isometry3 = Eigen::Isometry3d;  ///< rigid transform (rotation + translation)
using Affine3 = Eigen::Affine3d;      ///< general affine map (e.g. voxel index → world)
using Vec2f = Eigen::Vector2f;
using Vec3f = Eigen::Vector3f;
using Vec4f = Eigen::Vector4f;
using Vec3i = Eigen::Vector3i;

/// Axis-aligned box; empty when min > max on any axis.
using Aabb = Eigen::AlignedBox3d;

}  // namespace dm
