#pragma once
// Procedural textures for the synthetic worlds.
//
// Usage: `Texture wall = Texture::generate(TextureKind::kPlaster, 0.3, seed);` makes a square BGR
// image (with a mip-map pyramid) whose content depends only on the kind, the density and the seed.
// The renderer samples it with sample(x_texel, y_texel, level, wrap). Textures are immutable once
// generated and may be shared by any number of renderers.
//
// Density (0..1) controls how much structure a surface carries: 0 gives a nearly featureless
// surface (faint low-frequency plaster shading only, the corridor case paper 002 targets), 1 a
// surface dense with contrasty marks (notices, scuffs, switches, stains) whose corners FAST/ORB
// detect. Posters are always rich: blocks of colour, rings, stripes, checker patches and rows of
// "text".

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>

namespace slamd::synth {

enum class TextureKind {
  kPlaster,       ///< painted wall: faint shading plus density-controlled marks
  kFloorTiles,    ///< square tiles with grout lines and speckle
  kCeilingTiles,  ///< acoustic ceiling tiles on a grid
  kWoodDoor,      ///< wood grain, vertical
  kPoster,        ///< rich structured print (not tiled)
  kWood,          ///< furniture wood
  kMetal,         ///< brushed metal / painted steel
  kFabric,        ///< upholstery
};

/// A regular tiling: identical (or nearly identical) tiles in one or two alternating colours,
/// the repeating pattern of corridor floors and tiled walls that fools descriptor matching.
struct TileStyle {
  int tiles_per_side = 16;      ///< tiles along each side of the texture (divides its size)
  double contrast = 0.2;        ///< luma difference of alternating (checker) tiles, 0..1 of 255
  double grout_contrast = 0.4;  ///< how much darker the grout lines are, 0..1
  double variation = 0.0;       ///< per-tile random shade, 0 = identical tiles .. 1 = +-12 levels
  double base_luma = 150.0;     ///< mean tile brightness, 0..255
};

class Texture {
 public:
  Texture() = default;
  /// A size_px x size_px regular tiling (see TileStyle); throws std::invalid_argument when
  /// tiles_per_side does not divide size_px or a field is out of range.
  static Texture tiles(const TileStyle& style, std::uint64_t seed, int size_px);

  /// A size_px x size_px texture (size a power of two, 16..2048).
  static Texture generate(TextureKind kind, double density, std::uint64_t seed, int size_px = 512);
  /// Wraps an existing CV_8UC3 image (square, power-of-two side); builds the mip pyramid.
  static Texture fromImage(const cv::Mat& image_bgr);

  /// Bilinear sample of mip level `level` (0 = full resolution) at texel coordinates of level 0
  /// (x right, y down; texel centres at integers). wrap: tile the image; else clamp to the edge.
  /// Returns B, G, R in 0..255.
  cv::Vec3f sample(double x_texel, double y_texel, int level, bool wrap) const;

  int size() const { return levels_.empty() ? 0 : levels_.front().cols; }
  int levelCount() const { return static_cast<int>(levels_.size()); }
  const cv::Mat& level(int index) const { return levels_.at(static_cast<std::size_t>(index)); }

 private:
  std::vector<cv::Mat> levels_;  ///< CV_8UC3 pyramid, each half the size of the previous
};

// Inline: called once per rendered pixel.
inline cv::Vec3f Texture::sample(double x_texel, double y_texel, int level, bool wrap) const {
  level = std::clamp(level, 0, levelCount() - 1);
  const cv::Mat& image = levels_[static_cast<std::size_t>(level)];
  const int n = image.cols;
  const double scale = 1.0 / static_cast<double>(1 << level);
  const double x = (x_texel + 0.5) * scale - 0.5;
  const double y = (y_texel + 0.5) * scale - 0.5;
  const double fx0 = std::floor(x);
  const double fy0 = std::floor(y);
  const float tx = static_cast<float>(x - fx0);
  const float ty = static_cast<float>(y - fy0);
  // Texture coordinates can be large (tens of metres of wall): reduce in 64-bit before masking.
  auto x0 = static_cast<long long>(fx0);
  auto y0 = static_cast<long long>(fy0);
  long long x1 = x0 + 1;
  long long y1 = y0 + 1;
  if (wrap) {
    const long long mask = n - 1;
    x0 &= mask;
    x1 &= mask;
    y0 &= mask;
    y1 &= mask;
  } else {
    x0 = std::clamp<long long>(x0, 0, n - 1);
    x1 = std::clamp<long long>(x1, 0, n - 1);
    y0 = std::clamp<long long>(y0, 0, n - 1);
    y1 = std::clamp<long long>(y1, 0, n - 1);
  }
  const auto* row0 = image.ptr<cv::Vec3b>(static_cast<int>(y0));
  const auto* row1 = image.ptr<cv::Vec3b>(static_cast<int>(y1));
  const cv::Vec3b& a = row0[x0];
  const cv::Vec3b& b = row0[x1];
  const cv::Vec3b& c = row1[x0];
  const cv::Vec3b& d = row1[x1];
  cv::Vec3f out;
  for (int k = 0; k < 3; ++k) {
    const float top =
        static_cast<float>(a[k]) + tx * (static_cast<float>(b[k]) - static_cast<float>(a[k]));
    const float bottom =
        static_cast<float>(c[k]) + tx * (static_cast<float>(d[k]) - static_cast<float>(c[k]));
    out[k] = top + ty * (bottom - top);
  }
  return out;
}

}  // namespace slamd::synth
