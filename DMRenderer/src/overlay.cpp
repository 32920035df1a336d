// overlay.cpp — the batched 2-D overlay: text from the FreeType atlas,
// rectangles, mitred polylines, sprites and line plots in one vertex array,
// drawn by end() with as few draw calls as sprite textures allow.
#include <dm/renderer/overlay.hpp>
#include <dm/renderer/render_target.hpp>
#include <dm/renderer/shader.hpp>

#include <algorithm>
#include <climits>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <system_error>
#include <utility>
#include <vector>

#include "font_atlas.hpp"
#include "gl.hpp"

namespace dm {

namespace {

constexpr const char* kVs = R"(
layout(location = 0) in vec2 a_pos;
layout(location = 1) in vec2 a_uv;
layout(location = 2) in vec4 a_color;
layout(location = 3) in uint a_mode;
uniform vec2 u_viewport;
out vec2 v_uv;
out vec4 v_color;
flat out uint v_mode;
void main() {
  v_uv = a_uv;
  v_color = a_color;
  v_mode = a_mode;
  gl_Position = vec4(2.0 * a_pos.x / u_viewport.x - 1.0, 1.0 - 2.0 * a_pos.y / u_viewport.y, 0.0, 1.0);
}
)";

// Mode 1 (text): uv in atlas texels, coverage in .r. Mode 2 (sprite): uv normalised.
constexpr const char* kFs = R"(
layout(binding = 0) uniform sampler2D u_font;
layout(binding = 1) uniform sampler2D u_sprite;
in vec2 v_uv;
in vec4 v_color;
flat in uint v_mode;
out vec4 o_color;
void main() {
  vec4 c = v_color;
  if (v_mode == 1u)
    c.a *= textureLod(u_font, v_uv / vec2(textureSize(u_font, 0)), 0.0).r;
  else if (v_mode == 2u)
    c *= textureLod(u_sprite, v_uv, 0.0);
  o_color = c;
}
)";

enum Mode : std::uint32_t { kSolid = 0, kText = 1, kSprite = 2 };

struct Vertex {
  float x, y, u, v;
  float r, g, b, a;
  std::uint32_t mode;
};

struct Batch {
  std::size_t first = 0;
  GLuint texture = 0;  // sprite texture of this run; 0 = none yet
};

struct OverlayTextureSlot {
  GLuint name = 0;
  std::uint32_t generation = 0;
  bool live = false, owned = false, bottomUp = false;
  TextureOptions options;
};

constexpr int kMinTextPx = 4, kMaxTextPx = 256;

int textPixels(float sizePx) {
  if (!std::isfinite(sizePx)) return kMinTextPx;
  return std::clamp(static_cast<int>(std::lround(sizePx)), kMinTextPx, kMaxTextPx);
}

// Grid step 1, 2 or 5 x 10^k giving about `count` intervals over `range`.
float gridStep(float range, int count) {
  const double raw = static_cast<double>(range) / count;
  const double decade = std::pow(10.0, std::floor(std::log10(raw)));
  const double f = raw / decade;
  return static_cast<float>((f < 1.5 ? 1.0 : f < 3.0 ? 2.0 : f < 7.0 ? 5.0 : 10.0) * decade);
}

