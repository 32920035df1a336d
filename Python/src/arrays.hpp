// arrays.hpp (private) — NumPy at the module's boundary, shared by its
// sources: (n, k) rows of any array-like, 4x4 matrices, affines and rigid
// poses, 3-vectors, and views of C++ rows that share their memory.
#pragma once

#include <dm/core/types.hpp>

#include <pybind11/numpy.h>

#include <string>
#include <vector>

#include "bindings.hpp"

namespace dm::python {

// An (n, columns) C-ordered array of T from any array-like; InvalidArgument
// naming `where` for another shape.
template <class T>
inline py::array_t<T, py::array::c_style | py::array::forcecast> rowsOf(const py::object& o,
                                                                        py::ssize_t columns,
                                                                        const char* where) {
  auto a = py::array_t<T, py::array::c_style | py::array::forcecast>::ensure(o);
  if (!a || a.ndim() != 2 || a.shape(1) != columns)
    raise(fail(ErrorCode::InvalidArgument, "expected an (n, " + std::to_string(columns) + ") array", where));
  return a;
}

inline Mat4 mat4Of(const py::object& o, const char* where) {
  const auto a = rowsOf<double>(o, 4, where);
  if (a.shape(0) != 4) raise(fail(ErrorCode::InvalidArgument, "expected a 4x4 matrix", where));
  Mat4 m;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) m(r, c) = a.at(r, c);
  return m;
}

inline py::array_t<double> arrayOf(const Mat4& m) {
  py::array_t<double> out({4, 4});
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) out.mutable_at(r, c) = m(r, c);
  return out;
}

inline Affine3 affineOf(const Mat4& m, const char* where) {
  if (!m.allFinite() || m.row(3) != Vec4(0, 0, 0, 1).transpose())
    raise(fail(ErrorCode::InvalidArgument, "not a finite affine matrix with last row [0, 0, 0, 1]", where,
               "pass a 4x4 index-to-world matrix (metres)"));
  Affine3 a = Affine3::Identity();
  a.matrix() = m;
  return a;
}

// A rigid pose from a 4x4 matrix (None: the identity); InvalidArgument
// naming `where` when it is not finite and rigid.
inline Isometry3 poseOf(const py::object& o, const char* where) {
  if (o.is_none()) return Isometry3::Identity();
  const Mat4 m = mat4Of(o, where);
  const Mat3 r = m.topLeftCorner<3, 3>();
  if (!m.allFinite() || m.row(3) != Vec4(0, 0, 0, 1).transpose() ||
      (r.transpose() * r - Mat3::Identity()).norm() > 1e-6 || r.determinant() < 0)
    raise(fail(ErrorCode::InvalidArgument,
               "not a rigid pose (rotation and translation, last row [0, 0, 0, 1])", where,
               "pass a 4x4 matrix whose top-left 3x3 is a rotation"));
  Isometry3 pose = Isometry3::Identity();
  pose.linear() = r;
  pose.translation() = m.topRightCorner<3, 1>();
  return pose;
}

// Three finite numbers; InvalidArgument naming `where`.
inline Vec3 vec3Of(const py::object& o, const char* where) {
  auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(o);
  if (!a || a.size() != 3) raise(fail(ErrorCode::InvalidArgument, "expected 3 numbers", where));
  const Vec3 v(a.data()[0], a.data()[1], a.data()[2]);
  if (!v.allFinite()) raise(fail(ErrorCode::InvalidArgument, "expected 3 finite numbers", where));
  return v;
}

// (n, 3) finite points as Vec3s, copied (so that work on them can run
// without the GIL); InvalidArgument naming `where` and the row otherwise.
inline std::vector<Vec3> pointsOf(const py::object& o, const char* where) {
  const auto a = rowsOf<double>(o, 3, where);
  std::vector<Vec3> out(static_cast<std::size_t>(a.shape(0)));
  for (std::size_t i = 0; i < out.size(); ++i) {
    out[i] = Vec3(a.at(py::ssize_t(i), 0), a.at(py::ssize_t(i), 1), a.at(py::ssize_t(i), 2));
    if (!out[i].allFinite())
      raise(fail(ErrorCode::InvalidArgument, "row " + std::to_string(i) + " is not finite", where));
  }
  return out;
}

inline py::array_t<double> arrayOf(const Vec3& v) {
  py::array_t<double> out(3);
  for (int i = 0; i < 3; ++i) out.mutable_at(i) = v[i];
  return out;
}

// Views of C++ rows (vertices, triangles) sharing their memory; `owner`
// keeps it alive.
template <class T, class Vector>
py::array rowsView(Vector& rows, std::size_t columns, const py::object& owner) {
  const auto n = static_cast<py::ssize_t>(rows.size()), c = static_cast<py::ssize_t>(columns);
  const auto item = static_cast<py::ssize_t>(sizeof(T));
  return py::array_t<T>({n, c}, {c * item, item}, reinterpret_cast<T*>(rows.data()), owner);
}

}  // namespace dm::python
