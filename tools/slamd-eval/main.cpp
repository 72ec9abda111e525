// slamd-eval: trajectory error of an estimate against ground truth, numerically as the TUM RGB-D
// benchmark's evaluate_ate.py / evaluate_rpe.py compute it.
//
//   slamd-eval ate GT EST [--json] [--plot FILE.png] [--align se3|sim3|none]
//   slamd-eval rpe GT EST [--delta 1.0] [--delta-unit s|f|m|rad|deg] [--json] [--plot FILE.png]
//
// Defaults can also come from the configuration section `eval` (keys max_difference_s, offset_s,
// scale, alignment, delta, delta_unit, max_pairs); command-line options win.

#include <cstdio>
#include <fstream>
#include <iostream>
#include <stdexcept>
#include <string>

#include "slamd/common/config.hpp"
#include "slamd/common/program_options.hpp"
#include "slamd/common/trajectory.hpp"
#include "slamd/eval/json_writer.hpp"
#include "slamd/eval/trajectory_error.hpp"
#include "slamd/eval/trajectory_plot.hpp"

namespace {

using slamd::eval::ErrorStatistics;
using slamd::eval::JsonWriter;

void writeStatistics(JsonWriter& json, const ErrorStatistics& s) {
  json.key("rmse").value(s.rmse).key("mean").value(s.mean).key("median").value(s.median);
  json.key("std").value(s.std).key("min").value(s.min).key("max").value(s.max);
}

void printStatistics(const std::string& prefix, const ErrorStatistics& s, const char* unit) {
  std::printf("%s.rmse %f %s\n", prefix.c_str(), s.rmse, unit);
  std::printf("%s.mean %f %s\n", prefix.c_str(), s.mean, unit);
  std::printf("%s.median %f %s\n", prefix.c_str(), s.median, unit);
  std::printf("%s.std %f %s\n", prefix.c_str(), s.std, unit);
  std::printf("%s.min %f %s\n", prefix.c_str(), s.min, unit);
  std::printf("%s.max %f %s\n", prefix.c_str(), s.max, unit);
}

double numberOption(const slamd::ProgramOptions& options, const std::string& name,
                    double config_value) {
  if (!options.has(name)) return config_value;
  const std::string text = options.value(name);
  char* end = nullptr;
  const double value = std::strtod(text.c_str(), &end);
  if (text.empty() || *end != '\0') {
    throw std::invalid_argument("--" + name + " '" + text + "' is not a number");
  }
  return value;
}

}  // namespace

