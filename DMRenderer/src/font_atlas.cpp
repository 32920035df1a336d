// font_atlas.cpp — FreeType rasterisation and shelf packing of the overlay's
// glyph atlas.
#include "font_atlas.hpp"

#include <ft2build.h>
#include FT_FREETYPE_H

#include <algorithm>
#include <cmath>
#include <cstring>
#include <system_error>
#include <utility>

namespace dm::detail {

namespace {

// Code points baked after printable ASCII (slots 95..).
constexpr std::array<char32_t, kGlyphCount - 95> kExtraCodepoints = {
    0x00B0,  // ° degree
    0x00B1,  // ± plus-minus
    0x00B5,  // µ micro sign
    0x00B2,  // ² superscript two
    0x00B3,  // ³ superscript three
    0x00D7,  // × multiplication
    0x00B7,  // · middle dot
    0x03BC,  // μ Greek mu
    0x0394,  // Δ Greek capital delta
};

char32_t slotCodepoint(int slot) {
  return slot < 95 ? static_cast<char32_t>(32 + slot) : kExtraCodepoints[static_cast<std::size_t>(slot - 95)];
}

// Blank texels between glyphs so linear filtering never bleeds a neighbour.
constexpr int kPadding = 1;

}  // namespace

int glyphSlot(char32_t cp) noexcept {
  if (cp >= 32 && cp <= 126) return static_cast<int>(cp - 32);
  for (std::size_t i = 0; i < kExtraCodepoints.size(); ++i)
    if (kExtraCodepoints[i] == cp) return 95 + static_cast<int>(i);
  return '?' - 32;
}

char32_t nextCodepoint(std::string_view s, std::size_t& pos) noexcept {
  const auto byte = [&](std::size_t i) { return static_cast<unsigned char>(s[i]); };
  const unsigned char c = byte(pos);
  int extra = 0;
  char32_t cp = 0;
  if (c < 0x80) {
    ++pos;
    return c;
  } else if ((c & 0xE0) == 0xC0) {
    extra = 1;
    cp = c & 0x1Fu;
  } else if ((c & 0xF0) == 0xE0) {
    extra = 2;
    cp = c & 0x0Fu;
  } else if ((c & 0xF8) == 0xF0) {
    extra = 3;
    cp = c & 0x07u;
  } else {
    ++pos;
    return 0xFFFD;
  }
  if (pos + static_cast<std::size_t>(extra) >= s.size()) {
    ++pos;
    return 0xFFFD;
  }
  for (int k = 1; k <= extra; ++k) {
    const unsigned char cc = byte(pos + static_cast<std::size_t>(k));
    if ((cc & 0xC0) != 0x80) {
      ++pos;
      return 0xFFFD;
    }
    cp = (cp << 6) | (cc & 0x3Fu);
  }
  pos += static_cast<std::size_t>(extra) + 1;
  return cp;
}

struct FontAtlas::Ft {
  FT_Library library = nullptr;
  FT_Face face = nullptr;
  ~Ft() {
    if (face != nullptr) FT_Done_Face(face);
    if (library != nullptr) FT_Done_FreeType(library);
  }
};

FontAtlas::FontAtlas() = default;
FontAtlas::FontAtlas(FontAtlas&&) noexcept = default;
FontAtlas& FontAtlas::operator=(FontAtlas&&) noexcept = default;
FontAtlas::~FontAtlas() = default;

Result<FontAtlas> FontAtlas::open(const std::filesystem::path& path, int atlasSize) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec))
    return fail(ErrorCode::NotFound, "font file not found", path.string(),
                "install the Debian package fonts-dejavu-core (apt install fonts-dejavu-core) or set "
                "OverlayOptions::fontPath to a TrueType/OpenType font");
  FontAtlas atlas;
  atlas.ft_ = std::make_unique<Ft>();
  if (FT_Error e = FT_Init_FreeType(&atlas.ft_->library); e != 0)
    return fail(ErrorCode::Internal, formatString("FT_Init_FreeType failed with FreeType error %d", e),
                "FontAtlas::open");
  if (FT_Error e = FT_New_Face(atlas.ft_->library, path.c_str(), 0, &atlas.ft_->face); e != 0) {
    atlas.ft_->face = nullptr;
    return fail(ErrorCode::Parse, formatString("FreeType cannot read the font (FreeType error %d)", e),
                path.string(), "give a TrueType or OpenType font file (e.g. DejaVuSansMono.ttf)");
  }
  if (FT_Select_Charmap(atlas.ft_->face, FT_ENCODING_UNICODE) != 0)
    return fail(ErrorCode::Unsupported, "the font has no Unicode character map", path.string(),
                "use a Unicode TrueType font such as DejaVuSans.ttf");
  atlas.path_ = path;
  atlas.width_ = atlas.height_ = std::clamp(atlasSize, 64, 4096);
  atlas.pixels_.assign(static_cast<std::size_t>(atlas.width_) * static_cast<std::size_t>(atlas.height_), 0);
  atlas.dirty_ = atlas.grown_ = true;
  return atlas;
}

