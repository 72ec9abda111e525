#pragma once
// Plots of trajectory errors, drawn with OpenCV into an image (written as PNG).
//
// renderAtePlot() draws three panels: a top view and a side view of the ground truth (dark grey)
// and the aligned estimate (coloured by its error, green = small, red = large, with a colour
// bar), thin red segments joining associated poses so the size and direction of the error is
// visible, the worst pose circled; below, the error over time with the RMSE and median as dashed
// lines. The header repeats the statistics. renderRpePlot() draws translation and rotation
// relative error over time.
//
// Views: the ground truth's axis with the smallest extent is taken as vertical (the world's
// z for TUM motion capture, y for a camera-started world); the top view shows the other two axes,
// the side view the widest horizontal axis against the vertical one. Both keep equal scale on
// their axes. Positions are metres in the ground-truth world frame; errors are shown in mm, cm or
// m depending on their size; time is seconds since the first associated pose.
//
// Usage:
//   eval::PlotOptions options;
//   options.subtitle = "gt: groundtruth.txt   est: estimate.txt";
//   eval::writeAtePlot("ate.png", eval::computeAte(gt, est), options);   // throws on I/O error

#include <string>

#include <opencv2/core.hpp>

#include "slamd/eval/trajectory_error.hpp"

namespace slamd::eval {

struct PlotOptions {
  int width_px = 1600;
  int height_px = 1100;
  std::string title;     ///< empty = a title naming the metric and alignment
  std::string subtitle;  ///< e.g. the file names
};

/// The ATE figure as a BGR image. Throws std::invalid_argument when `ate` has no pairs.
cv::Mat renderAtePlot(const AteResult& ate, const PlotOptions& options = {},
                      AlignmentModel alignment = AlignmentModel::kSE3);

/// The RPE figure as a BGR image. Throws std::invalid_argument when `rpe` has no pairs.
cv::Mat renderRpePlot(const RpeResult& rpe, const PlotOptions& options = {});

/// Writes an image as PNG; throws std::runtime_error when the file cannot be written.
void writePng(const std::string& path, const cv::Mat& image);

}  // namespace slamd::eval