// Lays out UTF-8 text at one baked size: calls emit(glyph, x, y, w, h) with
// the glyph's pixel rectangle relative to the text box's top-left.
template <class Emit>
TextMetrics layoutText(const detail::BakedSize& baked, int px, std::string_view s, Emit&& emit) {
  const float scale = static_cast<float>(px) / static_cast<float>(baked.px);
  const auto scaled = [scale](float v) { return static_cast<int>(std::lround(v * scale)); };
  TextMetrics m;
  m.ascent = static_cast<int>(std::ceil(static_cast<float>(baked.ascent) * scale));
  m.descent = static_cast<int>(std::ceil(static_cast<float>(baked.descent) * scale));
  m.lineHeight = static_cast<int>(std::ceil(static_cast<float>(baked.lineHeight) * scale));
  m.lines = 1;
  int baseline = m.ascent;
  float pen = 0;
  int inkL = INT_MAX, inkT = INT_MAX, inkR = INT_MIN, inkB = INT_MIN;
  for (std::size_t pos = 0; pos < s.size();) {
    const char32_t cp = detail::nextCodepoint(s, pos);
    if (cp == U'\n') {
      m.width = std::max(m.width, pen);
      pen = 0;
      baseline += m.lineHeight;
      ++m.lines;
      continue;
    }
    if (cp < 32) continue;  // other control characters take no space
    const detail::GlyphInfo& g = baked.glyphs[static_cast<std::size_t>(detail::glyphSlot(cp))];
    if (g.width > 0) {
      const int x = static_cast<int>(std::lround(pen)) + scaled(static_cast<float>(g.left));
      const int y = baseline - scaled(static_cast<float>(g.top));
      const int w = std::max(1, scaled(static_cast<float>(g.width)));
      const int h = std::max(1, scaled(static_cast<float>(g.height)));
      emit(g, x, y, w, h);
      inkL = std::min(inkL, x);
      inkT = std::min(inkT, y);
      inkR = std::max(inkR, x + w);
      inkB = std::max(inkB, y + h);
    }
    pen += g.advance * scale;
  }
  m.width = std::max(m.width, pen);
  m.height = static_cast<float>((m.lines - 1) * m.lineHeight + m.ascent + m.descent);
  if (inkL <= inkR) {
    m.inkLeft = inkL;
    m.inkTop = inkT;
    m.inkRight = inkR;
    m.inkBottom = inkB;
  }
  return m;
}

}  // namespace

struct Overlay::Impl {
  OverlayOptions options;
  detail::FontAtlas font;
  ShaderProgram program;
  GLint viewportLoc = -1;
  GLuint vao = 0, vbo = 0, atlasTex = 0;
  std::size_t vboCapacity = 0;  // vertices
  int maxTextureSize = 0;
  std::vector<Vertex> vertices;
  std::vector<Batch> batches;
  std::vector<Vec2f> plotPoints;  // plot(): one series in pixels
  std::vector<Vec2f> runPoints;   // polyline(): one finite run without repeated points
  std::vector<OverlayTextureSlot> textures;
  const RenderTarget* target = nullptr;
  OverlayStats stats;

  ~Impl() {
    for (OverlayTextureSlot& t : textures)
      if (t.live && t.owned) glDeleteTextures(1, &t.name);
    if (atlasTex != 0) glDeleteTextures(1, &atlasTex);
    if (vbo != 0) glDeleteBuffers(1, &vbo);
    if (vao != 0) glDeleteVertexArrays(1, &vao);
  }

  void useTexture(GLuint tex) {
    if (batches.empty()) {
      batches.push_back({vertices.size(), tex});
    } else if (tex != 0 && batches.back().texture != tex) {
      if (batches.back().texture == 0)
        batches.back().texture = tex;
      else
        batches.push_back({vertices.size(), tex});
    }
  }

  void vertex(float x, float y, float u, float v, const Vec4f& c, Mode mode) {
    vertices.push_back({x, y, u, v, c.x(), c.y(), c.z(), c.w(), mode});
  }

  // Quad a-b-c-d (in order around it) as two triangles.
  void quad(const Vec2f& a, const Vec2f& b, const Vec2f& c, const Vec2f& d, const Vec4f& color) {
    useTexture(0);
    vertex(a.x(), a.y(), 0, 0, color, kSolid);
    vertex(b.x(), b.y(), 0, 0, color, kSolid);
    vertex(c.x(), c.y(), 0, 0, color, kSolid);
    vertex(a.x(), a.y(), 0, 0, color, kSolid);
    vertex(c.x(), c.y(), 0, 0, color, kSolid);
    vertex(d.x(), d.y(), 0, 0, color, kSolid);
  }

  void texturedRect(float x0, float y0, float x1, float y1, float u0, float v0, float u1, float v1,
                    const Vec4f& color, Mode mode) {
    vertex(x0, y0, u0, v0, color, mode);
    vertex(x1, y0, u1, v0, color, mode);
    vertex(x1, y1, u1, v1, color, mode);
    vertex(x0, y0, u0, v0, color, mode);
    vertex(x1, y1, u1, v1, color, mode);
    vertex(x0, y1, u0, v1, color, mode);
  }

  void fill(float x, float y, float w, float h, const Vec4f& color) {
    if (!(w > 0 && h > 0)) return;
    quad(Vec2f(x, y), Vec2f(x + w, y), Vec2f(x + w, y + h), Vec2f(x, y + h), color);
  }

