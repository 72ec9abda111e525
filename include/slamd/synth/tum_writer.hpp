#pragma once
// TumSequenceWriter: writes RGB-D frames as a TUM RGB-D benchmark folder.
//
// Usage:
//   TumSequenceWriter writer("/tmp/corridor", "slamd-synth corridor zigzag seed 42");
//   writer.open();                       // creates DIR/rgb, DIR/depth; throws std::runtime_error
//   for (each frame) writer.write(*frame);
//   writer.finish(ground_truth);         // rgb.txt, depth.txt, groundtruth.txt
//
// Layout and conventions (the benchmark's): rgb/<t>.png (8-bit colour), depth/<t>.png (16-bit
// grey, value = depth in metres * 5000, 0 = no measurement), where <t> is the timestamp in
// seconds with 6 decimals; rgb.txt and depth.txt list `timestamp filename` under three '#' header
// lines; groundtruth.txt holds `timestamp tx ty tz qx qy qz qw` (T_world_camera of the optical
// frame). Depth is rounded to the nearest 1/5000 m (0.2 mm) and written at the frame's depth
// time (RgbdFrame::depthUtime), which may differ from the colour's. One thread owns a writer.
//
// TumImageFormat::kUncompressed writes the same pixels as binary PPM (colour) and 16-bit PGM
// (depth) instead of PNG: about twice the bytes, but read back with a copy rather than inflate,
// for folders replayed in real time, where decoding competes with tracking for the CPU.

#include <fstream>
#include <optional>
#include <string>

#include "slamd/common/rgbd_frame.hpp"
#include "slamd/common/trajectory.hpp"

namespace slamd {

enum class TumImageFormat {
  kPng,           ///< rgb/<t>.png, depth/<t>.png: the benchmark's own layout
  kUncompressed,  ///< rgb/<t>.ppm, depth/<t>.pgm (16-bit): cheap to read back in real time
};

class TumSequenceWriter {
 public:
  /// @param folder output folder (created if missing; existing list files are replaced).
  /// @param description written into the list headers (e.g. the generating command).
  /// @param depth_scale raw units per metre in the depth PNGs (5000 in the TUM benchmark).
  /// @param format image files written (PNG, or uncompressed PPM/PGM).
  TumSequenceWriter(std::string folder, std::string description, double depth_scale = 5000.0,
                    TumImageFormat format = TumImageFormat::kPng);

  void open();
  /// Writes one frame's colour and depth images and list lines; throws std::runtime_error
  /// naming the file on I/O errors.
  void write(const RgbdFrame& frame);
  /// Writes groundtruth.txt (when non-empty) and closes the lists.
  void finish(const Trajectory& ground_truth);

  int framesWritten() const { return frames_written_; }

 private:
  std::string folder_;
  std::string description_;
  double depth_scale_;
  TumImageFormat format_;
  std::ofstream rgb_list_;
  std::ofstream depth_list_;
  int frames_written_ = 0;
};

/// "png" or "uncompressed" (the --images option of slamd-synth and slamd-play); nullopt otherwise.
std::optional<TumImageFormat> parseTumImageFormat(const std::string& name);

/// The timestamp of a utime as the benchmark writes it: seconds with 6 decimals.
std::string formatTumTimestamp(Utime utime);

}  // namespace slamd
