// The filter on real images without a dominant corridor (TUM fr1/xyz, a desk seen from a hand-held
// camera): odometry is ground truth plus sampled noise, so any vanishing point the filter accepts
// wrongly shows up as extra error. ATE must stay within 5% of odometry alone (issue 7).

#include <cmath>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "noisy_odometry.hpp"
#include "slamd/common/trajectory.hpp"
#include "slamd/filter/vanishing_point_filter.hpp"
#include "test_data.hpp"

namespace slamd {
namespace {

struct ImageEntry {
  double timestamp_s;
  std::string path;
};

std::vector<ImageEntry> readImageList(const std::filesystem::path& root) {
  std::ifstream in(root / "rgb.txt");
  std::vector<ImageEntry> list;
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream fields(line);
    ImageEntry e;
    if (fields >> e.timestamp_s >> e.path)
      list.push_back({e.timestamp_s, (root / e.path).string()});
  }
  return list;
}

const StampedPose* nearest(const Trajectory& t, double timestamp_s) {
  const StampedPose* best = nullptr;
  for (const auto& p : t) {
    if (!best ||
        std::abs(p.timestamp_s - timestamp_s) < std::abs(best->timestamp_s - timestamp_s)) {
      best = &p;
    }
  }
  return best && std::abs(best->timestamp_s - timestamp_s) < 0.02 ? best : nullptr;
}

TEST(TumFr1Xyz, VanishingPointsDoNotHurtWithoutACorridor) {
  const auto root = test::findDataset("tum_fr1_xyz");
  if (!root) GTEST_SKIP() << test::missingDataMessage("tum_fr1_xyz");
  const Trajectory truth = readTumTrajectory((*root / "groundtruth.txt").string());
  const std::vector<ImageEntry> images = readImageList(*root);
  ASSERT_GT(images.size(), 300u);

  CameraIntrinsics K;
  K.fx = 517.3;
  K.fy = 516.5;
  K.cx = 318.6;
  K.cy = 255.3;
  // The images are not undistorted (as in the daemon): the detector undistorts segment end points.
  K.distortion_model = DistortionModel::kPlumbBob;
  K.distortion = {0.2624, -0.9531, -0.0054, 0.0026, 1.1633};
  VanishingPointFilter filter(FilterConfig{}, K);
  filter_test::NoisyOdometry odometry_model(0.003, 0.003, 42);

  const StampedPose* first = nullptr;
  const StampedPose* previous = nullptr;
  SE3 odometry = SE3::Identity();
  double sq_odometry = 0.0, sq_filter = 0.0;
  int frames = 0, detected = 0, accepted = 0, gated = 0;
  for (std::size_t i = 0; i < 300; ++i) {
    const StampedPose* gt = nearest(truth, images[i].timestamp_s);
    if (!gt) continue;
    if (!first) {
      first = previous = gt;
      continue;
    }
    FilterInput in;
    in.T_prev_curr =
        odometry_model.measure(previous->T_world_camera.inverse() * gt->T_world_camera);
    in.covariance = odometry_model.covariance();
    in.dt_s = gt->timestamp_s - previous->timestamp_s;
    in.gray = cv::imread(images[i].path, cv::IMREAD_GRAYSCALE);
    ASSERT_FALSE(in.gray.empty()) << images[i].path;
    odometry = odometry * in.T_prev_curr;
    const FilterOutput out = filter.process(in);
    detected += out.vanishing_point && out.vanishing_point->status == VanishingPointStatus::kOk;
    accepted += out.update && out.update->accepted;
    gated += out.update && out.update->status == VpUpdateStatus::kGated;
    const SE3 relative_truth = first->T_world_camera.inverse() * gt->T_world_camera;
    sq_odometry += (relative_truth.translation() - odometry.translation()).squaredNorm();
    sq_filter +=
        (relative_truth.translation() - out.pose.T_world_camera.translation()).squaredNorm();
    ++frames;
    previous = gt;
  }
  const double ate_odometry = std::sqrt(sq_odometry / frames);
  const double ate_filter = std::sqrt(sq_filter / frames);
  std::printf(
      "fr1/xyz %d frames: %d vanishing points, %d accepted, %d gated, %zu landmarks; ATE "
      "odometry %.4f m, filter %.4f m\n",
      frames, detected, accepted, gated, filter.ekf().landmarks().size(), ate_odometry, ate_filter);
  EXPECT_GT(frames, 250);
  EXPECT_LE(ate_filter, 1.05 * ate_odometry);
}

}  // namespace
}  // namespace slamd
