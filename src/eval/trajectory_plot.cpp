#include "slamd/eval/trajectory_plot.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace slamd::eval {
namespace {

const cv::Scalar kWhite(255, 255, 255);
const cv::Scalar kBlack(0, 0, 0);
const cv::Scalar kGrid(228, 228, 228);
const cv::Scalar kAxis(90, 90, 90);
const cv::Scalar kGroundTruth(60, 60, 60);
const cv::Scalar kDifference(120, 120, 235);
const cv::Scalar kWorst(20, 20, 200);
const cv::Scalar kSeries(170, 90, 20);
const cv::Scalar kRmse(0, 140, 255);
const cv::Scalar kMedian(150, 60, 150);
constexpr int kFont = cv::FONT_HERSHEY_SIMPLEX;
constexpr double kTickFontScale = 0.45;
constexpr double kLabelFontScale = 0.55;

struct Range {
  double lo = 0.0;
  double hi = 1.0;
  double span() const { return hi - lo; }
};

// A rectangle of the image showing data ranges x and y (y grows upwards on screen).
struct Panel {
  cv::Rect rect;
  Range x;
  Range y;
  cv::Point2d toPixel(double vx, double vy) const {
    return {rect.x + (vx - x.lo) / x.span() * rect.width,
            rect.y + rect.height - (vy - y.lo) / y.span() * rect.height};
  }
};

cv::Point px(const cv::Point2d& p) {
  // Sub-pixel coordinates with 4 fractional bits for smooth anti-aliased lines.
  return {static_cast<int>(std::lround(p.x * 16.0)), static_cast<int>(std::lround(p.y * 16.0))};
}

void line(cv::Mat& image, const cv::Point2d& a, const cv::Point2d& b, const cv::Scalar& colour,
          int thickness) {
  cv::line(image, px(a), px(b), colour, thickness, cv::LINE_AA, 4);
}

void dashedLine(cv::Mat& image, const cv::Point2d& a, const cv::Point2d& b,
                const cv::Scalar& colour, int thickness) {
  const double length = cv::norm(b - a);
  const cv::Point2d direction = (b - a) / std::max(length, 1e-9);
  for (double s = 0.0; s < length; s += 14.0) {
    line(image, a + direction * s, a + direction * std::min(s + 8.0, length), colour, thickness);
  }
}

enum class Anchor { kLeft, kCentre, kRight };

void text(cv::Mat& image, const std::string& content, cv::Point2d at, double scale,
          const cv::Scalar& colour, Anchor anchor = Anchor::kLeft, int thickness = 1,
          bool centre_vertically = false) {
  int baseline = 0;
  const cv::Size size = cv::getTextSize(content, kFont, scale, thickness, &baseline);
  if (anchor == Anchor::kCentre) at.x -= size.width / 2.0;
  if (anchor == Anchor::kRight) at.x -= size.width;
  if (centre_vertically) at.y += size.height / 2.0;
  cv::putText(image, content, cv::Point(static_cast<int>(at.x), static_cast<int>(at.y)), kFont,
              scale, colour, thickness, cv::LINE_AA);
}

// Text rotated 90 degrees counter-clockwise, centred on `centre` (for y-axis labels).
void verticalText(cv::Mat& image, const std::string& content, cv::Point centre, double scale) {
  int baseline = 0;
  const cv::Size size = cv::getTextSize(content, kFont, scale, 1, &baseline);
  cv::Mat strip(size.height + baseline + 4, size.width + 4, CV_8UC3, kWhite);
  cv::putText(strip, content, cv::Point(2, size.height + 1), kFont, scale, kBlack, 1, cv::LINE_AA);
  cv::Mat rotated;
  cv::rotate(strip, rotated, cv::ROTATE_90_COUNTERCLOCKWISE);
  const cv::Rect target(centre.x - rotated.cols / 2, centre.y - rotated.rows / 2, rotated.cols,
                        rotated.rows);
  const cv::Rect clipped = target & cv::Rect(0, 0, image.cols, image.rows);
  if (clipped.area() == 0) return;
  rotated(cv::Rect(clipped.x - target.x, clipped.y - target.y, clipped.width, clipped.height))
      .copyTo(image(clipped));
}

// A "nice" tick step (1, 2 or 5 times a power of ten) giving about `count` ticks over `span`.
double niceStep(double span, int count) {
  const double raw = span / std::max(count, 1);
  const double power = std::pow(10.0, std::floor(std::log10(raw)));
  const double fraction = raw / power;
  const double nice = fraction < 1.5 ? 1.0 : fraction < 3.5 ? 2.0 : fraction < 7.5 ? 5.0 : 10.0;
  return nice * power;
}

std::string tickLabel(double value, double step) {
  const int decimals = std::max(0, static_cast<int>(std::ceil(-std::log10(step) - 1e-9)));
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.*f", decimals,
                std::abs(value) < step * 1e-6 ? 0.0 : value);
  return buffer;
}