  // One finite run of a polyline, repeated points already removed.
  void strokeRun(std::span<const Vec2f> p, const Vec4f& color, float width) {
    const std::size_t m = p.size();
    if (m < 2) return;
    const float hw = 0.5f * width;
    const auto normal = [&](std::size_t k) {
      const Vec2f d = (p[k + 1] - p[k]).normalized();
      return Vec2f(-d.y(), d.x());
    };
    Vec2f prevL, prevR;
    for (std::size_t j = 0; j < m; ++j) {
      Vec2f off;
      if (j == 0) {
        off = normal(0) * hw;
      } else if (j == m - 1) {
        off = normal(m - 2) * hw;
      } else {
        const Vec2f n1 = normal(j);
        const Vec2f miter = normal(j - 1) + n1;
        const float len = miter.norm();
        if (len < 1e-3f) {
          off = n1 * hw;  // the line turns back on itself
        } else {
          // The miter keeps the line width constant; limit its length at sharp turns.
          const Vec2f dir = miter / len;
          off = dir * (hw / std::max(dir.dot(n1), 0.25f));
        }
      }
      const Vec2f l = p[j] + off, r = p[j] - off;
      if (j > 0) quad(prevL, prevR, r, l, color);
      prevL = l;
      prevR = r;
    }
  }

