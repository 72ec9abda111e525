#pragma once
// Renderer: exact colour + depth images of a synthetic Scene by ray casting.
//
// Usage:
//   Renderer renderer(scene, intrinsics);           // keeps a reference to scene: outlive it
//   RenderOutput out;                               // reuse across frames (no reallocation)
//   renderer.render(T_world_camera, out);
//   // out.depth_m(v, u) = z of the first surface hit by the ray through pixel centre (u, v)
//
// Conventions: T_world_camera maps points from the camera optical frame (x right, y down, z
// forward) to the scene's world frame; pixel (0, 0) is the centre of the top-left pixel; depth is
// z along the optical axis in metres (CV_32F), NaN where the ray hits nothing.
//
// Method: per-rectangle rasterisation-style ray casting. Each visible (front-facing) rectangle is
// clipped to the near plane and projected; for the pixels inside its projected outline, the exact
// ray-plane intersection (in double precision) is tested against the rectangle's extent and a
// depth buffer. A second pass shades only the visible surface of each pixel: bilinear texture
// lookup in the mip level matching the pixel footprint, times Lambertian lighting (ambient plus
// two directional lights; Lambert's cosine law, which for planar faces and directional lights is
// constant per face). Scenes with ceiling lamps (Scene::lamps) modulate that light per pixel by
// the nearest lamps (nine, or three in a row; downlights, cosine law, inverse-square falloff);
// glossy surfaces (SurfaceRect::gloss) add white Blinn-Phong highlights of the key light and the
// lamps, which move with the viewpoint.
// No noise: sensor effects are SensorModel's job.
//
// Thread-safety: render() is const and touches only its output; one Renderer may serve several
// threads with separate outputs, but slamd calls it from one thread.

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "slamd/common/camera_intrinsics.hpp"
#include "slamd/common/se3.hpp"
#include "slamd/synth/scene.hpp"

namespace slamd::synth {

struct RenderOutput {
  cv::Mat color_bgr;      ///< CV_8UC3, BGR
  cv::Mat depth_m;        ///< CV_32FC1, z along the optical axis in metres, NaN for no hit
  cv::Mat cos_incidence;  ///< CV_32FC1, cosine of the angle between ray and surface normal
  cv::Mat surface_id;     ///< CV_32SC1, index into Scene::rects, -1 for no hit
};

struct LightingOptions {
  double ambient = 0.40;  ///< fraction of the texture colour lit by ambient light
  /// Directions towards the lights, world frame (normalised on use), and their strengths.
  Eigen::Vector3d key_direction_world = Eigen::Vector3d(0.35, 0.55, 1.0);
  double key_strength = 0.50;
  Eigen::Vector3d fill_direction_world = Eigen::Vector3d(-0.6, -0.4, 0.5);
  double fill_strength = 0.30;
};

class Renderer {
 public:
  /// @param scene world to render; kept by reference, must outlive the renderer.
  /// @param intrinsics ideal pinhole (distortion is ignored).
  Renderer(const Scene& scene, const CameraIntrinsics& intrinsics,
           const LightingOptions& lighting = LightingOptions());

  /// Renders the view from T_world_camera into `out` (allocated on first use).
  void render(const SE3& T_world_camera, RenderOutput& out) const;

  const CameraIntrinsics& intrinsics() const { return intrinsics_; }
  const Scene& scene() const { return scene_; }

  /// Rays closer than this (metres, along z) are clipped.
  static constexpr double kNearPlaneM = 0.02;

 private:
  /// Lamp light and highlights at a visible point (world frame), see the file comment.
  struct PointLight {
    float diffuse = 1.0f;   ///< lamp light relative to its mean on the floor, 0..2
    float specular = 0.0f;  ///< highlight intensity, 0..~1, before the surface's gloss
  };
  PointLight lightAt(const Eigen::Vector3d& p_world, const Eigen::Vector3d& normal_world,
                     const Eigen::Vector3d& to_eye_world, bool glossy) const;

  const Scene& scene_;
  CameraIntrinsics intrinsics_;
  std::vector<float> shade_;  ///< Lambertian factor per rectangle (directional lights)
  Eigen::Vector3d key_direction_world_;
  double key_strength_ = 0.0;
};

}  // namespace slamd::synth
