// isosurface.cpp — marching cubes and marching tetrahedra on a dm::Volume.
//
// Three passes, each parallel over z and each deterministic:
//  1. Classify: one bit per node (value > iso), packed 64 nodes to a word per
//     x-row, with the comparison specialised on the voxel type. With
//     closeBorders the bit grid gets a ring of outside nodes around it.
//  2. Count: per node slice k, the crossed lattice edges whose lower node is in
//     slice k (popcounts of XORed rows). A prefix sum gives every slice the
//     first id of its vertices, so vertex ids are global and canonical: slice
//     by slice; inside a slice by edge kind, then row, then x.
//  3. Extract, per slab of node slices: enumerate the crossed edges of each
//     slice (computing the owned vertices' positions and normals straight into
//     the output, and the ids into two rolling per-slice maps), then walk the
//     cells of each layer. Active cells are found 64 at a time from the bit
//     rows (a cell is active when its eight corner bits differ), so empty and
//     full regions cost a few word operations per 64 cells. A slab also
//     enumerates (ids only) the first slice of the next slab, which another
//     thread owns, to find the ids of the shared vertices. Triangles go to a
//     per-slab list in cell order and are concatenated in slab order.
// The output therefore does not depend on the number of threads or slabs.
#include <dm/math/isosurface.hpp>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <new>
#include <string>
#include <thread>
#include <type_traits>
#include <utility>
#include <vector>

#include "mc_tables.hpp"

namespace dm {
namespace {

using detail::kCellEdges;
using detail::kKindStep;
using detail::kSliceKinds;

/// Where a voxel equals iso (integer data at an integer iso, which is what
/// people type) the linear root of every edge from it to an inside
/// neighbour is that voxel itself: one position for several vertices,
/// zero-area triangles, and a mesh that falls apart into non-manifold edges
/// as soon as anything merges vertices by position (an STL file, a mesh
/// tool). Such vertices go this fraction of their edge into it instead: all
/// of them the same fraction, so the little corner cut they make around the
/// voxel keeps its orientation, and far enough apart (3.9 µm at 1 mm voxels)
/// for a float32 STL to keep them distinct.
constexpr double kOnVoxelMargin = 1.0 / 256.0;
/// Any other root stays at least this fraction of its edge off both ends, so
/// that no rounding puts two vertices on one position. It moves only roots
/// that close to a voxel, and by less than 8 nm at 0.5 mm voxels: a wider
/// clamp for every root (1/256 was tried) bends the tiny triangles near
/// voxels that are almost at iso, and the god-object felt it on a torus
/// sampled at 0.5 mm (5.8° off the true normal against 0.8°).
constexpr double kEdgeFloor = 1.0 / 65536.0;

constexpr std::uint64_t lowBits(int n) {
  return n >= 64 ? ~std::uint64_t{0} : n <= 0 ? 0 : (std::uint64_t{1} << n) - 1;
}

/// Runs body(task, worker) for task in [0, tasks) on up to `threads` threads
/// (the caller's included). If the system refuses a thread, fewer do the
/// work. Returns false, after skipping the remaining tasks, if a task ran out
/// of memory (std::bad_alloc must not escape a std::thread).
template <class F>
bool parallelTasks(int tasks, int threads, F&& body) {
  std::atomic<bool> outOfMemory{false};
  std::atomic<int> next{0};
  const auto run = [&](int worker) {
    for (int t = next.fetch_add(1, std::memory_order_relaxed); t < tasks;
         t = next.fetch_add(1, std::memory_order_relaxed)) {
      if (outOfMemory.load(std::memory_order_relaxed)) return;
      try {
        body(t, worker);
      } catch (const std::bad_alloc&) {
        outOfMemory.store(true);
      }
    }
  };
  const int workers = std::max(1, std::min(threads, tasks));
  std::vector<std::thread> pool;
  if (workers > 1) {
    try {
      pool.reserve(static_cast<std::size_t>(workers - 1));
      for (int w = 1; w < workers; ++w) pool.emplace_back(run, w);
    } catch (const std::exception&) {
      // std::system_error or std::bad_alloc: carry on with the threads we have.
    }
  }
  run(0);
  for (auto& t : pool) t.join();
  return !outOfMemory.load();
}

/// inside(v) ⇔ double(v) > iso, computed in a type the compiler vectorises:
/// integers against floor(iso) saturated to the type's range, float against
/// the largest float <= iso, double directly.
template <class T>
struct InsideTest {
  using Wide = std::conditional_t<std::is_floating_point_v<T>, T,
                                  std::conditional_t<(sizeof(T) < 4), std::int32_t, std::int64_t>>;
  Wide threshold;

