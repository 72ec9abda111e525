#include "slamd/synth/texture.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include <opencv2/imgproc.hpp>

#include "random.hpp"

namespace slamd::synth {
namespace {

bool isPowerOfTwo(int n) { return n > 0 && (n & (n - 1)) == 0; }

cv::Scalar bgr(double b, double g, double r) { return cv::Scalar(b, g, r); }

/// A random colour far from `base` in brightness, so marks make corners against the background.
cv::Scalar contrastingColor(Rng& rng, const cv::Scalar& base) {
  const double base_luma = (base[0] + base[1] + base[2]) / 3.0;
  const bool dark = base_luma > 110.0 ? rng.uniform() < 0.85 : rng.uniform() < 0.15;
  const double level = dark ? rng.uniform(15.0, 80.0) : rng.uniform(170.0, 245.0);
  const double tint = rng.uniform(0.0, 1.0) < 0.4 ? 60.0 : 15.0;  // some saturated marks
  return bgr(std::clamp(level + rng.uniform(-tint, tint), 0.0, 255.0),
             std::clamp(level + rng.uniform(-tint, tint), 0.0, 255.0),
             std::clamp(level + rng.uniform(-tint, tint), 0.0, 255.0));
}

/// Periodic smooth value noise in [-1, 1]: `cells` x `cells` random lattice values interpolated
/// with smoothstep, wrapping at the image edge so tiled textures have no seams.
cv::Mat periodicNoise(Rng& rng, int size, int cells_x, int cells_y) {
  std::vector<float> lattice(static_cast<std::size_t>(cells_x * cells_y));
  for (auto& value : lattice) value = static_cast<float>(rng.uniform(-1.0, 1.0));
  cv::Mat noise(size, size, CV_32FC1);
  for (int y = 0; y < size; ++y) {
    const double gy = static_cast<double>(y) * cells_y / size;
    const int y0 = static_cast<int>(gy);
    double ty = gy - y0;
    ty = ty * ty * (3.0 - 2.0 * ty);
    const int y1 = (y0 + 1) % cells_y;
    auto* row = noise.ptr<float>(y);
    for (int x = 0; x < size; ++x) {
      const double gx = static_cast<double>(x) * cells_x / size;
      const int x0 = static_cast<int>(gx);
      double tx = gx - x0;
      tx = tx * tx * (3.0 - 2.0 * tx);
      const int x1 = (x0 + 1) % cells_x;
      const auto at = [&](int cx, int cy) {
        return static_cast<double>(lattice[static_cast<std::size_t>(cy * cells_x + cx)]);
      };
      const double top = at(x0, y0) * (1.0 - tx) + at(x1, y0) * tx;
      const double bottom = at(x0, y1) * (1.0 - tx) + at(x1, y1) * tx;
      row[x] = static_cast<float>(top * (1.0 - ty) + bottom * ty);
    }
  }
  return noise;
}

/// Fills the image with `base` modulated by noise of the given amplitude (grey levels).
void fillWithNoise(cv::Mat& image, const cv::Scalar& base, const cv::Mat& noise, double amplitude) {
  for (int y = 0; y < image.rows; ++y) {
    auto* out = image.ptr<cv::Vec3b>(y);
    const auto* n = noise.ptr<float>(y);
    for (int x = 0; x < image.cols; ++x) {
      const double delta = amplitude * static_cast<double>(n[x]);
      for (int c = 0; c < 3; ++c) out[x][c] = cv::saturate_cast<std::uint8_t>(base[c] + delta);
    }
  }
}

/// Draws a shape at its place and at the eight positions shifted by one texture period, so marks
/// crossing an edge continue on the opposite edge (seamless tiling).
template <typename Draw>
void drawWrapped(int size, Draw draw) {
  for (int dy = -1; dy <= 1; ++dy) {
    for (int dx = -1; dx <= 1; ++dx) draw(cv::Point(dx * size, dy * size));
  }
}

/// Random marks on a wall: notices, switch plates, scuffs, pipes, stains.
void drawWallMarks(cv::Mat& image, Rng& rng, int count, const cv::Scalar& base) {
  const int size = image.cols;
  for (int i = 0; i < count; ++i) {
    const cv::Point centre(rng.uniformInt(0, size - 1), rng.uniformInt(0, size - 1));
    const cv::Scalar color = contrastingColor(rng, base);
    const int shape = rng.uniformInt(0, 5);
    const int w = rng.uniformInt(3, 18);
    const int h = rng.uniformInt(3, 18);
    drawWrapped(size, [&](cv::Point shift) {
      const cv::Point c = centre + shift;
      switch (shape) {
        case 0:  // notice: filled rectangle with a border
          cv::rectangle(image, c, c + cv::Point(w, h), color, cv::FILLED, cv::LINE_8);
          cv::rectangle(image, c, c + cv::Point(w, h), contrastingColor(rng, color), 1, cv::LINE_8);
          break;
        case 1:  // switch plate: square with an inner square
          cv::rectangle(image, c, c + cv::Point(5, 5), color, cv::FILLED, cv::LINE_8);
          cv::rectangle(image, c + cv::Point(2, 1), c + cv::Point(3, 4),
                        contrastingColor(rng, color), cv::FILLED, cv::LINE_8);
          break;
        case 2:  // stain
          cv::circle(image, c, std::max(2, w / 3), color, cv::FILLED, cv::LINE_8);
          break;
        case 3:  // horizontal pipe or rail
          cv::line(image, c, c + cv::Point(4 * w, 0), color, 2, cv::LINE_8);
          break;
        case 4:  // scuff: short slanted stroke
          cv::line(image, c, c + cv::Point(w, h / 2), color, 1, cv::LINE_8);
          break;
        default:  // small checker sticker
          for (int k = 0; k < 4; ++k) {
            const cv::Point corner = c + cv::Point((k % 2) * 3, (k / 2) * 3);
            cv::rectangle(image, corner, corner + cv::Point(2, 2),
                          (k == 0 || k == 3) ? color : bgr(235, 235, 235), cv::FILLED, cv::LINE_8);
          }
          break;
      }
    });
  }
}

cv::Mat makePlaster(Rng& rng, int size, double density) {
  const double luma = rng.uniform(185.0, 230.0);
  const cv::Scalar base =
      bgr(luma + rng.uniform(-12, 12), luma + rng.uniform(-8, 8), luma + rng.uniform(-12, 12));
  cv::Mat image(size, size, CV_8UC3);
  // Faint low-frequency shading only: at density 0 this is all there is (a nearly featureless
  // wall: gradients of a few grey levels over metres give FAST nothing to fire on).
  fillWithNoise(image, base, periodicNoise(rng, size, 8, 8), 4.0);
  const int marks =
      static_cast<int>(std::lround(density * 260.0 * (size / 512.0) * (size / 512.0)));
  drawWallMarks(image, rng, marks, base);
  return image;
}

cv::Mat makeTiles(Rng& rng, int size, double density, bool ceiling) {
  const int tile = std::max(8, size / 16);
  const double luma = ceiling ? rng.uniform(200.0, 230.0) : rng.uniform(90.0, 170.0);
  const cv::Scalar base =
      bgr(luma + rng.uniform(-15, 15), luma + rng.uniform(-10, 10), luma + rng.uniform(-15, 15));
  cv::Mat image(size, size, CV_8UC3);
  fillWithNoise(image, base, periodicNoise(rng, size, 32, 32), ceiling ? 3.0 : 6.0);
  const int tiles = size / tile;
  for (int ty = 0; ty < tiles; ++ty) {
    for (int tx = 0; tx < tiles; ++tx) {
      const cv::Rect cell(tx * tile + 1, ty * tile + 1, tile - 1, tile - 1);
      if (ceiling && rng.uniform() < 0.08) {  // light panel
        image(cell).setTo(bgr(250, 250, 250));
        continue;
      }
      const double shade = rng.uniform(-10.0, 10.0) * (0.3 + density);
      cv::Mat cell_view = image(cell);
      cell_view += cv::Scalar::all(std::max(0.0, shade));
      cell_view -= cv::Scalar::all(std::max(0.0, -shade));
    }
  }
  const cv::Scalar grout = ceiling ? bgr(150, 150, 150) : base * 0.55;
  for (int k = 0; k < tiles; ++k) {
    cv::line(image, cv::Point(k * tile, 0), cv::Point(k * tile, size - 1), grout, 1, cv::LINE_8);
    cv::line(image, cv::Point(0, k * tile), cv::Point(size - 1, k * tile), grout, 1, cv::LINE_8);
  }
  // Speckle (terrazzo, dirt): scales with density.
  const int speckles =
      static_cast<int>(std::lround(density * 600.0 * (size / 512.0) * (size / 512.0)));
  for (int i = 0; i < speckles; ++i) {
    const cv::Point p(rng.uniformInt(0, size - 1), rng.uniformInt(0, size - 1));
    const cv::Scalar color = contrastingColor(rng, base);
    drawWrapped(size, [&](cv::Point shift) {
      cv::circle(image, p + shift, rng.uniformInt(1, 2), color, cv::FILLED, cv::LINE_8);
    });
  }
  return image;
}

cv::Mat makeWood(Rng& rng, int size, double density, bool door) {
  const cv::Scalar base =
      door ? bgr(rng.uniform(40, 70), rng.uniform(80, 110), rng.uniform(130, 170))
           : bgr(rng.uniform(60, 110), rng.uniform(110, 150), rng.uniform(150, 200));
  cv::Mat image(size, size, CV_8UC3);
  cv::Mat grain = periodicNoise(rng, size, 64, 4);
  const cv::Mat coarse = periodicNoise(rng, size, 8, 8);
  grain = grain * 0.7 + coarse * 0.3;
  fillWithNoise(image, base, grain, 28.0);
  // Knots and panel lines.
  const int knots = 2 + static_cast<int>(std::lround(density * 12.0));
  for (int i = 0; i < knots; ++i) {
    const cv::Point p(rng.uniformInt(0, size - 1), rng.uniformInt(0, size - 1));
    const cv::Size axes(rng.uniformInt(2, 5), rng.uniformInt(5, 12));
    drawWrapped(size, [&](cv::Point shift) {
      cv::ellipse(image, p + shift, axes, 0.0, 0.0, 360.0, base * 0.45, cv::FILLED, cv::LINE_8);
    });
  }
  return image;
}

cv::Mat makeMetal(Rng& rng, int size, double density) {
  const double luma = rng.uniform(70.0, 190.0);
  const cv::Scalar base = bgr(luma + rng.uniform(-20, 25), luma, luma - rng.uniform(0, 15));
  cv::Mat image(size, size, CV_8UC3);
  fillWithNoise(image, base, periodicNoise(rng, size, 128, 8), 10.0);
  const int panels = 4;
  const int step = size / panels;
  for (int k = 0; k < panels; ++k) {
    cv::line(image, cv::Point(0, k * step), cv::Point(size - 1, k * step), base * 0.4, 2,
             cv::LINE_8);
    cv::line(image, cv::Point(k * step, 0), cv::Point(k * step, size - 1), base * 0.4, 2,
             cv::LINE_8);
  }
  // Labels, screws and handles.
  drawWallMarks(image, rng, 8 + static_cast<int>(std::lround(density * 60.0)), base);
  return image;
}

cv::Mat makeFabric(Rng& rng, int size, double density) {
  const cv::Scalar base = bgr(rng.uniform(40, 140), rng.uniform(30, 100), rng.uniform(20, 90));
  cv::Mat image(size, size, CV_8UC3);
  fillWithNoise(image, base, periodicNoise(rng, size, size / 4, size / 4), 18.0);
  drawWallMarks(image, rng, static_cast<int>(std::lround(density * 40.0)), base);
  return image;
}

/// A poster: rich structure everywhere (blocks, rings, stripes, checkers, text rows), for strong
/// ORB/FAST corners even on otherwise featureless walls.
cv::Mat makePoster(Rng& rng, int size) {
  const cv::Scalar background = bgr(rng.uniform(0, 255), rng.uniform(0, 255), rng.uniform(0, 255));
  cv::Mat image(size, size, CV_8UC3, background);
  const auto random_color = [&] {
    return bgr(rng.uniformInt(0, 1) * 200 + rng.uniform(0, 55),
               rng.uniformInt(0, 1) * 200 + rng.uniform(0, 55),
               rng.uniformInt(0, 1) * 200 + rng.uniform(0, 55));
  };
  const double s = size / 256.0;
  const int blocks = rng.uniformInt(4, 9);
  for (int i = 0; i < blocks; ++i) {
    const cv::Point a(rng.uniformInt(0, size - 1), rng.uniformInt(0, size - 1));
    const cv::Point b = a + cv::Point(rng.uniformInt(10, 90), rng.uniformInt(10, 90)) * s;
    cv::rectangle(image, a, b, random_color(), cv::FILLED, cv::LINE_8);
  }
  const int rings = rng.uniformInt(1, 4);
  for (int i = 0; i < rings; ++i) {
    const cv::Point c(rng.uniformInt(0, size - 1), rng.uniformInt(0, size - 1));
    const int radius = static_cast<int>(rng.uniformInt(8, 40) * s);
    cv::circle(image, c, radius, random_color(), std::max(2, radius / 4), cv::LINE_8);
  }
  const int stripes = rng.uniformInt(0, 3);
  for (int i = 0; i < stripes; ++i) {
    const int y = rng.uniformInt(0, size - 1);
    cv::rectangle(image, cv::Point(0, y), cv::Point(size - 1, y + static_cast<int>(6 * s)),
                  random_color(), cv::FILLED, cv::LINE_8);
  }
  // A checker patch.
  {
    const int cell = static_cast<int>(rng.uniformInt(6, 12) * s);
    const cv::Point origin(rng.uniformInt(0, size / 2), rng.uniformInt(0, size / 2));
    const cv::Scalar a = random_color();
    const cv::Scalar b = bgr(255, 255, 255) - a;
    for (int cy = 0; cy < 5; ++cy) {
      for (int cx = 0; cx < 5; ++cx) {
        const cv::Point corner = origin + cv::Point(cx * cell, cy * cell);
        cv::rectangle(image, corner, corner + cv::Point(cell - 1, cell - 1), (cx + cy) % 2 ? a : b,
                      cv::FILLED, cv::LINE_8);
      }
    }
  }
  // Rows of "text": dark word blocks on a light band.
  const int rows = rng.uniformInt(3, 8);
  const int top = rng.uniformInt(size / 2, size - static_cast<int>(rows * 12 * s) - 1);
  for (int r = 0; r < rows; ++r) {
    int x = static_cast<int>(12 * s);
    const int y = top + static_cast<int>(r * 12 * s);
    cv::rectangle(image, cv::Point(x - 4, y - 2),
                  cv::Point(size - x + 4, y + static_cast<int>(9 * s)), bgr(240, 240, 240),
                  cv::FILLED, cv::LINE_8);
    while (x < size - 20 * s) {
      const int word = static_cast<int>(rng.uniformInt(6, 28) * s);
      cv::rectangle(image, cv::Point(x, y),
                    cv::Point(std::min(x + word, size - 12), y + static_cast<int>(6 * s)),
                    bgr(20, 20, 20), cv::FILLED, cv::LINE_8);
      x += word + static_cast<int>(5 * s);
    }
  }
  cv::rectangle(image, cv::Point(0, 0), cv::Point(size - 1, size - 1), bgr(30, 30, 30),
                std::max(2, size / 64), cv::LINE_8);
  return image;
}

}  // namespace

Texture Texture::generate(TextureKind kind, double density, std::uint64_t seed, int size_px) {
  if (!isPowerOfTwo(size_px) || size_px < 16 || size_px > 2048) {
    throw std::invalid_argument("texture size " + std::to_string(size_px) +
                                " px must be a power of two in [16, 2048]");
  }
  if (!(density >= 0.0 && density <= 1.0)) {
    throw std::invalid_argument("texture density " + std::to_string(density) +
                                " must be in [0, 1]");
  }
  Rng rng(seed);
  cv::Mat image;
  switch (kind) {
    case TextureKind::kPlaster:
      image = makePlaster(rng, size_px, density);
      break;
    case TextureKind::kFloorTiles:
      image = makeTiles(rng, size_px, density, false);
      break;
    case TextureKind::kCeilingTiles:
      image = makeTiles(rng, size_px, density, true);
      break;
    case TextureKind::kWoodDoor:
      image = makeWood(rng, size_px, density, true);
      break;
    case TextureKind::kPoster:
      image = makePoster(rng, size_px);
      break;
    case TextureKind::kWood:
      image = makeWood(rng, size_px, density, false);
      break;
    case TextureKind::kMetal:
      image = makeMetal(rng, size_px, density);
      break;
    case TextureKind::kFabric:
      image = makeFabric(rng, size_px, density);
      break;
  }
  return fromImage(image);
}

Texture Texture::tiles(const TileStyle& style, std::uint64_t seed, int size_px) {
  if (!isPowerOfTwo(size_px) || size_px < 16 || size_px > 2048) {
    throw std::invalid_argument("texture size " + std::to_string(size_px) +
                                " px must be a power of two in [16, 2048]");
  }
  if (style.tiles_per_side < 1 || size_px % style.tiles_per_side != 0 ||
      size_px / style.tiles_per_side < 4) {
    throw std::invalid_argument("tiles_per_side " + std::to_string(style.tiles_per_side) +
                                " must divide the texture size " + std::to_string(size_px) +
                                " into tiles of at least 4 px");
  }
  const auto in_unit = [](double value) { return value >= 0.0 && value <= 1.0; };
  if (!in_unit(style.contrast) || !in_unit(style.grout_contrast) || !in_unit(style.variation) ||
      !(style.base_luma >= 0.0 && style.base_luma <= 255.0)) {
    throw std::invalid_argument(
        "tile style: contrast, grout_contrast and variation must be in "
        "[0, 1], base_luma in [0, 255]");
  }
  Rng rng(seed);
  const int tile = size_px / style.tiles_per_side;
  // A slight tint, the same for every tile: the pattern stays exactly periodic.
  const cv::Scalar tint(rng.uniform(-12.0, 12.0), rng.uniform(-6.0, 6.0), rng.uniform(-12.0, 12.0));
  const double half_step = 0.5 * 255.0 * style.contrast;
  cv::Mat image(size_px, size_px, CV_8UC3);
  for (int ty = 0; ty < style.tiles_per_side; ++ty) {
    for (int tx = 0; tx < style.tiles_per_side; ++tx) {
      const double checker = ((tx + ty) % 2 == 0) ? half_step : -half_step;
      const double luma = style.base_luma + checker + 12.0 * style.variation * rng.uniform(-1, 1);
      image(cv::Rect(tx * tile, ty * tile, tile, tile)).setTo(cv::Scalar::all(luma) + tint);
    }
  }
  const cv::Scalar grout = (cv::Scalar::all(style.base_luma) + tint) * (1.0 - style.grout_contrast);
  const int grout_px = std::max(1, tile / 16);
  for (int k = 0; k < style.tiles_per_side; ++k) {
    image(cv::Rect(k * tile, 0, grout_px, size_px)).setTo(grout);
    image(cv::Rect(0, k * tile, size_px, grout_px)).setTo(grout);
  }
  return fromImage(image);
}

Texture Texture::fromImage(const cv::Mat& image_bgr) {
  if (image_bgr.type() != CV_8UC3 || image_bgr.cols != image_bgr.rows ||
      !isPowerOfTwo(image_bgr.cols)) {
    throw std::invalid_argument("texture image must be square CV_8UC3 with a power-of-two side");
  }
  Texture texture;
  texture.levels_.push_back(image_bgr.clone());
  while (texture.levels_.back().cols > 4) {
    cv::Mat smaller;
    const int side = texture.levels_.back().cols / 2;
    // INTER_AREA halving is the 2x2 box filter: the standard mip-map reduction.
    cv::resize(texture.levels_.back(), smaller, cv::Size(side, side), 0.0, 0.0, cv::INTER_AREA);
    texture.levels_.push_back(smaller);
  }
  return texture;
}

}  // namespace slamd::synth
