// light_uniforms.hpp (private) — the scene's lights as the GLSL arrays the
// mesh and fluid shaders read: u_lightType (0 directional, 1 point, 2 spot),
// u_lightPos, u_lightDir (unit, direction of travel), u_lightColor (colour ×
// intensity), u_lightRange and u_lightCone (cosines of the inner and outer
// half-angles), in world space or, through a view matrix, in view space.
#pragma once

#include <dm/renderer/scene_renderer.hpp>
#include <dm/renderer/shader.hpp>

#include <array>
#include <cmath>
#include <cstddef>
#include <numbers>
#include <span>

#include "gl.hpp"

namespace dm::gl {

struct LightUniforms {
  static constexpr int kMax = 8;
  int count = 0;
  std::array<int, kMax> type{};
  std::array<float, 3 * kMax> pos{}, dir{}, color{};
  std::array<float, kMax> range{};
  std::array<float, 2 * kMax> cone{};

  /// Packs the first kMax of `lights`, positions and directions carried
  /// into the frame `toFrame` maps world points to (identity: world).
  void pack(std::span<const Light> lights, const Mat4f& toFrame = Mat4f::Identity()) {
    count = static_cast<int>(std::min<std::size_t>(lights.size(), kMax));
    const Mat3f rot = toFrame.topLeftCorner<3, 3>();
    for (int i = 0; i < count; ++i) {
      const Light& l = lights[std::size_t(i)];
      const auto u = std::size_t(i);
      type[u] = int(l.type);
      const Vec3f p = (toFrame * l.position.cast<float>().homogeneous()).head<3>();
      const Vec3f d = rot * (l.type == Light::Type::Point ? Vec3f(Vec3f::UnitZ())
                                                          : Vec3f(l.direction.normalized().cast<float>()));
      const Vec3f c = l.color * l.intensity;
      for (int k = 0; k < 3; ++k) {
        pos[3 * u + std::size_t(k)] = p[k];
        dir[3 * u + std::size_t(k)] = d[k];
        color[3 * u + std::size_t(k)] = c[k];
      }
      range[u] = float(l.range);
      cone[2 * u] = float(std::cos(l.innerConeDeg * std::numbers::pi / 180));
      cone[2 * u + 1] = float(std::cos(l.outerConeDeg * std::numbers::pi / 180));
    }
  }

  /// Sets the arrays on `p` (nothing when there are no lights).
  void upload(ShaderProgram& p) const {
    if (count == 0) return;
    const GLuint id = p.id();
    glProgramUniform1iv(id, p.location("u_lightType"), count, type.data());
    glProgramUniform3fv(id, p.location("u_lightPos"), count, pos.data());
    glProgramUniform3fv(id, p.location("u_lightDir"), count, dir.data());
    glProgramUniform3fv(id, p.location("u_lightColor"), count, color.data());
    glProgramUniform1fv(id, p.location("u_lightRange"), count, range.data());
    glProgramUniform2fv(id, p.location("u_lightCone"), count, cone.data());
  }
};

}  // namespace dm::gl