  explicit InsideTest(double iso) {
    if constexpr (std::is_same_v<T, double>) {
      threshold = iso;
    } else if constexpr (std::is_same_v<T, float>) {
      constexpr float kMax = std::numeric_limits<float>::max();
      if (iso >= static_cast<double>(kMax)) {
        threshold = kMax;
      } else if (iso < -static_cast<double>(kMax)) {
        threshold = -std::numeric_limits<float>::infinity();
      } else {
        float f = static_cast<float>(iso);
        if (static_cast<double>(f) > iso) f = std::nextafter(f, -std::numeric_limits<float>::infinity());
        threshold = f;
      }
    } else {
      const double lo = static_cast<double>(std::numeric_limits<T>::lowest()) - 1.0;
      const double hi = static_cast<double>(std::numeric_limits<T>::max());
      threshold = static_cast<Wide>(std::clamp(std::floor(iso), lo, hi));
    }
  }
  bool operator()(T v) const { return static_cast<Wide>(v) > threshold; }
  /// Every value of T is inside (only possible for integers).
  bool allInside() const {
    if constexpr (std::is_integral_v<T>)
      return threshold < static_cast<Wide>(std::numeric_limits<T>::lowest());
    else
      return false;
  }
  /// No value of T is inside (only possible for integers).
  bool noneInside() const {
    if constexpr (std::is_integral_v<T>)
      return threshold >= static_cast<Wide>(std::numeric_limits<T>::max());
    else
      return false;
  }
};

/// Packs inside(v[b]) into bit b, for b < n (portable path).
template <class T>
std::uint64_t packBitsScalar(const T* v, int n, const InsideTest<T>& inside) {
  std::uint64_t m = 0;
  for (int b = 0; b < n; ++b) m |= std::uint64_t{inside(v[b])} << b;
  return m;
}

/// Packs inside(v[b]) for b < 64. With SSE2 (every x86-64) the comparisons
/// run 16, 8, 4 or 2 lanes at a time and movemask packs the bits; integers
/// compare as signed after flipping the sign bit of unsigned types. Needs
/// lowest(T) <= threshold < max(T) for integers (the caller handles the
/// all-inside and all-outside cases).
template <class T>
std::uint64_t packBits64(const T* v, const InsideTest<T>& inside) {
#if defined(__SSE2__)
  std::uint64_t m = 0;
  if constexpr (std::is_integral_v<T>) {
    constexpr int kBits = 8 * static_cast<int>(sizeof(T));
    using S = std::make_signed_t<T>;
    using U = std::make_unsigned_t<T>;
    constexpr U bias = std::is_signed_v<T> ? U{0} : static_cast<U>(U{1} << (kBits - 1));
    const auto flip = [](T x) { return static_cast<S>(static_cast<U>(static_cast<U>(x) ^ bias)); };
    const S t = flip(static_cast<T>(inside.threshold));
    const auto load = [v](int q) { return _mm_loadu_si128(reinterpret_cast<const __m128i*>(v) + q); };
    if constexpr (kBits == 8) {
      const __m128i b = _mm_set1_epi8(static_cast<char>(bias)), th = _mm_set1_epi8(t);
      for (int q = 0; q < 4; ++q) {
        const __m128i gt = _mm_cmpgt_epi8(_mm_xor_si128(load(q), b), th);
        m |= std::uint64_t{static_cast<std::uint16_t>(_mm_movemask_epi8(gt))} << (16 * q);
      }
    } else if constexpr (kBits == 16) {
      const __m128i b = _mm_set1_epi16(static_cast<short>(bias)), th = _mm_set1_epi16(t);
      for (int q = 0; q < 4; ++q) {
        const __m128i lo = _mm_cmpgt_epi16(_mm_xor_si128(load(2 * q), b), th);
        const __m128i hi = _mm_cmpgt_epi16(_mm_xor_si128(load(2 * q + 1), b), th);
        m |= std::uint64_t{static_cast<std::uint16_t>(_mm_movemask_epi8(_mm_packs_epi16(lo, hi)))}
             << (16 * q);
      }
    } else {
      static_assert(kBits == 32);
      const __m128i b = _mm_set1_epi32(static_cast<int>(bias)), th = _mm_set1_epi32(t);
      for (int q = 0; q < 16; ++q) {
        const __m128i gt = _mm_cmpgt_epi32(_mm_xor_si128(load(q), b), th);
        m |= std::uint64_t{static_cast<unsigned>(_mm_movemask_ps(_mm_castsi128_ps(gt)))} << (4 * q);
      }
    }
  } else if constexpr (std::is_same_v<T, float>) {
    const __m128 th = _mm_set1_ps(inside.threshold);
    for (int q = 0; q < 16; ++q)
      m |= std::uint64_t{static_cast<unsigned>(_mm_movemask_ps(_mm_cmpgt_ps(_mm_loadu_ps(v + 4 * q), th)))}
           << (4 * q);
  } else {
    const __m128d th = _mm_set1_pd(inside.threshold);
    for (int q = 0; q < 32; ++q)
      m |= std::uint64_t{static_cast<unsigned>(_mm_movemask_pd(_mm_cmpgt_pd(_mm_loadu_pd(v + 2 * q), th)))}
           << (2 * q);
  }
  return m;
#else
  return packBitsScalar(v, 64, inside);
#endif
}

/// Set bits of x (a single instruction where the target has one).
inline int popcount64(std::uint64_t x) {
#if defined(__POPCNT__)
  return std::popcount(x);
#else
  // Without -mpopcnt GCC calls a library routine; this is the same SWAR sum inline.
  x = x - ((x >> 1) & 0x5555555555555555ull);
  x = (x & 0x3333333333333333ull) + ((x >> 2) & 0x3333333333333333ull);
  x = (x + (x >> 4)) & 0x0F0F0F0F0F0F0F0Full;
  return static_cast<int>((x * 0x0101010101010101ull) >> 56);
#endif
}

/// The node grid: the volume's voxels, plus a ring of outside nodes when
/// closing the borders. Node (i, j, k) is voxel (i − pad, j − pad, k − pad).
struct Layout {
  int nx, ny, nz;  // voxels
  int pad;         // 0 or 1
  int Nx, Ny, Nz;  // nodes
  int words;       // 64-bit words per node row
  std::size_t row(int j, int k) const {
    return (static_cast<std::size_t>(k) * static_cast<std::size_t>(Ny) + static_cast<std::size_t>(j)) *
           static_cast<std::size_t>(words);
  }
};

Error outOfMemory() {
  return fail(ErrorCode::Unsupported, "out of memory extracting the isosurface", "extractIsosurface",
              "set maxTriangles, crop or downsample the volume, or free memory");
}

template <class T, bool kTets>
class Extractor {
 public:
  static constexpr int kEdges = kTets ? detail::kMtEdgeCount : detail::kMcEdgeCount;
  static constexpr int kKindCount = kTets ? 7 : 3;
  static constexpr int kSliceKindCount = kTets ? 3 : 2;
  // Canonical order of the edge kinds in a slice: the in-slice kinds first, so
  // a neighbour can number them without visiting the others.
  static constexpr std::array<std::uint8_t, 7> kKinds =
      kTets ? std::array<std::uint8_t, 7>{detail::kEdgeX,  detail::kEdgeY,  detail::kEdgeXY, detail::kEdgeZ,
                                          detail::kEdgeXZ, detail::kEdgeYZ, detail::kEdgeXYZ}
            : std::array<std::uint8_t, 7>{detail::kEdgeX, detail::kEdgeY, detail::kEdgeZ, 0, 0, 0, 0};

