#pragma once
// createFrameSource: builds any slamd frame source from a specification string, wrapped in depth
// pre-processing and pacing as configured. Programs (the daemon, slamd-play, benchmarks) call it
// on the main thread at start-up; the returned source then belongs to the capture thread.
//
//   Config config = options.loadConfig();
//   std::unique_ptr<FrameSource> source = createFrameSource("tum:/data/fr1_xyz", config);
//   reportConfig(config, "program");      // every capture.* / camera.* key read is reported
//   source->open();
//
// Specifications:
//   tum:DIR            TUM RGB-D folder (TumSource; capture.tum.*, camera.* with depth scale 5000)
//   openni2[:URI]      OpenNI2 device, first one without URI (OpenNi2Source; capture.openni2.*)
//   oni:FILE           OpenNI2 recording, played once (capture.oni.realtime; capture.pacing.mode
//                      realtime plays it with OpenNI's own real-time player at
//                      capture.pacing.speed)
//   lcm:CHANNEL        slamd.rgbd_frame_t / kinect.frame_msg_t on LCM (LcmFrameSource;
//                      capture.lcm.*)
//   synthetic:SCENE    slamd's synthetic worlds (createSyntheticSource; synthetic.*)
// Wrapping: PreprocessedSource when any capture.preprocess.* step is enabled, then PacedSource
// when capture.pacing.mode is realtime or fixed and the source is not live (a live source runs on
// its own clock: pacing is ignored, with a warning).
// Throws SourceError for an unknown or malformed specification (naming the accepted ones) and
// ConfigError for bad configuration values.

#include <memory>
#include <string>

#include "slamd/capture/frame_source.hpp"
#include "slamd/capture/preprocessed_source.hpp"
#include "slamd/common/config.hpp"

namespace slamd {

std::unique_ptr<FrameSource> createFrameSource(const std::string& spec, Config& config);

/// The source without pre-processing and pacing (for tests and tools that want raw frames).
std::unique_ptr<FrameSource> createRawFrameSource(const std::string& spec, Config& config);

/// The pre-processing stage inside a source built by createFrameSource, or null when none.
const PreprocessedSource* findPreprocessing(const FrameSource& source);

/// One line listing the accepted specifications, for --help texts.
const char* frameSourceSpecHelp();

}  // namespace slamd
