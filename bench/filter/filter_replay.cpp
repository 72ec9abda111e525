// slamd-filter-replay: the filter stage over a whole sequence, for tuning and diagnosis. Runs the
// visual odometry once (or reads it back from --odometry-cache), then the filter as the daemon's
// filter thread does (one FilterInput per frame), and reports, against the source's ground truth:
// ATE of odometry alone and of the filter, the end rotation error about the world axes, the NIS
// of every vanishing point compared with a landmark, and the filter's thread CPU time per frame.
//
//   slamd-filter-replay --source tum:../shared/data/tum_fr1_xyz --config config/tum_fr1.yaml
//       --odometry-cache /tmp/fr1_orb.odo --vp-log /tmp/vp.txt
//
// Depth pre-processing of the daemon's capture stage is not applied, so the odometry can differ
// slightly from a slamd run; the daemon's numbers are the reference, this is a quick loop.

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "slamd/capture/tum_source.hpp"
#include "slamd/common/log.hpp"
#include "slamd/common/program_options.hpp"
#include "slamd/common/time.hpp"
#include "slamd/common/trajectory.hpp"
#include "slamd/eval/trajectory_error.hpp"
#include "slamd/filter/vanishing_point_filter.hpp"
#include "slamd/synth/synthetic_source.hpp"
#include "slamd/tracking/visual_odometry.hpp"

using namespace slamd;

namespace {

struct OdometryRecord {
  Utime utime = 0;
  SE3 T_prev_curr = SE3::Identity();
  Matrix6d covariance = Matrix6d::Identity();
};

bool readCache(const std::string& path, std::vector<OdometryRecord>* records) {
  std::ifstream in(path);
  if (!in) return false;
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream f(line);
    OdometryRecord r;
    f >> r.utime;
    Eigen::Matrix4d M = Eigen::Matrix4d::Identity();
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 4; ++j) f >> M(i, j);
    }
    for (int i = 0; i < 36; ++i) f >> r.covariance(i / 6, i % 6);
    if (!f) return false;
    r.T_prev_curr.matrix() = M;
    records->push_back(r);
  }
  return !records->empty();
}

void writeCache(const std::string& path, const std::vector<OdometryRecord>& records) {
  std::ofstream out(path);
  out.precision(17);
  for (const auto& r : records) {
    out << r.utime;
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 4; ++j) out << ' ' << r.T_prev_curr.matrix()(i, j);
    }
    for (int i = 0; i < 36; ++i) out << ' ' << r.covariance(i / 6, i % 6);
    out << '\n';
  }
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(std::min<double>(v.size() - 1, p / 100.0 * v.size()))];
}

/// The ground-truth pose nearest to t_s, or nullptr when none is within 20 ms.
const StampedPose* nearestGroundTruth(const Trajectory& gt, double t_s) {
  const auto it = std::lower_bound(
      gt.begin(), gt.end(), t_s, [](const StampedPose& p, double s) { return p.timestamp_s < s; });
  const StampedPose* best = nullptr;
  if (it != gt.end()) best = &*it;
  if (it != gt.begin() && (!best || t_s - std::prev(it)->timestamp_s < best->timestamp_s - t_s)) {
    best = &*std::prev(it);
  }
  return best && std::abs(best->timestamp_s - t_s) < 0.02 ? best : nullptr;
}

/// Rotation error of every estimated pose that has ground truth within 20 ms (ground truth vs
/// estimate, the estimate expressed in the ground truth's world through the first pose), about the
/// world axes, degrees, in time order.
std::vector<Eigen::Vector3d> rotationErrorsDeg(const Trajectory& gt, const Trajectory& est) {
  std::vector<Eigen::Vector3d> errors;
  const auto nearest = [&](double t_s) { return nearestGroundTruth(gt, t_s); };
  if (est.empty()) return errors;
  const StampedPose* g0 = nearest(est.front().timestamp_s);
  if (!g0) return errors;
  const Eigen::Matrix3d R_gt_est =
      g0->T_world_camera.linear() * est.front().T_world_camera.linear().transpose();
  for (const StampedPose& p : est) {
    const StampedPose* g = nearest(p.timestamp_s);
    if (!g) continue;
    const Eigen::Matrix3d R_est_world = R_gt_est * p.T_world_camera.linear();
    errors.push_back(logSO3(g->T_world_camera.linear() * R_est_world.transpose()) * 180.0 / M_PI);
  }
  return errors;
}

