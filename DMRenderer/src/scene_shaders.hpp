// scene_shaders.hpp (private) — GLSL 4.50 sources of SceneRenderer: the mesh
// vertex stage shared by every shading model, the lit/unlit fragment stage
// (MODEL 0 unlit, 1 Blinn–Phong, 2 metallic–roughness PBR) and the depth-only
// shadow pass. Vertex attributes: 0 position, 1 normal, 2 uv, 3 colour,
// 4 tangent (xyz, w = bitangent sign); 5..8 the per-instance model matrix,
// 9..11 its normal matrix. Features a material or frame does not use are
// compiled out (COLOR_TEX, NORMAL_TEX, HEIGHT_TEX, VERTEX_COLOR, SHADOWS,
// DIRECTIONAL_ONLY: no point or spot light this frame; SINGLE: a draw of one
// instance takes its matrices as uniforms), not
// branched over at run time, and the light loop runs to the constant NUM_LIGHTS.
//
// HEIGHT_TEX: parallax occlusion mapping. The height map's red channel is the
// relief (1 = the mesh surface, 0 = u_heightScale metres below it). The uv
// offset per metre of depth comes from the screen-space derivatives of the
// world position and uv (the world gradients of u and v in the surface plane),
// so the scale is metres whatever the uv mapping, model scale or tiling; it is
// exact on flat triangles and piecewise constant across curved ones.
#pragma once

namespace dm::scene_glsl {

inline constexpr const char* kMeshVs = R"(
// Variant macros (0 or 1): COLOR_TEX, NORMAL_TEX, HEIGHT_TEX, VERTEX_COLOR, SINGLE.
// Only what a variant reads is interpolated: llvmpipe pays per varying and
// per branch.
layout(location = 0) in vec3 a_position;
layout(location = 1) in vec3 a_normal;
layout(location = 2) in vec2 a_uv;
layout(location = 3) in vec4 a_color;
layout(location = 4) in vec4 a_tangent;
layout(location = 5) in mat4 a_model;
layout(location = 9) in vec4 a_normalMatrix0;  // inverse transpose of the model's 3x3, per instance
layout(location = 10) in vec4 a_normalMatrix1;
layout(location = 11) in vec4 a_normalMatrix2;

uniform mat4 u_viewProj;
#if SINGLE
// One instance: the matrices as uniforms (llvmpipe would fetch seven
// per-instance attributes for every vertex).
uniform mat4 u_model;
uniform mat3 u_normalMatrix;
#define MODEL_MATRIX u_model
#define NORMAL_MATRIX u_normalMatrix
#else
#define MODEL_MATRIX a_model
#define NORMAL_MATRIX mat3(a_normalMatrix0.xyz, a_normalMatrix1.xyz, a_normalMatrix2.xyz)
#endif

out vec3 v_worldPos;
out vec3 v_normal;
#if COLOR_TEX || NORMAL_TEX || HEIGHT_TEX
out vec2 v_uv;
#endif
#if VERTEX_COLOR
out vec4 v_color;
#endif
#if NORMAL_TEX
out vec4 v_tangent;
#endif

void main() {
  vec4 world = MODEL_MATRIX * vec4(a_position, 1.0);
  v_worldPos = world.xyz;
  v_normal = NORMAL_MATRIX * a_normal;
#if NORMAL_TEX
  v_tangent = vec4(mat3(MODEL_MATRIX) * a_tangent.xyz, a_tangent.w);
#endif
#if COLOR_TEX || NORMAL_TEX || HEIGHT_TEX
  v_uv = a_uv;
#endif
#if VERTEX_COLOR
  v_color = a_color;
#endif
  gl_Position = u_viewProj * world;
}
)";

inline constexpr const char* kMeshFs = R"(
#define MAX_LIGHTS 8
#define MAX_SHADOWS 4
#define PI 3.14159265358979

