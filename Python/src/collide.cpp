// collide.cpp — collision queries for Python: a MeshTree (dm::MeshBvh) over
// a mesh, queried at rigid poses (4x4) for closest points and signed
// distances of many points at once, rays, the distance between two meshes
// with their closest points, whether they intersect and their contacts
// (dm/collide/mesh_query.hpp). Batches run with the GIL released.
#include <dm/collide/bvh.hpp>
#include <dm/collide/mesh_query.hpp>
#include <dm/core/mesh.hpp>

#include <pybind11/numpy.h>

#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

#include "arrays.hpp"
#include "bindings.hpp"

namespace dm::python {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// An (n, 3) float64 array to fill.
py::array_t<double> rows3(std::size_t n) { return py::array_t<double>({py::ssize_t(n), py::ssize_t(3)}); }

std::int64_t triangleOf(std::uint32_t t) { return t == kNoTriangle ? -1 : std::int64_t(t); }

}  // namespace

void bindCollide(py::module_& m) {
  py::class_<MeshBvh, std::shared_ptr<MeshBvh>>(
      m, "MeshTree",
      R"(A bounding volume hierarchy over a mesh's triangles, for collision queries at rigid poses
(4x4 matrices, metres; None is the identity). Built once; queries never copy the mesh.)")
      .def(py::init([](const Mesh& mesh) {
             return std::make_shared<MeshBvh>(unwrap(released([&] { return MeshBvh::build(mesh); })));
           }),
           py::arg("mesh"), "Builds the tree (binned SAH, O(n log n)).")
      .def_property_readonly("triangle_count", &MeshBvh::triangleCount)
      .def_property_readonly("is_closed", &MeshBvh::isClosed,
                             "Every edge shared by two triangles: distances are signed (negative inside).")
      .def_property_readonly(
          "bounds",
          [](const MeshBvh& b) {
            return py::make_tuple(arrayOf(Vec3(b.bounds().min())), arrayOf(Vec3(b.bounds().max())));
          },
          "(min, max) corners of the mesh's box, its own frame.")
      .def(
          "closest_points",
          [](const MeshBvh& tree, const py::object& pointsIn, const py::object& poseIn, double maxDistance) {
            const std::vector<Vec3> points = pointsOf(pointsIn, "points");
            const Isometry3 pose = poseOf(poseIn, "pose");
            std::vector<MeshPointQuery> q(points.size());
            {
              py::gil_scoped_release release;
              for (std::size_t i = 0; i < points.size(); ++i)
                q[i] = closestPointOnMesh(tree, pose, points[i], maxDistance);
            }
            py::array_t<double> distance(py::ssize_t(q.size()));
            py::array_t<double> point = rows3(q.size()), normal = rows3(q.size());
            py::array_t<std::int64_t> triangle(py::ssize_t(q.size()));
            for (std::size_t i = 0; i < q.size(); ++i) {
              const auto r = py::ssize_t(i);
              distance.mutable_at(r) = q[i].distance;
              triangle.mutable_at(r) = triangleOf(q[i].triangle);
              for (int c = 0; c < 3; ++c) {
                point.mutable_at(r, c) = q[i].point[c];
                normal.mutable_at(r, c) = q[i].normal[c];
              }
            }
            py::dict out;
            out["distance"] = distance;
            out["point"] = point;
            out["normal"] = normal;
            out["triangle"] = triangle;
            return out;
          },
          py::arg("points"), py::arg("pose") = py::none(), py::arg("max_distance") = kInf,
          "For (n, 3) world points: distance (signed for a closed mesh, negative inside; inf beyond "
          "max_distance), the closest point and its normal (world) and the triangle (-1: none).")
      .def(
          "raycast",
          [](const MeshBvh& tree, const py::object& originsIn, const py::object& directionsIn,
             const py::object& poseIn, double tMax) {
            const std::vector<Vec3> origins = pointsOf(originsIn, "origins");
            const std::vector<Vec3> directions = pointsOf(directionsIn, "directions");
            if (directions.size() != origins.size() && directions.size() != 1)
              raise(fail(ErrorCode::InvalidArgument,
                         std::to_string(directions.size()) + " directions for " +
                             std::to_string(origins.size()) + " origins",
                         "directions", "give one direction per origin, or one for all"));
            const Isometry3 pose = poseOf(poseIn, "pose");
            std::vector<MeshRayHit> hits(origins.size());
            std::vector<char> hit(origins.size(), 0);
            {
              py::gil_scoped_release release;
              for (std::size_t i = 0; i < origins.size(); ++i)
                hit[i] = raycastMesh(tree, pose, origins[i], directions[directions.size() == 1 ? 0 : i], tMax,
                                     hits[i]);
            }
            py::array_t<double> t(py::ssize_t(hits.size()));
            py::array_t<double> point = rows3(hits.size());
            py::array_t<std::int64_t> triangle(py::ssize_t(hits.size()));
            for (std::size_t i = 0; i < hits.size(); ++i) {
              const auto r = py::ssize_t(i);
              t.mutable_at(r) = hit[i] ? hits[i].t : kInf;
              triangle.mutable_at(r) = hit[i] ? triangleOf(hits[i].triangle) : -1;
              for (int c = 0; c < 3; ++c)
                point.mutable_at(r, c) = hit[i] ? hits[i].point[c] : std::numeric_limits<double>::quiet_NaN();
            }
            py::dict out;
            out["t"] = t;
            out["point"] = point;
            out["triangle"] = triangle;
            return out;
          },
          py::arg("origins"), py::arg("directions"), py::arg("pose") = py::none(), py::arg("t_max") = kInf,
          "First hits of the rays origin + t * direction, t in [0, t_max] (both faces): t (inf: a miss), "
          "the point (NaN: a miss) and the triangle (-1: a miss).")
      .def(
          "distance",
          [](const MeshBvh& a, const MeshBvh& b, const py::object& poseA, const py::object& poseB,
             double maxDistance) {
            const Isometry3 pa = poseOf(poseA, "pose"), pb = poseOf(poseB, "other_pose");
            const MeshDistance d = released([&] { return meshMeshDistance(a, pa, b, pb, maxDistance); });
            py::dict out;
            out["distance"] = d.distance;
            out["point"] = arrayOf(d.pointA);
            out["other_point"] = arrayOf(d.pointB);
            out["triangle"] = triangleOf(d.triangleA);
            out["other_triangle"] = triangleOf(d.triangleB);
            return out;
          },
          py::arg("other"), py::arg("pose") = py::none(), py::arg("other_pose") = py::none(),
          py::arg("max_distance") = kInf,
          "Distance between this mesh and `other` at their poses (0 when they intersect; inf beyond "
          "max_distance) with the closest points (world) and triangles.")
      .def(
          "intersects",
          [](const MeshBvh& a, const MeshBvh& b, const py::object& poseA, const py::object& poseB) {
            const Isometry3 pa = poseOf(poseA, "pose"), pb = poseOf(poseB, "other_pose");
            return released([&] { return meshMeshIntersect(a, pa, b, pb); });
          },
          py::arg("other"), py::arg("pose") = py::none(), py::arg("other_pose") = py::none(),
          "Whether any triangle of this mesh touches one of `other`'s.")
      .def(
          "contacts",
          [](const MeshBvh& a, const MeshBvh& b, const py::object& poseA, const py::object& poseB,
             std::size_t maxContacts) {
            const Isometry3 pa = poseOf(poseA, "pose"), pb = poseOf(poseB, "other_pose");
            std::vector<MeshContact> c;
            released([&] { return meshMeshContacts(a, pa, b, pb, c, maxContacts); });
            py::array_t<double> position = rows3(c.size()), normal = rows3(c.size());
            py::array_t<double> depth(py::ssize_t(c.size()));
            py::array_t<std::int64_t> ta(py::ssize_t(c.size())), tb(py::ssize_t(c.size()));
            for (std::size_t i = 0; i < c.size(); ++i) {
              const auto r = py::ssize_t(i);
              depth.mutable_at(r) = c[i].depth;
              ta.mutable_at(r) = triangleOf(c[i].triangleA);
              tb.mutable_at(r) = triangleOf(c[i].triangleB);
              for (int k = 0; k < 3; ++k) {
                position.mutable_at(r, k) = c[i].position[k];
                normal.mutable_at(r, k) = c[i].normal[k];
              }
            }
            py::dict out;
            out["position"] = position;
            out["normal"] = normal;
            out["depth"] = depth;
            out["triangle"] = ta;
            out["other_triangle"] = tb;
            return out;
          },
          py::arg("other"), py::arg("pose") = py::none(), py::arg("other_pose") = py::none(),
          py::arg("max_contacts") = std::size_t(1) << 20,
          "One contact per intersecting triangle pair: position, the normal along which `other` separates, "
          "an upper bound of the pair's depth, and the triangles.")
      .def("__repr__", [](const MeshBvh& b) {
        return "<dmplatform.MeshTree " + std::to_string(b.triangleCount()) + " triangles" +
               (b.isClosed() ? ", closed>" : ", open>");
      });
}

}  // namespace dm::python
