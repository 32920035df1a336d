// fluid_shaders.hpp (private) — GLSL of FluidRenderer's passes (see
// dm/renderer/fluid_renderer.hpp for the method). All view-space: x right,
// y up, the camera looking down −z; "eye depth" is −z, positive.
#pragma once

namespace dm::fluid_shaders {

/// One camera-facing quad per particle (a 4-vertex strip, instanced): placed
/// one radius in front of the centre with half-size one radius, so it covers
/// the sphere's silhouette for any camera outside the sphere.
inline constexpr const char* kParticleVs = R"(
layout(location = 0) in vec3 a_center;
uniform mat4 u_view;
uniform mat4 u_proj;
uniform float u_radius;
out vec3 v_posView;
flat out vec3 v_centerView;
void main() {
  vec2 corner = vec2((gl_VertexID & 1) == 0 ? -1.0 : 1.0, (gl_VertexID & 2) == 0 ? -1.0 : 1.0);
  vec4 c = u_view * vec4(a_center, 1.0);
  v_centerView = c.xyz;
  v_posView = c.xyz + vec3(corner * u_radius, u_radius);
  gl_Position = u_proj * vec4(v_posView, 1.0);
}
)";

/// The view ray through this fragment against the particle's sphere; the
/// near hit in view space and the chord length; false on a miss. Then the
/// hit's window depth, tested against the scene's (a mesh in front hides it).
inline constexpr const char* kSphereHit = R"(
in vec3 v_posView;
flat in vec3 v_centerView;
uniform mat4 u_proj;
uniform float u_radius;
uniform int u_ortho;
uniform ivec2 u_vpOrigin;  // the viewport's lower-left pixel in the target
layout(binding = 0) uniform sampler2D u_sceneDepth;

bool hitSphere(out vec3 hit, out float chord, out float windowDepth) {
  vec3 o = u_ortho != 0 ? vec3(v_posView.xy, 0.0) : vec3(0.0);
  vec3 d = u_ortho != 0 ? vec3(0.0, 0.0, -1.0) : normalize(v_posView);
  vec3 oc = v_centerView - o;
  float b = dot(oc, d);
  float h = u_radius * u_radius - (dot(oc, oc) - b * b);
  if (h <= 0.0) return false;
  float s = sqrt(h);
  hit = o + (b - s) * d;
  chord = 2.0 * s;
  vec4 clip = u_proj * vec4(hit, 1.0);
  windowDepth = clip.z / clip.w * 0.5 + 0.5;
  if (windowDepth <= 0.0) return false;  // in front of the near plane
  float scene = texelFetch(u_sceneDepth, ivec2(gl_FragCoord.xy) + u_vpOrigin, 0).r;
  return windowDepth < scene;
}
)";

/// Pass 1: the nearest sphere's eye depth (depth-tested among particles).
inline constexpr const char* kDepthFs = R"(
out float o_depth;
void main() {
  vec3 hit;
  float chord, wd;
  if (!hitSphere(hit, chord, wd)) discard;
  gl_FragDepth = wd;
  o_depth = -hit.z;
}
)";

/// Pass 2: chord lengths, summed by additive blending.
inline constexpr const char* kThicknessFs = R"(
uniform float u_thicknessScale;  // particle volume / sphere volume
out float o_thickness;
void main() {
  vec3 hit;
  float chord, wd;
  if (!hitSphere(hit, chord, wd)) discard;
  o_thickness = chord * u_thicknessScale;
}
)";

/// A full-screen triangle.
inline constexpr const char* kFullscreenVs = R"(
void main() {
  vec2 p = vec2((gl_VertexID & 1) != 0 ? 3.0 : -1.0, (gl_VertexID & 2) != 0 ? 3.0 : -1.0);
  gl_Position = vec4(p, 0.0, 1.0);
}
)";