in vec3 v_worldPos;
in vec3 v_normal;
#if COLOR_TEX || NORMAL_TEX || HEIGHT_TEX
in vec2 v_uv;
#endif
#if VERTEX_COLOR
in vec4 v_color;
#endif
#if NORMAL_TEX
in vec4 v_tangent;
#endif

uniform vec4 u_baseColor;
uniform vec3 u_specular;
uniform float u_shininess;
uniform float u_metallic;
uniform float u_roughness;
uniform vec3 u_emissive;
uniform int u_doubleSided;
uniform float u_heightScale;  // m of relief between height 1 and height 0
layout(binding = 0) uniform sampler2D u_colorTex;
layout(binding = 1) uniform sampler2D u_normalTex;
layout(binding = 2) uniform sampler2DArrayShadow u_shadowMaps;
layout(binding = 3) uniform sampler2D u_heightTex;

uniform vec3 u_cameraPos;
uniform vec4 u_orthoToEye;  // orthographic camera: (-forward, 1); perspective: 0
uniform vec3 u_ambient;
uniform int u_lightType[MAX_LIGHTS];      // 0 directional, 1 point, 2 spot
uniform vec3 u_lightPos[MAX_LIGHTS];
uniform vec3 u_lightDir[MAX_LIGHTS];      // unit, direction of travel
uniform vec3 u_lightColor[MAX_LIGHTS];    // colour x intensity
// Blinn-Phong: light colour x specular colour, and x base colour where that
// is the same for every fragment (CONST_BASE), folded on the CPU; then the
// ambient and emissive terms are one uniform too.
#define CONST_BASE (!VERTEX_COLOR && !COLOR_TEX)
uniform vec3 u_lightDiffuse[MAX_LIGHTS];
uniform vec3 u_lightSpecular[MAX_LIGHTS];
uniform vec3 u_ambientEmissive;
uniform float u_lightRange[MAX_LIGHTS];
uniform vec2 u_lightCone[MAX_LIGHTS];     // cos(inner), cos(outer)
uniform int u_lightShadow[MAX_LIGHTS];    // shadow map layer or -1
uniform mat4 u_shadowMatrix[MAX_SHADOWS];
uniform float u_shadowTexel[MAX_SHADOWS];  // world size of a texel (at 1 m for spots)
uniform int u_shadowPerspective[MAX_SHADOWS];

out vec4 o_color;

// Fraction of light reaching p (3x3 PCF over hardware-filtered compares).
float shadowFactor(int layer, vec3 p, vec3 n, vec3 toLight, float lightDist) {
  float texel = u_shadowTexel[layer] * (u_shadowPerspective[layer] != 0 ? lightDist : 1.0);
  // Normal offset grows with the angle between the surface and the light.
  float cosT = clamp(dot(n, toLight), 0.0, 1.0);
  vec3 q = p + n * texel * NORMAL_OFFSET * (1.0 - 0.5 * cosT);
  vec4 s = u_shadowMatrix[layer] * vec4(q, 1.0);
  s.xyz /= s.w;
  s.xyz = s.xyz * 0.5 + 0.5;
  if (s.x <= 0.0 || s.x >= 1.0 || s.y <= 0.0 || s.y >= 1.0 || s.z >= 1.0) return 1.0;
  vec2 size = vec2(textureSize(u_shadowMaps, 0).xy);
  float sum = 0.0;
  for (int dy = -1; dy <= 1; ++dy)
    for (int dx = -1; dx <= 1; ++dx)
      sum += texture(u_shadowMaps, vec4(s.xy + vec2(dx, dy) / size, float(layer), s.z));
  return sum / 9.0;
}

float ggx(float nh, float a) {
  float a2 = a * a;
  float d = nh * nh * (a2 - 1.0) + 1.0;
  return a2 / (PI * d * d);
}

