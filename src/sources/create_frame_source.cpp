#include "slamd/sources/create_frame_source.hpp"

#include "slamd/capture/paced_source.hpp"
#include "slamd/capture/tum_source.hpp"
#include "slamd/common/log.hpp"
#include "slamd/comms/lcm_frame_source.hpp"
#ifdef SLAMD_HAVE_OPENNI2
#include "slamd/capture/openni2_source.hpp"
#endif
#ifdef SLAMD_HAVE_SYNTH
#include "slamd/synth/synthetic_source.hpp"
#endif

namespace slamd {

const char* frameSourceSpecHelp() {
  return "tum:DIR | openni2[:URI] | oni:FILE | lcm:CHANNEL | synthetic:SCENE";
}

std::unique_ptr<FrameSource> createRawFrameSource(const std::string& spec, Config& config) {
  const auto colon = spec.find(':');
  const std::string kind = spec.substr(0, colon);
  const std::string argument = colon == std::string::npos ? std::string() : spec.substr(colon + 1);
  auto requireArgument = [&](const char* what) {
    if (argument.empty()) {
      throw SourceError("source '" + spec + "' needs " + what + " after '" + kind + ":'");
    }
  };
  if (kind == "tum") {
    requireArgument("a folder");
    return std::make_unique<TumSource>(argument, TumSourceConfig::load(config));
  }
  if (kind == "lcm") {
    requireArgument("a channel");
    return std::make_unique<LcmFrameSource>(argument, LcmFrameSourceConfig::load(config));
  }
  if (kind == "openni2" || kind == "oni") {
#ifdef SLAMD_HAVE_OPENNI2
    if (kind == "oni") requireArgument("a file");
    OpenNi2Config openni2 = OpenNi2Config::load(config);
    const PacingConfig pacing = PacingConfig::load(config);
    if (kind == "oni" && pacing.mode == PacingMode::kRealTime) {
      // OpenNI's own player paces a recording like a camera (the newest frame, gaps counted)
      // without reading the frames it passes over; slamd's pacer would have to read them.
      openni2.oni_realtime = true;
      openni2.oni_speed = pacing.speed;
    }
    return std::make_unique<OpenNi2Source>(
        kind == "oni" ? OpenNi2Source::Kind::kFile : OpenNi2Source::Kind::kDevice, argument,
        openni2);
#else
    throw SourceError("source '" + spec +
                      "': this slamd was built without OpenNI2 (-DSLAMD_WITH_OPENNI2=OFF)");
#endif
  }
  if (kind == "synthetic") {
    requireArgument("a scene");
#ifdef SLAMD_HAVE_SYNTH
    return createSyntheticSource(argument, config);
#else
    throw SourceError("source '" + spec + "': synthetic worlds are not built in this tree");
#endif
  }
  throw SourceError("unknown source '" + spec + "'; use " + frameSourceSpecHelp());
}

std::unique_ptr<FrameSource> createFrameSource(const std::string& spec, Config& config) {
  std::unique_ptr<FrameSource> source = createRawFrameSource(spec, config);
  const DepthPreprocessorConfig preprocess = DepthPreprocessorConfig::load(config);
  const PacingConfig pacing = PacingConfig::load(config);
  if (preprocess.anyEnabled()) {
    source = std::make_unique<PreprocessedSource>(std::move(source), preprocess);
  }
  if (pacing.mode != PacingMode::kAsFastAsPossible) {
    if (!source->isLive()) {
      source = std::make_unique<PacedSource>(std::move(source), pacing);
    } else if (spec.rfind("oni:", 0) != 0) {
      SLAMD_LOG_WARN("capture.pacing")
          << spec << " is live: frames arrive on the device's clock, pacing "
          << pacingModeName(pacing.mode) << " ignored";
    }
  }
  return source;
}

const PreprocessedSource* findPreprocessing(const FrameSource& source) {
  if (const auto* pre = dynamic_cast<const PreprocessedSource*>(&source)) return pre;
  if (const auto* paced = dynamic_cast<const PacedSource*>(&source)) {
    return dynamic_cast<const PreprocessedSource*>(&paced->inner());
  }
  return nullptr;
}

}  // namespace slamd