/// Pass 3: one direction of the separable filter. DEPTH: bilateral over the
/// eye depth (pixels without fluid neither count nor change). Otherwise a
/// Gaussian over the thickness, whose radius comes from the raw depth.
inline constexpr const char* kSmoothFs = R"(
#define MAX_RADIUS 16
layout(binding = 0) uniform sampler2D u_src;
layout(binding = 1) uniform sampler2D u_eyeDepth;
uniform ivec2 u_dir;
uniform float u_radiusWorld;     // filter radius, m on the surface
uniform float u_pixelsPerMetre;  // at eye depth 1 m (orthographic: everywhere)
uniform int u_ortho;
uniform float u_rangeScale;      // depth: 1 / the range falloff, 1/m
out float o_value;
ivec2 g_size;

// One tap: the spatial weight w, times (DEPTH) Tukey's biweight of the depth
// difference, (1 - (dz / falloff)^2)^2, zero beyond the falloff; pixels
// without fluid do not count.
void tap(ivec2 q, float w, float centre, inout float sum, inout float wsum) {
  float s = texelFetch(u_src, clamp(q, ivec2(0), g_size - 1), 0).r;
#if DEPTH
  if (s <= 0.0) return;
  float dz = (s - centre) * u_rangeScale;
  float b = max(1.0 - dz * dz, 0.0);
  w *= b * b;
#endif
  sum += w * s;
  wsum += w;
}

void main() {
  ivec2 p = ivec2(gl_FragCoord.xy);
  g_size = textureSize(u_src, 0);
  float z = texelFetch(u_eyeDepth, p, 0).r;
  float v = texelFetch(u_src, p, 0).r;
  if (z <= 0.0) { o_value = v; return; }
  float rpx = u_radiusWorld * u_pixelsPerMetre / (u_ortho != 0 ? 1.0 : z);
  int n = int(min(ceil(rpx), float(MAX_RADIUS)));
  float sigma = max(0.5 * rpx, 0.5);
  float k = -0.5 / (sigma * sigma);
  // Gaussian weights exp(k i^2) by recurrence: two products a tap, no exp.
  float w = 1.0, g = exp(k), step = g * g;
  float sum = v, wsum = 1.0;
  for (int i = 1; i <= n; ++i) {
    w *= g;
    g *= step;
    tap(p + i * u_dir, w, v, sum, wsum);
    tap(p - i * u_dir, w, v, sum, wsum);
  }
  o_value = sum / wsum;
}
)";

/// Passes 4 and 5: normals from the smoothed depth, then the shading, over
/// the target (depth-tested against the scene, depth written).
inline constexpr const char* kCompositeFs = R"(
#define MAX_LIGHTS 8
layout(binding = 0) uniform sampler2D u_depth;      // smoothed eye depth, 0 = no fluid
layout(binding = 1) uniform sampler2D u_thickness;  // m
layout(binding = 2) uniform sampler2D u_sceneColor; // linear (decoded when sRGB)
uniform ivec2 u_vpOrigin;
uniform mat4 u_proj;
uniform mat4 u_invProj;
uniform int u_ortho;
uniform vec3 u_color;
uniform vec3 u_absorption;
uniform float u_f0;
uniform float u_specular;
uniform float u_shininess;
uniform float u_refraction;
uniform vec3 u_ambient;
uniform int u_lightCount;
uniform int u_lightType[MAX_LIGHTS];    // 0 directional, 1 point, 2 spot
uniform vec3 u_lightPos[MAX_LIGHTS];    // view space
uniform vec3 u_lightDir[MAX_LIGHTS];    // view space, unit, direction of travel
uniform vec3 u_lightColor[MAX_LIGHTS];  // colour x intensity
uniform float u_lightRange[MAX_LIGHTS];
uniform vec2 u_lightCone[MAX_LIGHTS];   // cos inner, cos outer
out vec4 o_color;

ivec2 g_size;