Range padded(double lo, double hi, double fraction) {
  if (!(hi > lo)) {
    const double half = std::max(std::abs(lo) * 0.05, 0.05);
    return {lo - half, hi + half};
  }
  const double pad = (hi - lo) * fraction;
  return {lo - pad, hi + pad};
}

// Grows the narrower range so one metre is as long on both axes.
void equalizeAspect(Panel& panel) {
  const double scale_x = panel.rect.width / panel.x.span();
  const double scale_y = panel.rect.height / panel.y.span();
  if (scale_x > scale_y) {
    const double grow = panel.rect.width / scale_y - panel.x.span();
    panel.x = {panel.x.lo - grow / 2.0, panel.x.hi + grow / 2.0};
  } else {
    const double grow = panel.rect.height / scale_x - panel.y.span();
    panel.y = {panel.y.lo - grow / 2.0, panel.y.hi + grow / 2.0};
  }
}

void drawAxes(cv::Mat& image, const Panel& panel, const std::string& x_label,
              const std::string& y_label, const std::string& title) {
  cv::rectangle(image, panel.rect, kWhite, cv::FILLED);
  const double step_x = niceStep(panel.x.span(), std::max(3, panel.rect.width / 110));
  const double step_y = niceStep(panel.y.span(), std::max(3, panel.rect.height / 70));
  const int bottom = panel.rect.y + panel.rect.height;
  for (double v = std::ceil(panel.x.lo / step_x) * step_x; v <= panel.x.hi + 1e-12; v += step_x) {
    const double x = panel.toPixel(v, 0.0).x;
    line(image, {x, static_cast<double>(panel.rect.y)}, {x, static_cast<double>(bottom)}, kGrid, 1);
    line(image, {x, static_cast<double>(bottom)}, {x, bottom + 5.0}, kAxis, 1);
    text(image, tickLabel(v, step_x), {x, bottom + 20.0}, kTickFontScale, kAxis, Anchor::kCentre);
  }
  for (double v = std::ceil(panel.y.lo / step_y) * step_y; v <= panel.y.hi + 1e-12; v += step_y) {
    const double y = panel.toPixel(0.0, v).y;
    line(image, {static_cast<double>(panel.rect.x), y},
         {static_cast<double>(panel.rect.x + panel.rect.width), y}, kGrid, 1);
    line(image, {panel.rect.x - 5.0, y}, {static_cast<double>(panel.rect.x), y}, kAxis, 1);
    text(image, tickLabel(v, step_y), {panel.rect.x - 8.0, y}, kTickFontScale, kAxis,
         Anchor::kRight, 1, true);
  }
  cv::rectangle(image, panel.rect, kAxis, 1);
  text(image, x_label, {panel.rect.x + panel.rect.width / 2.0, bottom + 42.0}, kLabelFontScale,
       kBlack, Anchor::kCentre);
  verticalText(image, y_label, cv::Point(panel.rect.x - 62, panel.rect.y + panel.rect.height / 2),
               kLabelFontScale);
  text(image, title, {static_cast<double>(panel.rect.x), panel.rect.y - 10.0}, 0.6, kBlack,
       Anchor::kLeft, 1);
}

