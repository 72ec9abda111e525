// fuzz_seeds OUT_DIR: writes the seed corpus of every fuzz target into OUT_DIR/<target>/, built
// from real data: messages encoded by slamd's own encoders from a rendered synthetic frame, a
// map integrated by the mapper, the status and pose messages the daemon sends, the configuration
// files in config/, a trained vocabulary, and TUM list files (the first lines of the real
// tum_fr1_xyz lists when the data folder is present, otherwise lists in the same format).
//
// `make fuzz` and the replay tests run it; both start from the same seeds.

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <octomap/ColorOcTree.h>
#include <octomap/OcTree.h>
#include <opencv2/imgproc.hpp>

#include "frame_codec_layout.hpp"
#include "slamd/backend/session.hpp"
#include "slamd/backend/vocabulary.hpp"
#include "slamd/common/config.hpp"
#include "slamd/comms/frame_codec.hpp"
#include "slamd/comms/map_codec.hpp"
#include "slamd/comms/message_codec.hpp"
#include "slamd/comms/odometry_codec.hpp"
#include "slamd/comms/plane_map_codec.hpp"
#include "slamd/comms/pose_codec.hpp"
#include "slamd/comms/status_codec.hpp"
#include "slamd/mapping/keyframe_cloud_io.hpp"
#include "slamd/mapping/mapper.hpp"
#include "slamd/synth/synthetic_source.hpp"
#include "test_data.hpp"

namespace {

using namespace slamd;
namespace fs = std::filesystem;
using Bytes = std::vector<std::uint8_t>;

class CorpusWriter {
 public:
  explicit CorpusWriter(fs::path root) : root_(std::move(root)) {}
  void add(const std::string& target, const Bytes& bytes) {
    const fs::path folder = root_ / target;
    fs::create_directories(folder);
    char name[32];
    std::snprintf(name, sizeof(name), "seed-%03d", counts_[target]++);
    std::ofstream(folder / name, std::ios::binary)
        .write(reinterpret_cast<const char*>(bytes.data()),
               static_cast<std::streamsize>(bytes.size()));
  }
  void add(const std::string& target, std::uint8_t selector, const Bytes& bytes) {
    Bytes with_selector{selector};
    with_selector.insert(with_selector.end(), bytes.begin(), bytes.end());
    add(target, with_selector);
  }
  void add(const std::string& target, std::uint8_t selector, const std::string& text) {
    add(target, selector, Bytes(text.begin(), text.end()));
  }
  std::map<std::string, int> counts() const { return counts_; }