const BakedSize* FontAtlas::size(int px, int maxAtlasSize) {
  const BakedSize* best = nullptr;
  for (const auto& s : sizes_) {
    if (s->px == px) return s.get();
    if (best == nullptr || std::abs(s->px - px) < std::abs(best->px - px)) best = s.get();
  }
  // A size that did not fit once is not retried (it would rasterise again every frame).
  if (std::find(unfit_.begin(), unfit_.end(), px) != unfit_.end()) return best;
  if (bake(px, maxAtlasSize)) return sizes_.back().get();
  unfit_.push_back(px);
  return best;
}

bool FontAtlas::bake(int px, int maxAtlasSize) {
  FT_Face face = ft_->face;
  if (FT_Set_Pixel_Sizes(face, 0, static_cast<FT_UInt>(px)) != 0) return false;
  auto baked = std::make_unique<BakedSize>();
  baked->px = px;
  const FT_Size_Metrics& m = face->size->metrics;
  baked->ascent = static_cast<int>((m.ascender + 63) / 64);
  baked->descent = static_cast<int>((-m.descender + 63) / 64);
  baked->lineHeight = std::max(static_cast<int>((m.height + 63) / 64), baked->ascent + baked->descent);
  // Pack with a copy of the shelf state: a failed bake commits nothing.
  int shelfX = std::max(shelfX_, kPadding), shelfY = std::max(shelfY_, kPadding), shelfH = shelfH_;
  int height = height_;
  // On failure, blank what this bake wrote beyond the committed shelves, so
  // the padding around committed glyphs stays empty for filtered sampling.
  const auto discard = [this] {
    const std::size_t w = static_cast<std::size_t>(width_);
    const int firstFree = std::max(shelfY_, kPadding);
    for (int r = firstFree; r < height_; ++r) {
      const int from = r < firstFree + shelfH_ ? std::max(shelfX_, kPadding) - kPadding : 0;
      std::fill(pixels_.begin() + static_cast<std::ptrdiff_t>(static_cast<std::size_t>(r) * w +
                                                              static_cast<std::size_t>(from)),
                pixels_.begin() + static_cast<std::ptrdiff_t>((static_cast<std::size_t>(r) + 1) * w),
                std::uint8_t{0});
    }
    return false;
  };
  for (int slot = 0; slot < kGlyphCount; ++slot) {
    const FT_UInt index = FT_Get_Char_Index(face, static_cast<FT_ULong>(slotCodepoint(slot)));
    GlyphInfo& g = baked->glyphs[static_cast<std::size_t>(slot)];
    if (FT_Load_Glyph(face, index, FT_LOAD_RENDER | FT_LOAD_TARGET_LIGHT) != 0) {
      g = baked->glyphs[static_cast<std::size_t>('?' - 32)];
      continue;
    }
    const FT_GlyphSlot gs = face->glyph;
    const FT_Bitmap& bm = gs->bitmap;
    g.advance = static_cast<float>(gs->advance.x) / 64.0f;
    g.left = gs->bitmap_left;
    g.top = gs->bitmap_top;
    g.width = static_cast<int>(bm.width);
    g.height = static_cast<int>(bm.rows);
    if (g.width == 0 || g.height == 0 || bm.pixel_mode != FT_PIXEL_MODE_GRAY) {
      g.width = g.height = 0;
      continue;
    }
    if (g.width + 2 * kPadding > width_) return discard();
    if (shelfX + g.width + kPadding > width_) {
      shelfY += shelfH;
      shelfX = kPadding;
      shelfH = 0;
    }
    while (shelfY + g.height + kPadding > height) {
      if (height * 2 > maxAtlasSize) return discard();
      height *= 2;
    }
    if (height != height_) {
      // Grow: rows are appended, existing glyphs keep their texel positions.
      pixels_.resize(static_cast<std::size_t>(width_) * static_cast<std::size_t>(height), 0);
      height_ = height;
      grown_ = true;
    }
    for (int r = 0; r < g.height; ++r)
      std::memcpy(&pixels_[static_cast<std::size_t>(shelfY + r) * static_cast<std::size_t>(width_) +
                           static_cast<std::size_t>(shelfX)],
                  bm.buffer + static_cast<std::ptrdiff_t>(r) * bm.pitch, static_cast<std::size_t>(g.width));
    g.atlasX = shelfX;
    g.atlasY = shelfY;
    shelfX += g.width + kPadding;
    shelfH = std::max(shelfH, g.height + kPadding);
  }
  shelfX_ = shelfX;
  shelfY_ = shelfY;
  shelfH_ = shelfH;
  dirty_ = true;
  sizes_.push_back(std::move(baked));
  return true;
}

}  // namespace dm::detail
