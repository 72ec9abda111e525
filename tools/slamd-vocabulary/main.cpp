// slamd-vocabulary: trains the back end's bag-of-words vocabulary (k-majority tree over ORB
// descriptors) and writes it for backend.vocabulary_file, or checks an existing file.
//
//   slamd-vocabulary --out room.voc                                   # synthetic room (default)
//   slamd-vocabulary --source synthetic:corridor --out corridor.voc
//   slamd-vocabulary --source tum:/data/fr2_desk --config config/tum_fr2.yaml --every 15
//       --out fr2.voc
//   slamd-vocabulary --check fr2.voc
//
// The build runs `slamd-vocabulary --images 20 --out <build>/share/slamd/orb_vocabulary.voc`:
// the vocabulary the daemon loads when backend.vocabulary_file is empty.
//
// Training images: every --every-th frame of the source (at most --images of them); features
// from tracking's front end as configured (tracking.*, the ORB front end). Tree shape from
// backend.vocabulary_branching / backend.vocabulary_depth. Train on a place other than the one
// to be mapped when evaluating, so the vocabulary does not know the test scene.
// Exit codes: 0 written / valid, 2 bad command line, 3 configuration error or invalid file,
// 4 source error, 5 the file could not be written.

#include <chrono>
#include <cstdio>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "slamd/backend/backend_config.hpp"
#include "slamd/backend/vocabulary.hpp"
#include "slamd/common/program_options.hpp"
#include "slamd/sources/create_frame_source.hpp"
#include "slamd/tracking/features.hpp"
#include "slamd/tracking/tracking_config.hpp"
#include "vocabulary_training.hpp"

using namespace slamd;

namespace {

double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

int check(const std::string& path) {
  try {
    const Vocabulary vocabulary = Vocabulary::load(path);
    std::printf("%s: valid, format version %u, %d words, branching %d, depth %d\n", path.c_str(),
                Vocabulary::kFileVersion, vocabulary.numWords(), vocabulary.branching(),
                vocabulary.depth());
    return kExitOk;
  } catch (const VocabularyError& e) {
    std::cerr << e.what() << "\n";
    return kExitConfigError;
  }
}

}  // namespace

int main(int argc, char** argv) {
  ProgramOptions options("slamd-vocabulary",
                         "Trains the back end's vocabulary and writes it, or checks a file.");
  options.addOption("source", "SOURCE", "tum:DIR or synthetic:SCENE (frames to train on)", "");
  options.addOption("out", "FILE", "vocabulary file to write");
  options.addOption("every", "N", "use every N-th frame of a recorded source", "30");
  options.addOption("images", "N", "at most N training images", "40");
  options.addOption("check", "FILE", "load FILE, report it and exit (3 when invalid)");
  if (!options.parse(argc, argv)) return options.exitCode();
  if (options.has("check")) return check(options.value("check"));
  if (!options.has("out")) {
    std::cerr << "slamd-vocabulary: --out FILE (or --check FILE) is required\n";
    return kExitUsage;
  }
  cv::setNumThreads(1);
  const int every = std::max(1, std::stoi(options.value("every")));
  const int max_images = std::max(1, std::stoi(options.value("images")));
  const std::string spec = options.value("source");
  const auto start = std::chrono::steady_clock::now();

  Vocabulary vocabulary;
  try {
    Config config = options.loadConfig();
    const BackendConfig backend = BackendConfig::load(config);
    if (spec.empty()) {
      vocabulary = trainVocabularyOnSyntheticScene("room", backend.vocabulary_branching,
                                                   backend.vocabulary_depth, max_images);
      std::printf("trained on the synthetic room (%d images)\n", max_images);
    } else {
      const TrackingConfig tracking = TrackingConfig::load(config);
      auto extractor = makeFeatureExtractor(tracking);
      std::unique_ptr<FrameSource> source = createFrameSource(spec, config);
      source->open();
      std::vector<cv::Mat> descriptors;
      long index = 0;
      while (static_cast<int>(descriptors.size()) < max_images) {
        const FrameRead read = source->next(std::chrono::milliseconds(1000));
        if (read.status == FrameRead::Status::kEndOfStream) break;
        if (read.status != FrameRead::Status::kFrame) continue;
        if (index++ % every != 0) continue;
        cv::Mat gray = read.frame->gray;
        if (gray.empty()) cv::cvtColor(read.frame->color_bgr, gray, cv::COLOR_BGR2GRAY);
        FeatureSet features;
        extractor->extract(gray, features);
        if (features.descriptors.type() != CV_8UC1 || features.descriptors.cols != 32) {
          std::cerr << "slamd-vocabulary: the front end gives no 256-bit binary descriptors "
                       "(use tracking.frontend=orb)\n";
          return kExitConfigError;
        }
        descriptors.push_back(features.descriptors);
      }
      source->close();
      if (descriptors.empty()) {
        std::cerr << "slamd-vocabulary: no frames read from " << spec << "\n";
        return kExitSourceError;
      }
      vocabulary = Vocabulary::train(descriptors, backend.vocabulary_branching,
                                     backend.vocabulary_depth, 42);
      std::printf("trained on %zu images of %s\n", descriptors.size(), spec.c_str());
    }
  } catch (const ConfigError& e) {
    std::cerr << e.what() << "\n";
    return kExitConfigError;
  } catch (const SourceError& e) {
    std::cerr << e.what() << "\n";
    return kExitSourceError;
  }
  if (vocabulary.empty()) {
    std::cerr << "slamd-vocabulary: no descriptors to train on\n";
    return kExitFailure;
  }
  try {
    vocabulary.save(options.value("out"));
  } catch (const VocabularyError& e) {
    std::cerr << e.what() << "\n";
    return kExitOutputError;
  }
  std::printf("%s: %d words (branching %d, depth %d), %.1f s\n", options.value("out").c_str(),
              vocabulary.numWords(), vocabulary.branching(), vocabulary.depth(),
              secondsSince(start));
  return kExitOk;
}