  Extractor(const Volume& v, const IsosurfaceOptions& o)
      : data_(v.data<T>()),
        iso_(o.iso),
        inside_(o.iso),
        normals_(o.computeNormals),
        cap_(o.maxTriangles),
        progress_(o.progress) {
    const Vec3i d = v.dims();
    const int pad = o.closeBorders ? 1 : 0;
    g_ = Layout{d.x(), d.y(), d.z(), pad, d.x() + 2 * pad, d.y() + 2 * pad, d.z() + 2 * pad, 0};
    g_.words = (g_.Nx + 63) / 64;
    const Mat3 linear = v.indexToWorld().linear();
    const Mat3 normalMap = v.worldToIndex().linear().transpose();
    for (int c = 0; c < 3; ++c)
      for (int r = 0; r < 3; ++r) {
        l_[3 * c + r] = linear(r, c);
        m_[3 * c + r] = normalMap(r, c);
      }
    for (int r = 0; r < 3; ++r) o_[r] = v.indexToWorld().translation()[r];
    flip_ = linear.determinant() < 0;
    sx_ = 1;
    sy_ = static_cast<std::ptrdiff_t>(g_.nx);
    sz_ = sy_ * static_cast<std::ptrdiff_t>(g_.ny);
  }

  Result<Mesh> run(int threads) {
    Mesh mesh;
    report(0.0);
    if (g_.Nx < 2 || g_.Ny < 2 || g_.Nz < 2) return done(std::move(mesh));  // no cells
    if (g_.nx * static_cast<double>(g_.ny) * g_.nz < 32768.0) threads = 1;  // not worth a thread
    threads = std::max(1, std::min(threads, g_.Nz / 2));

    // 1. Classify.
    bits_.assign(static_cast<std::size_t>(g_.Nz) * static_cast<std::size_t>(g_.Ny) *
                     static_cast<std::size_t>(g_.words),
                 0);
    const int chunks = std::min(g_.nz, 8 * threads);
    parallelTasks(chunks, threads, [&](int c, int) {
      for (int z = g_.nz * c / chunks; z < g_.nz * (c + 1) / chunks; ++z) classifySlice(z);
    });  // allocates nothing
    report(0.1);

    // 2. Count the vertices of each node slice and number them.
    std::vector<std::size_t> first(static_cast<std::size_t>(g_.Nz) + 1, 0);
    const int countChunks = std::min(g_.Nz, 8 * threads);
    parallelTasks(countChunks, threads, [&](int c, int) {
      for (int k = g_.Nz * c / countChunks; k < g_.Nz * (c + 1) / countChunks; ++k)
        first[static_cast<std::size_t>(k) + 1] = countSlice(k);
    });  // allocates nothing
    for (std::size_t k = 0; k < static_cast<std::size_t>(g_.Nz); ++k) first[k + 1] += first[k];
    const std::size_t vertexCount = first.back();
    report(0.2);
    if (vertexCount == 0) return done(std::move(mesh));
    if (vertexCount > std::numeric_limits<std::uint32_t>::max())
      return fail(ErrorCode::Unsupported,
                  "isosurface would have " + std::to_string(vertexCount) + " vertices", "extractIsosurface",
                  "meshes index vertices with 32 bits; crop or downsample the volume");
    // Every vertex is on some triangle, and a triangle has three: V <= 3T.
    if (cap_ != 0 && vertexCount / 3 > cap_) return tooManyTriangles();
    first_ = std::move(first);

    mesh.positions.resize(vertexCount);
    positions_ = mesh.positions.data();
    if (normals_) {
      mesh.normals.resize(vertexCount);
      normalsOut_ = mesh.normals.data();
    }

    // 3. Extract, slab by slab.
    const int slabs = threads == 1 ? 1 : std::min(g_.Nz / 2, 4 * threads);
    std::vector<std::vector<Triangle>> slabTriangles(static_cast<std::size_t>(slabs));
    std::vector<Scratch> scratch(static_cast<std::size_t>(threads));
    std::atomic<int> slabsDone{0};
    const bool allocated = parallelTasks(slabs, threads, [&](int s, int worker) {
      auto& sc = scratch[static_cast<std::size_t>(worker)];
      sc.allocate(static_cast<std::size_t>(g_.Nx) * static_cast<std::size_t>(g_.Ny));
      extractSlab(g_.Nz * s / slabs, g_.Nz * (s + 1) / slabs, sc, slabTriangles[static_cast<std::size_t>(s)]);
      const int finished = slabsDone.fetch_add(1, std::memory_order_relaxed) + 1;
      // Worker 0 is the calling thread: only it reports, so the callback
      // never runs concurrently with itself or on a pool thread.
      if (worker == 0) report(0.2 + 0.75 * finished / slabs);
    });
    if (!allocated) return outOfMemory();
    if (stop_.load()) return tooManyTriangles();

    if (slabs == 1) {
      mesh.triangles = std::move(slabTriangles[0]);
    } else {
      std::size_t total = 0;
      for (const auto& t : slabTriangles) total += t.size();
      mesh.triangles.reserve(total);
      for (auto& t : slabTriangles) {
        mesh.triangles.insert(mesh.triangles.end(), t.begin(), t.end());
        std::vector<Triangle>().swap(t);
      }
    }
    return done(std::move(mesh));
  }

