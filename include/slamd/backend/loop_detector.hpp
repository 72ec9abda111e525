#pragma once
// LoopDetector: place recognition over keyframes. Each keyframe's ORB descriptors become a
// bag-of-words vector (Vocabulary); an inverted index (word -> keyframes) retrieves earlier
// keyframes that look alike, excluding the most recent ones; the best candidates are verified
// geometrically with tracking's RANSAC (ransacRigid) and robust refinement (refinePose) on
// descriptor matches; a loop is accepted only when consecutive keyframes verify candidates at the
// same place (consistency), which rejects isolated false matches, and when its relative pose
// agrees with the odometry within the drift expected over the path between the two keyframes
// (which rejects places that look and fit alike but lie far apart: repeated textures).
//
// Usage (one thread owns it, typically the back-end thread; there are no threads inside):
//   auto vocabulary = std::make_shared<const Vocabulary>(Vocabulary::train(...));
//   LoopDetector detector(BackendConfig::load(config), vocabulary);
//   for each keyframe (ids increasing):
//     LoopDetection d = detector.processKeyframe(*keyframe);   // queries, then adds it
//     if (d.status == LoopStatus::kLoopFound)
//       graph.addEdge({d.match_id, d.query_id, d.T_match_query, d.information, EdgeKind::kLoop});
//   LoopDetection r = detector.query(features, intrinsics);     // relocalisation: no insertion
//
// Frames: T_match_query maps points of the query keyframe's camera frame into the matched
// keyframe's camera frame (metres), the convention of a pose-graph edge from match to query.
// Only binary 256-bit descriptors (the ORB front end) are indexed; other front ends report
// kUnsupportedDescriptors.

#include <cstdint>
#include <functional>
#include <memory>
#include <random>
#include <unordered_map>
#include <vector>

#include "slamd/backend/backend_config.hpp"
#include "slamd/backend/vocabulary.hpp"
#include "slamd/common/camera_intrinsics.hpp"
#include "slamd/common/se3.hpp"
#include "slamd/tracking/features.hpp"
#include "slamd/tracking/visual_odometry.hpp"

namespace slamd {

enum class LoopStatus : std::int8_t {
  kLoopFound = 0,               ///< verified and consistent: add the edge
  kNoCandidate = 1,             ///< nothing similar enough outside the recent keyframes
  kGeometryRejected = 2,        ///< candidates failed RANSAC / refinement / minimum inliers
  kAwaitingConsistency = 3,     ///< verified, but not yet confirmed by consecutive keyframes
  kUnsupportedDescriptors = 4,  ///< not 256-bit binary descriptors, or no features
  kOdometryRejected = 5,        ///< verified, but too far from the odometry (aliasing)
};

const char* loopStatusName(LoopStatus status);

struct LoopDetection {
  LoopStatus status = LoopStatus::kNoCandidate;
  std::int64_t query_id = -1;           ///< the keyframe processed (-1 for query())
  std::int64_t match_id = -1;           ///< the earlier keyframe it was verified against
  SE3 T_match_query = SE3::Identity();  ///< metres
  /// Information of the loop edge (inverse covariance from the refinement, with a floor of
  /// 1 cm / 0.5 degree standard deviation), order x y z rx ry rz.
  Matrix6d information = Matrix6d::Identity();
  double score = 0.0;      ///< BoW similarity of the match, [0, 1]
  int num_candidates = 0;  ///< candidates retrieved above the score threshold
  int num_matches = 0;     ///< descriptor matches with the verified candidate
  int num_inliers = 0;     ///< RANSAC inliers after refinement
  int consistency = 0;     ///< consecutive keyframes agreeing on this place
  double time_ms = 0.0;
};

class LoopDetector {
 public:
  LoopDetector(const BackendConfig& config, std::shared_ptr<const Vocabulary> vocabulary);

  /// Looks for a loop between `keyframe` and the keyframes added before it, then adds it to the
  /// database. The keyframe's features need descriptors, undistorted pixels and 3D points.
  /// `already_verified`: matches of this keyframe the caller verified itself (matchLocal()); a
  /// candidate among them with at least backend.loop_min_inliers is not matched again (its
  /// detection is then the caller's, with the caller's information matrix).
  LoopDetection processKeyframe(const KeyframePtr& keyframe,
                                const std::vector<LoopDetection>& already_verified = {});

  /// Best verified match of a frame's features among all stored keyframes (relocalisation):
  /// no recent-keyframe exclusion, no consistency, nothing stored. match_id < 0 when none.
  LoopDetection query(const FeatureSet& features, const CameraIntrinsics& intrinsics);