int main(int argc, char** argv) {
  slamd::ProgramOptions options(
      "slamd-eval",
      "Trajectory error of EST against GT (TUM files), as the TUM benchmark's evaluate_ate.py "
      "(COMMAND ate) and evaluate_rpe.py --fixed_delta (COMMAND rpe) compute it.");
  options.setPositional("COMMAND(ate|rpe) GT EST", 3, 3);
  options.addOption("log-level", "LEVEL", "debug, info, warn or error", "warn");
  options.addFlag("json", "print one JSON object instead of text");
  options.addOption("plot", "FILE.png", "draw the trajectories and errors into a PNG");
  options.addOption("max-difference", "SECONDS", "ate: largest timestamp difference to associate",
                    "0.02");
  options.addOption("offset", "SECONDS", "time offset added to EST timestamps", "0");
  options.addOption("scale", "FACTOR", "multiply EST positions by this before evaluating", "1");
  options.addOption("align", "MODEL", "ate: se3 (rigid), sim3 (with scale) or none", "se3");
  options.addOption("save-associations", "FILE",
                    "ate: write 'gt_time gt_x gt_y gt_z est_time est_x est_y est_z' per pair "
                    "(estimate aligned)");
  options.addOption("delta", "VALUE", "rpe: interval between the poses compared", "1.0");
  options.addOption("delta-unit", "UNIT", "rpe: s (seconds), f (frames), m, rad or deg", "s");
  options.addOption("max-pairs", "N", "rpe: evaluate a seeded random sample of N pairs (0 = all)",
                    "0");
  if (!options.parse(argc, argv)) return options.exitCode();

  const std::string command = options.positional()[0];
  const std::string gt_path = options.positional()[1];
  const std::string est_path = options.positional()[2];
  if (command != "ate" && command != "rpe") {
    std::cerr << "slamd-eval: unknown command '" << command << "' (ate or rpe)\n\n"
              << options.usage();
    return slamd::kExitUsage;
  }

  slamd::Config config;
  double max_difference_s = 0.02, offset_s = 0.0, scale = 1.0, delta = 1.0;
  std::string alignment_text, delta_unit_text;
  int max_pairs = 0;
  try {
    config = options.loadConfig();
    max_difference_s = numberOption(options, "max-difference",
                                    config.getDouble("eval.max_difference_s", 0.02, 0.0, 1e9));
    offset_s = numberOption(options, "offset", config.getDouble("eval.offset_s", 0.0, -1e9, 1e9));
    scale = numberOption(options, "scale", config.getDouble("eval.scale", 1.0, 1e-9, 1e9));
    delta = numberOption(options, "delta", config.getDouble("eval.delta", 1.0, 0.0, 1e12));
    max_pairs = static_cast<int>(
        numberOption(options, "max-pairs", config.getInt("eval.max_pairs", 0, 0, 100000000)));
    alignment_text = options.has("align")
                         ? options.value("align")
                         : config.getChoice("eval.alignment", "se3", {"se3", "sim3", "none"});
    delta_unit_text = options.has("delta-unit")
                          ? options.value("delta-unit")
                          : config.getChoice("eval.delta_unit", "s", {"s", "f", "m", "rad", "deg"});
    slamd::reportConfig(config, "slamd-eval", slamd::UnknownKeys::kInSectionsItRead);
  } catch (const slamd::ConfigError& e) {
    std::cerr << "slamd-eval: " << e.what() << "\n";
    return slamd::kExitConfigError;
  } catch (const std::invalid_argument& e) {
    std::cerr << "slamd-eval: " << e.what() << "\n\n" << options.usage();
    return slamd::kExitUsage;
  }

  slamd::Trajectory groundtruth, estimate;
  try {
    groundtruth = slamd::readTumTrajectory(gt_path);
    estimate = slamd::readTumTrajectory(est_path);
  } catch (const std::runtime_error& e) {
    std::cerr << "slamd-eval: " << e.what() << "\n";
    return slamd::kExitSourceError;
  }

  slamd::eval::PlotOptions plot_options;
  plot_options.subtitle = "ground truth: " + gt_path + "     estimate: " + est_path;
  const bool json_output = options.flag("json");
  try {
    if (command == "ate") {
      slamd::eval::AteOptions ate_options;
      ate_options.association.max_difference_s = max_difference_s;
      ate_options.association.offset_s = offset_s;
      ate_options.scale = scale;
      ate_options.alignment = slamd::eval::parseAlignmentModel(alignment_text);
      const slamd::eval::AteResult ate =
          slamd::eval::computeAte(groundtruth, estimate, ate_options);
      const ErrorStatistics& s = ate.translation_m;
      if (json_output) {
        JsonWriter json(true);
        json.beginObject().key("metric").value("ate").key("unit").value("m");
        json.key("groundtruth").value(gt_path).key("estimate").value(est_path);
        json.key("alignment").value(slamd::eval::alignmentModelName(ate_options.alignment));
        json.key("max_difference_s").value(max_difference_s).key("offset_s").value(offset_s);
        json.key("pairs").value(s.count);
        writeStatistics(json, s);
        json.key("alignment_scale").value(ate.alignment.scale);
        json.endObject();
        std::cout << json.str() << "\n";
      } else {
        std::printf("compared_pose_pairs %zu pairs\n", s.count);
        printStatistics("absolute_translational_error", s, "m");
        std::printf("alignment %s", slamd::eval::alignmentModelName(ate_options.alignment));
        if (ate_options.alignment == slamd::eval::AlignmentModel::kSim3) {
          std::printf(" scale %f", ate.alignment.scale);
        }
        std::printf("\n");
      }
      if (options.has("save-associations")) {
        std::ofstream out(options.value("save-associations"));
        for (const auto& pair : ate.pairs) {
          out << slamd::eval::JsonWriter::number(pair.timestamp_gt_s) << " "
              << pair.position_gt_m.transpose() << " "
              << slamd::eval::JsonWriter::number(pair.timestamp_est_s) << " "
              << pair.position_est_m.transpose() << "\n";
        }
        if (!out) {
          std::cerr << "slamd-eval: cannot write " << options.value("save-associations") << "\n";
          return slamd::kExitOutputError;
        }
      }
      if (options.has("plot")) {
        slamd::eval::writePng(options.value("plot"),
                              slamd::eval::renderAtePlot(ate, plot_options, ate_options.alignment));
      }
    } else {
      slamd::eval::RpeOptions rpe_options;
      rpe_options.delta = delta;
      rpe_options.delta_unit = slamd::eval::parseDeltaUnit(delta_unit_text);
      rpe_options.offset_s = offset_s;
      rpe_options.scale = scale;
      rpe_options.max_pairs = static_cast<std::size_t>(max_pairs);
      const slamd::eval::RpeResult rpe =
          slamd::eval::computeRpe(groundtruth, estimate, rpe_options);
      if (json_output) {
        JsonWriter json(true);
        json.beginObject().key("metric").value("rpe");
        json.key("groundtruth").value(gt_path).key("estimate").value(est_path);
        json.key("delta").value(delta).key("delta_unit").value(delta_unit_text);
        json.key("offset_s").value(offset_s);
        json.key("pairs").value(rpe.translation_m.count);
        json.key("translation").beginObject().key("unit").value("m");
        writeStatistics(json, rpe.translation_m);
        json.endObject();
        json.key("rotation").beginObject().key("unit").value("deg");
        writeStatistics(json, rpe.rotation_deg);
        json.endObject().endObject();
        std::cout << json.str() << "\n";
      } else {
        std::printf("compared_pose_pairs %zu pairs\n", rpe.translation_m.count);
        printStatistics("translational_error", rpe.translation_m, "m");
        printStatistics("rotational_error", rpe.rotation_deg, "deg");
      }
      if (options.has("plot")) {
        plot_options.title = "Relative pose error over " + slamd::eval::JsonWriter::number(delta) +
                             " " + delta_unit_text;
        slamd::eval::writePng(options.value("plot"), slamd::eval::renderRpePlot(rpe, plot_options));
      }
    }
  } catch (const std::invalid_argument& e) {
    std::cerr << "slamd-eval: " << e.what() << "\n\n" << options.usage();
    return slamd::kExitUsage;
  } catch (const std::runtime_error& e) {
    std::cerr << "slamd-eval: " << e.what() << "\n";
    return e.what() == std::string()                                 ? slamd::kExitFailure
           : std::string(e.what()).find("plot") != std::string::npos ? slamd::kExitOutputError
                                                                     : slamd::kExitFailure;
  }
  return slamd::kExitOk;
}