 private:
  struct Scratch {
    // ids[kind][slice parity]: vertex id of the crossed edge of that kind whose
    // lower node is (i, j) of the slice, at j·Nx + i. Only crossed entries are
    // written and only crossed entries are read.
    std::array<std::array<std::vector<std::uint32_t>, 2>, detail::kEdgeKinds> ids;
    void allocate(std::size_t n) {
      for (int q = 0; q < kKindCount; ++q)
        for (auto& m : ids[kKinds[static_cast<std::size_t>(q)]])
          if (m.size() != n) m.assign(n, 0);
    }
  };

  // Progress comes from the calling thread only (phase ends and the slabs it
  // finishes), so it never decreases; steps under 1 % are skipped, so the
  // callback runs at most ~100 times whatever the slab count.
  void report(double fraction) {
    if (!progress_ || (fraction < 1.0 && fraction - reported_ < 0.01 && reported_ >= 0.0)) return;
    reported_ = fraction;
    progress_(fraction);
  }
  Mesh done(Mesh mesh) {
    report(1.0);
    return mesh;
  }

  Error tooManyTriangles() const {
    return fail(ErrorCode::Unsupported,
                "isosurface has more than maxTriangles = " + std::to_string(cap_) + " triangles",
                "extractIsosurface", "raise maxTriangles, downsample the volume, or use marching cubes");
  }