// Green (small) through yellow to red (large), t in [0, 1]; BGR.
cv::Scalar errorColour(double t) {
  t = std::clamp(t, 0.0, 1.0);
  const cv::Vec3d green(60, 175, 40), yellow(0, 200, 240), red(30, 30, 215);
  const cv::Vec3d c =
      t < 0.5 ? green + (yellow - green) * (t * 2.0) : yellow + (red - yellow) * ((t - 0.5) * 2.0);
  return {c[0], c[1], c[2]};
}

struct ErrorUnit {
  const char* name;
  double per_metre;
};

ErrorUnit errorUnitFor(double max_error_m) {
  if (max_error_m < 0.1) return {"mm", 1000.0};
  if (max_error_m < 1.0) return {"cm", 100.0};
  return {"m", 1.0};
}

std::string fixed(double value, int decimals) {
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), "%.*f", decimals, value);
  return buffer;
}

// Consecutive samples further apart in time than this are not joined (tracking gaps).
double gapThreshold(const std::vector<double>& times_s) {
  std::vector<double> intervals;
  for (std::size_t i = 0; i + 1 < times_s.size(); ++i)
    intervals.push_back(times_s[i + 1] - times_s[i]);
  if (intervals.empty()) return 1.0;
  std::nth_element(intervals.begin(), intervals.begin() + intervals.size() / 2, intervals.end());
  return std::max(5.0 * intervals[intervals.size() / 2], 0.2);
}

void drawColourBar(cv::Mat& image, cv::Rect rect, double max_value, const std::string& unit) {
  for (int row = 0; row < rect.height; ++row) {
    const double t = 1.0 - static_cast<double>(row) / (rect.height - 1);
    cv::line(image, {rect.x, rect.y + row}, {rect.x + rect.width - 1, rect.y + row}, errorColour(t),
             1);
  }
  cv::rectangle(image, rect, kAxis, 1);
  const double step = niceStep(max_value, 5);
  for (double v = 0.0; v <= max_value + 1e-12; v += step) {
    const double y = rect.y + rect.height - v / max_value * rect.height;
    line(image, {rect.x + rect.width + 0.0, y}, {rect.x + rect.width + 5.0, y}, kAxis, 1);
    text(image, tickLabel(v, step), {rect.x + rect.width + 8.0, y}, kTickFontScale, kAxis,
         Anchor::kLeft, 1, true);
  }
  text(image, "error [" + unit + "]", {rect.x + rect.width / 2.0, rect.y - 10.0}, kTickFontScale,
       kBlack, Anchor::kCentre);
}

struct Series {
  std::vector<double> x;
  std::vector<double> y;
};