float smithSchlick(float nv, float nl, float roughness) {
  float k = (roughness + 1.0) * (roughness + 1.0) / 8.0;
  return nv / (nv * (1.0 - k) + k) * nl / (nl * (1.0 - k) + k);
}

vec3 schlick(float c, vec3 f0) { return f0 + (1.0 - f0) * pow(1.0 - c, 5.0); }

#if HEIGHT_TEX
// Parallax occlusion mapping: march the view ray below the surface in depth
// layers (8 looking straight down to 32 at grazing angles) until it passes
// under the height field, then intersect the segment between the last two
// samples with the linearly interpolated height field. Returns the uv the ray
// hits. `duvdx`, `duvdy`: the uv derivatives of the unshifted fragment, used
// for every lookup (the loop is non-uniform control flow, and the shifted uv
// jumps at steps, so implicit derivatives would pick wrong mip levels).
vec2 parallaxUv(vec2 uv, vec3 n, vec3 toEye, vec2 duvdx, vec2 duvdy) {
  // World gradients of u and v in the surface plane (n x dp1, dp2 x n basis).
  vec3 dp1 = dFdx(v_worldPos), dp2 = dFdy(v_worldPos);
  vec3 dp2perp = cross(dp2, n), dp1perp = cross(n, dp1);
  float det = dot(dp1, dp2perp);
  float nv = dot(n, toEye);
  if (abs(det) < 1e-30 || nv <= 1e-3) return uv;
  vec3 gradU = (dp2perp * duvdx.x + dp1perp * duvdy.x) / det;
  vec3 gradV = (dp2perp * duvdx.y + dp1perp * duvdy.y) / det;
  // Going one metre deeper along the view ray moves -(toEye - n nv) / nv along the surface.
  vec2 uvPerMetre = -vec2(dot(gradU, toEye), dot(gradV, toEye)) / nv;
  float layers = mix(32.0, 8.0, clamp(nv, 0.0, 1.0));
  float layerDepth = 1.0 / layers;  // in units of u_heightScale
  vec2 layerUv = uvPerMetre * (u_heightScale * layerDepth);
  float rayDepth = 0.0;
  float mapDepth = 1.0 - textureGrad(u_heightTex, uv, duvdx, duvdy).r;
  for (int i = 0; i < 33 && rayDepth < mapDepth; ++i) {  // <= 32 layers reach depth 1; 33 bounds rounding
    uv += layerUv;
    rayDepth += layerDepth;
    mapDepth = 1.0 - textureGrad(u_heightTex, uv, duvdx, duvdy).r;
  }
  // The ray is now at or below the field; the previous sample was above it.
  float after = mapDepth - rayDepth;
  float before = 1.0 - textureGrad(u_heightTex, uv - layerUv, duvdx, duvdy).r - (rayDepth - layerDepth);
  float denom = after - before;
  float w = abs(denom) > 1e-6 ? clamp(after / denom, 0.0, 1.0) : 0.0;
  return uv - layerUv * w;
}
#endif