  void classifySlice(int z) {
    if (inside_.noneInside()) return;  // the bits are already zero
    const bool all = inside_.allInside();
    const T* slice = data_ + static_cast<std::ptrdiff_t>(z) * sz_;
    for (int y = 0; y < g_.ny; ++y) {
      const T* v = slice + static_cast<std::ptrdiff_t>(y) * sy_;
      std::uint64_t* out = bits_.data() + g_.row(y + g_.pad, z + g_.pad);
      for (int c = 0; c * 64 < g_.nx; ++c) {
        const int n = std::min(64, g_.nx - 64 * c);
        const std::uint64_t m = all       ? lowBits(n)
                                : n == 64 ? packBits64(v + 64 * c, inside_)
                                          : packBitsScalar(v + 64 * c, n, inside_);
        if (g_.pad == 0) {
          out[c] = m;
        } else {
          out[c] |= m << 1;
          if (c + 1 < g_.words) out[c + 1] |= m >> 63;
        }
      }
    }
  }

  /// Bit row of nodes (·, j, k).
  const std::uint64_t* rowBits(int j, int k) const { return bits_.data() + g_.row(j, k); }

  /// Bits w of `r` shifted down by one node (bit i = node i + 1).
  std::uint64_t shifted(const std::uint64_t* r, int w) const {
    return (r[w] >> 1) | (w + 1 < g_.words ? r[w + 1] << 63 : 0);
  }

  /// Calls f(i) for every crossed edge of `kind` whose lower node is (i, j, k),
  /// i ascending.
  template <class F>
  void forEachCrossing(int kind, int j, int k, F&& f) const {
    const auto& s = kKindStep[static_cast<std::size_t>(kind)];
    if (j + s[1] >= g_.Ny || k + s[2] >= g_.Nz) return;
    const std::uint64_t* a = rowBits(j, k);
    const std::uint64_t* b = rowBits(j + s[1], k + s[2]);
    const int valid = g_.Nx - s[0];
    for (int w = 0; w < g_.words; ++w) {
      std::uint64_t x = a[w] ^ (s[0] ? shifted(b, w) : b[w]);
      x &= lowBits(valid - 64 * w);
      while (x) {
        f(64 * w + std::countr_zero(x));
        x &= x - 1;
      }
    }
  }

  std::size_t countSlice(int k) const {
    std::size_t n = 0;
    for (int q = 0; q < kKindCount; ++q) {
      const auto& s = kKindStep[kKinds[static_cast<std::size_t>(q)]];
      if (k + s[2] >= g_.Nz) continue;
      for (int j = 0; j + s[1] < g_.Ny; ++j) {
        const std::uint64_t* a = rowBits(j, k);
        const std::uint64_t* b = rowBits(j + s[1], k + s[2]);
        for (int w = 0; w < g_.words; ++w) {
          const std::uint64_t x = (a[w] ^ (s[0] ? shifted(b, w) : b[w])) & lowBits(g_.Nx - s[0] - 64 * w);
          n += static_cast<std::size_t>(popcount64(x));
        }
      }
    }
    return n;
  }