// Error over time with dashed RMSE and median lines and the maximum marked.
void drawTimePanel(cv::Mat& image, cv::Rect rect, const Series& series, const ErrorStatistics& s,
                   double unit_scale, const std::string& y_label, const std::string& title,
                   const std::string& unit) {
  Panel panel;
  panel.rect = rect;
  panel.x = {series.x.front(), std::max(series.x.back(), series.x.front() + 1e-3)};
  panel.y = {0.0, std::max(s.max * unit_scale * 1.12, 1e-9)};
  drawAxes(image, panel, "time since start [s]", y_label, title);
  const double gap = gapThreshold(series.x);
  std::size_t worst = 0;
  for (std::size_t i = 0; i < series.x.size(); ++i) {
    if (series.y[i] > series.y[worst]) worst = i;
    if (i > 0 && series.x[i] - series.x[i - 1] <= gap) {
      line(image, panel.toPixel(series.x[i - 1], series.y[i - 1] * unit_scale),
           panel.toPixel(series.x[i], series.y[i] * unit_scale), kSeries, 1);
    }
  }
  const double left = rect.x, right = rect.x + rect.width;
  const double rmse_y = panel.toPixel(0.0, s.rmse * unit_scale).y;
  const double median_y = panel.toPixel(0.0, s.median * unit_scale).y;
  dashedLine(image, {left, rmse_y}, {right, rmse_y}, kRmse, 2);
  dashedLine(image, {left, median_y}, {right, median_y}, kMedian, 1);
  const cv::Point2d worst_px = panel.toPixel(series.x[worst], series.y[worst] * unit_scale);
  cv::circle(image, px(worst_px), 7 * 16, kWorst, 2, cv::LINE_AA, 4);
  const std::string worst_text = "max " + fixed(series.y[worst] * unit_scale, 2) + " " + unit +
                                 " at " + fixed(series.x[worst], 1) + " s";
  const bool label_left = worst_px.x > rect.x + rect.width * 0.75;
  text(image, worst_text, {worst_px.x + (label_left ? -12.0 : 12.0), worst_px.y + 4.0},
       kTickFontScale, kWorst, label_left ? Anchor::kRight : Anchor::kLeft);

  // Legend, top right inside the panel.
  const double lx = right - 215.0, ly = rect.y + 12.0;
  cv::rectangle(image, cv::Rect(static_cast<int>(lx), static_cast<int>(ly), 205, 66), kWhite,
                cv::FILLED);
  cv::rectangle(image, cv::Rect(static_cast<int>(lx), static_cast<int>(ly), 205, 66), kAxis, 1);
  line(image, {lx + 10, ly + 16}, {lx + 40, ly + 16}, kSeries, 2);
  text(image, "error", {lx + 50, ly + 16}, kTickFontScale, kBlack, Anchor::kLeft, 1, true);
  dashedLine(image, {lx + 10, ly + 34}, {lx + 40, ly + 34}, kRmse, 2);
  text(image, "RMSE " + fixed(s.rmse * unit_scale, 2) + " " + unit, {lx + 50, ly + 34},
       kTickFontScale, kBlack, Anchor::kLeft, 1, true);
  dashedLine(image, {lx + 10, ly + 52}, {lx + 40, ly + 52}, kMedian, 1);
  text(image, "median " + fixed(s.median * unit_scale, 2) + " " + unit, {lx + 50, ly + 52},
       kTickFontScale, kBlack, Anchor::kLeft, 1, true);
}

const char* kAxisNames[3] = {"x", "y", "z"};

}  // namespace

