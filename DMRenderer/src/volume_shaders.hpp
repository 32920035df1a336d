// volume_shaders.hpp (private) — GLSL 4.50 sources of the volume renderer
// (ShaderProgram adds the #version line and the MODE define).
//
// Conventions shared by every stage: voxel-index space has voxel centres at
// integer indices and the volume box is [-0.5, dims - 0.5]; a texture sample
// at index p uses coordinate (p + 0.5) / dims. Values in the volume texture
// are normalised to [0, 1] over the volume's value range; the transfer
// function table covers the same [0, 1].
#pragma once

namespace dm::volume_shaders {

/// The unit cube's 36 corners (12 triangles, CCW seen from outside) and its
/// six face normals in the order the triangles come (-x, +x, -y, +y, -z, +z).
inline constexpr const char* kCube = R"(
const vec3 kCorner[36] = vec3[36](
  vec3(0,0,0), vec3(0,0,1), vec3(0,1,1), vec3(0,0,0), vec3(0,1,1), vec3(0,1,0),
  vec3(1,0,0), vec3(1,1,0), vec3(1,1,1), vec3(1,0,0), vec3(1,1,1), vec3(1,0,1),
  vec3(0,0,0), vec3(1,0,0), vec3(1,0,1), vec3(0,0,0), vec3(1,0,1), vec3(0,0,1),
  vec3(0,1,0), vec3(0,1,1), vec3(1,1,1), vec3(0,1,0), vec3(1,1,1), vec3(1,1,0),
  vec3(0,0,0), vec3(0,1,0), vec3(1,1,0), vec3(0,0,0), vec3(1,1,0), vec3(1,0,0),
  vec3(0,0,1), vec3(1,0,1), vec3(1,1,1), vec3(0,0,1), vec3(1,1,1), vec3(0,1,1));
const vec3 kFaceNormal[6] = vec3[6](vec3(-1,0,0), vec3(1,0,0), vec3(0,-1,0), vec3(0,1,0), vec3(0,0,-1), vec3(0,0,1));
)";

/// Proxy geometry of the ray caster: the volume box in world space.
inline constexpr const char* kBoxVs = R"(
uniform mat4 u_viewProj;
uniform mat4 u_indexToWorld;
uniform vec3 u_dims;
void main() {
  vec3 idx = kCorner[gl_VertexID] * u_dims - 0.5;
  gl_Position = u_viewProj * (u_indexToWorld * vec4(idx, 1.0));
}
)";

/// Ray caster; MODE 0 composite, 1 MIP, 2 first-hit iso.
inline constexpr const char* kRayFs = R"(
layout(std430, binding = 0) buffer Stats { uint st_rays; uint st_samples; uint st_skipped; uint st_voxels; };
uniform mat4 u_viewProj;
uniform mat4 u_invViewProj;
uniform mat4 u_indexToWorld;
uniform mat4 u_worldToIndex;
uniform mat3 u_gradToWorld;   // transpose of worldToIndex's linear part
uniform vec3 u_dims;
uniform vec4 u_viewport;      // GL window coordinates: x, y (bottom), w, h
uniform sampler3D u_volume;
uniform sampler1D u_tf;
uniform sampler3D u_cells;    // R8: 1 = cell may contribute under the TF
uniform sampler3D u_cellMinMax;
uniform sampler2D u_sceneDepth;
uniform float u_cellSize;
uniform ivec3 u_cellGrid;
uniform float u_step;         // index units
uniform float u_unitLength;   // m
uniform vec2 u_tfMap;         // table coordinate = v * x + y
uniform int u_skip;
uniform int u_stats;
uniform int u_shading;
uniform int u_writeDepth;
uniform float u_termAlpha;
uniform float u_depthAlpha;
uniform vec3 u_lightDir;      // world, towards the light
uniform vec4 u_material;      // ambient, diffuse, specular, shininess
uniform vec2 u_window;        // normalised low, high
uniform float u_iso;          // normalised
uniform vec3 u_isoColor;
out vec4 o_color;

float sampleVolume(vec3 p) { return texture(u_volume, (p + 0.5) / u_dims).r; }

vec3 shade(vec3 rgb, vec3 p, vec3 toEye) {
  vec3 gi = 0.5 * vec3(sampleVolume(p + vec3(1, 0, 0)) - sampleVolume(p - vec3(1, 0, 0)),
                       sampleVolume(p + vec3(0, 1, 0)) - sampleVolume(p - vec3(0, 1, 0)),
                       sampleVolume(p + vec3(0, 0, 1)) - sampleVolume(p - vec3(0, 0, 1)));
  vec3 g = u_gradToWorld * gi;
  float gl = length(g);
  if (gl < 1e-4) return rgb * (u_material.x + u_material.y);
  vec3 n = -g / gl;
  if (dot(n, toEye) < 0.0) n = -n;
  float diff = max(dot(n, u_lightDir), 0.0);
  vec3 h = normalize(u_lightDir + toEye);
  float spec = pow(max(dot(n, h), 0.0), u_material.w);
  return rgb * (u_material.x + u_material.y * diff) + vec3(u_material.z * spec);
}