Eigen::Vector3d rmsPerAxis(const std::vector<Eigen::Vector3d>& errors) {
  Eigen::Vector3d sum_sq = Eigen::Vector3d::Zero();
  for (const auto& e : errors) sum_sq += e.cwiseProduct(e);
  return errors.empty()
             ? Eigen::Vector3d::Constant(NAN)
             : Eigen::Vector3d((sum_sq / static_cast<double>(errors.size())).cwiseSqrt());
}

/// Per-frame rotation errors (rotationErrorsDeg of odometry and filter over the same timestamps,
/// so the k-th error of each belongs to the k-th pose with ground truth) and the true vanishing
/// point of the world x axis (the corridor's), for diagnosis.
void writeRotationErrors(const std::string& path, const Trajectory& gt, const Trajectory& est,
                         const std::vector<Eigen::Vector3d>& rot_odometry_deg,
                         const std::vector<Eigen::Vector3d>& rot_filter_deg,
                         const CameraIntrinsics& intrinsics) {
  std::ofstream out(path);
  out << "# t_s odometry_x odometry_y odometry_z filter_x filter_y filter_z (deg, about world "
         "axes) true_vp_x_px true_vp_y_px (world x axis)\n";
  std::size_t k = 0;
  for (const StampedPose& p : est) {
    if (k >= rot_odometry_deg.size() || k >= rot_filter_deg.size()) break;
    const StampedPose* truth = nearestGroundTruth(gt, p.timestamp_s);
    if (!truth) continue;
    const Eigen::Vector2d vp =
        intrinsics.project(truth->T_world_camera.linear().transpose() * Eigen::Vector3d::UnitX());
    out << std::fixed << std::setprecision(6) << p.timestamp_s << std::setprecision(4);
    for (int i = 0; i < 3; ++i) out << ' ' << rot_odometry_deg[k][i];
    for (int i = 0; i < 3; ++i) out << ' ' << rot_filter_deg[k][i];
    out << std::setprecision(2) << ' ' << vp.x() << ' ' << vp.y() << '\n';
    ++k;
  }
}

}  // namespace