void main() {
#if HEIGHT_TEX
  // Derivatives before any branch (uniform control flow).
  vec2 duvdx = dFdx(v_uv), duvdy = dFdy(v_uv);
  vec3 surfN = normalize(v_normal);
  if (!gl_FrontFacing) surfN = -surfN;
  vec3 toEye = u_orthoToEye.w != 0.0 ? u_orthoToEye.xyz : normalize(u_cameraPos - v_worldPos);
  vec2 uv = parallaxUv(v_uv, surfN, toEye, duvdx, duvdy);
#define SAMPLE(tex) textureGrad(tex, uv, duvdx, duvdy)
#elif COLOR_TEX || NORMAL_TEX
  vec2 uv = v_uv;
#define SAMPLE(tex) texture(tex, uv)
#endif
  vec4 base = u_baseColor;
#if VERTEX_COLOR
  base *= v_color;
#endif
#if COLOR_TEX
  base *= SAMPLE(u_colorTex);
#endif
#if MODEL == 0
  o_color = vec4(base.rgb + u_emissive, 1.0);
#else
  vec3 n = normalize(v_normal);
  if (u_doubleSided != 0 && !gl_FrontFacing) n = -n;
  vec3 geomN = n;
#if NORMAL_TEX
  {
    vec3 t = v_tangent.xyz - n * dot(n, v_tangent.xyz);
    if (dot(t, t) > 1e-12) {
      t = normalize(t);
      vec3 b = cross(n, t) * (v_tangent.w < 0.0 ? -1.0 : 1.0);
      vec3 m = SAMPLE(u_normalTex).xyz * 2.0 - 1.0;
      n = normalize(mat3(t, b, n) * m);
    }
  }
#endif
  vec3 v = normalize(u_cameraPos - v_worldPos);
  float nv = max(dot(n, v), 1e-4);
#if MODEL == 2
  float rough = clamp(u_roughness, 0.04, 1.0);
  float alpha = rough * rough;
  vec3 f0 = mix(vec3(0.04), base.rgb, u_metallic);
  vec3 diffuseColor = base.rgb * (1.0 - u_metallic);
  vec3 color = u_ambient * (diffuseColor + schlick(nv, f0) * (1.0 - 0.5 * rough));
#elif CONST_BASE
  vec3 color = u_ambientEmissive;
#else
  vec3 color = u_ambient * base.rgb + u_emissive;
#endif
  for (int i = 0; i < NUM_LIGHTS; ++i) {  // a constant: llvmpipe runs dynamic loops far slower
    vec3 l;
    float atten = 1.0;
    float dist = 1.0;
#if DIRECTIONAL_ONLY
    l = -u_lightDir[i];
#else
    if (u_lightType[i] == 0) {
      l = -u_lightDir[i];
    } else {
      vec3 d = u_lightPos[i] - v_worldPos;
      dist = length(d);
      l = d / max(dist, 1e-6);
      float x = dist / u_lightRange[i];
      float window = clamp(1.0 - x * x * x * x, 0.0, 1.0);
      atten = window * window / max(dist * dist, 1e-8);
      if (u_lightType[i] == 2)
        atten *= smoothstep(u_lightCone[i].y, u_lightCone[i].x, dot(-l, u_lightDir[i]));
    }
#endif
    float nl = dot(n, l);
    if (nl <= 0.0 || atten <= 0.0) continue;
#if SHADOWS
    if (u_lightShadow[i] >= 0) atten *= shadowFactor(u_lightShadow[i], v_worldPos, geomN, l, dist);
#endif
    vec3 h = normalize(l + v);
    float nh = max(dot(n, h), 0.0);
#if MODEL == 2
    vec3 e = u_lightColor[i] * atten;
    vec3 f = schlick(max(dot(h, v), 0.0), f0);
    vec3 spec = f * ggx(nh, alpha) * smithSchlick(nv, nl, rough) / (4.0 * nv * nl);
    vec3 kd = (1.0 - f) * diffuseColor / PI;
    color += PI * (kd + spec) * e * nl;
#elif CONST_BASE
    color += (u_lightDiffuse[i] * nl + u_lightSpecular[i] * pow(nh, u_shininess)) * atten;
#else
    color += (base.rgb * u_lightDiffuse[i] * nl + u_lightSpecular[i] * pow(nh, u_shininess)) * atten;
#endif
  }
#if MODEL == 2
  color += u_emissive;
#endif
  o_color = vec4(color, 1.0);
#endif
}
)";

inline constexpr const char* kDepthVs = R"(
layout(location = 0) in vec3 a_position;
layout(location = 5) in mat4 a_model;
uniform mat4 u_viewProj;
void main() { gl_Position = u_viewProj * (a_model * vec4(a_position, 1.0)); }
)";

inline constexpr const char* kDepthFs = R"(
void main() {}
)";

}  // namespace dm::scene_glsl
