#pragma once
// A keyframe of visual odometry: what tracking's local map, mapping and the back end consume.

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "slamd/common/camera_intrinsics.hpp"
#include "slamd/common/rgbd_frame.hpp"
#include "slamd/common/se3.hpp"
#include "slamd/tracking/features.hpp"

namespace slamd {

/// A keyframe: what mapping and the back end consume. Immutable once published.
struct Keyframe {
  std::int64_t id = 0;       ///< 0, 1, 2, ... across segments
  std::int64_t segment = 0;  ///< tracking segment (incremented after LOST)
  Utime utime = 0;           ///< capture time of the frame
  std::int64_t frame_sequence = 0;
  SE3 T_world_camera = SE3::Identity();  ///< odometry pose when the keyframe was made
  CameraIntrinsics intrinsics;
  FeatureSet features;  ///< keypoints, descriptors, undistorted pixels, 3D points (camera frame)
  RgbdFramePtr frame;   ///< images (null when processFrame got a reference, not a pointer)
  double median_depth_m = 0.0;  ///< median depth of the features with depth; 0 = none
};
using KeyframePtr = std::shared_ptr<const Keyframe>;

/// Keyframes another part of the system keeps (the back end's map) near one of tracking's own
/// keyframes, the anchor, each with its pose relative to the anchor. Before making a keyframe,
/// tracking measures against one of them where the map already holds the view
/// (VisualOdometry::setMapKeyframes). The keyframes are shared and immutable; their
/// T_world_camera is in their keeper's frame, not tracking's.
struct MapKeyframes {
  struct Member {
    KeyframePtr keyframe;
    SE3 T_anchor_keyframe = SE3::Identity();
  };
  std::int64_t anchor_id = -1;  ///< -1: none
  std::vector<Member> members;  ///< nearest first
  /// The anchor's segment is not yet placed in the map (after a loss, or in a loaded session
  /// before the first relocalisation): each keyframe of it the keeper gets is a relocalisation
  /// attempt. members then holds keyframes of that segment only.
  bool relocalization_pending = false;
};

/// What the back end keeps of a keyframe: a copy without the frame's images and without the
/// grey image the features came from. Keypoints, descriptors, undistorted pixels, 3D points and
/// poses stay; so does the smoothed grey image (features.align_gray) when keep_alignment_image
/// (the back end aligns patches of it to make its edges sub-pixel: backend.align_patches).
std::shared_ptr<Keyframe> compactKeyframe(const Keyframe& keyframe, bool keep_alignment_image);

/// Bytes held by a keyframe's buffers: feature vectors, descriptors and images (a buffer that two
/// fields share counted once).
std::size_t keyframeBytes(const Keyframe& keyframe);

}  // namespace slamd