  /// Which stored keyframes a search may return: (keyframe id, tracking segment) -> allowed.
  using KeyframeFilter = std::function<bool(std::int64_t id, std::int64_t segment)>;
  /// The caller's estimate of T_match_query for a stored keyframe id (guides the matching of
  /// local edges), or false when it has none.
  using PosePrior = std::function<bool(std::int64_t id, SE3& T_match_query)>;

  /// query() restricted to the stored keyframes `allowed` accepts (e.g. earlier tracking
  /// segments), with its own minimum of inliers (0 = backend.loop_min_inliers).
  LoopDetection query(const FeatureSet& features, const CameraIntrinsics& intrinsics,
                      const KeyframeFilter& allowed, int min_inliers = 0);

  /// Local (covisibility) matches of a keyframe not yet stored: the best BoW candidates among
  /// the stored keyframes `allowed` accepts, recent ones included (backend.local_max_candidates
  /// of them), each verified with RANSAC + refinement (backend.local_min_inliers); without
  /// culling (backend.cull_redundant_keyframes), the search stops at backend.local_edges verified
  /// ones. Every verified one is returned (status kLoopFound, best inliers first) with
  /// T_match_query and an information matrix from the refinement floored by
  /// backend.local_min_sigma_*. Nothing is stored and no consistency is required: the caller checks
  /// each against its pose estimate. With `prior`, descriptors are matched near the projections the
  /// prior predicts (backend.local_search_radius_px) instead of over all pairs.
  std::vector<LoopDetection> matchLocal(const Keyframe& keyframe, const KeyframeFilter& allowed,
                                        const PosePrior& prior = PosePrior());

  /// Stores a keyframe without searching (a keyframe of a loaded session): later searches can
  /// return it. A keyframe without binary descriptors, or an empty vocabulary, stores nothing.
  void insertKeyframe(const KeyframePtr& keyframe);

  /// Forgets a stored keyframe (culled by the back end): no search returns it any more and its
  /// features are released. Its place in the order of keyframes stays (the recent-keyframe
  /// exclusion and path lengths count it). Returns false for an unknown or removed id.
  bool removeKeyframe(std::int64_t id);

  /// The features of a searchable stored keyframe (valid until the detector changes), or null.
  const FeatureSet* features(std::int64_t id) const;
  /// A searchable stored keyframe (as it was given), or null.
  KeyframePtr keyframe(std::int64_t id) const;
  /// The features of every searchable stored keyframe, by id (pointers into the detector, valid
  /// until it changes).
  std::unordered_map<std::int64_t, const FeatureSet*> storedFeatures() const;

  /// Stored entries, removed ones included.
  std::size_t size() const { return entries_.size(); }
  /// Entries that searches can return.
  std::size_t numSearchable() const { return entries_.size() - num_removed_; }

 private:
  struct Entry {
    std::int64_t id = 0;
    std::int64_t segment = 0;
    SE3 T_world_camera = SE3::Identity();  ///< odometry pose when added
    double path_length_m = 0.0;            ///< distance travelled from the first keyframe
    BowVector bow;
    KeyframePtr keyframe;  ///< the keyframe as given; null once removed
    bool removed = false;  ///< removeKeyframe(): out of the index, keyframe released
    const FeatureSet& features() const { return keyframe->features; }
  };
  struct Candidate {
    int entry = -1;
    double score = 0.0;
  };
  struct Group {
    std::int64_t match_id = 0;
    int count = 0;
  };

  /// Adds an entry and its postings.
  void store(const KeyframePtr& keyframe, BowVector bow, double path_length_m);
  std::vector<Candidate> retrieve(const BowVector& bow, std::size_t num_searchable,
                                  double min_score,
                                  const KeyframeFilter& allowed = KeyframeFilter()) const;
  /// Matches, RANSAC and refinement of the query against entry `e`; fills the geometric fields.
  /// Sub-pixel alignment of the RANSAC inliers' reference patches in the query image.
  void alignInliers(const FeatureSet& ref, const FeatureSet& query, const CameraIntrinsics& K,
                    const RansacResult& ransac, std::vector<Correspondence>& matches) const;
  /// With a prior T_match_query, descriptors are matched near the predicted projections only
  /// (backend.local_search_radius_px); without, over all pairs.
  bool verify(const FeatureSet& query, const CameraIntrinsics& intrinsics, const Entry& e,
              LoopDetection& detection, int min_inliers, double min_sigma_m, double min_sigma_rad,
              const SE3* T_match_query_prior = nullptr);

  BackendConfig config_;
  std::shared_ptr<const Vocabulary> vocabulary_;
  std::vector<Entry> entries_;
  std::unordered_map<int, std::vector<std::pair<int, double>>> inverted_;  ///< word -> (entry, w)
  std::vector<Group> groups_;  ///< places verified by the previous keyframe
  std::size_t num_removed_ = 0;
  std::mt19937 rng_{42};
};

}  // namespace slamd