  Status uploadAtlas() {
    if (!font.dirty()) return ok();
    if (font.grown() || atlasTex == 0) {
      if (atlasTex != 0) glDeleteTextures(1, &atlasTex);
      glCreateTextures(GL_TEXTURE_2D, 1, &atlasTex);
      glTextureStorage2D(atlasTex, 1, GL_R8, font.width(), font.height());
      glTextureParameteri(atlasTex, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
      glTextureParameteri(atlasTex, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
      glTextureParameteri(atlasTex, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
      glTextureParameteri(atlasTex, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
    }
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    glPixelStorei(GL_UNPACK_ROW_LENGTH, 0);
    glTextureSubImage2D(atlasTex, 0, 0, 0, font.width(), font.height(), GL_RED, GL_UNSIGNED_BYTE,
                        font.pixels());
    glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
    font.clearDirty();
    stats.atlasWidth = font.width();
    stats.atlasHeight = font.height();
    stats.bakedSizes = font.bakedCount();
    return gl::check("Overlay: glyph atlas upload");
  }

  const OverlayTextureSlot* slot(SpriteId id) const {
    if (!id.valid() || id.index >= textures.size()) return nullptr;
    const OverlayTextureSlot& t = textures[id.index];
    return t.live && t.generation == id.generation ? &t : nullptr;
  }

  // Uploads `image` into slot `s` (new storage when `fresh`).
  Status upload(OverlayTextureSlot& s, const Image& image, bool fresh) {
    if (image.empty() || image.type() != PixelType::U8 || image.channels() < 1 || image.channels() > 4)
      return fail(
          ErrorCode::Unsupported,
          formatString("sprite image is %s with %d channels", toString(image.type()), image.channels()),
          "Overlay::createTexture", "give a non-empty U8 image with 1 to 4 channels");
    if (image.width() > maxTextureSize || image.height() > maxTextureSize)
      return fail(ErrorCode::InvalidArgument,
                  formatString("sprite image %dx%d exceeds GL_MAX_TEXTURE_SIZE %d", image.width(),
                               image.height(), maxTextureSize),
                  "Overlay::createTexture", "downscale the image");
    // Expand to RGBA8 so every channel count samples the same way (an upload, not a frame: allocating is
    // fine).
    std::vector<std::uint8_t> rgba(static_cast<std::size_t>(image.width()) *
                                   static_cast<std::size_t>(image.height()) * 4);
    const int c = image.channels();
    std::size_t o = 0;
    for (int y = 0; y < image.height(); ++y) {
      const auto* row = reinterpret_cast<const std::uint8_t*>(image.row(y));
      for (int x = 0; x < image.width(); ++x, o += 4) {
        const std::uint8_t* px = row + static_cast<std::size_t>(x) * static_cast<std::size_t>(c);
        const bool gray = c <= 2;
        rgba[o] = px[0];
        rgba[o + 1] = gray ? px[0] : px[1];
        rgba[o + 2] = gray ? px[0] : px[2];
        rgba[o + 3] = c == 2 ? px[1] : c == 4 ? px[3] : 255;
      }
    }
    if (fresh) {
      if (s.name != 0 && s.owned) glDeleteTextures(1, &s.name);
      glCreateTextures(GL_TEXTURE_2D, 1, &s.name);
      glTextureStorage2D(s.name, 1, s.options.srgb ? GL_SRGB8_ALPHA8 : GL_RGBA8, image.width(),
                         image.height());
      const GLint filter = s.options.linear ? GL_LINEAR : GL_NEAREST;
      glTextureParameteri(s.name, GL_TEXTURE_MIN_FILTER, filter);
      glTextureParameteri(s.name, GL_TEXTURE_MAG_FILTER, filter);
      glTextureParameteri(s.name, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
      glTextureParameteri(s.name, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
    }
    glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
    glPixelStorei(GL_UNPACK_ROW_LENGTH, 0);
    glTextureSubImage2D(s.name, 0, 0, 0, image.width(), image.height(), GL_RGBA, GL_UNSIGNED_BYTE,
                        rgba.data());
    return gl::check("Overlay: sprite texture upload");
  }

  SpriteId addSlot(OverlayTextureSlot s) {
    for (std::size_t i = 0; i < textures.size(); ++i)
      if (!textures[i].live) {
        s.generation = textures[i].generation + 1;
        textures[i] = s;
        return {static_cast<std::uint32_t>(i), s.generation};
      }
    s.generation = 1;
    textures.push_back(s);
    return {static_cast<std::uint32_t>(textures.size() - 1), 1};
  }
};

Overlay::Overlay() = default;
Overlay::Overlay(Overlay&&) noexcept = default;
Overlay& Overlay::operator=(Overlay&&) noexcept = default;
Overlay::~Overlay() = default;

Result<Overlay> Overlay::create(const OverlayOptions& options) {
  GLint maxTex = 0;
  glGetIntegerv(GL_MAX_TEXTURE_SIZE, &maxTex);
  if (maxTex <= 0)
    return fail(ErrorCode::InvalidArgument, "no OpenGL context is current", "Overlay::create",
                "create a dm::GlContext on this thread first");
  if (options.bakeSize < kMinTextPx || options.bakeSize > kMaxTextPx)
    return fail(ErrorCode::InvalidArgument, formatString("bakeSize is %d px", options.bakeSize),
                "OverlayOptions::bakeSize", formatString("use %d..%d", kMinTextPx, kMaxTextPx));
  std::filesystem::path fontPath = options.fontPath;
  if (fontPath.empty()) {
    std::error_code ec;
    for (const char* candidate : {kDejaVuSansMonoPath, kDejaVuSansPath})
      if (std::filesystem::is_regular_file(candidate, ec)) {
        fontPath = candidate;
        break;
      }
    if (fontPath.empty())
      return fail(ErrorCode::NotFound,
                  formatString("no font: neither %s nor %s exists", kDejaVuSansMonoPath, kDejaVuSansPath),
                  "OverlayOptions::fontPath",
                  "install the Debian package fonts-dejavu-core (apt install fonts-dejavu-core) or set "
                  "OverlayOptions::fontPath");
  }
  auto font = detail::FontAtlas::open(fontPath, options.atlasSize);
  if (!font) return std::move(font).error();

  Overlay o;
  o.impl_ = std::make_unique<Impl>();
  Impl& d = *o.impl_;
  d.options = options;
  d.options.fontPath = fontPath;
  d.maxTextureSize = maxTex;
  d.options.maxAtlasHeight = std::clamp(options.maxAtlasHeight, 64, maxTex);
  d.font = std::move(*font);
  const detail::BakedSize* baked = d.font.size(options.bakeSize, d.options.maxAtlasHeight);
  if (baked == nullptr || baked->px != options.bakeSize)
    return fail(ErrorCode::InvalidArgument,
                formatString("the glyphs at %d px do not fit a %dx%d atlas", options.bakeSize, d.font.width(),
                             d.options.maxAtlasHeight),
                "OverlayOptions::atlasSize",
                "use a larger atlasSize or maxAtlasHeight, or a smaller bakeSize");
  auto prog = ShaderProgram::create("overlay", {{ShaderStage::Vertex, kVs}, {ShaderStage::Fragment, kFs}});
  if (!prog) return std::move(prog).error();
  d.program = std::move(*prog);
  d.viewportLoc = d.program.location("u_viewport");

  glCreateBuffers(1, &d.vbo);
  glCreateVertexArrays(1, &d.vao);
  glVertexArrayVertexBuffer(d.vao, 0, d.vbo, 0, sizeof(Vertex));
  for (GLuint a = 0; a < 4; ++a) {
    glEnableVertexArrayAttrib(d.vao, a);
    glVertexArrayAttribBinding(d.vao, a, 0);
  }
  glVertexArrayAttribFormat(d.vao, 0, 2, GL_FLOAT, GL_FALSE, offsetof(Vertex, x));
  glVertexArrayAttribFormat(d.vao, 1, 2, GL_FLOAT, GL_FALSE, offsetof(Vertex, u));
  glVertexArrayAttribFormat(d.vao, 2, 4, GL_FLOAT, GL_FALSE, offsetof(Vertex, r));
  glVertexArrayAttribIFormat(d.vao, 3, 1, GL_UNSIGNED_INT, offsetof(Vertex, mode));
  if (auto s = d.uploadAtlas(); !s) return std::move(s).error();
  return o;
}

const std::filesystem::path& Overlay::fontPath() const { return impl_->options.fontPath; }

const OverlayStats& Overlay::stats() const { return impl_->stats; }

void Overlay::begin(const RenderTarget& target) {
  impl_->target = &target;
  impl_->vertices.clear();
  impl_->batches.clear();
}

Status Overlay::end() {
  Impl& d = *impl_;
  if (d.target == nullptr)
    return fail(ErrorCode::InvalidArgument, "end() without begin()", "Overlay::end",
                "call begin(target) before drawing");
  const RenderTarget& target = *d.target;
  d.target = nullptr;
  d.stats.drawCalls = 0;
  d.stats.vertices = d.vertices.size();
  if (auto s = d.uploadAtlas(); !s) return s;
  if (d.vertices.empty()) return ok();
  if (d.vertices.size() > d.vboCapacity) {
    d.vboCapacity = std::max({d.vertices.size(), 2 * d.vboCapacity, std::size_t{4096}});
    glNamedBufferData(d.vbo, static_cast<GLsizeiptr>(d.vboCapacity * sizeof(Vertex)), nullptr,
                      GL_STREAM_DRAW);
  } else {
    glInvalidateBufferData(d.vbo);
  }
  glNamedBufferSubData(d.vbo, 0, static_cast<GLsizeiptr>(d.vertices.size() * sizeof(Vertex)),
                       d.vertices.data());

  const GLboolean blend = glIsEnabled(GL_BLEND), depth = glIsEnabled(GL_DEPTH_TEST),
                  cull = glIsEnabled(GL_CULL_FACE), scissor = glIsEnabled(GL_SCISSOR_TEST);
  GLint srcRgb = GL_ONE, dstRgb = GL_ZERO, srcA = GL_ONE, dstA = GL_ZERO;
  glGetIntegerv(GL_BLEND_SRC_RGB, &srcRgb);
  glGetIntegerv(GL_BLEND_DST_RGB, &dstRgb);
  glGetIntegerv(GL_BLEND_SRC_ALPHA, &srcA);
  glGetIntegerv(GL_BLEND_DST_ALPHA, &dstA);
  target.bind();
  glEnable(GL_BLEND);
  glBlendFuncSeparate(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA, GL_ONE, GL_ONE_MINUS_SRC_ALPHA);
  glDisable(GL_DEPTH_TEST);
  glDisable(GL_CULL_FACE);
  glDisable(GL_SCISSOR_TEST);
  d.program.use();
  glProgramUniform2f(d.program.id(), d.viewportLoc, static_cast<float>(target.width()),
                     static_cast<float>(target.height()));
  glBindVertexArray(d.vao);
  glBindTextureUnit(0, d.atlasTex);
  for (std::size_t b = 0; b < d.batches.size(); ++b) {
    const std::size_t first = d.batches[b].first;
    const std::size_t last = b + 1 < d.batches.size() ? d.batches[b + 1].first : d.vertices.size();
    if (last == first) continue;
    if (d.batches[b].texture != 0) glBindTextureUnit(1, d.batches[b].texture);
    glDrawArrays(GL_TRIANGLES, static_cast<GLint>(first), static_cast<GLsizei>(last - first));
    ++d.stats.drawCalls;
  }
  glBindVertexArray(0);
  glBlendFuncSeparate(static_cast<GLenum>(srcRgb), static_cast<GLenum>(dstRgb), static_cast<GLenum>(srcA),
                      static_cast<GLenum>(dstA));
  const auto restore = [](GLenum cap, GLboolean on) { on ? glEnable(cap) : glDisable(cap); };
  restore(GL_BLEND, blend);
  restore(GL_DEPTH_TEST, depth);
  restore(GL_CULL_FACE, cull);
  restore(GL_SCISSOR_TEST, scissor);
  return gl::check("Overlay::end");
}

TextMetrics Overlay::measureText(std::string_view text, float sizePx) {
  const int px = textPixels(sizePx);
  const detail::BakedSize* baked = impl_->font.size(px, impl_->options.maxAtlasHeight);
  if (baked == nullptr) return {};
  return layoutText(*baked, px, text, [](const detail::GlyphInfo&, int, int, int, int) {});
}

void Overlay::text(float x, float y, std::string_view text, float sizePx, const Vec4f& color,
                   TextAnchor anchor) {
  Impl& d = *impl_;
  const int px = textPixels(sizePx);
  const detail::BakedSize* baked = d.font.size(px, d.options.maxAtlasHeight);
  if (baked == nullptr || !std::isfinite(x) || !std::isfinite(y)) return;
  const TextMetrics m = layoutText(*baked, px, text, [](const detail::GlyphInfo&, int, int, int, int) {});
  float fx = 0, fy = 0;
  switch (anchor) {
    case TextAnchor::TopLeft:
      break;
    case TextAnchor::Top:
      fx = 0.5f;
      break;
    case TextAnchor::TopRight:
      fx = 1;
      break;
    case TextAnchor::Left:
      fy = 0.5f;
      break;
    case TextAnchor::Center:
      fx = fy = 0.5f;
      break;
    case TextAnchor::Right:
      fx = 1;
      fy = 0.5f;
      break;
    case TextAnchor::BottomLeft:
      fy = 1;
      break;
    case TextAnchor::Bottom:
      fx = 0.5f;
      fy = 1;
      break;
    case TextAnchor::BottomRight:
      fx = fy = 1;
      break;
    case TextAnchor::BaselineLeft:
      break;
  }
  const float top = anchor == TextAnchor::BaselineLeft ? y - static_cast<float>(m.ascent) : y - fy * m.height;
  const float ox = std::round(x - fx * m.width), oy = std::round(top);
  d.useTexture(0);
  layoutText(*baked, px, text, [&](const detail::GlyphInfo& g, int gx, int gy, int w, int h) {
    const float x0 = ox + static_cast<float>(gx), y0 = oy + static_cast<float>(gy);
    d.texturedRect(x0, y0, x0 + static_cast<float>(w), y0 + static_cast<float>(h),
                   static_cast<float>(g.atlasX), static_cast<float>(g.atlasY),
                   static_cast<float>(g.atlasX + g.width), static_cast<float>(g.atlasY + g.height), color,
                   kText);
  });
}

void Overlay::fillRect(const OverlayRect& r, const Vec4f& color) {
  impl_->fill(r.x, r.y, r.width, r.height, color);
}

void Overlay::strokeRect(const OverlayRect& r, const Vec4f& color, float width) {
  if (!(width > 0)) return;
  const float t = std::min({width, 0.5f * r.width, 0.5f * r.height});
  Impl& d = *impl_;
  d.fill(r.x, r.y, r.width, t, color);
  d.fill(r.x, r.y + r.height - t, r.width, t, color);
  d.fill(r.x, r.y + t, t, r.height - 2 * t, color);
  d.fill(r.x + r.width - t, r.y + t, t, r.height - 2 * t, color);
}

void Overlay::line(const Vec2f& a, const Vec2f& b, const Vec4f& color, float width) {
  const Vec2f pts[2] = {a, b};
  polyline(pts, color, width);
}

void Overlay::polyline(std::span<const Vec2f> points, const Vec4f& color, float width) {
  Impl& d = *impl_;
  if (!(width > 0)) return;
  width = std::min(width, 1e4f);  // keeps vertices finite for absurd widths
  std::size_t i = 0;
  while (i < points.size()) {
    while (i < points.size() && !points[i].allFinite()) ++i;
    d.runPoints.clear();
    for (; i < points.size() && points[i].allFinite(); ++i)
      if (d.runPoints.empty() || (points[i] - d.runPoints.back()).squaredNorm() > 1e-8f)
        d.runPoints.push_back(points[i]);
    d.strokeRun(d.runPoints, color, width);
  }
}

Result<SpriteId> Overlay::createTexture(const Image& image, const TextureOptions& options) {
  OverlayTextureSlot s;
  s.options = options;
  s.owned = true;
  if (auto st = impl_->upload(s, image, true); !st) {
    if (s.name != 0) glDeleteTextures(1, &s.name);
    return std::move(st).error();
  }
  s.live = true;
  return impl_->addSlot(s);
}

Status Overlay::updateTexture(SpriteId id, const Image& image) {
  const OverlayTextureSlot* found = impl_->slot(id);
  if (found == nullptr || !found->owned)
    return fail(ErrorCode::NotFound, "no texture made by createTexture() with this handle",
                "Overlay::updateTexture", "the texture was destroyed or wrapped; create a new one");
  OverlayTextureSlot& s = impl_->textures[id.index];
  GLint w = 0, h = 0;
  glGetTextureLevelParameteriv(s.name, 0, GL_TEXTURE_WIDTH, &w);
  glGetTextureLevelParameteriv(s.name, 0, GL_TEXTURE_HEIGHT, &h);
  return impl_->upload(s, image, w != image.width() || h != image.height());
}

SpriteId Overlay::wrapTexture(std::uint32_t glTexture) {
  if (glTexture == 0) return {};
  OverlayTextureSlot s;
  s.name = glTexture;
  s.live = true;
  s.bottomUp = true;
  return impl_->addSlot(s);
}

void Overlay::destroyTexture(SpriteId id) {
  if (impl_->slot(id) == nullptr) return;
  OverlayTextureSlot& s = impl_->textures[id.index];
  if (s.owned) glDeleteTextures(1, &s.name);
  s.name = 0;
  s.live = false;
}

void Overlay::sprite(SpriteId id, const OverlayRect& dst, const Vec4f& tint) {
  Impl& d = *impl_;
  const OverlayTextureSlot* s = d.slot(id);
  if (s == nullptr || !(dst.width > 0 && dst.height > 0)) return;
  d.useTexture(s->name);
  // Images are uploaded top row first; GL textures owned elsewhere (render targets) keep row 0 at the bottom.
  const float v0 = s->bottomUp ? 1.0f : 0.0f, v1 = 1.0f - v0;
  d.texturedRect(dst.x, dst.y, dst.x + dst.width, dst.y + dst.height, 0, v0, 1, v1, tint, kSprite);
}

PlotLayout Overlay::plot(const OverlayRect& frame, std::span<const OverlaySeries> series,
                         const PlotOptions& opt) {
  Impl& d = *impl_;
  PlotLayout layout;
  float lo = opt.yMin, hi = opt.yMax;
  if (opt.autoRange) {
    lo = INFINITY;
    hi = -INFINITY;
    for (const OverlaySeries& s : series)
      for (float v : s.values)
        if (std::isfinite(v)) {
          lo = std::min(lo, v);
          hi = std::max(hi, v);
        }
    if (lo > hi) {
      lo = 0;
      hi = 1;
    }
  }
  if (!std::isfinite(lo) || !std::isfinite(hi)) {
    lo = 0;
    hi = 1;
  }
  // Keep hi - lo finite in float.
  lo = std::clamp(lo, -1e30f, 1e30f);
  hi = std::clamp(hi, -1e30f, 1e30f);
  if (hi < lo) std::swap(lo, hi);
  if (hi - lo <= 1e-6f * std::max(1.0f, std::abs(hi))) {
    const float pad = hi != 0 ? 0.1f * std::abs(hi) : 1.0f;
    lo -= pad;
    hi += pad;
  }
  const float step = gridStep(hi - lo, 4);
  if (opt.autoRange) {
    lo = std::floor(lo / step) * step;
    hi = std::ceil(hi / step) * step;
  }
  layout.yMin = lo;
  layout.yMax = hi;
  layout.yStep = step;
  const float xMin = std::isfinite(opt.xMin) ? opt.xMin : 0, xMax = std::isfinite(opt.xMax) ? opt.xMax : 1;
  const float xStep = xMax != xMin ? gridStep(std::abs(xMax - xMin), 5) : 0;
  // Tick values k * step inside [a, b]; at most 64 of them.
  const auto forTicks = [](float a, float b, float st, auto&& fn) {
    if (!(st > 0)) return;
    const float first = std::ceil(std::min(a, b) / st - 1e-4f) * st, end = std::max(a, b) + 1e-4f * st;
    int k = 0;
    for (float v = first; v <= end && k < 64; v = first + static_cast<float>(++k) * st)
      fn(std::abs(v) < 1e-6f * st ? 0.0f : v);
  };
  char buf[32];
  const auto label = [&buf](float v) {
    std::snprintf(buf, sizeof buf, "%g", static_cast<double>(v));
    return std::string_view(buf);
  };

  constexpr float pad = 3;
  const float lineH = static_cast<float>(measureText("", opt.textSize).lineHeight);
  float left = pad, right = pad, top = pad, bottom = pad;
  if (opt.labels) {
    float widest = 0;
    forTicks(lo, hi, step,
             [&](float v) { widest = std::max(widest, measureText(label(v), opt.textSize).width); });
    left += widest + pad;
    bottom += lineH + pad;
    right += 0.5f * measureText(label(xMax), opt.textSize).width;
  }
  if (!opt.title.empty() || !opt.yLabel.empty()) top += lineH + pad;
  if (!opt.xLabel.empty()) bottom += lineH + pad;
  OverlayRect area{std::round(frame.x + left), std::round(frame.y + top), 0, 0};
  area.width = std::max(1.0f, std::round(frame.x + frame.width - right) - area.x);
  area.height = std::max(1.0f, std::round(frame.y + frame.height - bottom) - area.y);
  layout.area = area;
  const auto yOf = [&](float v) { return area.y + area.height * (hi - std::clamp(v, lo, hi)) / (hi - lo); };
  const auto xOf = [&](float v) { return area.x + area.width * (v - xMin) / (xMax - xMin); };

  if (opt.background.w() > 0) fillRect(frame, opt.background);
  forTicks(lo, hi, step, [&](float v) {
    const float y = std::min(std::floor(yOf(v)), area.y + area.height - 1);
    if (opt.grid) d.fill(area.x, y, area.width, 1, opt.gridColor);
    if (opt.labels)
      text(area.x - pad - 1, y + 0.5f, label(v), opt.textSize, opt.textColor, TextAnchor::Right);
  });
  if (xStep > 0)
    forTicks(xMin, xMax, xStep, [&](float v) {
      const float x = std::min(std::floor(xOf(v)), area.x + area.width - 1);
      if (opt.grid) d.fill(x, area.y, 1, area.height, opt.gridColor);
      if (opt.labels)
        text(x + 0.5f, area.y + area.height + pad, label(v), opt.textSize, opt.textColor, TextAnchor::Top);
    });
  if (opt.axes) {
    d.fill(area.x - 1, area.y, 1, area.height + 1, opt.axisColor);
    d.fill(area.x, area.y + area.height, area.width, 1, opt.axisColor);
  }
  if (!opt.title.empty())
    text(area.x + 0.5f * area.width, frame.y + pad, opt.title, opt.textSize, opt.textColor, TextAnchor::Top);
  if (!opt.yLabel.empty()) text(frame.x + pad, frame.y + pad, opt.yLabel, opt.textSize, opt.textColor);
  if (!opt.xLabel.empty())
    text(area.x + 0.5f * area.width, frame.y + frame.height - pad, opt.xLabel, opt.textSize, opt.textColor,
         TextAnchor::Bottom);

  for (const OverlaySeries& s : series) {
    const std::size_t n = s.values.size();
    if (n < 2) continue;
    d.plotPoints.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      const float v = s.values[i];
      const float x = area.x + area.width * static_cast<float>(i) / static_cast<float>(n - 1);
      d.plotPoints[i] = std::isfinite(v) ? Vec2f(x, yOf(v)) : Vec2f(NAN, NAN);
    }
    polyline(d.plotPoints, s.color, s.width);
  }
  return layout;
}

}  // namespace dm