// View-space point at eye depth z on the ray through pixel p's centre.
vec3 viewPos(ivec2 p, float z) {
  vec2 ndc = (vec2(p) + 0.5) / vec2(g_size) * 2.0 - 1.0;
  vec4 a = u_invProj * vec4(ndc, -1.0, 1.0);
  vec4 b = u_invProj * vec4(ndc, 1.0, 1.0);
  a /= a.w;
  b /= b.w;
  return mix(a.xyz, b.xyz, (-z - a.z) / (b.z - a.z));
}

// The difference to the neighbour on either side along `dir` whose depth is
// closer to this pixel's; zero when neither has fluid.
vec3 difference(ivec2 p, vec3 here, float z, ivec2 dir) {
  ivec2 a = p + dir, b = p - dir;
  bool hasA = all(greaterThanEqual(a, ivec2(0))) && all(lessThan(a, g_size));
  bool hasB = all(greaterThanEqual(b, ivec2(0))) && all(lessThan(b, g_size));
  float za = hasA ? texelFetch(u_depth, a, 0).r : 0.0;
  float zb = hasB ? texelFetch(u_depth, b, 0).r : 0.0;
  hasA = za > 0.0;
  hasB = zb > 0.0;
  if (hasA && (!hasB || abs(za - z) <= abs(zb - z))) return viewPos(a, za) - here;
  if (hasB) return here - viewPos(b, zb);
  return vec3(0.0);
}

void main() {
  g_size = textureSize(u_depth, 0);
  ivec2 p = ivec2(gl_FragCoord.xy) - u_vpOrigin;
  float z = texelFetch(u_depth, p, 0).r;
  if (z <= 0.0) discard;
  vec3 P = viewPos(p, z);
  vec3 dx = difference(p, P, z, ivec2(1, 0));
  vec3 dy = difference(p, P, z, ivec2(0, 1));
  vec3 V = u_ortho != 0 ? vec3(0.0, 0.0, 1.0) : normalize(-P);
  vec3 n = cross(dx, dy);
  n = dot(n, n) > 0.0 ? normalize(n) : V;
  if (dot(n, V) < 0.0) n = -n;

  float t = texelFetch(u_thickness, p, 0).r;
  vec3 transmit = exp(-u_absorption * t);
  float hidden = 1.0 - exp(-dot(u_absorption, vec3(1.0 / 3.0)) * t);
  ivec2 lo = u_vpOrigin, hi = u_vpOrigin + g_size - 1;
  ivec2 q = clamp(ivec2(gl_FragCoord.xy + n.xy * u_refraction), lo, hi);
  vec3 behind = texelFetch(u_sceneColor, q, 0).rgb;

  vec3 diffuse = u_ambient, spec = vec3(0.0);
  for (int i = 0; i < u_lightCount; ++i) {
    vec3 l;
    float atten = 1.0;
    if (u_lightType[i] == 0) {
      l = -u_lightDir[i];
    } else {
      vec3 d = u_lightPos[i] - P;
      float dist = length(d);
      l = d / max(dist, 1e-6);
      float x = dist / u_lightRange[i];
      float window = clamp(1.0 - x * x * x * x, 0.0, 1.0);
      atten = window * window / max(dist * dist, 1e-8);
      if (u_lightType[i] == 2) atten *= smoothstep(u_lightCone[i].y, u_lightCone[i].x, dot(-l, u_lightDir[i]));
    }
    float nl = dot(n, l);
    if (nl <= 0.0 || atten <= 0.0) continue;
    vec3 e = u_lightColor[i] * atten;
    diffuse += e * nl;
    spec += e * pow(max(dot(n, normalize(l + V)), 0.0), u_shininess);
  }
  float nv = max(dot(n, V), 0.0);
  float F = u_f0 + (1.0 - u_f0) * pow(1.0 - nv, 5.0);
  vec3 color = (1.0 - F) * (behind * transmit + u_color * diffuse * hidden) + F * u_ambient + u_specular * spec;
  vec4 clip = u_proj * vec4(P, 1.0);
  gl_FragDepth = clip.z / clip.w * 0.5 + 0.5;
  o_color = vec4(color, 1.0);
}
)";

}  // namespace dm::fluid_shaders
