// deformed_surface.hpp (private) — the render thread's side of a deforming
// object's surface (soft tissue, membranes): the newest vertex positions a
// physics step published into a triple buffer, over triangles fixed at
// build.
#pragma once

#include <dm/core/mesh.hpp>
#include <dm/core/triple_buffer.hpp>

#include <vector>

namespace dm {

/// Fills `out` from `positions` when a step published since the last call,
/// and on the first call (its triangles are set then and stay; its normals
/// are cleared for the renderer to recompute). One reader thread.
inline bool latestDeformedSurface(TripleBuffer<std::vector<Vec3>>& positions,
                                  const std::vector<Triangle>& triangles, Mesh& out) {
  if (!positions.update() && !out.triangles.empty()) return false;
  if (out.triangles.empty()) out.triangles = triangles;
  out.positions = positions.readBuffer();
  out.normals.clear();  // recomputed by the renderer
  return true;
}

}  // namespace dm
