#include "slamd/tracking/local_map.hpp"

#include <algorithm>
#include <utility>

namespace slamd {

LocalMap::LocalMap(double depth_sigma_coeff) : depth_sigma_coeff_(depth_sigma_coeff) {}

void LocalMap::observationOf(const Keyframe& keyframe, int feature_index, Eigen::Vector3d& p_world,
                             double& weight) const {
  const Eigen::Vector3d& p_camera =
      keyframe.features.points[static_cast<std::size_t>(feature_index)];
  p_world = keyframe.T_world_camera * p_camera;
  const double z = p_camera.z();
  const double sigma_m = std::max(1e-4, depth_sigma_coeff_ * z * z);
  weight = 1.0 / (sigma_m * sigma_m);
}

void LocalMap::addKeyframe(const KeyframePtr& keyframe,
                           const std::vector<std::int64_t>& feature_landmarks) {
  if (keyframe == nullptr || hasKeyframe(keyframe->id)) return;
  ++revision_;
  const FeatureSet& features = keyframe->features;
  KeyframeEntry entry;
  entry.keyframe = keyframe;
  entry.landmarks.assign(features.size(), -1);
  for (std::size_t i = 0; i < features.size(); ++i) {
    if (!features.hasDepth(i)) continue;
    Eigen::Vector3d p_world;
    double weight = 0.0;
    observationOf(*keyframe, static_cast<int>(i), p_world, weight);
    std::int64_t id = i < feature_landmarks.size() ? feature_landmarks[i] : -1;
    auto found = id >= 0 ? landmarks_.find(id) : landmarks_.end();
    // Two features of one keyframe matched to one landmark: the second starts its own.
    if (found != landmarks_.end() && found->second.representative().keyframe_id == keyframe->id) {
      found = landmarks_.end();
    }
    if (found == landmarks_.end()) {
      id = next_landmark_id_++;
      found = landmarks_.emplace(id, MapLandmark()).first;
    }
    MapLandmark& landmark = found->second;
    landmark.observations.push_back({keyframe->id, static_cast<int>(i)});
    landmark.weighted_sum += weight * p_world;
    landmark.weight += weight;
    landmark.p_world = landmark.weighted_sum / landmark.weight;
    entry.landmarks[i] = id;
  }
  keyframes_.emplace(keyframe->id, std::move(entry));
}

void LocalMap::removeKeyframe(std::int64_t keyframe_id) {
  const auto entry = keyframes_.find(keyframe_id);
  if (entry == keyframes_.end()) return;
  ++revision_;
  const std::vector<std::int64_t>& ids = entry->second.landmarks;
  for (std::size_t i = 0; i < ids.size(); ++i) {
    if (ids[i] < 0) continue;
    const auto found = landmarks_.find(ids[i]);
    if (found == landmarks_.end()) continue;
    MapLandmark& landmark = found->second;
    auto& observations = landmark.observations;
    observations.erase(std::remove_if(observations.begin(), observations.end(),
                                      [&](const MapLandmark::Observation& o) {
                                        return o.keyframe_id == keyframe_id;
                                      }),
                       observations.end());
    if (observations.empty()) {
      landmarks_.erase(found);
      continue;
    }
    // Rebuilt from the observations left (a handful) rather than subtracted: no rounding drift.
    landmark.weighted_sum.setZero();
    landmark.weight = 0.0;
    for (const MapLandmark::Observation& o : observations) {
      Eigen::Vector3d p_world;
      double weight = 0.0;
      observationOf(*keyframes_.at(o.keyframe_id).keyframe, o.feature_index, p_world, weight);
      landmark.weighted_sum += weight * p_world;
      landmark.weight += weight;
    }
    landmark.p_world = landmark.weighted_sum / landmark.weight;
  }
  keyframes_.erase(entry);
}

void LocalMap::clear() {
  ++revision_;
  keyframes_.clear();
  landmarks_.clear();
}

const MapLandmark* LocalMap::landmark(std::int64_t landmark_id) const {
  const auto found = landmarks_.find(landmark_id);
  return found == landmarks_.end() ? nullptr : &found->second;
}

std::vector<std::int64_t> LocalMap::covisibleKeyframes(std::int64_t keyframe_id, int min_shared,
                                                       int max_keyframes) const {
  std::vector<std::int64_t> result;
  const auto entry = keyframes_.find(keyframe_id);
  if (entry == keyframes_.end()) return result;
  std::unordered_map<std::int64_t, int> shared;
  for (std::int64_t id : entry->second.landmarks) {
    if (id < 0) continue;
    const auto found = landmarks_.find(id);
    if (found == landmarks_.end()) continue;
    for (const MapLandmark::Observation& o : found->second.observations) {
      if (o.keyframe_id != keyframe_id) ++shared[o.keyframe_id];
    }
  }
  std::vector<std::pair<int, std::int64_t>> ranked;
  for (const auto& [id, count] : shared) {
    if (count >= min_shared) ranked.emplace_back(count, id);
  }
  // Most shared first; among equals the newer keyframe.
  std::sort(ranked.begin(), ranked.end(), [](const auto& a, const auto& b) {
    return a.first != b.first ? a.first > b.first : a.second > b.second;
  });
  for (std::size_t k = 0; k < ranked.size() && static_cast<int>(k) < max_keyframes; ++k) {
    result.push_back(ranked[k].second);
  }
  return result;
}

}  // namespace slamd
