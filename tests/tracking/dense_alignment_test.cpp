// Dense RGB-D alignment on slamd's rendered scenes (sensor noise on): accuracy from a perturbed
// prior, a plain corridor's free direction left to the prior and shown in the covariance, and
// failures reported for inputs that do not fit.

#include "slamd/tracking/dense_alignment.hpp"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <memory>
#include <string>

#include <Eigen/Eigenvalues>
#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "slamd/synth/synthetic_source.hpp"

namespace slamd {
namespace {

constexpr double kDeg = M_PI / 180.0;

std::unique_ptr<SyntheticSource> makeSource(const std::string& scene,
                                            const std::vector<std::string>& overrides) {
  Config config;
  for (const std::string& o : overrides) config.applyOverride(o);
  auto source = std::make_unique<SyntheticSource>(scene, SyntheticConfig::load(config));
  source->open();
  return source;
}

DenseFrame denseFrame(const SyntheticSource& source, int index,
                      const DenseAlignmentOptions& options) {
  const RgbdFramePtr frame = source.renderFrame(index);
  cv::Mat gray = frame->gray;
  if (gray.empty()) cv::cvtColor(frame->color_bgr, gray, cv::COLOR_BGR2GRAY);
  return makeDenseFrame(gray, frame->depth_m, frame->intrinsics, options);
}

SE3 trueMotion(const SyntheticSource& source, int ref_index, int curr_index) {
  const Trajectory truth = *source.groundTruth();
  return truth.at(static_cast<std::size_t>(ref_index)).T_world_camera.inverse() *
         truth.at(static_cast<std::size_t>(curr_index)).T_world_camera;
}

Matrix6d priorCovariance(double sigma_m, double sigma_deg) {
  Vector6d diagonal;
  const double sigma_rad = sigma_deg * kDeg;
  diagonal << sigma_m * sigma_m, sigma_m * sigma_m, sigma_m * sigma_m, sigma_rad * sigma_rad,
      sigma_rad * sigma_rad, sigma_rad * sigma_rad;
  return diagonal.asDiagonal();
}

TEST(DenseAlignment, RoomFramesAlignFromAPerturbedPrior) {
  cv::setNumThreads(1);
  const auto source = makeSource("room", {});
  const DenseAlignmentOptions options;
  for (const int ref_index : {10, 200, 400}) {
    const int curr_index = ref_index + 3;
    const DenseFrame ref = denseFrame(*source, ref_index, options);
    const DenseFrame curr = denseFrame(*source, curr_index, options);
    const SE3 truth = trueMotion(*source, ref_index, curr_index);
    Vector6d offset;
    offset << 0.02, -0.015, 0.01, 1.0 * kDeg, -1.5 * kDeg, 0.5 * kDeg;
    const SE3 prior = truth * expSE3(offset);
    const DenseAlignmentResult r =
        alignDense(ref, curr, prior, priorCovariance(0.05, 3.0), options);
    ASSERT_TRUE(r.success) << r.failure;
    const SE3 error = truth.inverse() * r.T_ref_curr;
    if (std::getenv("SLAMD_DENSE_DEBUG")) {
      std::fprintf(stderr,
                   "frame %d: err %.5f m %.4f deg, %d+%d residuals, rms %.2f / %.4f m, %d it, %.1f "
                   "ms, sigma %.5f m %.4f deg\n",
                   ref_index, error.translation().norm(), rotationAngleRad(error.linear()) / kDeg,
                   r.photometric_residuals, r.geometric_residuals, r.photometric_rms,
                   r.geometric_rms_m, r.iterations, r.time_ms, std::sqrt(r.covariance(0, 0)),
                   std::sqrt(r.covariance(3, 3)) / kDeg);
    }
    EXPECT_LT(error.translation().norm(), 0.003) << "frame " << ref_index;
    EXPECT_LT(rotationAngleRad(error.linear()) / kDeg, 0.1) << "frame " << ref_index;
    EXPECT_EQ(r.degenerate_directions, 0) << "frame " << ref_index;
    EXPECT_GT(r.photometric_residuals, 1000);
    EXPECT_GT(r.geometric_residuals, 1000);
    // The covariance is the data's, far below the prior's in every direction.
    for (int k = 0; k < 6; ++k)
      EXPECT_LT(r.covariance(k, k), 0.01 * priorCovariance(0.05, 3.0)(k, k));
  }
}

TEST(DenseAlignment, APlainCorridorLeavesTheTranslationAlongItToThePrior) {
  // Depth alone, of a corridor without doors or posters (walls, floor, ceiling and skirting boards
  // parallel to the world's x axis; the end wall beyond the depth range): the planes fix five
  // degrees of freedom, not the sixth.
  cv::setNumThreads(1);
  const auto source = makeSource("corridor", {"synthetic.trajectory=zigzag",
                                              "synthetic.doors=false", "synthetic.posters=false"});
  const DenseAlignmentOptions options;
  const int ref_index = 40;
  const int curr_index = 43;
  const auto blankFrame = [&](int index) {
    const RgbdFramePtr frame = source->renderFrame(index);
    const cv::Mat blank(frame->depth_m.size(), CV_8UC1, cv::Scalar(128));
    return makeDenseFrame(blank, frame->depth_m, frame->intrinsics, options);
  };
  const DenseFrame ref = blankFrame(ref_index);
  const DenseFrame curr = blankFrame(curr_index);
  const SE3 truth = trueMotion(*source, ref_index, curr_index);
  const SE3 T_world_ref = source->groundTruth()->at(ref_index).T_world_camera;
  const Eigen::Vector3d along_ref = T_world_ref.linear().transpose() * Eigen::Vector3d::UnitX();
  // The prior is 5 cm off along the corridor, and off across it and in rotation.
  Vector6d offset;
  offset << 0.01, -0.01, 0.0, 0.5 * kDeg, -0.5 * kDeg, 0.3 * kDeg;
  SE3 prior = truth * expSE3(offset);
  prior.translation() += 0.05 * along_ref;
  const Matrix6d prior_covariance = priorCovariance(0.05, 3.0);
  const DenseAlignmentResult r = alignDense(ref, curr, prior, prior_covariance, options);
  ASSERT_TRUE(r.success) << r.failure;
  EXPECT_EQ(r.degenerate_directions, 1);
  EXPECT_EQ(r.photometric_residuals, 0);
  const Eigen::Vector3d error_m = r.T_ref_curr.translation() - truth.translation();
  const double along_error_m = error_m.dot(along_ref);
  // Along: the prior's value, not a made-up one; across: measured; rotation: measured.
  EXPECT_NEAR(along_error_m, 0.05, 0.005);
  EXPECT_LT((error_m - along_error_m * along_ref).norm(), 0.003);
  EXPECT_LT(rotationAngleRad(truth.linear().transpose() * r.T_ref_curr.linear()) / kDeg, 0.1);
  // The covariance says so: along the corridor about the prior's variance, across far less.
  // (Translation covariance is in the current frame for the right perturbation.)
  const Eigen::Vector3d along_curr = r.T_ref_curr.linear().transpose() * along_ref;
  const Eigen::Matrix3d translation_covariance = r.covariance.topLeftCorner<3, 3>();
  const double along_variance = along_curr.dot(translation_covariance * along_curr);
  EXPECT_GT(along_variance, 0.5 * 0.05 * 0.05);
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(translation_covariance);
  EXPECT_LT(eigen.eigenvalues()(1), 0.02 * 0.05 * 0.05);  // the two across
  EXPECT_GT(std::abs(eigen.eigenvectors().col(2).dot(along_curr)), 0.99);
}

TEST(DenseAlignment, OneEdgeAndAFewSpecksLeaveTheMotionAlongTheEdgeToThePrior) {
  // A wall seen square on at 2 m: its depth measures the distance and the tilts, not the slides
  // along it. The image has one vertical edge (the jamb of a door) and a few specks: the edge
  // measures the sideways slide and the roll, and the motion along it is measured by nothing but
  // the specks. The curvature of a few specks' cost is not a measurement to trust (it is flat a
  // pixel away), so the vertical slide stays at the prior and the covariance says so. With the
  // specks dense enough to be texture, the vertical slide is measured.
  DenseAlignmentOptions options;
  options.min_gradient_share = 0.05;
  CameraIntrinsics K;
  const cv::Mat depth(K.height, K.width, CV_32FC1, cv::Scalar(2.0F));
  const auto wallImage = [&](int specks_per_row) {
    cv::Mat gray(K.height, K.width, CV_8UC1, cv::Scalar(70));
    gray.colRange(K.width / 2, K.width).setTo(170);
    for (int row = 0; row < specks_per_row; ++row) {
      for (int col = 0; col < specks_per_row; ++col) {
        const cv::Point centre(40 + col * (K.width - 80) / specks_per_row + 7 * row,
                               40 + row * (K.height - 80) / specks_per_row + 5 * col);
        cv::circle(gray, centre, 3, cv::Scalar(col % 2 == 0 ? 20 : 230), cv::FILLED);
      }
    }
    cv::GaussianBlur(gray, gray, cv::Size(5, 5), 1.0);
    return makeDenseFrame(gray, depth, K, options);
  };
  const Matrix6d prior_covariance = priorCovariance(0.05, 3.0);
  Vector6d offset;  // the truth is no motion; the prior is 2 cm off along the edge, 1 cm across
  offset << 0.01, 0.02, 0.0, 0.0, 0.0, 0.0;
  const SE3 prior = expSE3(offset);

  const DenseFrame sparse = wallImage(2);
  const DenseAlignmentResult edge = alignDense(sparse, sparse, prior, prior_covariance, options);
  ASSERT_TRUE(edge.success) << edge.failure;
  EXPECT_GT(edge.photometric_residuals, 200);
  EXPECT_NEAR(edge.T_ref_curr.translation().x(), 0.0, 0.002);   // across the edge: measured
  EXPECT_NEAR(edge.T_ref_curr.translation().y(), 0.02, 0.002);  // along it: the prior's value
  EXPECT_GT(edge.covariance(1, 1), 0.5 * prior_covariance(1, 1));
  EXPECT_LT(edge.covariance(0, 0), 0.01 * prior_covariance(0, 0));
  EXPECT_EQ(edge.degenerate_directions, 1);

  const DenseFrame textured = wallImage(12);
  const DenseAlignmentResult texture =
      alignDense(textured, textured, prior, prior_covariance, options);
  ASSERT_TRUE(texture.success) << texture.failure;
  EXPECT_NEAR(texture.T_ref_curr.translation().x(), 0.0, 0.002);
  EXPECT_NEAR(texture.T_ref_curr.translation().y(), 0.0, 0.002);
  EXPECT_LT(texture.covariance(1, 1), 0.01 * prior_covariance(1, 1));
  EXPECT_EQ(texture.degenerate_directions, 0);
}

TEST(DenseAlignment, APlainCorridorsFarEndIsNotPulledOffAlongItsOneEdge) {
  // The far end of a plain corridor (texture density 0.04, no posters; seed 9002): the corner
  // between two plain walls 1-2 m away, nearly vertical, and a few specks. Depth fixes the
  // distance and the tilts, not the vertical motion; the grey image has one orientation. From the
  // true motion as the prior, the alignment used to move 26-46 mm vertically and claim 3-7 mm: at
  // the coarse levels the blurred edge's cost was flat along it with minima centimetres away,
  // which the finest level could not leave. Depth alone aligns those levels now.
  cv::setNumThreads(1);
  const DenseAlignmentOptions options;
  const auto source =
      makeSource("corridor", {"synthetic.variety=false", "synthetic.texture_density=0.04",
                              "synthetic.posters=false", "synthetic.seed=9002",
                              "synthetic.trajectory=zigzag", "synthetic.corridor_length_m=33"});
  for (const int ref_index : {1098, 1099, 1101}) {
    const int curr_index = ref_index + 1;
    const DenseFrame ref = denseFrame(*source, ref_index, options);
    const DenseFrame curr = denseFrame(*source, curr_index, options);
    const SE3 truth = trueMotion(*source, ref_index, curr_index);
    const DenseAlignmentResult r =
        alignDense(ref, curr, truth, priorCovariance(0.02, 2.0), options);
    ASSERT_TRUE(r.success) << r.failure;
    const SE3 error = truth.inverse() * r.T_ref_curr;
    EXPECT_LT(error.translation().norm(), 0.015) << "frame " << curr_index;
    EXPECT_LT(rotationAngleRad(error.linear()) / kDeg, 0.1) << "frame " << curr_index;
  }
}

/// Equal element for element, NaN matching NaN.
bool sameFloats(const cv::Mat& a, const cv::Mat& b) {
  if (a.size() != b.size() || a.type() != b.type()) return false;
  const cv::Mat a1 = a.reshape(1), b1 = b.reshape(1);
  for (int v = 0; v < a1.rows; ++v) {
    for (int u = 0; u < a1.cols; ++u) {
      const float x = a1.at<float>(v, u), y = b1.at<float>(v, u);
      if (!(x == y || (std::isnan(x) && std::isnan(y)))) return false;
    }
  }
  return true;
}

TEST(DenseAlignment, HalfResolutionBuiltStraightFromTheInputsIsTheSameAsFromFullResolution) {
  // finest_level 1 builds level 1 from the 8-bit grey and raw depth directly; finest_level 0 goes
  // through full-resolution float images. Every level both build must hold the same values.
  const auto source = makeSource("room", {});
  const RgbdFramePtr frame = source->renderFrame(30);
  cv::Mat gray = frame->gray;
  if (gray.empty()) cv::cvtColor(frame->color_bgr, gray, cv::COLOR_BGR2GRAY);
  cv::Mat depth_m = frame->depth_m.clone();
  // Depths outside [min_depth_m, max_depth_m], zero and unknown, in blocks and single pixels.
  depth_m(cv::Rect(100, 100, 40, 30)).setTo(0.0F);
  depth_m(cv::Rect(300, 200, 33, 21)).setTo(9.0F);
  depth_m(cv::Rect(401, 51, 17, 9)).setTo(std::numeric_limits<float>::quiet_NaN());
  for (int k = 0; k < 500; ++k) depth_m.at<float>((k * 37) % 480, (k * 101) % 640) = 0.1F;
  DenseAlignmentOptions from_full;
  from_full.finest_level = 0;
  DenseAlignmentOptions from_half;
  ASSERT_EQ(from_half.finest_level, 1);
  const DenseFrame full = makeDenseFrame(gray, depth_m, frame->intrinsics, from_full);
  const DenseFrame half = makeDenseFrame(gray, depth_m, frame->intrinsics, from_half);
  ASSERT_EQ(full.levels.size(), half.levels.size());
  for (std::size_t k = 1; k < half.levels.size(); ++k) {
    const DenseFrame::Level& a = full.levels[k];
    const DenseFrame::Level& b = half.levels[k];
    EXPECT_TRUE(sameFloats(a.gray, b.gray)) << "level " << k;
    EXPECT_TRUE(sameFloats(a.depth_m, b.depth_m)) << "level " << k;
    EXPECT_TRUE(sameFloats(a.grad_x, b.grad_x)) << "level " << k;
    EXPECT_TRUE(sameFloats(a.grad_y, b.grad_y)) << "level " << k;
    EXPECT_TRUE(sameFloats(a.normals, b.normals)) << "level " << k;
  }
  // And the blocks are gone at half resolution, not averaged in.
  EXPECT_TRUE(std::isnan(half.levels[1].depth_m.at<float>(60, 60)));
  EXPECT_TRUE(std::isnan(half.levels[1].depth_m.at<float>(105, 155)));
}

TEST(DenseAlignment, InputsThatDoNotFitAreReportedNotThrown) {
  const DenseAlignmentOptions options;
  CameraIntrinsics K;
  const cv::Mat gray(K.height, K.width, CV_8UC1, cv::Scalar(100));
  const cv::Mat depth(K.height, K.width, CV_32FC1, cv::Scalar(2.0F));
  EXPECT_TRUE(makeDenseFrame(gray, depth, K, options).levels.size() == 4);
  EXPECT_TRUE(makeDenseFrame(cv::Mat(), depth, K, options).empty());
  EXPECT_TRUE(makeDenseFrame(gray, cv::Mat(10, 10, CV_32FC1), K, options).empty());
  EXPECT_TRUE(makeDenseFrame(gray, cv::Mat(depth.size(), CV_16UC1), K, options).empty());
  DenseAlignmentOptions coarse = options;
  coarse.levels = 8;  // 5x3 pixels at the top: too small
  EXPECT_TRUE(makeDenseFrame(gray, depth, K, coarse).empty());

  const DenseFrame frame = makeDenseFrame(gray, depth, K, options);
  const Matrix6d prior = priorCovariance(0.05, 3.0);
  DenseAlignmentResult r = alignDense(DenseFrame(), frame, SE3::Identity(), prior, options);
  EXPECT_FALSE(r.success);
  EXPECT_FALSE(r.failure.empty());
  r = alignDense(frame, frame, SE3::Identity(), -prior, options);
  EXPECT_FALSE(r.success);
  EXPECT_NE(r.failure.find("positive definite"), std::string::npos);
  // A flat wall, seen square on, without texture: three directions (the two translations along
  // it and the rotation about its normal) are free; that is as few as are accepted.
  r = alignDense(frame, frame, SE3::Identity(), prior, options);
  EXPECT_TRUE(r.success) << r.failure;
  EXPECT_EQ(r.degenerate_directions, 3);
  // Without depth nothing is measured.
  const cv::Mat no_depth(K.height, K.width, CV_32FC1,
                         cv::Scalar(std::numeric_limits<float>::quiet_NaN()));
  const DenseFrame blind = makeDenseFrame(gray, no_depth, K, options);
  r = alignDense(blind, blind, SE3::Identity(), prior, options);
  EXPECT_FALSE(r.success);
}

}  // namespace
}  // namespace slamd