cv::Mat renderAtePlot(const AteResult& ate, const PlotOptions& options, AlignmentModel alignment) {
  if (ate.pairs.empty()) throw std::invalid_argument("renderAtePlot: no pose pairs");
  cv::Mat image(options.height_px, options.width_px, CV_8UC3, kWhite);
  const ErrorStatistics& s = ate.translation_m;
  const ErrorUnit unit = errorUnitFor(s.max);

  // Which ground-truth axis is vertical (the one with the smallest extent).
  Eigen::Vector3d lo = ate.pairs.front().position_gt_m, hi = lo;
  for (const auto& pair : ate.pairs) {
    lo = lo.cwiseMin(pair.position_gt_m).cwiseMin(pair.position_est_m);
    hi = hi.cwiseMax(pair.position_gt_m).cwiseMax(pair.position_est_m);
  }
  int vertical = 0;
  (hi - lo).minCoeff(&vertical);
  const int a = vertical == 0 ? 1 : 0;
  const int b = vertical == 2 ? 1 : 2;
  const int side = (hi - lo)(a) >= (hi - lo)(b) ? a : b;

  // Header: title, statistics, subtitle.
  const std::string title = options.title.empty()
                                ? std::string("Absolute trajectory error (") +
                                      alignmentModelName(alignment) + " alignment)"
                                : options.title;
  text(image, title, {30.0, 34.0}, 0.85, kBlack, Anchor::kLeft, 2);
  const double k = unit.per_metre;
  const std::string u = unit.name;
  const std::string stats = std::to_string(s.count) + " pairs   RMSE " + fixed(s.rmse * k, 2) +
                            " " + u + "   mean " + fixed(s.mean * k, 2) + "   median " +
                            fixed(s.median * k, 2) + "   std " + fixed(s.std * k, 2) + "   min " +
                            fixed(s.min * k, 2) + "   max " + fixed(s.max * k, 2) + " " + u;
  text(image, stats, {30.0, 64.0}, 0.6, kBlack);
  if (!options.subtitle.empty()) text(image, options.subtitle, {30.0, 88.0}, 0.48, kAxis);

  const int top = 130;
  const int spatial_height = static_cast<int>(options.height_px * 0.50);
  const int bar_width = 22;
  const int usable = options.width_px - 100 - 110 - bar_width - 60;
  const int panel_width = (usable - 100) / 2;
  std::size_t worst = 0;
  for (std::size_t i = 0; i < ate.pairs.size(); ++i) {
    if (ate.pairs[i].error_m > ate.pairs[worst].error_m) worst = i;
  }
  std::vector<double> times;
  for (const auto& pair : ate.pairs)
    times.push_back(pair.timestamp_gt_s - ate.pairs.front().timestamp_gt_s);
  const double gap = gapThreshold(times);
  const double max_error = std::max(s.max, 1e-12);
  // Draw about 250 difference segments at most, so they stay readable.
  const std::size_t every = std::max<std::size_t>(1, ate.pairs.size() / 250);

  for (int view = 0; view < 2; ++view) {
    const int h_axis = view == 0 ? a : side;
    const int v_axis = view == 0 ? b : vertical;
    Panel panel;
    panel.rect = cv::Rect(100 + view * (panel_width + 100), top, panel_width, spatial_height);
    panel.x = padded(lo(h_axis), hi(h_axis), 0.06);
    panel.y = padded(lo(v_axis), hi(v_axis), 0.06);
    equalizeAspect(panel);
    drawAxes(
        image, panel, std::string(kAxisNames[h_axis]) + " [m]",
        std::string(kAxisNames[v_axis]) + " [m]",
        view == 0
            ? std::string("Top view (") + kAxisNames[h_axis] + "-" + kAxisNames[v_axis] + ")"
            : std::string("Side view (") + kAxisNames[h_axis] + "-" + kAxisNames[v_axis] + ")");
    const auto at = [&](const Eigen::Vector3d& p) { return panel.toPixel(p(h_axis), p(v_axis)); };
    for (std::size_t i = 0; i < ate.pairs.size(); i += every) {
      line(image, at(ate.pairs[i].position_gt_m), at(ate.pairs[i].position_est_m), kDifference, 1);
    }
    for (std::size_t i = 1; i < ate.pairs.size(); ++i) {
      if (times[i] - times[i - 1] > gap) continue;
      line(image, at(ate.pairs[i - 1].position_gt_m), at(ate.pairs[i].position_gt_m), kGroundTruth,
           2);
    }
    for (std::size_t i = 1; i < ate.pairs.size(); ++i) {
      if (times[i] - times[i - 1] > gap) continue;
      const double t = 0.5 * (ate.pairs[i - 1].error_m + ate.pairs[i].error_m) / max_error;
      line(image, at(ate.pairs[i - 1].position_est_m), at(ate.pairs[i].position_est_m),
           errorColour(t), 2);
    }
    cv::circle(image, px(at(ate.pairs.front().position_gt_m)), 5 * 16, kGroundTruth, cv::FILLED,
               cv::LINE_AA, 4);
    cv::circle(image, px(at(ate.pairs[worst].position_est_m)), 8 * 16, kWorst, 2, cv::LINE_AA, 4);
    line(image, at(ate.pairs[worst].position_gt_m), at(ate.pairs[worst].position_est_m), kWorst, 2);
    cv::rectangle(image, panel.rect, kAxis, 1);
  }
  // Legend under the spatial panels.
  const double legend_y = top + spatial_height + 62.0;
  double lx = 100.0;
  line(image, {lx, legend_y}, {lx + 30, legend_y}, kGroundTruth, 2);
  text(image, "ground truth (dot = start)", {lx + 38, legend_y}, kTickFontScale, kBlack,
       Anchor::kLeft, 1, true);
  lx += 265;
  for (int i = 0; i < 30; ++i) {
    line(image, {lx + i, legend_y}, {lx + i + 1, legend_y}, errorColour(i / 29.0), 3);
  }
  text(image, "estimate, aligned (colour = error)", {lx + 38, legend_y}, kTickFontScale, kBlack,
       Anchor::kLeft, 1, true);
  lx += 300;
  line(image, {lx, legend_y}, {lx + 30, legend_y}, kDifference, 1);
  text(image, "associated poses", {lx + 38, legend_y}, kTickFontScale, kBlack, Anchor::kLeft, 1,
       true);
  lx += 190;
  cv::circle(image, px({lx + 15, legend_y}), 8 * 16, kWorst, 2, cv::LINE_AA, 4);
  text(image, "largest error", {lx + 38, legend_y}, kTickFontScale, kBlack, Anchor::kLeft, 1, true);

  drawColourBar(
      image, cv::Rect(100 + 2 * panel_width + 100 + 30, top + 20, bar_width, spatial_height - 40),
      max_error * k, u);

  // Error over time.
  Series series;
  series.x = times;
  for (const auto& pair : ate.pairs) series.y.push_back(pair.error_m);
  const int time_top = top + spatial_height + 125;
  const cv::Rect time_rect(100, time_top, options.width_px - 100 - 60,
                           options.height_px - time_top - 60);
  drawTimePanel(image, time_rect, series, s, k, "ATE [" + u + "]", "Error over time", u);
  return image;
}

