// isosurface_bench — dm::extractIsosurface against VTK and OpenVDB on one volume.
//
//   isosurface_bench [volume.nii.gz] [iso] [repetitions]
//
// Defaults: /usr/share/mricron/templates/ch2better.nii.gz (301×370×316 uint8,
// MNI colin27 head), iso 40 (skin), 5 repetitions; the best time is shown.
// When the file is missing (or not a uint8 NIfTI-1), a synthetic head-sized
// uint8 phantom of the same dimensions is used instead. Every contender gets
// the same voxels and iso level:
//  - dm MarchingCubes / MarchingTetrahedra, one thread and all threads, with
//    and without normals;
//  - VTK 9.1 vtkFlyingEdges3D on its TBB vtkSMPTools backend, limited to one
//    thread (serial) or not, normals on and off, no scalars or gradients;
//    vtkMarchingCubes (serial), normals on;
//  - OpenVDB tools::volumeToMesh (TBB; serial via tbb::global_control), on a
//    FloatGrid made beforehand with tools::copyFromDense (timed separately).
// The ratio column is the contender's time over dm MC's time in the same
// configuration (threads, normals): above 1 means dm is faster.
// Times include allocating and filling the output.
#include <dm/core/volume.hpp>
#include <dm/math/isosurface.hpp>

#include <tbb/global_control.h>

#include <openvdb/openvdb.h>
#include <openvdb/tools/Dense.h>
#include <openvdb/tools/VolumeToMesh.h>
#include <vtkFlyingEdges3D.h>
#include <vtkImageData.h>
#include <vtkMarchingCubes.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkPolyData.h>
#include <vtkUnsignedCharArray.h>
#include <zlib.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <functional>
#include <random>
#include <string>
#include <thread>
#include <vector>

namespace {

/// Reads a gzipped NIfTI-1 uint8 volume: dims are int16 dim[1..3] at byte 42,
/// datatype int16 at 70 (2 = uint8), pixdim[0..3] float at 76 (mm),
/// vox_offset float at 108. Little-endian hosts only, like the files.
bool loadNiftiU8(const char* path, dm::Volume& out) {
  gzFile f = gzopen(path, "rb");
  if (!f) return false;
  unsigned char header[352];
  if (gzread(f, header, sizeof header) != static_cast<int>(sizeof header)) {
    gzclose(f);
    return false;
  }
  std::int32_t sizeofHdr;
  std::int16_t dim[4], datatype;
  float pixdim[4], voxOffset;
  std::memcpy(&sizeofHdr, header, 4);
  std::memcpy(dim, header + 40, 8);
  std::memcpy(&datatype, header + 70, 2);
  std::memcpy(pixdim, header + 76, 16);
  std::memcpy(&voxOffset, header + 108, 4);
  if (sizeofHdr != 348 || dim[0] < 3 || datatype != 2 || voxOffset < 352) {
    std::fprintf(stderr, "%s: not a uint8 NIfTI-1 volume\n", path);
    gzclose(f);
    return false;
  }
  for (long skip = static_cast<long>(voxOffset) - 352; skip > 0; --skip) gzgetc(f);
  dm::Affine3 a = dm::Affine3::Identity();
  a.linear() = 1e-3 * dm::Vec3(pixdim[1], pixdim[2], pixdim[3]).asDiagonal();
  auto v = dm::Volume::create({dim[1], dim[2], dim[3]}, dm::VoxelType::U8, a);
  if (!v) {
    gzclose(f);
    return false;
  }
  const auto bytes = static_cast<unsigned>(v->byteSize());
  const bool ok = gzread(f, v->bytes(), bytes) == static_cast<int>(bytes);
  gzclose(f);
  if (ok) out = std::move(*v);
  return ok;
}

/// A head-sized phantom: a noisy ellipsoidal "skin" shell around a lumpy
/// "brain", 301×370×316 uint8 at 1 mm.
dm::Volume phantom() {
  const dm::Vec3i d(301, 370, 316);
  dm::Affine3 a = dm::Affine3::Identity();
  a.linear() = 1e-3 * dm::Mat3::Identity();
  auto v = dm::Volume::create(d, dm::VoxelType::U8, a);
  std::mt19937 rng(1);
  std::uniform_int_distribution<int> noise(-12, 12);
  auto* p = v->data<std::uint8_t>();
  for (int k = 0; k < d.z(); ++k)
    for (int j = 0; j < d.y(); ++j)
      for (int i = 0; i < d.x(); ++i) {
        const double x = (i - 150.0) / 80, y = (j - 185.0) / 100, z = (k - 150.0) / 95;
        const double r = std::sqrt(x * x + y * y + z * z);
        double value = 0;
        if (r < 1.0) value = 90 + 40 * std::sin(9 * x) * std::cos(11 * y) * std::sin(7 * z);
        if (r < 1.05 && r >= 0.95) value = 120;
        *p++ = static_cast<std::uint8_t>(std::clamp(value + noise(rng), 0.0, 255.0));
      }
  return std::move(*v);
}

/// Best-of-`reps` wall and CPU (user + system, all threads) seconds. The
/// minimum is the least disturbed run on a shared machine.
struct Time {
  double wall = 1e300, cpu = 1e300;
};
Time bestOf(int reps, const std::function<void()>& f) {
  Time best;
  for (int r = 0; r < reps; ++r) {
    const auto w0 = std::chrono::steady_clock::now();
    const std::clock_t c0 = std::clock();
    f();
    const double cpu = static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC;
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - w0).count();
    best.wall = std::min(best.wall, wall);
    best.cpu = std::min(best.cpu, cpu);
  }
  return best;
}