  /// Numbers the crossed edges of node slice k into the id maps. With `own`,
  /// also computes their vertices and numbers the kinds that leave the slice;
  /// otherwise only the in-slice kinds (all a neighbouring slab needs).
  void enumerateSlice(int k, bool own, Scratch& sc) const {
    std::uint32_t id = static_cast<std::uint32_t>(first_[static_cast<std::size_t>(k)]);
    const int kinds = own ? kKindCount : kSliceKindCount;
    for (int q = 0; q < kinds; ++q) {
      switch (kKinds[static_cast<std::size_t>(q)]) {
        case detail::kEdgeX:
          enumerateKind<detail::kEdgeX>(k, own, sc, id);
          break;
        case detail::kEdgeY:
          enumerateKind<detail::kEdgeY>(k, own, sc, id);
          break;
        case detail::kEdgeXY:
          enumerateKind<detail::kEdgeXY>(k, own, sc, id);
          break;
        case detail::kEdgeZ:
          enumerateKind<detail::kEdgeZ>(k, own, sc, id);
          break;
        case detail::kEdgeXZ:
          enumerateKind<detail::kEdgeXZ>(k, own, sc, id);
          break;
        case detail::kEdgeYZ:
          enumerateKind<detail::kEdgeYZ>(k, own, sc, id);
          break;
        default:
          enumerateKind<detail::kEdgeXYZ>(k, own, sc, id);
          break;
      }
    }
  }

  template <int kKind>
  void enumerateKind(int k, bool own, Scratch& sc, std::uint32_t& id) const {
    std::uint32_t* map = sc.ids[kKind][static_cast<std::size_t>(k & 1)].data();
    for (int j = 0; j < g_.Ny; ++j) {
      std::uint32_t* mapRow = map + static_cast<std::size_t>(j) * static_cast<std::size_t>(g_.Nx);
      forEachCrossing(kKind, j, k, [&](int i) {
        mapRow[i] = id;
        if (own) makeVertex<kKind>(i, j, k, id);
        ++id;
      });
    }
  }

  /// Index-space central-difference gradient at voxel (x, y, z) (p points at
  /// it), one-sided at the border, zero along an axis of one voxel.
  void gradient(const T* p, int x, int y, int z, double g[3]) const {
    const auto diff = [p](int c, int n, std::ptrdiff_t stride) {
      if (c > 0 && c < n - 1) return 0.5 * (static_cast<double>(p[stride]) - static_cast<double>(p[-stride]));
      if (n < 2) return 0.0;
      if (c == 0) return static_cast<double>(p[stride]) - static_cast<double>(p[0]);
      return static_cast<double>(p[0]) - static_cast<double>(p[-stride]);
    };
    g[0] = diff(x, g_.nx, sx_);
    g[1] = diff(y, g_.ny, sy_);
    g[2] = diff(z, g_.nz, sz_);
  }

  bool isVoxel(int x, int y, int z) const {
    return x >= 0 && y >= 0 && z >= 0 && x < g_.nx && y < g_.ny && z < g_.nz;
  }
  const T* voxel(int x, int y, int z) const { return data_ + x * sx_ + y * sy_ + z * sz_; }

  /// Writes normalize(M·d) (M the index-to-world normal map) to normal `id`.
  void storeNormal(std::uint32_t id, const double d[3]) const {
    double n[3];
    for (int r = 0; r < 3; ++r) n[r] = m_[r] * d[0] + m_[3 + r] * d[1] + m_[6 + r] * d[2];
    const double inv = 1.0 / std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    normalsOut_[id] = Vec3(n[0] * inv, n[1] * inv, n[2] * inv);
  }

