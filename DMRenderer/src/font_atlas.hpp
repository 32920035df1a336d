// font_atlas.hpp (private) — glyph bitmaps rasterised with FreeType and
// shelf-packed into one 8-bit coverage atlas, for the overlay's text.
//
// A FontAtlas holds one open FreeType face and a CPU copy of the atlas
// (R8, rows top to bottom). bake(px) rasterises the fixed character set
// (printable ASCII plus a few symbols HUDs need: ° ± µ ² ³ × · μ Δ) at one
// pixel size; the overlay uploads the atlas when dirty() says it changed.
// Layout is kerning-free: a glyph advances the pen by its hinted advance.
// Baking allocates; looking glyphs up does not.
#pragma once

#include <dm/core/result.hpp>

#include <array>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string_view>
#include <vector>

namespace dm::detail {

/// Number of characters baked per size (printable ASCII + extra symbols).
inline constexpr int kGlyphCount = 95 + 9;

/// One rasterised glyph: bitmap size and bearings in pixels, atlas position.
struct GlyphInfo {
  float advance = 0;  ///< pen advance, pixels
  int left = 0;       ///< bitmap left edge relative to the pen
  int top = 0;        ///< bitmap top edge above the baseline
  int width = 0, height = 0;
  int atlasX = 0, atlasY = 0;
};

/// The character set at one pixel size.
struct BakedSize {
  int px = 0;
  int ascent = 0;      ///< pixels above the baseline (rounded up)
  int descent = 0;     ///< pixels below the baseline (rounded up, positive)
  int lineHeight = 0;  ///< baseline-to-baseline distance
  std::array<GlyphInfo, kGlyphCount> glyphs{};
};

/// Slot of a code point in the baked set; unknown code points map to '?'.
int glyphSlot(char32_t codepoint) noexcept;

/// Decodes the next UTF-8 code point of `text` at `pos` and advances `pos`;
/// malformed sequences give U+FFFD and skip one byte.
char32_t nextCodepoint(std::string_view text, std::size_t& pos) noexcept;

class FontAtlas {
 public:
  /// Opens `path` with FreeType. Fails with NotFound (naming the path and
  /// the Debian package) when the file is missing, Parse when FreeType
  /// cannot read it.
  static Result<FontAtlas> open(const std::filesystem::path& path, int atlasSize);

  FontAtlas();
  FontAtlas(FontAtlas&&) noexcept;
  FontAtlas& operator=(FontAtlas&&) noexcept;
  ~FontAtlas();

  /// The baked size closest to `px`, baking `px` first when it is missing
  /// and the atlas can still grow (up to `maxAtlasSize` texels high; a size
  /// that did not fit is not tried again). Null only when nothing is baked.
  const BakedSize* size(int px, int maxAtlasSize);

  const std::filesystem::path& path() const { return path_; }
  int width() const { return width_; }
  int height() const { return height_; }
  const std::uint8_t* pixels() const { return pixels_.data(); }
  /// True when pixels changed since the last clearDirty(); `grown` when the
  /// atlas height changed (the texture must be reallocated).
  bool dirty() const { return dirty_; }
  bool grown() const { return grown_; }
  void clearDirty() { dirty_ = grown_ = false; }
  int bakedCount() const { return static_cast<int>(sizes_.size()); }

 private:
  bool bake(int px, int maxAtlasSize);
  struct Ft;
  std::unique_ptr<Ft> ft_;
  std::filesystem::path path_;
  std::vector<std::unique_ptr<BakedSize>> sizes_;
  std::vector<int> unfit_;  // sizes whose bake did not fit the atlas
  std::vector<std::uint8_t> pixels_;
  int width_ = 0, height_ = 0;
  int shelfX_ = 0, shelfY_ = 0, shelfH_ = 0;
  bool dirty_ = false, grown_ = false;
};

}  // namespace dm::detail