 private:
  fs::path root_;
  std::map<std::string, int> counts_;
};

/// One synthetic room frame, shrunk to `width` x `height` (fuzzing decodes it many times).
RgbdFrame smallFrame(int width, int height) {
  Config config;
  std::unique_ptr<FrameSource> source = createSyntheticSource("room", config);
  source->open();
  FrameRead read;
  while ((read = source->next(std::chrono::milliseconds(5000))).status !=
         FrameRead::Status::kFrame) {
    if (read.status == FrameRead::Status::kEndOfStream) throw std::runtime_error("no frame");
  }
  const RgbdFrame& full = *read.frame;
  RgbdFrame frame;
  frame.utime = full.utime;
  frame.sequence = full.sequence;
  frame.intrinsics = full.intrinsics.scaled(width, height);
  cv::resize(full.color_bgr, frame.color_bgr, cv::Size(width, height), 0, 0, cv::INTER_AREA);
  cv::resize(full.depth_m, frame.depth_m, cv::Size(width, height), 0, 0, cv::INTER_NEAREST);
  cv::cvtColor(frame.color_bgr, frame.gray, cv::COLOR_BGR2GRAY);
  return frame;
}

void lcmAndFrameSeeds(CorpusWriter& corpus, const RgbdFrame& frame) {
  using fuzz::FrameCodecInput;
  using fuzz::FrameCodecKind;
  for (const ColorEncoding color :
       {ColorEncoding::kRgb8, ColorEncoding::kBgr8, ColorEncoding::kJpeg, ColorEncoding::kPng}) {
    for (const DepthEncoding depth :
         {DepthEncoding::kRawU16, DepthEncoding::kPngU16, DepthEncoding::kZlibU16}) {
      FrameEncodeOptions options;
      options.color = color;
      options.depth = depth;
      const slamd::rgbd_frame_t message = encodeRgbdFrame(frame, options);
      corpus.add("lcm_messages", encodeMessage(message));
      FrameCodecInput input;
      input.kind = FrameCodecKind::kRgbdFrame;
      input.width = message.width;
      input.height = message.height;
      input.color_format = static_cast<std::uint8_t>(message.color_encoding);
      input.depth_format = static_cast<std::uint8_t>(message.depth_encoding);
      input.color = message.color_data;
      input.depth = message.depth_data;
      corpus.add("frame_codec", fuzz::encodeFrameCodecInput(input));
      if (color == ColorEncoding::kPng && depth == DepthEncoding::kZlibU16) {
        input.kind = FrameCodecKind::kBareCodecs;
        corpus.add("frame_codec", fuzz::encodeFrameCodecInput(input));
      }
    }
  }
  for (const bool jpeg : {false, true}) {
    for (const bool zlib : {false, true}) {
      const kinect::frame_msg_t message = encodeKinectFrame(frame, jpeg, zlib);
      corpus.add("lcm_messages", encodeMessage(message));
      if (jpeg && zlib) {
        corpus.add("lcm_messages", encodeMessage(message.image));
        corpus.add("lcm_messages", encodeMessage(message.depth));
      }
      FrameCodecInput input;
      input.kind = FrameCodecKind::kKinectFrame;
      input.width = message.image.width;
      input.height = message.image.height;
      input.color_format = static_cast<std::uint8_t>(message.image.image_data_format);
      input.depth_format = static_cast<std::uint8_t>(message.depth.compression);
      input.variant = kinect::depth_msg_t::DEPTH_MM;
      input.color = message.image.image_data;
      input.depth = message.depth.depth_data;
      corpus.add("frame_codec", fuzz::encodeFrameCodecInput(input));
    }
  }
}

void poseAndStatusSeeds(CorpusWriter& corpus) {
  PoseEstimate pose;
  pose.utime = 1305031102175304;
  pose.sequence = 42;
  pose.T_world_camera.translation() = Eigen::Vector3d(1.3, 0.6, 1.6);
  pose.tracking_state = TrackingState::kOk;
  corpus.add("lcm_messages", encodeMessage(toPoseMessage(pose)));
  corpus.add("lcm_messages", encodeMessage(toBotCorePose(pose)));

  KeyframeTrajectory trajectory;
  trajectory.utime = pose.utime;
  trajectory.num_loops = 1;
  for (int i = 0; i < 3; ++i) {
    KeyframePoseEntry entry;
    entry.keyframe_id = i;
    entry.utime = pose.utime + i * 100000;
    entry.T_world_camera.translation() = Eigen::Vector3d(0.1 * i, 0.0, 0.0);
    trajectory.keyframes.push_back(entry);
  }
  const slamd::keyframe_trajectory_t keyframes = toKeyframeTrajectoryMessage(trajectory);
  corpus.add("lcm_messages", encodeMessage(keyframes));
  corpus.add("lcm_messages", encodeMessage(keyframes.keyframes.front()));

  OdometryResult odometry;
  odometry.utime = pose.utime;
  odometry.sequence = 7;
  odometry.tracking_state = TrackingState::kOk;
  corpus.add("lcm_messages", encodeMessage(toOdometryMessage(odometry)));
  corpus.add("lcm_messages", encodeMessage(toVanishingPointMessage(pose.utime, {})));

  planes::PlaneMapSnapshot plane_map;
  plane_map.utime = pose.utime;
  plane_map.frame_id = "world";
  planes::WorldPlane floor;
  floor.id = 3;
  floor.polygon_world = {{0, 0, 0}, {2, 0, 0}, {2, 1, 0}};
  floor.area_m2 = 1.0;
  floor.keyframe_ids = {0, 1};
  plane_map.planes = {floor, floor};
  plane_map.planes[1].id = 4;
  corpus.add("lcm_messages", encodeMessage(toPlaneMapMessage(plane_map)));

  std::vector<StageStats> stages(4);
  const char* names[] = {"capture", "tracking", "filter", "mapping"};
  for (std::size_t i = 0; i < stages.size(); ++i) {
    stages[i].name = names[i];
    stages[i].processed = 100 + i;
    stages[i].latency_buckets.assign(8, 1);
  }
  StatusBuilder builder;
  StatusExtras extras;
  extras.message = "tracking";
  builder.build(pose.utime, 1'000'000'000, stages, {}, extras);
  const slamd::status_t status = builder.build(pose.utime + 1000000, 2'000'000'000, stages,
                                               std::vector<std::uint64_t>(8, 2), extras);
  corpus.add("lcm_messages", encodeMessage(status));
  if (!status.stages.empty()) corpus.add("lcm_messages", encodeMessage(status.stages.front()));
}

void commandSeeds(CorpusWriter& corpus) {
  // lcm-gen declares the command constants without defining them: copied, never bound to a
  // reference (the sanitizer builds fail to link otherwise).
  using C = slamd::command_t;
  const std::vector<std::pair<std::int8_t, std::string>> commands = {
      {std::int8_t{C::SAVE_MAP}, ""},
      {std::int8_t{C::SAVE_MAP}, "map.bt"},
      {std::int8_t{C::SAVE_MAP}, "office.ot"},
      {std::int8_t{C::SAVE_MAP}, "/tmp/x/map.bt"},
      {std::int8_t{C::SAVE_MAP}, "../map.bt"},
      {std::int8_t{C::PAUSE}, ""},
      {std::int8_t{C::RESUME}, ""},
      {std::int8_t{C::RESET}, ""},
      {std::int8_t{C::SHUTDOWN}, ""},
      {std::int8_t{C::PUBLISH_MAP}, ""}};
  for (const auto& [code, argument] : commands) {
    slamd::command_t command;
    command.utime = 1;
    command.command = code;
    command.argument = argument;
    const Bytes bytes = encodeMessage(command);
    corpus.add("lcm_messages", bytes);
    corpus.add("command", 0, bytes);
    corpus.add("command", 1, argument);
  }
}

void mapSeeds(CorpusWriter& corpus, const RgbdFrame& frame) {
  // A small map (coarse voxels, short range, two frames): fuzzing decodes it many times.
  MappingConfig config;
  config.resolution_m = 0.25;
  config.max_range_m = 1.5;
  Mapper mapper(config);
  SE3 T_world_camera = SE3::Identity();
  for (int i = 0; i < 2; ++i) {
    T_world_camera.translation().x() = 0.1 * i;
    mapper.integrate(frame, T_world_camera);
  }
  const MapUpdate update = mapper.takeUpdate();
  const Bytes update_bytes = encodeMessage(toMapUpdateMessage(update));
  corpus.add("lcm_messages", update_bytes);
  corpus.add("map_codec", 1, update_bytes);
  const FullMap full = mapper.fullMap();
  const Bytes full_bytes = encodeMessage(toFullMapMessage(full));
  corpus.add("lcm_messages", full_bytes);
  corpus.add("map_codec", 0, full_bytes);
  corpus.add("map_codec", 2, full.data);
  if (!update.voxels.empty()) {
    const slamd::voxel_map_update_t message = toMapUpdateMessage(update);
    corpus.add("lcm_messages", encodeMessage(message.voxels.front()));
  }
  // Map files as mapping.load_path reads them: .bt and .ot of an OcTree and a ColorOcTree.
  std::string error;
  std::unique_ptr<octomap::OcTree> tree = fullMapToOcTree(full, &error);
  if (!tree) throw std::runtime_error("seed map: " + error);
  std::ostringstream bt, ot, color_ot;
  tree->writeBinary(bt);
  tree->write(ot);
  octomap::ColorOcTree color(tree->getResolution());
  for (auto it = tree->begin_leafs(); it != tree->end_leafs(); ++it) {
    color.updateNode(it.getKey(), it->getLogOdds() > 0)->setColor(200, 120, 40);
  }
  color.write(color_ot);
  for (const std::string& file : {bt.str(), ot.str(), color_ot.str()}) {
    corpus.add("map_codec", 3, file);
  }
}

void configSeeds(CorpusWriter& corpus) {
  for (const auto& entry : fs::directory_iterator(fs::path(SLAMD_SOURCE_DIR) / "config")) {
    if (entry.path().extension() != ".yaml") continue;
    std::ifstream in(entry.path(), std::ios::binary);
    std::stringstream text;
    text << in.rdbuf();
    corpus.add("config", 0, text.str());
  }
  corpus.add("config", 1,
             "tracking.frontend=fovis\nmapping.resolution_m=0.02\ncamera.intrinsics=[525, 525, "
             "319.5, 239.5]\ndaemon.save_dir=maps\ncapture.lcm.max_time_jump_s=2\n");
  corpus.add("config", 1, "backend.enabled=false\nfilter.vp.enabled=true\nlcm.url=memq://\n");
}

void vocabularySeeds(CorpusWriter& corpus) {
  cv::Mat descriptors(200, 32, CV_8UC1);
  cv::RNG rng(7);
  rng.fill(descriptors, cv::RNG::UNIFORM, 0, 256);
  const Vocabulary vocabulary = Vocabulary::train({descriptors}, 4, 2, 7);
  std::ostringstream file;
  vocabulary.write(file);
  const std::string bytes = file.str();
  corpus.add("vocabulary", 0, bytes);
  corpus.add("vocabulary", 1, bytes);
}

Bytes fileBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return Bytes(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

/// A session of two keyframes written by SessionWriter, and a keyframe-clouds file: the files
/// session_files_fuzz mutates.
void sessionSeeds(CorpusWriter& corpus, const fs::path& scratch) {
  BackendSnapshot snapshot;
  cv::RNG rng(11);
  for (std::int64_t id = 0; id < 2; ++id) {
    auto keyframe = std::make_shared<Keyframe>();
    keyframe->id = id;
    keyframe->utime = 1'600'000'000'000'000 + id * 33'333;
    keyframe->T_world_camera.translation().x() = 0.1 * static_cast<double>(id);
    keyframe->features.descriptors = cv::Mat(3, 32, CV_8UC1);
    rng.fill(keyframe->features.descriptors, cv::RNG::UNIFORM, 0, 256);
    for (int i = 0; i < 3; ++i) {
      keyframe->features.keypoints.emplace_back(10.0f * i + 5.0f, 20.0f, 31.0f);
      keyframe->features.pixels.emplace_back(10.0 * i + 5.0, 20.0);
      keyframe->features.points.emplace_back(0.1 * i, 0.0, 1.0 + 0.1 * i);
      keyframe->features.scale.push_back(1.0f);
    }
    keyframe->features.num_with_depth = 3;
    snapshot.keyframes.push_back(keyframe);
    snapshot.nodes.push_back({id, keyframe->T_world_camera, id == 0});
    snapshot.records.push_back({id, 0, 0.1 * static_cast<double>(id)});
  }
  snapshot.edges.push_back(
      {0, 1,
       snapshot.keyframes[0]->T_world_camera.inverse() * snapshot.keyframes[1]->T_world_camera,
       Matrix6d::Identity() * 100.0, EdgeKind::kOdometry});
  snapshot.segment_parents.emplace_back(0, 0);
  snapshot.next_keyframe_id = 2;
  snapshot.next_segment = 1;
  const fs::path session = scratch / "session";
  SessionWriter writer(session.string());
  writer.writeBackend(snapshot);
  const Bytes keyframes = fileBytes(writer.pathFor(kSessionKeyframesFile));
  const Bytes graph = fileBytes(writer.pathFor(kSessionGraphFile));
  Bytes backend{static_cast<std::uint8_t>(keyframes.size() >> 8),
                static_cast<std::uint8_t>(keyframes.size() & 0xff)};
  backend.insert(backend.end(), keyframes.begin(), keyframes.end());
  backend.insert(backend.end(), graph.begin(), graph.end());
  corpus.add("session_files", 0, backend);

  KeyframeCloudRecord record;
  record.id = 1;
  record.utime = 1'600'000'000'000'000;
  for (int i = 0; i < 8; ++i) {
    record.cloud_camera.points.emplace_back(0.1f * static_cast<float>(i), 0.0f, 1.0f);
  }
  record.part_points = 4;
  record.parts_in_map = 2;
  const fs::path clouds = scratch / "keyframe_clouds.bin";
  std::string error;
  if (!writeKeyframeCloudRecords(clouds.string(), {record}, &error)) {
    throw std::runtime_error(error);
  }
  corpus.add("session_files", 1, fileBytes(clouds));
  corpus.add("session_files", 3, fileBytes(clouds));
}

std::string firstLines(const fs::path& path, int count) {
  std::ifstream in(path);
  std::string line, out;
  for (int i = 0; i < count && std::getline(in, line); ++i) out += line + "\n";
  return out;
}

void tumSeeds(CorpusWriter& corpus) {
  const std::optional<fs::path> tum = slamd::test::findDataset("tum_fr1_xyz");
  std::string rgb, depth, groundtruth;
  if (tum && fs::is_regular_file(*tum / "rgb.txt")) {
    rgb = firstLines(*tum / "rgb.txt", 30);
    depth = firstLines(*tum / "depth.txt", 30);
    groundtruth = firstLines(*tum / "groundtruth.txt", 30);
  } else {
    rgb = "# color images\n# file: 'rgbd_dataset_freiburg1_xyz.bag'\n# timestamp filename\n";
    depth = "# depth maps\n# file: 'rgbd_dataset_freiburg1_xyz.bag'\n# timestamp filename\n";
    groundtruth = "# ground truth trajectory\n# timestamp tx ty tz qx qy qz qw\n";
    for (int i = 0; i < 20; ++i) {
      const double t = 1305031102.175304 + i / 30.0;
      char line[160];
      std::snprintf(line, sizeof(line), "%.6f rgb/%.6f.png\n", t, t);
      rgb += line;
      std::snprintf(line, sizeof(line), "%.6f depth/%.6f.png\n", t + 0.01, t + 0.01);
      depth += line;
      std::snprintf(line, sizeof(line), "%.4f 1.3405 0.6266 1.6575 0.6574 0.6126 -0.2949 -0.3248\n",
                    t);
      groundtruth += line;
    }
  }
  corpus.add("tum_lists", 0, rgb + "\f" + depth);
  std::string associations;
  std::istringstream rgb_lines(rgb), depth_lines(depth);
  std::string a, b;
  while (std::getline(rgb_lines, a) && std::getline(depth_lines, b)) {
    if (!a.empty() && a[0] != '#' && !b.empty() && b[0] != '#') associations += a + " " + b + "\n";
  }
  corpus.add("tum_lists", 1, associations);
  corpus.add("tum_lists", 2, groundtruth);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: fuzz_seeds OUT_DIR\n");
    return 2;
  }
  try {
    CorpusWriter corpus{fs::path(argv[1])};
    const RgbdFrame frame = smallFrame(32, 24);
    lcmAndFrameSeeds(corpus, frame);
    poseAndStatusSeeds(corpus);
    commandSeeds(corpus);
    mapSeeds(corpus, frame);
    configSeeds(corpus);
    vocabularySeeds(corpus);
    const fs::path scratch = fs::path(argv[1]) / "scratch";
    sessionSeeds(corpus, scratch);
    fs::remove_all(scratch);
    tumSeeds(corpus);
    for (const auto& [target, count] : corpus.counts()) {
      std::printf("%-14s %3d seeds\n", target.c_str(), count);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "fuzz_seeds: %s\n", e.what());
    return 1;
  }
  return 0;
}
