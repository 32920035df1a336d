// geometry.cpp — geometry and images for Python: voxelizing a closed mesh
// (occupancy or signed distance), simplifying a mesh (quadric edge
// collapse, with its report), the symmetric Hausdorff distance, and images
// (dm::Image) as NumPy arrays sharing their pixels, read and written as PNG.
#include <dm/core/image.hpp>
#include <dm/io/image_io.hpp>
#include <dm/math/simplify.hpp>
#include <dm/math/voxelize.hpp>

#include <pybind11/numpy.h>
#include <pybind11/stl/filesystem.h>

#include <cstring>
#include <limits>
#include <memory>

#include "arrays.hpp"
#include "bindings.hpp"

namespace dm::python {

namespace {

py::dtype dtypeOf(PixelType t) {
  switch (t) {
    case PixelType::U8:
      return py::dtype::of<std::uint8_t>();
    case PixelType::U16:
      return py::dtype::of<std::uint16_t>();
    case PixelType::F32:
      return py::dtype::of<float>();
  }
  return py::dtype::of<std::uint8_t>();
}

PixelType pixelTypeOf(const py::dtype& d) {
  if (d.is(py::dtype::of<std::uint8_t>())) return PixelType::U8;
  if (d.is(py::dtype::of<std::uint16_t>())) return PixelType::U16;
  if (d.is(py::dtype::of<float>())) return PixelType::F32;
  raise(fail(ErrorCode::Unsupported, "pixels of dtype " + py::str(py::handle(d)).cast<std::string>(), "array",
             "use uint8, uint16 or float32"));
}

}  // namespace

void bindGeometry(py::module_& m) {
  py::class_<Image, std::shared_ptr<Image>>(m, "Image", "A 2-D image: rows of pixels with 1 to 4 channels.")
      .def(py::init([](const py::array& array) {
             if (array.ndim() != 2 && array.ndim() != 3)
               raise(fail(ErrorCode::InvalidArgument, "expected an (h, w) or (h, w, c) array", "array"));
             const int channels = array.ndim() == 3 ? int(array.shape(2)) : 1;
             auto image = std::make_shared<Image>(unwrap(Image::create(
                 int(array.shape(1)), int(array.shape(0)), channels, pixelTypeOf(array.dtype()))));
             const auto c = py::array::ensure(array, py::array::c_style | py::array::forcecast);
             for (int y = 0; y < image->height(); ++y)
               std::memcpy(image->row(y),
                           static_cast<const std::byte*>(c.data()) + std::size_t(y) * image->rowBytes(),
                           image->rowBytes());
             return image;
           }),
           py::arg("array"), "An image of a copy of an (h, w) or (h, w, c) uint8, uint16 or float32 array.")
      .def_property_readonly(
          "array",
          [](const py::object& self) {
            Image& im = self.cast<Image&>();
            const auto item = py::ssize_t(pixelTypeBytes(im.type()));
            return py::array(dtypeOf(im.type()),
                             {py::ssize_t(im.height()), py::ssize_t(im.width()), py::ssize_t(im.channels())},
                             {py::ssize_t(im.strideBytes()), item * im.channels(), item}, im.data(), self);
          },
          "(h, w, c) pixels, sharing the image's memory.")
      .def_property_readonly("width", &Image::width)
      .def_property_readonly("height", &Image::height)
      .def_property_readonly("channels", &Image::channels)
      .def("__repr__", [](const Image& im) {
        return formatString("<dmplatform.Image %dx%d, %d channels>", im.width(), im.height(), im.channels());
      });
  m.def(
      "read_png",
      [](const std::filesystem::path& file) {
        return std::make_shared<Image>(unwrap(released([&] { return readPng(file); })));
      },
      py::arg("path"), "Reads a PNG (8 or 16 bits, gray, gray+alpha, RGB, RGBA).");
  m.def(
      "write_png",
      [](const Image& image, const std::filesystem::path& file) {
        unwrap(released([&] { return writePng(image, file); }));
      },
      py::arg("image"), py::arg("path"), "Writes an 8- or 16-bit image as PNG.");

  m.def(
      "voxelize",
      [](const Mesh& mesh, double voxelSize, bool signedDistance, int padding, double bandWidth) {
        VoxelizeOptions o;
        o.voxelSize = voxelSize;
        o.signedDistance = signedDistance;
        o.paddingVoxels = padding;
        o.bandWidth = bandWidth;
        return std::make_shared<Volume>(unwrap(released([&] { return voxelizeMesh(mesh, o); })));
      },
      py::arg("mesh"), py::arg("voxel_size"), py::arg("signed_distance") = false, py::arg("padding") = 2,
      py::arg("band_width") = 0.0,
      "A closed mesh on the world lattice of voxel_size (m): uint8 occupancy, or float32 signed distance "
      "(negative inside, exact within band_width; 0: everywhere).");
  m.def(
      "simplify",
      [](const Mesh& mesh, double ratio, std::size_t triangles, double maxError, bool preserveBoundary,
         bool preserveTopology) {
        SimplifyOptions o;
        o.targetRatio = ratio;
        o.targetTriangles = triangles;
        o.maxError = maxError;
        o.preserveBoundary = preserveBoundary;
        o.preserveTopology = preserveTopology;
        SimplifyReport report;
        auto out = std::make_shared<Mesh>(unwrap(released([&] { return simplifyMesh(mesh, o, &report); })));
        py::dict r;
        r["triangles_before"] = report.trianglesBefore;
        r["triangles_after"] = report.trianglesAfter;
        r["max_distance"] = report.maxDistance;
        return py::make_tuple(out, r);
      },
      py::arg("mesh"), py::arg("ratio") = 0.5, py::arg("triangles") = 0,
      py::arg("max_error") = std::numeric_limits<double>::infinity(), py::arg("preserve_boundary") = true,
      py::arg("preserve_topology") = true,
      "Quadric edge collapse to a ratio (or a triangle count), never farther than max_error (m) from the "
      "original; returns (mesh, report).");
  m.def(
      "hausdorff",
      [](const Mesh& a, const Mesh& b, int samples) {
        return released([&] { return hausdorffDistance(a, b, samples); });
      },
      py::arg("a"), py::arg("b"), py::arg("samples_per_triangle") = 4,
      "Symmetric Hausdorff distance (m) between two meshes, sampled on their triangles.");
}

}  // namespace dm::python