void main() {
  vec2 ndc = (gl_FragCoord.xy - u_viewport.xy) / u_viewport.zw * 2.0 - 1.0;
  vec4 a = u_invViewProj * vec4(ndc, -1.0, 1.0);
  vec4 b = u_invViewProj * vec4(ndc, 1.0, 1.0);
  vec3 pn = a.xyz / a.w;
  vec3 rayWorld = b.xyz / b.w - pn;
  vec3 o = (u_worldToIndex * vec4(pn, 1.0)).xyz;
  vec3 d = mat3(u_worldToIndex) * rayWorld;
  float len = length(d);
  vec3 dir = d / len;
  vec3 safeDir = mix(dir, vec3(1e-12), equal(dir, vec3(0.0)));
  vec3 inv = 1.0 / safeDir;
  vec3 t0 = (vec3(-0.5) - o) * inv;
  vec3 t1 = (u_dims - 0.5 - o) * inv;
  vec3 tmin = min(t0, t1), tmax = max(t0, t1);
  float sEnter = max(max(max(tmin.x, tmin.y), tmin.z), 0.0);
  float sExit = min(min(min(tmax.x, tmax.y), tmax.z), len);
  float zScene = texelFetch(u_sceneDepth, ivec2(gl_FragCoord.xy), 0).r;
  if (zScene < 1.0) {
    vec4 c = u_invViewProj * vec4(ndc, zScene * 2.0 - 1.0, 1.0);
    float ts = dot(c.xyz / c.w - pn, rayWorld) / dot(rayWorld, rayWorld);
    sExit = min(sExit, ts * len);
  }
  int k = int(ceil(sEnter / u_step));
  int kEnd = int(floor(sExit / u_step));
  if (k > kEnd) discard;
  vec3 toEye = -normalize(rayWorld);
  float stepWorld = length(mat3(u_indexToWorld) * dir) * u_step;
  uint nSamples = 0u, nSkipped = 0u;
  float hitS = -1.0;
#if MODE == 0
  vec4 acc = vec4(0.0);
#elif MODE == 1
  float vmax = 0.0;
#endif
  for (int guard = 0; k <= kEnd && guard < 262144; ++guard) {
    float s = float(k) * u_step;
    vec3 p = o + s * dir;
    if (u_skip != 0) {
      ivec3 c = clamp(ivec3(floor((p + 0.5) / u_cellSize)), ivec3(0), u_cellGrid - 1);
#if MODE == 0
      bool empty = texelFetch(u_cells, c, 0).r < 0.5;
#elif MODE == 1
      bool empty = texelFetch(u_cellMinMax, c, 0).g <= vmax;
#else
      bool empty = texelFetch(u_cellMinMax, c, 0).g < u_iso;
#endif
      if (empty) {
        vec3 clo = vec3(c) * u_cellSize - 0.5;
        vec3 te = max((clo - p) * inv, (clo + u_cellSize - p) * inv);
        float sOut = s + min(min(te.x, te.y), te.z);
        int kn = max(int(ceil(sOut / u_step)), k + 1);
        nSkipped += uint(min(kn, kEnd + 1) - k);
        k = kn;
        continue;
      }
    }
    float v = sampleVolume(p);
    ++nSamples;
#if MODE == 0
    vec4 c = texture(u_tf, v * u_tfMap.x + u_tfMap.y);
    if (c.a > 0.0) {
      float alpha = 1.0 - pow(1.0 - c.a, stepWorld / u_unitLength);
      vec3 rgb = u_shading != 0 ? shade(c.rgb, p, toEye) : c.rgb;
      acc.rgb += (1.0 - acc.a) * alpha * rgb;
      acc.a += (1.0 - acc.a) * alpha;
      if (hitS < 0.0 && acc.a >= u_depthAlpha) hitS = s;
      if (acc.a >= u_termAlpha) break;
    }
#elif MODE == 1
    vmax = max(vmax, v);
    if (vmax >= 1.0) break;
#else
    if (v >= u_iso) {
      float lo = max(s - u_step, sEnter), hi = s;
      for (int i = 0; i < 6; ++i) {
        float mid = 0.5 * (lo + hi);
        if (sampleVolume(o + mid * dir) >= u_iso) hi = mid; else lo = mid;
      }
      hitS = hi;
      break;
    }
#endif
    ++k;
  }
  if (u_stats != 0) {
    atomicAdd(st_rays, 1u);
    atomicAdd(st_samples, nSamples);
    atomicAdd(st_skipped, nSkipped);
  }
#if MODE == 0
  if (acc.a <= 0.0) discard;
  o_color = acc;
#elif MODE == 1
  float g = clamp((vmax - u_window.x) / max(u_window.y - u_window.x, 1e-9), 0.0, 1.0);
  if (g <= 0.0) discard;
  o_color = vec4(g, g, g, g);
#else
  if (hitS < 0.0) discard;
  o_color = vec4(shade(u_isoColor, o + hitS * dir, toEye), 1.0);
#endif
#if MODE != 1
  float depth = zScene;
  if (u_writeDepth != 0 && hitS >= 0.0) {
    vec4 clip = u_viewProj * vec4(pn + rayWorld * (hitS / len), 1.0);
    depth = clamp(clip.z / clip.w * 0.5 + 0.5, 0.0, 1.0);
  }
  gl_FragDepth = depth;
#endif
}
)";

