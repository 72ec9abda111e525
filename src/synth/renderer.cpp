#include "slamd/synth/renderer.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

namespace slamd::synth {
namespace {

/// A rectangle in the camera frame, with what the per-pixel tests need.
struct CameraRect {
  bool visible = false;
  Eigen::Vector3d normal;    ///< unit normal, camera frame
  double plane_k = 0.0;      ///< normal . origin (negative when front-facing)
  Eigen::Vector3d u_scaled;  ///< edge_u / |edge_u|^2: a = (p - origin) . u_scaled
  Eigen::Vector3d v_scaled;
  double a_offset = 0.0;  ///< origin . u_scaled
  double b_offset = 0.0;
  double texels_per_a = 0.0;  ///< texels along the texture's x per unit of a (|edge_u| * density)
  double texels_per_b = 0.0;
  double max_texels_per_m = 0.0;
};

/// Polygon clipping against z >= near (Sutherland-Hodgman, one plane).
int clipNear(const std::array<Eigen::Vector3d, 4>& in, double near_m,
             std::array<Eigen::Vector3d, 8>& out) {
  int count = 0;
  for (std::size_t i = 0; i < in.size(); ++i) {
    const Eigen::Vector3d& p = in[i];
    const Eigen::Vector3d& q = in[(i + 1) % in.size()];
    const bool p_in = p.z() >= near_m;
    const bool q_in = q.z() >= near_m;
    if (p_in) out[static_cast<std::size_t>(count++)] = p;
    if (p_in != q_in) {
      const double s = (near_m - p.z()) / (q.z() - p.z());
      out[static_cast<std::size_t>(count++)] = p + s * (q - p);
    }
  }
  return count;
}

constexpr double kEdgeTolerance = 1e-9;  ///< closes cracks between rectangles sharing an edge
constexpr double kShininess = 40.0;      ///< Blinn-Phong exponent: tight highlights of gloss paint
constexpr double kHighlightLevels = 120.0;  ///< grey levels added by a full-strength highlight

}  // namespace

Renderer::Renderer(const Scene& scene, const CameraIntrinsics& intrinsics,
                   const LightingOptions& lighting)
    : scene_(scene), intrinsics_(intrinsics) {
  const Eigen::Vector3d key = lighting.key_direction_world.normalized();
  const Eigen::Vector3d fill = lighting.fill_direction_world.normalized();
  key_direction_world_ = key;
  key_strength_ = lighting.key_strength;
  shade_.reserve(scene.rects.size());
  for (const auto& rect : scene.rects) {
    const Eigen::Vector3d n = rect.normal();
    // Lambert: reflected light proportional to max(0, cos(angle between normal and light)).
    const double shade = lighting.ambient + lighting.key_strength * std::max(0.0, n.dot(key)) +
                         lighting.fill_strength * std::max(0.0, n.dot(fill));
    shade_.push_back(static_cast<float>(shade));
  }
}

Renderer::PointLight Renderer::lightAt(const Eigen::Vector3d& p_world,
                                       const Eigen::Vector3d& normal_world,
                                       const Eigen::Vector3d& to_eye_world, bool glossy) const {
  PointLight light;
  double specular = 0.0;
  const auto highlight = [&](const Eigen::Vector3d& to_light, double strength) {
    if (normal_world.dot(to_light) <= 0.0) return;  // the light is behind the surface
    const Eigen::Vector3d half = (to_light + to_eye_world).normalized();
    const double cos_half = normal_world.dot(half);
    if (cos_half > 0.0) specular += strength * std::pow(cos_half, kShininess);
  };
  if (glossy) highlight(key_direction_world_, key_strength_);
  const LampGrid& lamps = scene_.lamps;
  if (lamps.spacing_m > 0.0 && lamps.strength > 0.0) {
    // The nearest lamps (nine, or three in a row). Each is a downlight: its intensity falls as
    // cos^3 of the angle from straight down; the light reaching a surface follows the cosine law
    // and the inverse square of the distance. The sum is divided by its mean over the floor
    // below a row of lamps ((5 pi / 16) H / spacing for lamps H above it), so the lamps modulate
    // the brightness around its usual level: pools under the lamps, darker stretches between.
    const double spacing = lamps.spacing_m;
    const double i0 = std::round((p_world.x() - lamps.origin_xy.x()) / spacing);
    const double j0 =
        lamps.single_row ? 0.0 : std::round((p_world.y() - lamps.origin_xy.y()) / spacing);
    const int rows = lamps.single_row ? 0 : 1;
    const double reference_m2 = lamps.height_m * lamps.height_m;
    double diffuse = 0.0;
    for (int di = -1; di <= 1; ++di) {
      for (int dj = -rows; dj <= rows; ++dj) {
        const Eigen::Vector3d lamp(lamps.origin_xy.x() + (i0 + di) * spacing,
                                   lamps.origin_xy.y() + (j0 + dj) * spacing, lamps.height_m);
        const Eigen::Vector3d to_lamp = lamp - p_world;
        const double distance2 = std::max(to_lamp.squaredNorm(), 0.01);
        const Eigen::Vector3d direction = to_lamp / std::sqrt(distance2);
        const double cosine = normal_world.dot(direction);
        const double emission = direction.z();  // cosine of the angle from straight down
        if (cosine <= 0.0 || emission <= 0.0) continue;
        diffuse += cosine * emission * emission * emission * reference_m2 / distance2;
        if (glossy) highlight(direction, std::min(1.0, reference_m2 / distance2));
      }
    }
    const double mean_floor_light = (5.0 * M_PI / 16.0) * lamps.height_m / spacing;
    light.diffuse = static_cast<float>(std::min(diffuse / mean_floor_light, 2.0));
  }
  light.specular = static_cast<float>(specular);
  return light;
}

void Renderer::render(const SE3& T_world_camera, RenderOutput& out) const {
  const int width = intrinsics_.width;
  const int height = intrinsics_.height;
  const double fx = intrinsics_.fx;
  const double fy = intrinsics_.fy;
  const double cx = intrinsics_.cx;
  const double cy = intrinsics_.cy;
  out.color_bgr.create(height, width, CV_8UC3);
  out.depth_m.create(height, width, CV_32FC1);
  out.cos_incidence.create(height, width, CV_32FC1);
  out.surface_id.create(height, width, CV_32SC1);
  out.surface_id.setTo(cv::Scalar(-1));
  // Pass 1 keeps the nearest hit's depth in a float buffer (ties only between coplanar surfaces,
  // which scenes avoid by standing decorations off their walls by millimetres).
  out.depth_m.setTo(cv::Scalar(std::numeric_limits<float>::infinity()));

  const SE3 T_camera_world = T_world_camera.inverse();
  const Eigen::Matrix3d R = T_camera_world.linear();
  const Eigen::Vector3d t = T_camera_world.translation();

  std::vector<CameraRect> rects(scene_.rects.size());
  for (std::size_t i = 0; i < scene_.rects.size(); ++i) {
    const SurfaceRect& world = scene_.rects[i];
    CameraRect& rect = rects[i];
    const Eigen::Vector3d o = R * world.origin_world + t;
    const Eigen::Vector3d u = R * world.edge_u_world;
    const Eigen::Vector3d v = R * world.edge_v_world;
    rect.normal = R * world.normal();
    rect.plane_k = rect.normal.dot(o);
    // Back-face culling: the camera (the origin) must be on the front side.
    if (!(rect.plane_k < 0.0)) continue;
    rect.u_scaled = u / u.squaredNorm();
    rect.v_scaled = v / v.squaredNorm();
    rect.a_offset = o.dot(rect.u_scaled);
    rect.b_offset = o.dot(rect.v_scaled);
    rect.texels_per_a = world.edge_u_world.norm() * world.texels_per_m_u;
    rect.texels_per_b = world.edge_v_world.norm() * world.texels_per_m_v;
    rect.max_texels_per_m = std::max(world.texels_per_m_u, world.texels_per_m_v);

    const std::array<Eigen::Vector3d, 4> corners = {o, o + u, o + u + v, o + v};
    std::array<Eigen::Vector3d, 8> clipped;
    const int n = clipNear(corners, kNearPlaneM, clipped);
    if (n < 3) continue;
    std::array<Eigen::Vector2d, 8> pixels;
    double y_min = std::numeric_limits<double>::infinity();
    double y_max = -y_min;
    double x_min = y_min;
    double x_max = -y_min;
    for (int k = 0; k < n; ++k) {
      const Eigen::Vector3d& p = clipped[static_cast<std::size_t>(k)];
      Eigen::Vector2d& q = pixels[static_cast<std::size_t>(k)];
      q = Eigen::Vector2d(fx * p.x() / p.z() + cx, fy * p.y() / p.z() + cy);
      y_min = std::min(y_min, q.y());
      y_max = std::max(y_max, q.y());
      x_min = std::min(x_min, q.x());
      x_max = std::max(x_max, q.x());
    }
    if (x_max < -1.0 || x_min > width || y_max < -1.0 || y_min > height) continue;
    rect.visible = true;
    const int row_begin = std::max(0, static_cast<int>(std::floor(y_min)) - 1);
    const int row_end = std::min(height - 1, static_cast<int>(std::ceil(y_max)) + 1);
    const int id = static_cast<int>(i);
    const Eigen::Vector3d& nn = rect.normal;
    for (int r = row_begin; r <= row_end; ++r) {
      // Span of the convex outline on this row (widened by a pixel: the exact test decides).
      double span_min = std::numeric_limits<double>::infinity();
      double span_max = -span_min;
      const double yr = r;
      for (int k = 0; k < n; ++k) {
        const Eigen::Vector2d& p = pixels[static_cast<std::size_t>(k)];
        const Eigen::Vector2d& q = pixels[static_cast<std::size_t>((k + 1) % n)];
        const double lo = std::min(p.y(), q.y()) - 1.0;
        const double hi = std::max(p.y(), q.y()) + 1.0;
        if (yr < lo || yr > hi) continue;
        double x;
        if (std::abs(q.y() - p.y()) < 1e-12) {
          span_min = std::min({span_min, p.x(), q.x()});
          span_max = std::max({span_max, p.x(), q.x()});
          continue;
        }
        const double s = std::clamp((yr - p.y()) / (q.y() - p.y()), 0.0, 1.0);
        x = p.x() + s * (q.x() - p.x());
        span_min = std::min(span_min, x);
        span_max = std::max(span_max, x);
      }
      if (!(span_min <= span_max)) continue;
      const int c_begin = std::max(0, static_cast<int>(std::floor(span_min)) - 1);
      const int c_end = std::min(width - 1, static_cast<int>(std::ceil(span_max)) + 1);
      if (c_begin > c_end) continue;
      const double ray_y = (yr - cy) / fy;
      // Row constants: every quantity is affine in ray_x.
      const double denom_0 = nn.y() * ray_y + nn.z();
      const double ua_0 = rect.u_scaled.y() * ray_y + rect.u_scaled.z();
      const double vb_0 = rect.v_scaled.y() * ray_y + rect.v_scaled.z();
      float* depth_row = out.depth_m.ptr<float>(r);
      int* id_row = out.surface_id.ptr<int>(r);
      for (int c = c_begin; c <= c_end; ++c) {
        const double ray_x = (c - cx) / fx;
        const double denom = nn.x() * ray_x + denom_0;
        if (!(denom < 0.0)) continue;
        const double z = rect.plane_k / denom;  // depth along the optical axis (ray has z = 1)
        if (!(z < static_cast<double>(depth_row[c]))) continue;
        const double a = z * (rect.u_scaled.x() * ray_x + ua_0) - rect.a_offset;
        if (a < -kEdgeTolerance || a > 1.0 + kEdgeTolerance) continue;
        const double b = z * (rect.v_scaled.x() * ray_x + vb_0) - rect.b_offset;
        if (b < -kEdgeTolerance || b > 1.0 + kEdgeTolerance) continue;
        depth_row[c] = static_cast<float>(z);
        id_row[c] = id;
      }
    }
  }

  // Pass 2: exact depth, incidence and colour of the visible surface per pixel.
  const bool has_lamps = scene_.lamps.spacing_m > 0.0 && scene_.lamps.strength > 0.0;
  const auto lamp_share = has_lamps ? static_cast<float>(scene_.lamps.strength) : 0.0f;
  const Eigen::Vector3d camera_world = T_world_camera.translation();
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (int r = 0; r < height; ++r) {
    const double ray_y = (r - cy) / fy;
    const int* id_row = out.surface_id.ptr<int>(r);
    float* depth_row = out.depth_m.ptr<float>(r);
    float* cos_row = out.cos_incidence.ptr<float>(r);
    auto* color_row = out.color_bgr.ptr<cv::Vec3b>(r);
    for (int c = 0; c < width; ++c) {
      const int id = id_row[c];
      if (id < 0) {
        depth_row[c] = nan;
        cos_row[c] = nan;
        color_row[c] = cv::Vec3b(0, 0, 0);
        continue;
      }
      const CameraRect& rect = rects[static_cast<std::size_t>(id)];
      const SurfaceRect& world = scene_.rects[static_cast<std::size_t>(id)];
      const Eigen::Vector3d ray((c - cx) / fx, ray_y, 1.0);
      const double denom = rect.normal.dot(ray);
      const double z = rect.plane_k / denom;
      const Eigen::Vector3d p = z * ray;
      const double a = std::clamp(p.dot(rect.u_scaled) - rect.a_offset, 0.0, 1.0);
      const double b = std::clamp(p.dot(rect.v_scaled) - rect.b_offset, 0.0, 1.0);
      const double ray_norm = ray.norm();
      const double cos_incidence = -denom / ray_norm;
      depth_row[c] = static_cast<float>(z);
      cos_row[c] = static_cast<float>(cos_incidence);

      const Texture& texture = scene_.textures[static_cast<std::size_t>(world.texture)];
      const double x_texel = world.texel_offset.x() + a * rect.texels_per_a;
      const double y_texel = world.texel_offset.y() + b * rect.texels_per_b;
      // Pixel footprint on the surface (metres): range / focal length, stretched by 1/cos.
      const double footprint_m = z * ray_norm / (fx * std::max(cos_incidence, 0.2));
      const double texels_per_pixel = footprint_m * rect.max_texels_per_m;
      const int level = texels_per_pixel > 1.0 ? std::ilogb(texels_per_pixel) : 0;
      const cv::Vec3f texel = texture.sample(x_texel, y_texel, level, world.wrap_texture);
      float shade = shade_[static_cast<std::size_t>(id)];
      float highlight = 0.0f;
      const bool glossy = world.gloss > 0.0;
      if (has_lamps || glossy) {
        const Eigen::Vector3d p_world = T_world_camera * p;
        const Eigen::Vector3d to_eye = (camera_world - p_world).normalized();
        const PointLight light = lightAt(p_world, world.normal(), to_eye, glossy);
        shade *= (1.0f - lamp_share) + lamp_share * light.diffuse;
        highlight = static_cast<float>(kHighlightLevels * world.gloss) * light.specular;
      }
      color_row[c] = cv::Vec3b(cv::saturate_cast<std::uint8_t>(texel[0] * shade + highlight),
                               cv::saturate_cast<std::uint8_t>(texel[1] * shade + highlight),
                               cv::saturate_cast<std::uint8_t>(texel[2] * shade + highlight));
    }
  }
}

}  // namespace slamd::synth
