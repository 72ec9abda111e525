#pragma once
// Tracking's local map: the 3D landmarks of the keyframes in tracking's recent window, each the
// same physical point across the keyframes that observed it.
//
// A keyframe's feature joins the landmark of the reference feature it was matched to (an inlier
// of the frame that became the keyframe, against its keyframe or against the local map), or
// starts a new landmark. So a landmark gathers its observations; its position is their
// inverse-variance mean in the world frame (depth noise sigma_z ~ z^2, so near views weigh
// more); its descriptor and keypoint are those of its latest observation, the view most like the
// frames to come. Keyframes that share landmarks are covisible.
//
// VisualOdometry owns one (no threads); it adds each keyframe it makes and removes those leaving
// its window, so the map stays bounded by the window.

#include <cstdint>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>

#include "slamd/tracking/keyframe.hpp"

namespace slamd {

struct MapLandmark {
  /// One keyframe's view of the landmark.
  struct Observation {
    std::int64_t keyframe_id = -1;
    int feature_index = -1;
  };
  /// World position (metres): the inverse-variance mean of the observations.
  Eigen::Vector3d p_world = Eigen::Vector3d::Zero();
  /// Oldest first; the last is the representative (descriptor, keypoint, patch).
  std::vector<Observation> observations;
  /// Sums behind p_world: sum of w_i * p_i and of w_i (w_i = 1 / sigma_z^2, 1/m^2).
  Eigen::Vector3d weighted_sum = Eigen::Vector3d::Zero();
  double weight = 0.0;

  const Observation& representative() const { return observations.back(); }
};

class LocalMap {
 public:
  /// depth_sigma_coeff: sigma_z = coeff * z^2 (metres), the weight of each observation.
  explicit LocalMap(double depth_sigma_coeff);

  /// Adds a keyframe. feature_landmarks[i] is the landmark feature i was matched to (-1: none; may
  /// be empty = none matched); a matched feature with depth joins that landmark unless the
  /// landmark is gone or already observed by this keyframe, and any other feature with depth
  /// starts a new landmark. A keyframe already in the map is ignored.
  void addKeyframe(const KeyframePtr& keyframe, const std::vector<std::int64_t>& feature_landmarks);
  /// Removes a keyframe's observations; landmarks left without any are deleted.
  void removeKeyframe(std::int64_t keyframe_id);
  void clear();

  bool hasKeyframe(std::int64_t keyframe_id) const { return keyframes_.count(keyframe_id) != 0; }
  const Keyframe& keyframe(std::int64_t keyframe_id) const {
    return *keyframes_.at(keyframe_id).keyframe;
  }
  /// The landmark of each of the keyframe's features (-1 without depth).
  const std::vector<std::int64_t>& landmarksOf(std::int64_t keyframe_id) const {
    return keyframes_.at(keyframe_id).landmarks;
  }
  /// Null when the landmark does not exist (any more).
  const MapLandmark* landmark(std::int64_t landmark_id) const;
  /// Keyframes sharing at least min_shared landmarks with keyframe_id (itself excluded), most
  /// shared first, at most max_keyframes.
  std::vector<std::int64_t> covisibleKeyframes(std::int64_t keyframe_id, int min_shared,
                                               int max_keyframes) const;
  std::size_t numLandmarks() const { return landmarks_.size(); }
  std::size_t numKeyframes() const { return keyframes_.size(); }
  /// Changes whenever a keyframe is added or removed or the map cleared (not when an add or a
  /// removal is ignored): what is derived from the map's keyframes and landmark observations is
  /// still valid while it stays the same.
  std::uint64_t revision() const { return revision_; }

 private:
  struct KeyframeEntry {
    KeyframePtr keyframe;
    std::vector<std::int64_t> landmarks;  ///< per feature
  };
  /// The observation's world point and weight.
  void observationOf(const Keyframe& keyframe, int feature_index, Eigen::Vector3d& p_world,
                     double& weight) const;

  double depth_sigma_coeff_;
  std::unordered_map<std::int64_t, KeyframeEntry> keyframes_;
  std::unordered_map<std::int64_t, MapLandmark> landmarks_;
  std::int64_t next_landmark_id_ = 0;
  std::uint64_t revision_ = 0;
};

}  // namespace slamd