int main(int argc, char** argv) {
  ProgramOptions options("slamd-filter-replay",
                         "Runs odometry and the vanishing-point filter over a sequence.");
  options.addOption("source", "SOURCE", "tum:DIR or synthetic:SCENE",
                    "tum:" SLAMD_SOURCE_DIR "/../shared/data/tum_fr1_xyz");
  options.addOption("odometry-cache", "FILE", "read odometry from FILE, or write it there");
  options.addOption("trajectory", "FILE", "write the filtered trajectory (TUM format)");
  options.addOption("odometry-trajectory", "FILE", "write the odometry-only trajectory");
  options.addOption("vp-log", "FILE", "one line per frame: status, pixel, update, NIS");
  options.addOption("rotation-errors", "FILE",
                    "one line per frame with ground truth: time, odometry and filter rotation "
                    "error about world x y z (deg), the true vanishing point of world x (px)");
  if (!options.parse(argc, argv)) return options.exitCode();
  cv::setNumThreads(1);

  const std::string spec = options.value("source");
  const bool synthetic = spec.rfind("synthetic:", 0) == 0;
  Config config;
  std::unique_ptr<FrameSource> source;
  FilterConfig filter_config;
  TrackingConfig tracking;
  try {
    config = options.loadConfig(synthetic ? SLAMD_SOURCE_DIR "/config/synthetic.yaml"
                                          : SLAMD_SOURCE_DIR "/config/tum_fr1.yaml");
    tracking = TrackingConfig::load(config);
    filter_config = FilterConfig::load(config);
    if (synthetic) {
      source = createSyntheticSource(spec.substr(10), config);
    } else {
      source = std::make_unique<TumSource>(spec.rfind("tum:", 0) == 0 ? spec.substr(4) : spec,
                                           TumSourceConfig::load(config));
    }
    source->open();
  } catch (const std::exception& e) {
    std::cerr << e.what() << "\n";
    return 3;
  }

  std::vector<OdometryRecord> cached;
  const bool have_cache =
      options.has("odometry-cache") && readCache(options.value("odometry-cache"), &cached);
  std::unique_ptr<VisualOdometry> vo;
  if (!have_cache) vo = std::make_unique<VisualOdometry>(tracking);
  std::vector<OdometryRecord> computed;

  std::unique_ptr<VanishingPointFilter> filter;
  std::FILE* vp_log =
      options.has("vp-log") ? std::fopen(options.value("vp-log").c_str(), "w") : nullptr;
  Trajectory filtered, odometry_only;
  SE3 chained = SE3::Identity();
  std::vector<double> cpu_ms, nis_compared, nis_accepted;
  int frames = 0, detected = 0, accepted = 0, gated = 0;
  int axes_seen = 0, axes_accepted = 0, axes_gated = 0;
  std::vector<double> axis_nis_compared;
  Utime last_utime = 0;
  CameraIntrinsics frame_intrinsics;
  while (true) {
    FrameRead read = source->next(std::chrono::milliseconds(1000));
    if (read.status == FrameRead::Status::kEndOfStream) break;
    if (read.status != FrameRead::Status::kFrame) continue;
    const RgbdFrame& frame = *read.frame;
    OdometryRecord r;
    if (have_cache) {
      if (static_cast<std::size_t>(frames) >= cached.size()) break;
      r = cached[static_cast<std::size_t>(frames)];
    } else {
      const OdometryResult o = vo->processFrame(read.frame);
      r = {o.utime, o.T_prev_curr, o.covariance};
      computed.push_back(r);
    }
    if (!filter) {
      filter = std::make_unique<VanishingPointFilter>(filter_config, frame.intrinsics);
      frame_intrinsics = frame.intrinsics;
    }
    FilterInput in;
    in.utime = r.utime;
    in.T_prev_curr = last_utime > 0 ? r.T_prev_curr : SE3::Identity();
    in.covariance = last_utime > 0 ? r.covariance : Matrix6d::Identity() * 1e-12;
    in.dt_s = last_utime > 0 ? utimeToSeconds(r.utime - last_utime) : 0.0;
    in.gray = frame.gray;
    in.depth_m = frame.depth_m;
    const double start = threadCpuMs();
    const FilterOutput out = filter->process(in);
    cpu_ms.push_back(threadCpuMs() - start);
    chained = chained * in.T_prev_curr;
    last_utime = r.utime;
    filtered.push_back({utimeToSeconds(r.utime), out.pose.T_world_camera});
    odometry_only.push_back({utimeToSeconds(r.utime), chained});
    ++frames;
    const bool ok = out.vanishing_point && out.vanishing_point->status == VanishingPointStatus::kOk;
    detected += ok;
    if (out.update) {
      accepted += out.update->accepted;
      gated += out.update->status == VpUpdateStatus::kGated;
      if (out.update->accepted || out.update->status == VpUpdateStatus::kGated) {
        nis_compared.push_back(out.update->nis);
      }
      if (out.update->accepted) nis_accepted.push_back(out.update->nis);
    }
    for (const VpUpdateResult& u : out.axis_updates) {
      ++axes_seen;
      axes_accepted += u.accepted;
      axes_gated += u.status == VpUpdateStatus::kGated;
      if (u.accepted || u.status == VpUpdateStatus::kGated) axis_nis_compared.push_back(u.nis);
    }
    if (vp_log) {
      std::fprintf(
          vp_log, "%d %.6f %s", frames, utimeToSeconds(r.utime),
          out.vanishing_point ? vanishingPointStatusName(out.vanishing_point->status) : "NONE");
      if (ok) {
        const VanishingPoint& vp = *out.vanishing_point;
        std::fprintf(vp_log, " px %.1f %.1f sd %.2f %.2f lines %d/%d rms %.2f", vp.pixel.x(),
                     vp.pixel.y(), std::sqrt(vp.pixel_covariance(0, 0)),
                     std::sqrt(vp.pixel_covariance(1, 1)), vp.num_supporting_lines, vp.num_segments,
                     vp.rms_residual_px);
      }
      if (out.update) {
        std::fprintf(vp_log, " %s lm %d pred %.1f %.1f nis %.2f",
                     vpUpdateStatusName(out.update->status), out.update->landmark_id,
                     out.update->predicted_px.x(), out.update->predicted_px.y(), out.update->nis);
      }
      for (std::size_t k = 0; k < out.axis_updates.size(); ++k) {
        const SurfaceAxis& axis = out.surface_axes->axes[k];
        const VpUpdateResult& u = out.axis_updates[k];
        std::fprintf(vp_log, " | axis %.3f %.3f %.3f sd %.3f deg cells %d %s lm %d nis %.2f",
                     axis.direction_camera.x(), axis.direction_camera.y(),
                     axis.direction_camera.z(),
                     std::sqrt(axis.covariance.trace() / 2.0) * 180.0 / M_PI, axis.num_cells,
                     vpUpdateStatusName(u.status), u.landmark_id, u.nis);
      }
      std::fprintf(vp_log, "\n");
    }
  }
  source->close();
  if (vp_log) std::fclose(vp_log);
  if (!have_cache && options.has("odometry-cache")) {
    writeCache(options.value("odometry-cache"), computed);
  }
  if (options.has("trajectory"))
    writeTumTrajectory(options.value("trajectory"), filtered, "filter");
  if (options.has("odometry-trajectory")) {
    writeTumTrajectory(options.value("odometry-trajectory"), odometry_only, "odometry");
  }

  double nis_mean = 0.0;
  for (double v : nis_compared) nis_mean += v;
  if (!nis_compared.empty()) nis_mean /= static_cast<double>(nis_compared.size());
  double nis_acc_mean = 0.0;
  for (double v : nis_accepted) nis_acc_mean += v;
  if (!nis_accepted.empty()) nis_acc_mean /= static_cast<double>(nis_accepted.size());
  std::printf(
      "%d frames: %d vanishing points, %d accepted, %d gated, %zu landmarks, %lld "
      "re-anchors; mean NIS %.2f over %zu compared (accepted only %.2f); filter CPU median "
      "%.2f ms p95 %.2f ms\n",
      frames, detected, accepted, gated, filter ? filter->ekf().landmarks().size() : 0u,
      filter ? static_cast<long long>(filter->ekf().counters().reanchors) : 0LL, nis_mean,
      nis_compared.size(), nis_acc_mean, percentile(cpu_ms, 50), percentile(cpu_ms, 95));
  double axis_nis_mean = 0.0;
  for (double v : axis_nis_compared) axis_nis_mean += v;
  if (!axis_nis_compared.empty()) axis_nis_mean /= static_cast<double>(axis_nis_compared.size());
  std::printf("plane axes: %d seen, %d accepted, %d gated; mean NIS %.2f over %zu compared\n",
              axes_seen, axes_accepted, axes_gated, axis_nis_mean, axis_nis_compared.size());
  if (const auto gt = source->groundTruth(); gt && !gt->empty() && frames > 2) {
    const double ate_odo = eval::computeAte(*gt, odometry_only).translation_m.rmse;
    const double ate_filter = eval::computeAte(*gt, filtered).translation_m.rmse;
    const std::vector<Eigen::Vector3d> rot_odo = rotationErrorsDeg(*gt, odometry_only);
    const std::vector<Eigen::Vector3d> rot_filter = rotationErrorsDeg(*gt, filtered);
    const Eigen::Vector3d nan3 = Eigen::Vector3d::Constant(NAN);
    const Eigen::Vector3d end_odo = rot_odo.empty() ? nan3 : rot_odo.back();
    const Eigen::Vector3d end_filter = rot_filter.empty() ? nan3 : rot_filter.back();
    const Eigen::Vector3d rms_odo = rmsPerAxis(rot_odo), rms_filter = rmsPerAxis(rot_filter);
    if (options.has("rotation-errors")) {
      writeRotationErrors(options.value("rotation-errors"), *gt, filtered, rot_odo, rot_filter,
                          frame_intrinsics);
    }
    std::printf("ATE odometry %.4f m, filter %.4f m (%.3fx)\n", ate_odo, ate_filter,
                ate_filter / ate_odo);
    std::printf(
        "end rotation error about world x y z (deg): odometry %.3f %.3f %.3f, filter "
        "%.3f %.3f %.3f\n",
        end_odo.x(), end_odo.y(), end_odo.z(), end_filter.x(), end_filter.y(), end_filter.z());
    std::printf(
        "RMS rotation error about world x y z (deg): odometry %.3f %.3f %.3f, filter "
        "%.3f %.3f %.3f\n",
        rms_odo.x(), rms_odo.y(), rms_odo.z(), rms_filter.x(), rms_filter.y(), rms_filter.z());
    // One line for scripts (bench/filter/corridor_eval.sh).
    std::printf(
        "summary ate_odometry_m=%.6f ate_filter_m=%.6f end_odometry_deg=%.4f,%.4f,%.4f "
        "end_filter_deg=%.4f,%.4f,%.4f rms_odometry_deg=%.4f,%.4f,%.4f "
        "rms_filter_deg=%.4f,%.4f,%.4f vp_nis_mean=%.3f filter_cpu_median_ms=%.3f\n",
        ate_odo, ate_filter, end_odo.x(), end_odo.y(), end_odo.z(), end_filter.x(), end_filter.y(),
        end_filter.z(), rms_odo.x(), rms_odo.y(), rms_odo.z(), rms_filter.x(), rms_filter.y(),
        rms_filter.z(), nis_mean, percentile(cpu_ms, 50));
  }
  return 0;
}
