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

class Texture {
 public:
  Texture() = default;

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

}  // namespace slamd::synth