  /// Vertex `id` on the crossed edge of kind kKind from node (i, j, k).
  template <int kKind>
  void makeVertex(int i, int j, int k, std::uint32_t id) const {
    constexpr int sx = kKindStep[kKind][0], sy = kKindStep[kKind][1], sz = kKindStep[kKind][2];
    const int ax = i - g_.pad, ay = j - g_.pad, az = k - g_.pad;
    const int bx = ax + sx, by = ay + sy, bz = az + sz;
    // Without padding every node is a voxel.
    const bool real = g_.pad == 0 || (isVoxel(ax, ay, az) && isVoxel(bx, by, bz));
    // An edge into the virtual outside ring is cut halfway.
    double t = 0.5;
    const T* pa = nullptr;
    const T* pb = nullptr;
    if (real) {
      pa = voxel(ax, ay, az);
      pb = pa + (sx * sx_ + sy * sy_ + sz * sz_);
      const double va = static_cast<double>(*pa), vb = static_cast<double>(*pb);
      const double r = (iso_ - va) / (vb - va);
      if (r >= 0 && r <= 1)  // false for NaN/Inf values
        t = r == 0   ? kOnVoxelMargin
            : r == 1 ? 1.0 - kOnVoxelMargin
                     : std::clamp(r, kEdgeFloor, 1.0 - kEdgeFloor);
    }
    const double p[3] = {ax + t * sx, ay + t * sy, az + t * sz};
    double w[3];
    for (int r = 0; r < 3; ++r) w[r] = l_[r] * p[0] + l_[3 + r] * p[1] + l_[6 + r] * p[2] + o_[r];
    positions_[id] = Vec3(w[0], w[1], w[2]);
    if (!normals_) return;
    if (real) {
      double ga[3], gb[3];
      gradient(pa, ax, ay, az, ga);
      gradient(pb, bx, by, bz, gb);
      // Outward is downhill: −∇f.
      const double g[3] = {-(ga[0] + t * (gb[0] - ga[0])), -(ga[1] + t * (gb[1] - ga[1])),
                           -(ga[2] + t * (gb[2] - ga[2]))};
      double n[3];
      for (int r = 0; r < 3; ++r) n[r] = m_[r] * g[0] + m_[3 + r] * g[1] + m_[6 + r] * g[2];
      const double len2 = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
      if (len2 > 0 && len2 <= std::numeric_limits<double>::max()) {
        const double inv = 1.0 / std::sqrt(len2);
        normalsOut_[id] = Vec3(n[0] * inv, n[1] * inv, n[2] * inv);
        return;
      }
      // A flat or non-finite gradient: from the inside voxel toward the outside one.
      const double sign = inside_(*pa) ? 1.0 : -1.0;
      const double d[3] = {sign * sx, sign * sy, sign * sz};
      storeNormal(id, d);
      return;
    }
    // A cap: the normal of the border plane(s) the virtual node lies beyond.
    const bool aReal = isVoxel(ax, ay, az);
    const int px = aReal ? bx : ax, py = aReal ? by : ay, pz = aReal ? bz : az;
    const double d[3] = {px < 0        ? -1.0
                         : px >= g_.nx ? 1.0
                                       : 0.0,
                         py < 0        ? -1.0
                         : py >= g_.ny ? 1.0
                                       : 0.0,
                         pz < 0        ? -1.0
                         : pz >= g_.nz ? 1.0
                                       : 0.0};
    storeNormal(id, d);
  }

  void extractSlab(int k0, int k1, Scratch& sc, std::vector<Triangle>& out) {
    const std::size_t expected = first_[static_cast<std::size_t>(k1)] - first_[static_cast<std::size_t>(k0)];
    out.reserve(2 * expected + 16);
    enumerateSlice(k0, true, sc);
    for (int k = k0; k < std::min(k1, g_.Nz - 1); ++k) {
      if (stop_.load(std::memory_order_relaxed)) return;
      enumerateSlice(k + 1, k + 1 < k1, sc);
      const std::size_t before = out.size();
      extractLayer(k, sc, out);
      if (cap_ == 0) continue;
      // The running total crosses the cap in some layer exactly when the final
      // total exceeds it, so the outcome does not depend on the scheduling.
      const std::size_t added = out.size() - before;
      if (produced_.fetch_add(added, std::memory_order_relaxed) + added > cap_)
        stop_.store(true, std::memory_order_relaxed);
    }
  }

