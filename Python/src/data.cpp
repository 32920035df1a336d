// data.cpp — dm::Volume and dm::Mesh for Python: their voxels, vertices and
// triangles as NumPy arrays that share the C++ object's memory (the array
// keeps the object alive), built from arrays (copied), read and written in
// every format DMIO knows, and isosurfaces.
#include <dm/core/mesh.hpp>
#include <dm/core/volume.hpp>
#include <dm/io/mesh_io.hpp>
#include <dm/io/volume_io.hpp>
#include <dm/math/isosurface.hpp>

#include <pybind11/numpy.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <cstring>
#include <memory>
#include <string>

#include "arrays.hpp"
#include "bindings.hpp"

namespace dm::python {

namespace {

py::dtype dtypeOf(VoxelType t) {
  switch (t) {
    case VoxelType::U8:
      return py::dtype::of<std::uint8_t>();
    case VoxelType::I8:
      return py::dtype::of<std::int8_t>();
    case VoxelType::U16:
      return py::dtype::of<std::uint16_t>();
    case VoxelType::I16:
      return py::dtype::of<std::int16_t>();
    case VoxelType::U32:
      return py::dtype::of<std::uint32_t>();
    case VoxelType::I32:
      return py::dtype::of<std::int32_t>();
    case VoxelType::F32:
      return py::dtype::of<float>();
    case VoxelType::F64:
      return py::dtype::of<double>();
  }
  return py::dtype::of<double>();
}

VoxelType voxelTypeOf(const py::dtype& d) {
  const std::pair<py::dtype, VoxelType> types[] = {
      {py::dtype::of<std::uint8_t>(), VoxelType::U8},   {py::dtype::of<std::int8_t>(), VoxelType::I8},
      {py::dtype::of<std::uint16_t>(), VoxelType::U16}, {py::dtype::of<std::int16_t>(), VoxelType::I16},
      {py::dtype::of<std::uint32_t>(), VoxelType::U32}, {py::dtype::of<std::int32_t>(), VoxelType::I32},
      {py::dtype::of<float>(), VoxelType::F32},         {py::dtype::of<double>(), VoxelType::F64}};
  for (const auto& [dt, t] : types)
    if (d.equal(dt)) return t;
  raise(fail(ErrorCode::Unsupported, "voxels of dtype " + py::str(py::handle(d)).cast<std::string>(), "array",
             "use uint8, int8, uint16, int16, uint32, int32, float32 or float64"));
}

// A volume from a C-ordered (z, y, x) array, copied.
std::shared_ptr<Volume> volumeFromArray(const py::array& array, const py::object& affine) {
  if (array.ndim() != 3)
    raise(fail(ErrorCode::InvalidArgument, "the array has " + std::to_string(array.ndim()) + " dimensions",
               "array", "pass a 3-D array indexed [z, y, x]"));
  const VoxelType type = voxelTypeOf(array.dtype());
  const Vec3i dims(static_cast<int>(array.shape(2)), static_cast<int>(array.shape(1)),
                   static_cast<int>(array.shape(0)));
  auto v = unwrap(Volume::create(
      dims, type, affine.is_none() ? Affine3::Identity() : affineOf(mat4Of(affine, "affine"), "affine")));
  const auto c = py::array::ensure(array, py::array::c_style | py::array::forcecast);
  std::memcpy(v.bytes(), c.data(), v.byteSize());
  return std::make_shared<Volume>(std::move(v));
}

}  // namespace

void bindData(py::module_& m) {
  py::class_<Volume, std::shared_ptr<Volume>>(m, "Volume", R"(A 3-D image (CT, MRI, a label map): voxels on a
grid placed in the world (metres) by a 4x4 index-to-world affine.)")
      .def(py::init(&volumeFromArray), py::arg("array"), py::arg("affine") = py::none(),
           "A volume of a copy of `array` (3-D, indexed [z, y, x]; uint8 ... float64) and its affine "
           "(default: identity, 1 m voxels).")
      .def_property_readonly(
          "array",
          [](const py::object& self) {
            Volume& v = self.cast<Volume&>();
            const auto item = static_cast<py::ssize_t>(voxelBytes(v.type()));
            const py::ssize_t nx = v.dims().x(), ny = v.dims().y(), nz = v.dims().z();
            return py::array(dtypeOf(v.type()), {nz, ny, nx}, {nx * ny * item, nx * item, item},
                             static_cast<void*>(v.bytes()), self);
          },
          "The voxels, indexed [z, y, x], sharing the volume's memory (writes change the volume).")
      .def_property(
          "affine", [](const Volume& v) { return arrayOf(v.indexToWorld().matrix()); },
          [](Volume& v, const py::object& a) {
            unwrap(v.setIndexToWorld(affineOf(mat4Of(a, "affine"), "affine")));
          },
          "The 4x4 index-to-world matrix (metres).")
      .def_property_readonly(
          "dims", [](const Volume& v) { return py::make_tuple(v.dims().x(), v.dims().y(), v.dims().z()); },
          "(nx, ny, nz).")
      .def_property_readonly(
          "spacing",
          [](const Volume& v) {
            const Vec3 sp = v.spacing();
            return py::make_tuple(sp.x(), sp.y(), sp.z());
          },
          "Voxel size along x, y, z, m.")
      .def_property_readonly("dtype", [](const Volume& v) { return dtypeOf(v.type()); })
      .def(
          "value",
          [](const Volume& v, int i, int j, int k) {
            if (!v.contains(i, j, k))
              raise(fail(ErrorCode::InvalidArgument,
                         "voxel (" + std::to_string(i) + ", " + std::to_string(j) + ", " + std::to_string(k) +
                             ") is outside the grid",
                         "index"));
            return v.value(i, j, k);
          },
          py::arg("i"), py::arg("j"), py::arg("k"), "The value of voxel (i, j, k) (x, y, z order).")
      .def(
          "index_to_world",
          [](const Volume& v, const py::object& points) {
            const auto ijk = rowsOf<double>(points, 3, "ijk");
            py::array_t<double> out({ijk.shape(0), py::ssize_t{3}});
            for (py::ssize_t r = 0; r < ijk.shape(0); ++r) {
              const Vec3 w = v.indexToWorld() * Vec3(ijk.at(r, 0), ijk.at(r, 1), ijk.at(r, 2));
              for (int c = 0; c < 3; ++c) out.mutable_at(r, c) = w[c];
            }
            return out;
          },
          py::arg("ijk"), "World points (m) of index points, an (n, 3) array in x, y, z order.")
      .def("__repr__", [](const Volume& v) {
        return "<dmplatform.Volume " + std::to_string(v.dims().x()) + "x" + std::to_string(v.dims().y()) +
               "x" + std::to_string(v.dims().z()) + " " + toString(v.type()) + ">";
      });

  py::class_<Mesh, std::shared_ptr<Mesh>>(
      m, "Mesh", "A triangle mesh (metres; triangles counter-clockwise from outside).")
      .def(py::init([](const py::object& positionsIn, const py::object& trianglesIn) {
             const auto positions = rowsOf<double>(positionsIn, 3, "positions");
             const auto triangles = rowsOf<std::int64_t>(trianglesIn, 3, "triangles");
             auto mesh = std::make_shared<Mesh>();
             mesh->positions.resize(static_cast<std::size_t>(positions.shape(0)));
             for (py::ssize_t r = 0; r < positions.shape(0); ++r)
               mesh->positions[static_cast<std::size_t>(r)] =
                   Vec3(positions.at(r, 0), positions.at(r, 1), positions.at(r, 2));
             mesh->triangles.resize(static_cast<std::size_t>(triangles.shape(0)));
             for (py::ssize_t r = 0; r < triangles.shape(0); ++r) {
               for (int c = 0; c < 3; ++c) {
                 const std::int64_t index = triangles.at(r, c);
                 if (index < 0 || index >= positions.shape(0))
                   raise(fail(ErrorCode::InvalidArgument,
                              "triangle " + std::to_string(r) + " names vertex " + std::to_string(index) +
                                  " of " + std::to_string(positions.shape(0)),
                              "triangles"));
                 mesh->triangles[static_cast<std::size_t>(r)][static_cast<std::size_t>(c)] =
                     static_cast<std::uint32_t>(index);
               }
             }
             return mesh;
           }),
           py::arg("positions"), py::arg("triangles"),
           "A mesh of copies of (n, 3) positions and (m, 3) vertex indices.")
      .def_property_readonly(
          "positions",
          [](const py::object& self) { return rowsView<double>(self.cast<Mesh&>().positions, 3, self); },
          "(n, 3) float64 vertex positions, sharing the mesh's memory.")
      .def_property_readonly(
          "normals",
          [](const py::object& self) { return rowsView<double>(self.cast<Mesh&>().normals, 3, self); },
          "(n, 3) float64 unit vertex normals (empty when the mesh has none), sharing its memory.")
      .def_property_readonly(
          "triangles",
          [](const py::object& self) {
            return rowsView<std::uint32_t>(self.cast<Mesh&>().triangles, 3, self);
          },
          "(m, 3) uint32 vertex indices, sharing the mesh's memory.")
      .def("__repr__", [](const Mesh& mesh) {
        return "<dmplatform.Mesh " + std::to_string(mesh.positions.size()) + " vertices, " +
               std::to_string(mesh.triangles.size()) + " triangles>";
      });

  m.def(
      "read_volume",
      [](const std::filesystem::path& file) {
        return std::make_shared<Volume>(unwrap(released([&] { return readVolume(file); })));
      },
      py::arg("path"), "Reads NIfTI, DICOM (any file of the series), MetaImage, NRRD or OpenVDB.");
  m.def(
      "write_volume",
      [](const Volume& v, const std::filesystem::path& file) {
        unwrap(released([&] { return writeVolume(v, file); }));
      },
      py::arg("volume"), py::arg("path"),
      "Writes a volume; the format follows the extension (.nii, .nii.gz, .mha, .nrrd, ...).");
  m.def(
      "read_mesh",
      [](const std::filesystem::path& file, const std::string& unit) {
        MeshImportOptions o;
        o.unit = unit;
        return std::make_shared<Mesh>(unwrap(released([&] { return readMesh(file, o); })));
      },
      py::arg("path"), py::arg("unit") = "m",
      "Reads any format Assimp reads; `unit` is the file's length unit.");
  m.def(
      "write_mesh",
      [](const Mesh& mesh, const std::filesystem::path& file) {
        unwrap(released([&] { return writeMesh(mesh, file); }));
      },
      py::arg("mesh"), py::arg("path"), "Writes STL, OBJ, PLY, glTF, ... (by the extension).");
  m.def(
      "isosurface",
      [](const Volume& v, double level) {
        return std::make_shared<Mesh>(unwrap(released([&] { return extractIsosurface(v, {.iso = level}); })));
      },
      py::arg("volume"), py::arg("level"),
      "The surface where the volume crosses `level` (marching cubes; inside is value > level), world "
      "metres.");
}

}  // namespace dm::python
