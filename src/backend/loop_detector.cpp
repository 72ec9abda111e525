#include "slamd/backend/loop_detector.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

#include <opencv2/features2d.hpp>

#include "slamd/tracking/motion_estimation.hpp"

namespace slamd {

namespace {

bool hasBinaryDescriptors(const FeatureSet& features) {
  return !features.descriptors.empty() && features.descriptors.type() == CV_8UC1 &&
         features.descriptors.cols == 32 &&
         static_cast<std::size_t>(features.descriptors.rows) == features.size() &&
         features.points.size() == features.size() && features.pixels.size() == features.size();
}

// Floor on the loop edge's standard deviations: the refinement's covariance assumes perfect
// matches and is overconfident for a loop measured across a long interval.
constexpr double kMinSigmaM = 0.01;
constexpr double kMinSigmaRad = 0.5 * M_PI / 180.0;

}  // namespace

const char* loopStatusName(LoopStatus status) {
  switch (status) {
    case LoopStatus::kLoopFound:
      return "loop_found";
    case LoopStatus::kNoCandidate:
      return "no_candidate";
    case LoopStatus::kGeometryRejected:
      return "geometry_rejected";
    case LoopStatus::kAwaitingConsistency:
      return "awaiting_consistency";
    case LoopStatus::kUnsupportedDescriptors:
      return "unsupported_descriptors";
    case LoopStatus::kOdometryRejected:
      return "odometry_rejected";
  }
  return "unknown";
}

LoopDetector::LoopDetector(const BackendConfig& config,
                           std::shared_ptr<const Vocabulary> vocabulary)
    : config_(config), vocabulary_(std::move(vocabulary)) {}

std::vector<LoopDetector::Candidate> LoopDetector::retrieve(const BowVector& bow,
                                                            std::size_t num_searchable,
                                                            double min_score,
                                                            const KeyframeFilter& allowed) const {
  std::vector<double> scores(num_searchable, 0.0);
  for (const auto& [word, weight] : bow) {
    const auto it = inverted_.find(word);
    if (it == inverted_.end()) continue;
    for (const auto& [entry, entry_weight] : it->second) {
      if (static_cast<std::size_t>(entry) < num_searchable) {
        scores[static_cast<std::size_t>(entry)] += std::min(weight, entry_weight);
      }
    }
  }
  std::vector<Candidate> candidates;
  for (std::size_t e = 0; e < num_searchable; ++e) {
    if (scores[e] >= min_score && scores[e] > 0.0 &&
        (!allowed || allowed(entries_[e].id, entries_[e].segment))) {
      candidates.push_back({static_cast<int>(e), scores[e]});
    }
  }
  std::sort(candidates.begin(), candidates.end(),
            [](const Candidate& a, const Candidate& b) { return a.score > b.score; });
  return candidates;
}

void LoopDetector::alignInliers(const FeatureSet& ref, const FeatureSet& query,
                                const CameraIntrinsics& K, const RansacResult& ransac,
                                std::vector<Correspondence>& matches) const {
  // Two independent ORB detections locate the same point to about a pixel at their pyramid
  // level; aligning the reference patch in the query image (as tracking does) makes each inlier
  // sub-pixel consistent with the reference keypoint, which is what makes the edge precise.
  const AlignedInliers aligned =
      alignInlierPatches(ref, query, K, ransac.T_ref_curr, matches, ransac.inliers);
  const std::vector<Eigen::Vector2d> pixels =
      undistortPixels(aligned.pixels_raw, K, TrackingConfig());
  for (std::size_t k = 0; k < aligned.match_indices.size(); ++k) {
    matches[aligned.match_indices[k]].pixel_curr = pixels[k];
    matches[aligned.match_indices[k]].pixel_sigma_px = 1.0;
  }
}

bool LoopDetector::verify(const FeatureSet& query, const CameraIntrinsics& intrinsics,
                          const Entry& e, LoopDetection& detection, int min_inliers,
                          double min_sigma_m, double min_sigma_rad,
                          const SE3* T_match_query_prior) {
  const FeatureSet& ref = e.features();
  // Descriptors of the features with depth, on both sides.
  const auto withDepth = [](const FeatureSet& features, std::vector<int>& rows) {
    cv::Mat descriptors;
    for (std::size_t j = 0; j < features.size(); ++j) {
      if (!features.hasDepth(j)) continue;
      rows.push_back(static_cast<int>(j));
      descriptors.push_back(features.descriptors.row(static_cast<int>(j)));
    }
    return descriptors;
  };
  std::vector<int> ref_rows;
  std::vector<int> query_rows;
  const cv::Mat ref_descriptors = withDepth(ref, ref_rows);
  const cv::Mat query_descriptors = withDepth(query, query_rows);
  if (ref_rows.size() < 3 || query_rows.size() < 3) return false;

  std::vector<int> best_query(ref.size(), -1);
  std::vector<int> best_query_distance(ref.size(), std::numeric_limits<int>::max());
  const auto keep = [&](std::size_t ref_row, int query_row, int best_distance,
                        int second_distance) {
    if (best_distance > config_.loop_max_descriptor_distance ||
        best_distance >= config_.loop_match_ratio * second_distance) {
      return;
    }
    if (best_distance < best_query_distance[ref_row]) {
      best_query_distance[ref_row] = best_distance;
      best_query[ref_row] = query_row;
    }
  };
  if (T_match_query_prior != nullptr) {
    // Guided: each reference point is projected with the prior and compared with the query
    // features near its projection only (a grid over the query pixels), with the ratio test
    // among those. Far cheaper than all pairs, and it cannot pick a look-alike elsewhere.
    constexpr double kCellPx = 32.0;
    const double radius_px = config_.local_search_radius_px;
    const int cols = static_cast<int>(intrinsics.width / kCellPx) + 1;
    const int rows = static_cast<int>(intrinsics.height / kCellPx) + 1;
    std::vector<std::vector<int>> grid(static_cast<std::size_t>(cols * rows));
    std::vector<BinaryDescriptor> query_binary(query.size());
    for (int q : query_rows) {
      const Eigen::Vector2d& uv = query.pixels[static_cast<std::size_t>(q)];
      const int cx = static_cast<int>(uv.x() / kCellPx);
      const int cy = static_cast<int>(uv.y() / kCellPx);
      if (cx < 0 || cy < 0 || cx >= cols || cy >= rows) continue;
      grid[static_cast<std::size_t>(cy * cols + cx)].push_back(q);
      query_binary[static_cast<std::size_t>(q)] = binaryDescriptorRow(query.descriptors, q);
    }
    const SE3 T_query_match = T_match_query_prior->inverse();
    for (int j : ref_rows) {
      const Eigen::Vector3d p = T_query_match * ref.points[static_cast<std::size_t>(j)];
      if (p.z() <= 0.0) continue;
      const Eigen::Vector2d uv = intrinsics.project(p);
      const BinaryDescriptor d = binaryDescriptorRow(ref.descriptors, j);
      int best = -1, best_distance = 257, second_distance = 257;
      const int x0 = std::max(0, static_cast<int>((uv.x() - radius_px) / kCellPx));
      const int x1 = std::min(cols - 1, static_cast<int>((uv.x() + radius_px) / kCellPx));
      const int y0 = std::max(0, static_cast<int>((uv.y() - radius_px) / kCellPx));
      const int y1 = std::min(rows - 1, static_cast<int>((uv.y() + radius_px) / kCellPx));
      for (int cy = y0; cy <= y1; ++cy) {
        for (int cx = x0; cx <= x1; ++cx) {
          for (int q : grid[static_cast<std::size_t>(cy * cols + cx)]) {
            if ((query.pixels[static_cast<std::size_t>(q)] - uv).squaredNorm() >
                radius_px * radius_px) {
              continue;
            }
            const int distance = hammingDistance(d, query_binary[static_cast<std::size_t>(q)]);
            if (distance < best_distance) {
              second_distance = best_distance;
              best_distance = distance;
              best = q;
            } else if (distance < second_distance) {
              second_distance = distance;
            }
          }
        }
      }
      if (best >= 0) keep(static_cast<std::size_t>(j), best, best_distance, second_distance);
    }
  } else {
    // Nearest neighbour over all pairs with a ratio test (OpenCV's brute-force Hamming matcher:
    // SIMD popcount); each reference feature keeps its closest query feature.
    std::vector<std::vector<cv::DMatch>> knn;
    cv::BFMatcher(cv::NORM_HAMMING).knnMatch(query_descriptors, ref_descriptors, knn, 2);
    for (const std::vector<cv::DMatch>& pair : knn) {
      if (pair.empty()) continue;
      keep(static_cast<std::size_t>(ref_rows[static_cast<std::size_t>(pair[0].trainIdx)]),
           query_rows[static_cast<std::size_t>(pair[0].queryIdx)],
           static_cast<int>(pair[0].distance),
           pair.size() > 1 ? static_cast<int>(pair[1].distance) : 257);
    }
  }
  std::vector<Correspondence> matches;
  for (std::size_t j = 0; j < ref.size(); ++j) {
    const int i = best_query[j];
    if (i < 0) continue;
    Correspondence c;
    c.point_ref = ref.points[j];
    c.pixel_curr = query.pixels[static_cast<std::size_t>(i)];
    c.depth_curr_m = query.points[static_cast<std::size_t>(i)].z();
    c.pixel_sigma_px = query.scale.size() == query.size()
                           ? static_cast<double>(query.scale[static_cast<std::size_t>(i)])
                           : 1.0;
    c.ref_index = static_cast<int>(j);
    c.curr_index = i;
    matches.push_back(c);
  }
  detection.num_matches = static_cast<int>(matches.size());
  if (detection.num_matches < min_inliers) return false;

  const RansacResult ransac = ransacRigid(matches, intrinsics, config_.loop_inlier_threshold_px,
                                          config_.loop_ransac_iterations, rng_);
  if (!ransac.success || ransac.num_inliers < min_inliers) return false;
  if (config_.align_patches) alignInliers(ref, query, intrinsics, ransac, matches);
  const RefinementResult refined =
      refinePose(matches, ransac.inliers, intrinsics, ransac.T_ref_curr, RefinementOptions());
  if (!refined.success) return false;
  int inliers = 0;
  for (const Correspondence& c : matches) {
    if (reprojectionErrorPx(c, intrinsics, refined.T_ref_curr) <
        config_.loop_inlier_threshold_px * c.pixel_sigma_px) {
      ++inliers;
    }
  }
  detection.num_inliers = inliers;
  if (inliers < min_inliers) return false;
  detection.T_match_query = refined.T_ref_curr;
  Matrix6d covariance = refined.covariance;
  for (int k = 0; k < 3; ++k) covariance(k, k) += min_sigma_m * min_sigma_m;
  for (int k = 3; k < 6; ++k) covariance(k, k) += min_sigma_rad * min_sigma_rad;
  detection.information = covariance.inverse();
  detection.information = 0.5 * (detection.information + detection.information.transpose());
  detection.match_id = e.id;
  return true;
}

LoopDetection LoopDetector::processKeyframe(const KeyframePtr& keyframe_ptr,
                                            const std::vector<LoopDetection>& already_verified) {
  const Keyframe& keyframe = *keyframe_ptr;
  const auto start = std::chrono::steady_clock::now();
  LoopDetection detection;
  detection.query_id = keyframe.id;
  const auto done = [&]() {
    detection.time_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    return detection;
  };
  if (!hasBinaryDescriptors(keyframe.features) || vocabulary_ == nullptr || vocabulary_->empty()) {
    detection.status = LoopStatus::kUnsupportedDescriptors;
    groups_.clear();
    return done();
  }
  const BowVector bow = vocabulary_->transform(keyframe.features.descriptors);

  const std::size_t excluded =
      std::min(entries_.size(), static_cast<std::size_t>(config_.loop_exclude_recent));
  const std::size_t num_searchable = entries_.size() - excluded;
  // A candidate must look at least a fraction as similar as the previous keyframe does (which
  // normally sees the same place): the threshold adapts to how distinctive the view is.
  double min_score = config_.loop_min_score;
  if (!entries_.empty()) {
    min_score =
        std::max(min_score, config_.loop_min_score_ratio * bowScore(bow, entries_.back().bow));
  }
  std::vector<Candidate> candidates =
      num_searchable > 0 ? retrieve(bow, num_searchable, min_score) : std::vector<Candidate>();
  detection.num_candidates = static_cast<int>(candidates.size());
  if (candidates.size() > static_cast<std::size_t>(config_.loop_max_candidates)) {
    candidates.resize(static_cast<std::size_t>(config_.loop_max_candidates));
  }

  double path_length_m = 0.0;
  if (!entries_.empty()) {
    path_length_m = entries_.back().path_length_m + (keyframe.T_world_camera.translation() -
                                                     entries_.back().T_world_camera.translation())
                                                        .norm();
  }

  // Verify the candidates; each verified one joins (or starts) a consistency group.
  std::vector<Group> new_groups;
  LoopDetection best;
  bool have_best = false;
  bool odometry_rejected = false;
  for (const Candidate& candidate : candidates) {
    LoopDetection attempt = detection;
    attempt.score = candidate.score;
    const Entry& entry = entries_[static_cast<std::size_t>(candidate.entry)];
    const auto known = std::find_if(already_verified.begin(), already_verified.end(),
                                    [&](const LoopDetection& d) { return d.match_id == entry.id; });
    if (known != already_verified.end() && known->num_inliers >= config_.loop_min_inliers) {
      // Verified moments ago (a local edge): the same images, no need to match them again.
      attempt.match_id = known->match_id;
      attempt.T_match_query = known->T_match_query;
      attempt.information = known->information;
      attempt.num_matches = known->num_matches;
      attempt.num_inliers = known->num_inliers;
    } else if (!verify(keyframe.features, keyframe.intrinsics, entry, attempt,
                       config_.loop_min_inliers, kMinSigmaM, kMinSigmaRad)) {
      if (!have_best && attempt.num_inliers > best.num_inliers) best = attempt;
      continue;
    }
    if (config_.loop_check_odometry && entry.segment == keyframe.segment) {
      const SE3 T_odometry = entry.T_world_camera.inverse() * keyframe.T_world_camera;
      const double discrepancy_m =
          (T_odometry.translation() - attempt.T_match_query.translation()).norm();
      const double allowed_m = config_.loop_max_drift_m +
                               config_.loop_max_drift_ratio * (path_length_m - entry.path_length_m);
      if (discrepancy_m > allowed_m) {
        odometry_rejected = true;
        continue;
      }
    }
    int count = 1;
    for (const Group& group : groups_) {
      if (std::abs(group.match_id - attempt.match_id) <= config_.loop_consistency_window) {
        count = std::max(count, group.count + 1);
      }
    }
    attempt.consistency = count;
    new_groups.push_back({attempt.match_id, count});
    // Prefer the most consistent place, then the most inliers.
    if (!have_best || attempt.consistency > best.consistency ||
        (attempt.consistency == best.consistency && attempt.num_inliers > best.num_inliers)) {
      best = attempt;
      have_best = true;
    }
  }
  groups_ = std::move(new_groups);

  if (have_best) {
    detection = best;
    detection.status = best.consistency >= config_.loop_consistency
                           ? LoopStatus::kLoopFound
                           : LoopStatus::kAwaitingConsistency;
  } else {
    detection.status = candidates.empty()  ? LoopStatus::kNoCandidate
                       : odometry_rejected ? LoopStatus::kOdometryRejected
                                           : LoopStatus::kGeometryRejected;
    detection.num_matches = best.num_matches;
    detection.num_inliers = best.num_inliers;
  }

  store(keyframe_ptr, bow, path_length_m);
  return done();
}

void LoopDetector::store(const KeyframePtr& keyframe, BowVector bow, double path_length_m) {
  // A removed entry kept its BoW only while it was the latest (the score threshold above).
  if (!entries_.empty() && entries_.back().removed) entries_.back().bow = BowVector();
  const int entry = static_cast<int>(entries_.size());
  for (const auto& [word, weight] : bow) inverted_[word].emplace_back(entry, weight);
  entries_.push_back({keyframe->id, keyframe->segment, keyframe->T_world_camera, path_length_m,
                      std::move(bow), keyframe});
}

void LoopDetector::insertKeyframe(const KeyframePtr& keyframe_ptr) {
  const Keyframe& keyframe = *keyframe_ptr;
  groups_.clear();
  if (!hasBinaryDescriptors(keyframe.features) || vocabulary_ == nullptr || vocabulary_->empty()) {
    return;
  }
  double path_length_m = 0.0;
  if (!entries_.empty()) {
    path_length_m = entries_.back().path_length_m + (keyframe.T_world_camera.translation() -
                                                     entries_.back().T_world_camera.translation())
                                                        .norm();
  }
  store(keyframe_ptr, vocabulary_->transform(keyframe.features.descriptors), path_length_m);
}

const FeatureSet* LoopDetector::features(std::int64_t id) const {
  const KeyframePtr stored = keyframe(id);  // the detector holds it: the pointer stays valid
  return stored != nullptr ? &stored->features : nullptr;
}

KeyframePtr LoopDetector::keyframe(std::int64_t id) const {
  const auto found = std::find_if(entries_.begin(), entries_.end(),
                                  [id](const Entry& e) { return e.id == id && !e.removed; });
  return found != entries_.end() ? found->keyframe : nullptr;
}

std::unordered_map<std::int64_t, const FeatureSet*> LoopDetector::storedFeatures() const {
  std::unordered_map<std::int64_t, const FeatureSet*> features;
  for (const Entry& entry : entries_) {
    if (!entry.removed) features[entry.id] = &entry.features();
  }
  return features;
}

bool LoopDetector::removeKeyframe(std::int64_t id) {
  const auto found = std::find_if(entries_.begin(), entries_.end(),
                                  [id](const Entry& e) { return e.id == id && !e.removed; });
  if (found == entries_.end()) return false;
  const int entry = static_cast<int>(found - entries_.begin());
  for (const auto& [word, weight] : found->bow) {
    const auto it = inverted_.find(word);
    if (it == inverted_.end()) continue;
    auto& postings = it->second;
    postings.erase(
        std::remove_if(postings.begin(), postings.end(),
                       [entry](const std::pair<int, double>& p) { return p.first == entry; }),
        postings.end());
    if (postings.empty()) inverted_.erase(it);
  }
  found->keyframe = nullptr;
  found->removed = true;
  // The latest entry's BoW still sets the next keyframe's score threshold.
  if (entry + 1 != static_cast<int>(entries_.size())) found->bow = BowVector();
  ++num_removed_;
  return true;
}

LoopDetection LoopDetector::query(const FeatureSet& features, const CameraIntrinsics& intrinsics) {
  return query(features, intrinsics, KeyframeFilter(), 0);
}

LoopDetection LoopDetector::query(const FeatureSet& features, const CameraIntrinsics& intrinsics,
                                  const KeyframeFilter& allowed, int min_inliers) {
  const auto start = std::chrono::steady_clock::now();
  LoopDetection detection;
  if (!hasBinaryDescriptors(features) || vocabulary_ == nullptr || vocabulary_->empty()) {
    detection.status = LoopStatus::kUnsupportedDescriptors;
    return detection;
  }
  if (min_inliers <= 0) min_inliers = config_.loop_min_inliers;
  const BowVector bow = vocabulary_->transform(features.descriptors);
  std::vector<Candidate> candidates =
      retrieve(bow, entries_.size(), config_.loop_min_score, allowed);
  detection.num_candidates = static_cast<int>(candidates.size());
  if (candidates.size() > static_cast<std::size_t>(config_.loop_max_candidates)) {
    candidates.resize(static_cast<std::size_t>(config_.loop_max_candidates));
  }
  detection.status = candidates.empty() ? LoopStatus::kNoCandidate : LoopStatus::kGeometryRejected;
  for (const Candidate& candidate : candidates) {
    LoopDetection attempt = detection;
    attempt.score = candidate.score;
    if (verify(features, intrinsics, entries_[static_cast<std::size_t>(candidate.entry)], attempt,
               min_inliers, kMinSigmaM, kMinSigmaRad) &&
        (detection.match_id < 0 || attempt.num_inliers > detection.num_inliers)) {
      detection = attempt;
      detection.status = LoopStatus::kLoopFound;
    } else if (detection.match_id < 0 && attempt.num_inliers > detection.num_inliers) {
      detection.num_matches = attempt.num_matches;
      detection.num_inliers = attempt.num_inliers;
    }
  }
  detection.time_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return detection;
}

std::vector<LoopDetection> LoopDetector::matchLocal(const Keyframe& keyframe,
                                                    const KeyframeFilter& allowed,
                                                    const PosePrior& prior) {
  std::vector<LoopDetection> matches;
  if (!hasBinaryDescriptors(keyframe.features) || vocabulary_ == nullptr || vocabulary_->empty() ||
      entries_.empty()) {
    return matches;
  }
  const BowVector bow = vocabulary_->transform(keyframe.features.descriptors);
  std::vector<Candidate> candidates = retrieve(bow, entries_.size(), 0.0, allowed);
  if (candidates.size() > static_cast<std::size_t>(config_.local_max_candidates)) {
    candidates.resize(static_cast<std::size_t>(config_.local_max_candidates));
  }
  for (const Candidate& candidate : candidates) {
    LoopDetection attempt;
    attempt.query_id = keyframe.id;
    attempt.score = candidate.score;
    const Entry& entry = entries_[static_cast<std::size_t>(candidate.entry)];
    SE3 T_prior = SE3::Identity();
    const bool have_prior = prior && prior(entry.id, T_prior);
    if (verify(keyframe.features, keyframe.intrinsics, entry, attempt, config_.local_min_inliers,
               config_.local_min_sigma_m, config_.local_min_sigma_rad,
               have_prior ? &T_prior : nullptr)) {
      attempt.status = LoopStatus::kLoopFound;
      matches.push_back(attempt);
      // Enough edges: the remaining candidates would only cost verification time. Culling
      // needs them all: every keyframe that sees the place is a view of it.
      if (!config_.cull_redundant_keyframes &&
          matches.size() >= static_cast<std::size_t>(std::max(1, config_.local_edges))) {
        break;
      }
    }
  }
  std::sort(matches.begin(), matches.end(), [](const LoopDetection& a, const LoopDetection& b) {
    return a.num_inliers > b.num_inliers;
  });
  return matches;
}

}  // namespace slamd