  /// Triangles of the cells between node slices k and k + 1.
  void extractLayer(int k, const Scratch& sc, std::vector<Triangle>& out) const {
    const auto& cases = caseTable();
    const std::uint32_t* base[kEdges];
    for (int j = 0; j + 1 < g_.Ny; ++j) {
      const std::uint64_t* r00 = rowBits(j, k);
      const std::uint64_t* r10 = rowBits(j + 1, k);
      const std::uint64_t* r01 = rowBits(j, k + 1);
      const std::uint64_t* r11 = rowBits(j + 1, k + 1);
      bool rowReady = false;
      for (int w = 0; w < g_.words; ++w) {
        const std::uint64_t x00 = r00[w], x10 = r10[w], x01 = r01[w], x11 = r11[w];
        const std::uint64_t s00 = shifted(r00, w), s10 = shifted(r10, w), s01 = shifted(r01, w),
                            s11 = shifted(r11, w);
        const std::uint64_t any = x00 | x10 | x01 | x11 | s00 | s10 | s01 | s11;
        const std::uint64_t all = x00 & x10 & x01 & x11 & s00 & s10 & s01 & s11;
        std::uint64_t active = (any & ~all) & lowBits(g_.Nx - 1 - 64 * w);
        if (!active) continue;
        if (!rowReady) {
          for (int e = 0; e < kEdges; ++e) {
            const auto& ce = kCellEdges[static_cast<std::size_t>(e)];
            const int slot = ce.kind < kSliceKinds ? ((k + ce.dz) & 1) : (k & 1);
            base[e] = sc.ids[ce.kind][static_cast<std::size_t>(slot)].data() +
                      static_cast<std::size_t>(j + ce.dy) * static_cast<std::size_t>(g_.Nx) + ce.dx;
          }
          rowReady = true;
        }
        while (active) {
          const int b = std::countr_zero(active);
          active &= active - 1;
          const unsigned cfg = static_cast<unsigned>(((x00 >> b) & 1) | (((s00 >> b) & 1) << 1) |
                                                     (((x10 >> b) & 1) << 2) | (((s10 >> b) & 1) << 3) |
                                                     (((x01 >> b) & 1) << 4) | (((s01 >> b) & 1) << 5) |
                                                     (((x11 >> b) & 1) << 6) | (((s11 >> b) & 1) << 7));
          const auto& c = cases[cfg];
          const int i = 64 * w + b;
          for (int t = 0; t < c.count; ++t) {
            const std::uint32_t v0 = base[c.edges[3 * t]][i];
            const std::uint32_t v1 = base[c.edges[3 * t + 1]][i];
            const std::uint32_t v2 = base[c.edges[3 * t + 2]][i];
            out.push_back(flip_ ? Triangle{v0, v2, v1} : Triangle{v0, v1, v2});
          }
        }
      }
    }
  }

  static const auto& caseTable() {
    if constexpr (kTets)
      return detail::kMarchingTetsCases;
    else
      return detail::kMarchingCubesCases;
  }

  const T* data_;
  double iso_;
  InsideTest<T> inside_;
  bool normals_;
  std::size_t cap_;
  const std::function<void(double)>& progress_;
  double reported_ = -1.0;  // last fraction passed to progress_
  Layout g_{};
  double l_[9];  // index-to-world linear part, column-major
  double m_[9];  // its inverse transpose (maps index-space gradients to world)
  double o_[3];  // index-to-world translation, m
  bool flip_ = false;
  std::ptrdiff_t sx_ = 1, sy_ = 0, sz_ = 0;
  std::vector<std::uint64_t> bits_;
  std::vector<std::size_t> first_;
  Vec3* positions_ = nullptr;
  Vec3* normalsOut_ = nullptr;
  std::atomic<std::size_t> produced_{0};
  std::atomic<bool> stop_{false};
};

template <class T>
Result<Mesh> extractTyped(const Volume& v, const IsosurfaceOptions& o, int threads) {
  try {
    if (o.method == IsoMethod::MarchingTetrahedra) return Extractor<T, true>(v, o).run(threads);
    return Extractor<T, false>(v, o).run(threads);
  } catch (const std::bad_alloc&) {
    return outOfMemory();
  }
}

}  // namespace

Result<Mesh> extractIsosurface(const Volume& volume, const IsosurfaceOptions& options) {
  if (volume.empty())
    return fail(ErrorCode::InvalidArgument, "volume is empty", "extractIsosurface",
                "load or create the volume before extracting a surface");
  if (!std::isfinite(options.iso))
    return fail(ErrorCode::InvalidArgument, "iso level is not finite (" + std::to_string(options.iso) + ")",
                "extractIsosurface", "pass a finite threshold in the volume's value units");
  if (options.threads < 0)
    return fail(ErrorCode::InvalidArgument, "threads is negative (" + std::to_string(options.threads) + ")",
                "extractIsosurface", "pass 0 for one thread per core, or a positive count");
  int threads = options.threads;
  if (threads == 0) threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  switch (volume.type()) {
    case VoxelType::U8:
      return extractTyped<std::uint8_t>(volume, options, threads);
    case VoxelType::I8:
      return extractTyped<std::int8_t>(volume, options, threads);
    case VoxelType::U16:
      return extractTyped<std::uint16_t>(volume, options, threads);
    case VoxelType::I16:
      return extractTyped<std::int16_t>(volume, options, threads);
    case VoxelType::U32:
      return extractTyped<std::uint32_t>(volume, options, threads);
    case VoxelType::I32:
      return extractTyped<std::int32_t>(volume, options, threads);
    case VoxelType::F32:
      return extractTyped<float>(volume, options, threads);
    case VoxelType::F64:
      return extractTyped<double>(volume, options, threads);
  }
  return fail(ErrorCode::Unsupported, "unknown voxel type", "extractIsosurface");
}

}  // namespace dm