struct Row {
  std::string name;
  int threads;
  bool normals;
  Time time;
  std::size_t triangles;
};

}  // namespace

int main(int argc, char** argv) {
  const char* path = argc > 1 ? argv[1] : "/usr/share/mricron/templates/ch2better.nii.gz";
  const double iso = argc > 2 ? std::atof(argv[2]) : 40.0;
  const int reps = argc > 3 ? std::max(1, std::atoi(argv[3])) : 5;
  const int cores = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  const std::vector<int> threadCounts = cores > 1 ? std::vector<int>{1, cores} : std::vector<int>{1};

  dm::Volume volume;
  std::string source = path;
  if (!loadNiftiU8(path, volume)) {
    source = "synthetic phantom (file not found or unreadable)";
    volume = phantom();
  }
  const dm::Vec3i d = volume.dims();
  const dm::Vec3 h = volume.spacing();
  const auto voxels = static_cast<double>(volume.voxelCount());
  std::printf(
      "volume: %s\n  %d x %d x %d uint8 (%.1f Mvoxels), spacing %.3g %.3g %.3g mm, iso %g, best of %d\n",
      source.c_str(), d.x(), d.y(), d.z(), voxels / 1e6, h.x() * 1e3, h.y() * 1e3, h.z() * 1e3, iso, reps);

  std::vector<Row> rows;
  std::vector<Row> ours;

  // dm.
  for (auto method : {dm::IsoMethod::MarchingCubes, dm::IsoMethod::MarchingTetrahedra})
    for (int threads : threadCounts)
      for (bool normals : {true, false}) {
        std::size_t tris = 0;
        const dm::IsosurfaceOptions o{
            .iso = iso, .method = method, .computeNormals = normals, .threads = threads};
        const Time s = bestOf(reps, [&] {
          auto m = dm::extractIsosurface(volume, o);
          if (!m) {
            std::fprintf(stderr, "%s\n", m.error().message().c_str());
            std::exit(1);
          }
          tris = m->triangleCount();
        });
        Row r{method == dm::IsoMethod::MarchingCubes ? "dm MarchingCubes" : "dm MarchingTetrahedra", threads,
              normals, s, tris};
        rows.push_back(r);
        if (method == dm::IsoMethod::MarchingCubes) ours.push_back(r);
      }

  // VTK: the same bytes, wrapped without a copy.
  vtkNew<vtkImageData> image;
  image->SetDimensions(d.x(), d.y(), d.z());
  image->SetSpacing(h.x(), h.y(), h.z());
  vtkNew<vtkUnsignedCharArray> scalars;
  scalars->SetArray(reinterpret_cast<unsigned char*>(volume.bytes()),
                    static_cast<vtkIdType>(volume.voxelCount()), 1);
  image->GetPointData()->SetScalars(scalars);
  for (int threads : threadCounts) {
    // vtkSMPTools.h does not compile as C++20 in VTK 9.1, so the TBB backend
    // (the Debian default) is limited through TBB itself.
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism,
                              static_cast<std::size_t>(threads));
    for (bool normals : {true, false}) {
      vtkNew<vtkFlyingEdges3D> fe;
      fe->SetInputData(image);
      fe->SetValue(0, iso);
      fe->SetComputeNormals(normals);
      fe->SetComputeGradients(false);
      fe->SetComputeScalars(false);
      fe->SetInterpolateAttributes(false);
      const Time s = bestOf(reps, [&] {
        fe->Modified();
        fe->Update();
      });
      rows.push_back({"VTK vtkFlyingEdges3D (SMP TBB)", threads, normals, s,
                      static_cast<std::size_t>(fe->GetOutput()->GetNumberOfPolys())});
    }
  }
  {
    vtkNew<vtkMarchingCubes> mc;
    mc->SetInputData(image);
    mc->SetValue(0, iso);
    mc->SetComputeNormals(true);
    mc->SetComputeGradients(false);
    mc->SetComputeScalars(false);
    const Time s = bestOf(reps, [&] {
      mc->Modified();
      mc->Update();
    });
    rows.push_back(
        {"VTK vtkMarchingCubes", 1, true, s, static_cast<std::size_t>(mc->GetOutput()->GetNumberOfPolys())});
  }

  // OpenVDB.
  openvdb::initialize();
  openvdb::FloatGrid::Ptr grid = openvdb::FloatGrid::create(0.0f);
  const openvdb::CoordBBox box(openvdb::Coord(0, 0, 0), openvdb::Coord(d.x() - 1, d.y() - 1, d.z() - 1));
  openvdb::tools::Dense<std::uint8_t, openvdb::tools::LayoutXYZ> dense(
      box, reinterpret_cast<std::uint8_t*>(volume.bytes()));
  const Time convert = bestOf(1, [&] { openvdb::tools::copyFromDense(dense, *grid, 0.0f); });
  std::printf("OpenVDB copyFromDense (not counted below): %.1f ms, %zu active voxels\n", convert.wall * 1e3,
              static_cast<std::size_t>(grid->activeVoxelCount()));
  for (int threads : threadCounts) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism,
                              static_cast<std::size_t>(threads));
    std::size_t tris = 0;
    const Time s = bestOf(reps, [&] {
      std::vector<openvdb::Vec3s> points;
      std::vector<openvdb::Vec3I> triangles;
      std::vector<openvdb::Vec4I> quads;
      openvdb::tools::volumeToMesh(*grid, points, triangles, quads, iso, 0.0);
      tris = triangles.size() + 2 * quads.size();
    });
    rows.push_back({"OpenVDB volumeToMesh (quads x2)", threads, false, s, tris});
  }

  std::printf("\n%-32s %7s %7s %9s %9s %10s %10s %8s %8s\n", "contender", "threads", "normals", "wall ms",
              "cpu ms", "Mvoxels/s", "triangles", "ratio", "cpu rat.");
  for (const Row& r : rows) {
    double ratio = 0, cpuRatio = 0;
    for (const Row& o : ours)
      if (o.threads == r.threads && o.normals == r.normals) {
        ratio = r.time.wall / o.time.wall;
        cpuRatio = r.time.cpu / o.time.cpu;
      }
    std::printf("%-32s %7d %7s %9.1f %9.1f %10.1f %10zu %8.2f %8.2f\n", r.name.c_str(), r.threads,
                r.normals ? "yes" : "no", r.time.wall * 1e3, r.time.cpu * 1e3, voxels / r.time.wall / 1e6,
                r.triangles, ratio, cpuRatio);
  }
  std::printf(
      "\nbest of %d runs; Mvoxels/s from wall time; ratio = contender / dm MarchingCubes with the same "
      "threads\n"
      "and normals, on wall and on CPU time (> 1: dm faster). CPU time sums all threads; on a loaded "
      "machine\n"
      "the single-thread CPU ratio is the fairer one.\n",
      reps);
  return 0;
}