cv::Mat renderRpePlot(const RpeResult& rpe, const PlotOptions& options) {
  if (rpe.pairs.empty()) throw std::invalid_argument("renderRpePlot: no pose pairs");
  cv::Mat image(options.height_px, options.width_px, CV_8UC3, kWhite);
  const ErrorUnit unit = errorUnitFor(rpe.translation_m.max);
  const std::string title = options.title.empty() ? "Relative pose error" : options.title;
  text(image, title, {30.0, 34.0}, 0.85, kBlack, Anchor::kLeft, 2);
  const std::string stats = std::to_string(rpe.translation_m.count) + " pairs   translation RMSE " +
                            fixed(rpe.translation_m.rmse * unit.per_metre, 2) + " " + unit.name +
                            "   rotation RMSE " + fixed(rpe.rotation_deg.rmse, 3) + " deg";
  text(image, stats, {30.0, 64.0}, 0.6, kBlack);
  if (!options.subtitle.empty()) text(image, options.subtitle, {30.0, 88.0}, 0.48, kAxis);

  Series translation, rotation;
  const double t0 = rpe.pairs.front().timestamp_est_0_s;
  for (const auto& pair : rpe.pairs) {
    translation.x.push_back(pair.timestamp_est_0_s - t0);
    translation.y.push_back(pair.translation_error_m);
    rotation.x.push_back(pair.timestamp_est_0_s - t0);
    rotation.y.push_back(pair.rotation_error_rad * 180.0 / M_PI);
  }
  const int top = 140;
  const int height = (options.height_px - top - 60 - 90) / 2;
  drawTimePanel(image, cv::Rect(100, top, options.width_px - 160, height), translation,
                rpe.translation_m, unit.per_metre, std::string("translation [") + unit.name + "]",
                "Translational error over time (by start of interval)", unit.name);
  drawTimePanel(image, cv::Rect(100, top + height + 110, options.width_px - 160, height), rotation,
                rpe.rotation_deg, 1.0, "rotation [deg]", "Rotational error over time", "deg");
  return image;
}

void writePng(const std::string& path, const cv::Mat& image) {
  bool written = false;
  try {
    written = cv::imwrite(path, image);
  } catch (const cv::Exception& e) {
    throw std::runtime_error("cannot write plot '" + path + "': " + e.what());
  }
  if (!written) throw std::runtime_error("cannot write plot '" + path + "'");
}

}  // namespace slamd::eval