/// Slice plane: a world quad (4 corners), textured from the volume.
inline constexpr const char* kSliceVs = R"(
uniform mat4 u_viewProj;
uniform vec3 u_quad[4];
out vec3 v_world;
void main() {
  const int kIndex[6] = int[6](0, 1, 2, 0, 2, 3);
  v_world = u_quad[kIndex[gl_VertexID]];
  gl_Position = u_viewProj * vec4(v_world, 1.0);
}
)";

inline constexpr const char* kSliceFs = R"(
uniform mat4 u_worldToIndex;
uniform vec3 u_dims;
uniform sampler3D u_volume;
uniform sampler1D u_tf;
uniform vec2 u_tfMap;
uniform vec2 u_window;
uniform int u_useTf;
in vec3 v_world;
out vec4 o_color;
void main() {
  vec3 p = (u_worldToIndex * vec4(v_world, 1.0)).xyz;
  if (any(lessThan(p, vec3(-0.5))) || any(greaterThan(p, u_dims - 0.5))) discard;
  float v = texture(u_volume, (p + 0.5) / u_dims).r;
  vec3 rgb = u_useTf != 0 ? texture(u_tf, v * u_tfMap.x + u_tfMap.y).rgb
                          : vec3(clamp((v - u_window.x) / max(u_window.y - u_window.x, 1e-9), 0.0, 1.0));
  o_color = vec4(rgb, 1.0);
}
)";

/// Voxel cubes: a compute pass appends the voxels at or above the threshold
/// (packed i | j << 16, k), then one instanced draw of 36 vertices each.
inline constexpr const char* kVoxelCs = R"(
layout(local_size_x = 8, local_size_y = 8, local_size_z = 4) in;
layout(std430, binding = 1) buffer Count { uint n_count; };
layout(std430, binding = 2) writeonly buffer Instances { uvec2 inst[]; };
uniform sampler3D u_volume;
uniform ivec3 u_idims;
uniform float u_threshold;
uniform uint u_capacity;
void main() {
  ivec3 ijk = ivec3(gl_GlobalInvocationID);
  if (any(greaterThanEqual(ijk, u_idims))) return;
  if (texelFetch(u_volume, ijk, 0).r >= u_threshold) {
    uint i = atomicAdd(n_count, 1u);
    if (i < u_capacity) inst[i] = uvec2(uint(ijk.x) | (uint(ijk.y) << 16), uint(ijk.z));
  }
}
)";

inline constexpr const char* kVoxelVs = R"(
layout(std430, binding = 2) readonly buffer Instances { uvec2 inst[]; };
uniform mat4 u_viewProj;
uniform mat4 u_indexToWorld;
uniform mat3 u_gradToWorld;
uniform sampler3D u_volume;
uniform sampler1D u_tf;
uniform vec2 u_tfMap;
uniform vec2 u_window;
uniform int u_useTf;
uniform vec3 u_lightDir;
uniform vec4 u_material;
flat out vec3 v_color;
void main() {
  uvec2 e = inst[gl_InstanceID];
  ivec3 ijk = ivec3(int(e.x & 0xffffu), int(e.x >> 16), int(e.y));
  vec3 idx = vec3(ijk) + kCorner[gl_VertexID] - 0.5;
  gl_Position = u_viewProj * (u_indexToWorld * vec4(idx, 1.0));
  vec3 n = normalize(u_gradToWorld * kFaceNormal[gl_VertexID / 6]);
  float v = texelFetch(u_volume, ijk, 0).r;
  vec3 rgb = u_useTf != 0 ? texture(u_tf, v * u_tfMap.x + u_tfMap.y).rgb
                          : vec3(clamp((v - u_window.x) / max(u_window.y - u_window.x, 1e-9), 0.0, 1.0));
  v_color = rgb * (u_material.x + u_material.y * max(dot(n, u_lightDir), 0.0));
}
)";

inline constexpr const char* kVoxelFs = R"(
flat in vec3 v_color;
out vec4 o_color;
void main() { o_color = vec4(v_color, 1.0); }
)";

}  // namespace dm::volume_shaders
