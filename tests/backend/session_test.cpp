// Session files: a saved session reads back field for field; saves are atomic (a save killed at
// any point leaves the previous session current); damaged, truncated, foreign or newer sessions
// are refused naming the file and the problem, and no bytes crash the reader.

#include "slamd/backend/session.hpp"

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "scoped_temp_dir.hpp"
#include "slamd/common/file_io.hpp"

namespace slamd {
namespace {

namespace fs = std::filesystem;

SE3 randomPose(std::mt19937& rng, double translation_m) {
  std::uniform_real_distribution<double> angle(-1.0, 1.0);
  std::uniform_real_distribution<double> offset(-translation_m, translation_m);
  SE3 T = SE3::Identity();
  T.linear() = expSO3(Eigen::Vector3d(angle(rng), angle(rng), angle(rng)));
  T.translation() = Eigen::Vector3d(offset(rng), offset(rng), offset(rng));
  return T;
}

Matrix6d randomInformation(std::mt19937& rng) {
  std::uniform_real_distribution<double> value(-1.0, 1.0);
  Matrix6d A;
  for (int i = 0; i < 36; ++i) A(i) = value(rng);
  return A * A.transpose() + 10.0 * Matrix6d::Identity();
}

/// A keyframe with random features: ORB-like descriptors (CV_8U, 32 columns) or float ones
/// (CV_32F, 64 columns), every fourth point without depth (NaN).
std::shared_ptr<Keyframe> randomKeyframe(std::int64_t id, std::int64_t segment, int num_features,
                                         bool float_descriptors, bool with_gradients,
                                         std::mt19937& rng) {
  auto keyframe = std::make_shared<Keyframe>();
  keyframe->id = id;
  keyframe->segment = segment;
  keyframe->utime = 1'700'000'000'000'000 + id * 33'333;
  keyframe->frame_sequence = 10 * id + 3;
  keyframe->T_world_camera = randomPose(rng, 2.0);
  keyframe->intrinsics.fx = 517.3;
  keyframe->intrinsics.fy = 516.5;
  keyframe->intrinsics.cx = 318.6;
  keyframe->intrinsics.cy = 255.3;
  if (id % 2 == 1) {
    keyframe->intrinsics.distortion_model = DistortionModel::kPlumbBob;
    keyframe->intrinsics.distortion = {0.2624, -0.9531, -0.0054, 0.0026, 1.1633};
  }
  keyframe->median_depth_m = 1.25 + 0.01 * static_cast<double>(id);
  std::uniform_real_distribution<float> pixel(0.0f, 640.0f);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  FeatureSet& f = keyframe->features;
  f.descriptors =
      float_descriptors ? cv::Mat(num_features, 64, CV_32F) : cv::Mat(num_features, 32, CV_8UC1);
  cv::RNG cv_rng(static_cast<std::uint64_t>(rng()));
  if (float_descriptors) {
    cv_rng.fill(f.descriptors, cv::RNG::UNIFORM, -1.0, 1.0);
  } else {
    cv_rng.fill(f.descriptors, cv::RNG::UNIFORM, 0, 256);
  }
  for (int i = 0; i < num_features; ++i) {
    cv::KeyPoint k(pixel(rng), pixel(rng) * 0.75f, 31.0f, pixel(rng) * 0.5f, pixel(rng) * 1e-3f,
                   i % 4, i - 1);
    f.keypoints.push_back(k);
    f.pixels.emplace_back(static_cast<double>(k.pt.x) + unit(rng),
                          static_cast<double>(k.pt.y) + unit(rng));
    if (i % 4 == 3) {
      f.points.emplace_back(std::numeric_limits<double>::quiet_NaN(),
                            std::numeric_limits<double>::quiet_NaN(),
                            std::numeric_limits<double>::quiet_NaN());
    } else {
      f.points.emplace_back(unit(rng), unit(rng), 1.0 + unit(rng) * 0.5);
      ++f.num_with_depth;
    }
    f.scale.push_back(std::pow(1.2f, static_cast<float>(k.octave)));
    if (with_gradients) f.inverse_depth_gradient.emplace_back(unit(rng) * 1e-3, unit(rng) * 1e-3);
  }
  return keyframe;
}

/// A back end after two tracking segments: keyframes 0 1 2 (segment 0) and 4 5 (segment 1,
/// joined to 0), keyframe 3 culled into 2 and keyframe 6 into 3 (a chain), edges of every kind.
BackendSnapshot syntheticSnapshot(int num_features = 24) {
  std::mt19937 rng(42);
  BackendSnapshot s;
  const std::int64_t ids[] = {0, 1, 2, 4, 5};
  for (std::int64_t id : ids) {
    s.keyframes.push_back(randomKeyframe(id, id < 3 ? 0 : 1, num_features, id == 4, id != 1, rng));
    BackendSnapshot::Node node;
    node.id = id;
    node.T_world_camera = randomPose(rng, 3.0);
    node.fixed = id == 0;
    s.nodes.push_back(node);
  }
  auto edge = [&](std::int64_t from, std::int64_t to, EdgeKind kind) {
    PoseGraphEdge e;
    e.from_id = from;
    e.to_id = to;
    e.T_from_to = randomPose(rng, 0.5);
    e.information = randomInformation(rng);
    e.kind = kind;
    s.edges.push_back(e);
  };
  edge(0, 1, EdgeKind::kOdometry);
  edge(1, 2, EdgeKind::kOdometry);
  edge(4, 5, EdgeKind::kOdometry);
  edge(0, 2, EdgeKind::kLocal);
  edge(5, 0, EdgeKind::kLoop);
  edge(2, 4, EdgeKind::kRelocalization);
  s.culled.push_back({3, 2, randomPose(rng, 0.2), randomInformation(rng)});
  s.culled.push_back({6, 3, randomPose(rng, 0.2), randomInformation(rng)});
  for (std::int64_t id = 0; id <= 6; ++id) {
    s.records.push_back({id, id < 4 ? 0 : 1, 0.125 * static_cast<double>(id)});
  }
  s.segment_parents = {{1, 0}, {0, 0}};
  s.views = {{0, 1}, {0, 2}, {2, 5}};
  s.first_segment = 0;
  s.next_keyframe_id = 7;
  s.next_segment = 2;
  s.num_loops = 1;
  s.num_local_edges = 1;
  s.num_relocalizations = 1;
  return s;
}

std::vector<cv::Mat> randomBinaryDescriptors(int images, int per_image) {
  cv::RNG rng(7);
  std::vector<cv::Mat> out;
  for (int i = 0; i < images; ++i) {
    cv::Mat d(per_image, 32, CV_8UC1);
    rng.fill(d, cv::RNG::UNIFORM, 0, 256);
    out.push_back(d);
  }
  return out;
}

const Vocabulary& tinyVocabulary() {
  static const Vocabulary vocabulary = Vocabulary::train(randomBinaryDescriptors(6, 80), 4, 2, 1);
  return vocabulary;
}

std::string vocabularyBytes(const Vocabulary& vocabulary) {
  std::ostringstream out;
  vocabulary.write(out);
  return out.str();
}

const char* const kMapBytes = "not really an octree, but bytes the session must carry";
const char* const kConfigText = "backend:\n  loop_min_score: 0.05\n";

SessionInfo sessionInfo(const BackendSnapshot& snapshot) {
  SessionInfo info;
  info.created_utime = 1'712'345'678'901'234;
  info.created_by = "slamd test";
  info.camera = snapshot.keyframes.front()->intrinsics;
  summarizeSnapshot(snapshot, info);
  info.map_voxels = 1234;
  info.map_min_m = Eigen::Vector3d(-1.5, -2.0, -0.25);
  info.map_max_m = Eigen::Vector3d(3.0, 2.5, 2.0);
  return info;
}

/// Saves a whole session (with a map and a configuration) and returns the generation's name.
std::string saveSession(const fs::path& dir, const BackendSnapshot& snapshot) {
  SessionWriter writer(dir.string());
  writer.writeBackend(snapshot);
  writer.writeVocabulary(tinyVocabulary());
  std::ofstream(writer.pathFor(kSessionMapFile), std::ios::binary) << kMapBytes;
  writer.addFile(kSessionMapFile);
  writer.writeText(kSessionConfigFile, kConfigText);
  writer.commit(sessionInfo(snapshot));
  return fs::path(writer.generationPath()).filename().string();
}

std::string readText(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream out;
  out << in.rdbuf();
  return out.str();
}

void writeBytes(const fs::path& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
}

std::vector<std::uint8_t> fileBytes(const fs::path& path) {
  const std::string text = readText(path);
  return std::vector<std::uint8_t>(text.begin(), text.end());
}

std::vector<std::string> generationFolders(const fs::path& dir) {
  std::vector<std::string> names;
  for (const auto& entry : fs::directory_iterator(dir)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind("generation-", 0) == 0) names.push_back(name);
  }
  std::sort(names.begin(), names.end());
  return names;
}

/// The message loadSession() refuses `dir` with ("" when it loads).
std::string loadError(const fs::path& dir) {
  try {
    loadSession(dir.string());
  } catch (const SessionError& e) {
    return e.what();
  }
  return "";
}

bool samePose(const SE3& a, const SE3& b) { return a.matrix() == b.matrix(); }

bool sameDoubles(const double* a, const double* b, int count) {
  return std::memcmp(a, b, sizeof(double) * static_cast<std::size_t>(count)) == 0;  // NaN too
}

void expectSameKeyframe(const Keyframe& a, const Keyframe& b) {
  SCOPED_TRACE("keyframe " + std::to_string(a.id));
  EXPECT_EQ(a.id, b.id);
  EXPECT_EQ(a.segment, b.segment);
  EXPECT_EQ(a.utime, b.utime);
  EXPECT_EQ(a.frame_sequence, b.frame_sequence);
  EXPECT_TRUE(samePose(a.T_world_camera, b.T_world_camera));
  EXPECT_TRUE(a.intrinsics == b.intrinsics);
  EXPECT_EQ(a.median_depth_m, b.median_depth_m);
  EXPECT_EQ(b.frame, nullptr);
  const FeatureSet& fa = a.features;
  const FeatureSet& fb = b.features;
  EXPECT_EQ(fa.num_with_depth, fb.num_with_depth);
  ASSERT_EQ(fa.keypoints.size(), fb.keypoints.size());
  for (std::size_t i = 0; i < fa.keypoints.size(); ++i) {
    const cv::KeyPoint& ka = fa.keypoints[i];
    const cv::KeyPoint& kb = fb.keypoints[i];
    EXPECT_EQ(ka.pt, kb.pt);
    EXPECT_EQ(ka.size, kb.size);
    EXPECT_EQ(ka.angle, kb.angle);
    EXPECT_EQ(ka.response, kb.response);
    EXPECT_EQ(ka.octave, kb.octave);
    EXPECT_EQ(ka.class_id, kb.class_id);
  }
  ASSERT_EQ(fa.descriptors.type(), fb.descriptors.type());
  ASSERT_EQ(fa.descriptors.size(), fb.descriptors.size());
  EXPECT_EQ(cv::norm(fa.descriptors, fb.descriptors, cv::NORM_INF), 0.0);
  ASSERT_EQ(fa.pixels.size(), fb.pixels.size());
  for (std::size_t i = 0; i < fa.pixels.size(); ++i) EXPECT_EQ(fa.pixels[i], fb.pixels[i]);
  ASSERT_EQ(fa.points.size(), fb.points.size());
  for (std::size_t i = 0; i < fa.points.size(); ++i) {
    EXPECT_TRUE(sameDoubles(fa.points[i].data(), fb.points[i].data(), 3)) << "point " << i;
    EXPECT_EQ(fa.hasDepth(i), fb.hasDepth(i));
  }
  EXPECT_EQ(fa.scale, fb.scale);
  ASSERT_EQ(fa.inverse_depth_gradient.size(), fb.inverse_depth_gradient.size());
  for (std::size_t i = 0; i < fa.inverse_depth_gradient.size(); ++i) {
    EXPECT_EQ(fa.inverse_depth_gradient[i], fb.inverse_depth_gradient[i]);
  }
  EXPECT_TRUE(fb.gray.empty());
  EXPECT_TRUE(fb.align_gray.empty());
}

void expectSameSnapshot(const BackendSnapshot& a, const BackendSnapshot& b) {
  ASSERT_EQ(a.keyframes.size(), b.keyframes.size());
  for (std::size_t i = 0; i < a.keyframes.size(); ++i) {
    expectSameKeyframe(*a.keyframes[i], *b.keyframes[i]);
  }
  ASSERT_EQ(a.nodes.size(), b.nodes.size());
  for (std::size_t i = 0; i < a.nodes.size(); ++i) {
    EXPECT_EQ(a.nodes[i].id, b.nodes[i].id);
    EXPECT_TRUE(samePose(a.nodes[i].T_world_camera, b.nodes[i].T_world_camera));
    EXPECT_EQ(a.nodes[i].fixed, b.nodes[i].fixed);
  }
  ASSERT_EQ(a.edges.size(), b.edges.size());
  for (std::size_t i = 0; i < a.edges.size(); ++i) {
    EXPECT_EQ(a.edges[i].from_id, b.edges[i].from_id);
    EXPECT_EQ(a.edges[i].to_id, b.edges[i].to_id);
    EXPECT_TRUE(samePose(a.edges[i].T_from_to, b.edges[i].T_from_to));
    EXPECT_EQ(a.edges[i].information, b.edges[i].information);
    EXPECT_EQ(a.edges[i].kind, b.edges[i].kind);
  }
  ASSERT_EQ(a.culled.size(), b.culled.size());
  for (std::size_t i = 0; i < a.culled.size(); ++i) {
    EXPECT_EQ(a.culled[i].id, b.culled[i].id);
    EXPECT_EQ(a.culled[i].anchor_id, b.culled[i].anchor_id);
    EXPECT_TRUE(samePose(a.culled[i].T_anchor_keyframe, b.culled[i].T_anchor_keyframe));
    EXPECT_EQ(a.culled[i].information, b.culled[i].information);
  }
  ASSERT_EQ(a.records.size(), b.records.size());
  for (std::size_t i = 0; i < a.records.size(); ++i) {
    EXPECT_EQ(a.records[i].id, b.records[i].id);
    EXPECT_EQ(a.records[i].segment, b.records[i].segment);
    EXPECT_EQ(a.records[i].path_length_m, b.records[i].path_length_m);
  }
  EXPECT_EQ(a.segment_parents, b.segment_parents);
  EXPECT_EQ(a.views, b.views);
  EXPECT_EQ(a.first_segment, b.first_segment);
  EXPECT_EQ(a.next_keyframe_id, b.next_keyframe_id);
  EXPECT_EQ(a.next_segment, b.next_segment);
  EXPECT_EQ(a.num_loops, b.num_loops);
  EXPECT_EQ(a.num_local_edges, b.num_local_edges);
  EXPECT_EQ(a.num_relocalizations, b.num_relocalizations);
}

/// Replaces the manifest's first line and recomputes its checksum line, as a newer (or older)
/// slamd would have written it.
void rewriteManifestVersion(const fs::path& manifest_path, const std::string& first_line) {
  std::string text = readText(manifest_path);
  const std::size_t first_end = text.find('\n');
  text = first_line + text.substr(first_end);
  const std::size_t checksum_start = text.rfind("checksum ");
  text.resize(checksum_start);
  char hex[17];
  std::snprintf(hex, sizeof(hex), "%016llx",
                static_cast<unsigned long long>(fnv1a64(text.data(), text.size())));
  text += std::string("checksum ") + hex + "\n";
  writeBytes(manifest_path, text);
}

TEST(SessionChecksum, Fnv1a64MatchesTheReferenceValuesAndChains) {
  EXPECT_EQ(fnv1a64("", 0), 0xcbf29ce484222325ull);
  EXPECT_EQ(fnv1a64("a", 1), 0xaf63dc4c8601ec8cull);
  EXPECT_EQ(fnv1a64("foobar", 6), 0x85944171f73967e8ull);
  EXPECT_EQ(fnv1a64("bar", 3, fnv1a64("foo", 3)), fnv1a64("foobar", 6));
}

TEST(Session, ARoundTripKeepsEveryField) {
  const test::ScopedTempDir dir("session");
  const BackendSnapshot snapshot = syntheticSnapshot();
  const std::string generation = saveSession(dir, snapshot);
  EXPECT_EQ(generation, "generation-000001");
  EXPECT_EQ(readText(dir / kSessionCurrentFile), generation + "\n");

  const Session session = loadSession(dir.string());
  EXPECT_EQ(session.dir, dir.string());
  EXPECT_EQ(session.generation_path, (dir / generation).string());
  expectSameSnapshot(snapshot, session.backend);

  ASSERT_NE(session.vocabulary, nullptr);
  EXPECT_EQ(session.vocabulary->numWords(), tinyVocabulary().numWords());
  EXPECT_EQ(vocabularyBytes(*session.vocabulary), vocabularyBytes(tinyVocabulary()));

  EXPECT_EQ(session.map_path, (dir / generation / kSessionMapFile).string());
  EXPECT_EQ(readText(session.map_path), kMapBytes);
  EXPECT_EQ(session.config_yaml, kConfigText);

  const SessionInfo expected = sessionInfo(snapshot);
  const SessionInfo& info = session.info;
  EXPECT_EQ(info.format_version, kSessionFormatVersion);
  EXPECT_EQ(info.created_utime, expected.created_utime);
  EXPECT_EQ(info.created_by, "slamd test");
  EXPECT_EQ(info.generation, generation);
  EXPECT_TRUE(info.camera == expected.camera);
  EXPECT_EQ(info.keyframes, 5);
  EXPECT_EQ(info.culled_keyframes, 2);
  EXPECT_EQ(info.landmarks, expected.landmarks);
  EXPECT_EQ(info.edges, 6);
  EXPECT_EQ(info.segments, 2);
  EXPECT_EQ(info.loops, 1);
  EXPECT_EQ(info.map_voxels, 1234);
  EXPECT_EQ(info.keyframe_min_m, expected.keyframe_min_m);
  EXPECT_EQ(info.keyframe_max_m, expected.keyframe_max_m);
  EXPECT_EQ(info.map_min_m, expected.map_min_m);
  EXPECT_EQ(info.map_max_m, expected.map_max_m);
  std::vector<std::string> names;
  for (const auto& [name, size] : info.files) {
    names.push_back(name);
    EXPECT_EQ(size, fs::file_size(dir / generation / name)) << name;
  }
  EXPECT_EQ(names, (std::vector<std::string>{kSessionKeyframesFile, kSessionGraphFile,
                                             kSessionVocabularyFile, kSessionMapFile,
                                             kSessionConfigFile}));
}

TEST(Session, ASessionWithoutMapOrConfigurationHasNeither) {
  const test::ScopedTempDir dir("session");
  const BackendSnapshot snapshot = syntheticSnapshot();
  {
    SessionWriter writer(dir.string());
    writer.writeBackend(snapshot);
    writer.writeVocabulary(tinyVocabulary());
    writer.commit(sessionInfo(snapshot));
  }
  const Session session = loadSession(dir.string());
  EXPECT_TRUE(session.map_path.empty());
  EXPECT_TRUE(session.config_yaml.empty());
  EXPECT_EQ(session.backend.keyframes.size(), 5u);
}

TEST(Session, AnEmptyBackendRoundTrips) {
  const test::ScopedTempDir dir("session");
  BackendSnapshot empty;
  SessionInfo info;
  summarizeSnapshot(empty, info);
  EXPECT_EQ(info.keyframes, 0);
  EXPECT_EQ(info.segments, 0);
  {
    SessionWriter writer(dir.string());
    writer.writeBackend(empty);
    writer.writeVocabulary(tinyVocabulary());
    writer.commit(info);
  }
  const Session session = loadSession(dir.string());
  EXPECT_TRUE(session.backend.keyframes.empty());
  EXPECT_TRUE(session.backend.nodes.empty());
  EXPECT_EQ(session.info.keyframes, 0);
}

TEST(Session, ASecondSaveReplacesTheFirstAndRemovesItsGeneration) {
  const test::ScopedTempDir dir("session");
  BackendSnapshot snapshot = syntheticSnapshot();
  ASSERT_EQ(saveSession(dir, snapshot), "generation-000001");
  snapshot.num_loops = 5;
  snapshot.nodes[2].T_world_camera.translation().x() += 1.0;
  ASSERT_EQ(saveSession(dir, snapshot), "generation-000002");
  EXPECT_EQ(generationFolders(dir), std::vector<std::string>{"generation-000002"});
  const Session session = loadSession(dir.string());
  EXPECT_EQ(session.info.generation, "generation-000002");
  expectSameSnapshot(snapshot, session.backend);
  EXPECT_FALSE(fs::exists(dir / "CURRENT.tmp"));
}

TEST(Session, AWriterDestroyedWithoutCommitLeavesThePreviousSessionCurrent) {
  const test::ScopedTempDir dir("session");
  const BackendSnapshot snapshot = syntheticSnapshot();
  saveSession(dir, snapshot);
  {
    SessionWriter writer(dir.string());
    EXPECT_EQ(fs::path(writer.generationPath()).filename(), "generation-000002");
    writer.writeBackend(syntheticSnapshot(3));
    EXPECT_TRUE(fs::exists(fs::path(writer.generationPath()) / kSessionKeyframesFile));
    // Abandoned: no commit.
  }
  EXPECT_EQ(generationFolders(dir), std::vector<std::string>{"generation-000001"});
  EXPECT_EQ(readText(dir / kSessionCurrentFile), "generation-000001\n");
  const Session session = loadSession(dir.string());
  expectSameSnapshot(snapshot, session.backend);
}

TEST(Session, AnUnfinishedGenerationLeftByAKilledSaveIsIgnoredThenRemovedByTheNextSave) {
  const test::ScopedTempDir dir("session");
  const BackendSnapshot snapshot = syntheticSnapshot();
  saveSession(dir, snapshot);
  // What kill -9 during a save leaves: a newer folder with some files, half of one, a temporary
  // file, no manifest, CURRENT untouched.
  const fs::path leftover = dir / "generation-000005";
  fs::create_directory(leftover);
  fs::copy_file(dir / "generation-000001" / kSessionGraphFile, leftover / kSessionGraphFile);
  const std::string keyframes = readText(dir / "generation-000001" / kSessionKeyframesFile);
  writeBytes(leftover / kSessionKeyframesFile, keyframes.substr(0, keyframes.size() / 2));
  writeBytes(leftover / "vocabulary.voc.tmp", "partial");

  const Session session = loadSession(dir.string());
  EXPECT_EQ(session.info.generation, "generation-000001");
  expectSameSnapshot(snapshot, session.backend);

  {
    SessionWriter writer(dir.string());
    EXPECT_FALSE(fs::exists(leftover));
    // Numbers are never reused, even a leftover's.
    EXPECT_EQ(fs::path(writer.generationPath()).filename(), "generation-000006");
    EXPECT_EQ(generationFolders(dir),
              (std::vector<std::string>{"generation-000001", "generation-000006"}));
  }
  EXPECT_EQ(generationFolders(dir), std::vector<std::string>{"generation-000001"});
  EXPECT_EQ(loadError(dir), "");
}

TEST(Session, AFirstSaveKilledBeforeCurrentLeavesNoSessionAndIsRemoved) {
  const test::ScopedTempDir dir("session");
  fs::create_directory(dir / "generation-000001");
  writeBytes(dir / "generation-000001" / kSessionKeyframesFile, "half");
  EXPECT_NE(loadError(dir).find(kSessionCurrentFile), std::string::npos);
  saveSession(dir, syntheticSnapshot());
  EXPECT_EQ(generationFolders(dir), std::vector<std::string>{"generation-000002"});
  EXPECT_EQ(loadError(dir), "");
}

TEST(Session, ACorruptByteInAnyFileIsRefusedNamingTheFile) {
  const test::ScopedTempDir source("session");
  const std::string generation = saveSession(source, syntheticSnapshot());
  std::vector<fs::path> files = {kSessionCurrentFile};
  for (const char* name : {kSessionManifestFile, kSessionKeyframesFile, kSessionGraphFile,
                           kSessionVocabularyFile, kSessionMapFile, kSessionConfigFile}) {
    files.push_back(fs::path(generation) / name);
  }
  for (const fs::path& file : files) {
    for (const double where : {0.0, 0.5, 0.99}) {
      const test::ScopedTempDir dir("session");
      fs::copy(source.path(), dir.path(), fs::copy_options::recursive);
      std::string bytes = readText(dir / file);
      const auto at = static_cast<std::size_t>(where * static_cast<double>(bytes.size() - 1));
      bytes[at] = static_cast<char>(bytes[at] ^ 0x80);
      writeBytes(dir / file, bytes);
      const std::string error = loadError(dir);
      EXPECT_NE(error.find((dir / file).string()), std::string::npos)
          << file << " byte " << at << ": '" << error << "'";
    }
  }
}

TEST(Session, ATruncatedFileIsRefusedNamingTheFile) {
  const test::ScopedTempDir source("session");
  const std::string generation = saveSession(source, syntheticSnapshot());
  for (const char* name : {kSessionManifestFile, kSessionKeyframesFile, kSessionGraphFile,
                           kSessionVocabularyFile, kSessionMapFile, kSessionConfigFile}) {
    const test::ScopedTempDir dir("session");
    fs::copy(source.path(), dir.path(), fs::copy_options::recursive);
    const fs::path path = dir / generation / name;
    fs::resize_file(path, fs::file_size(path) - 5);
    const std::string error = loadError(dir);
    EXPECT_NE(error.find(path.string()), std::string::npos) << name << ": '" << error << "'";
    if (std::string(name) != kSessionManifestFile) {
      EXPECT_NE(error.find("truncated or replaced"), std::string::npos) << error;
    }
  }
}

TEST(Session, AMissingFileIsRefusedNamingIt) {
  const test::ScopedTempDir source("session");
  const std::string generation = saveSession(source, syntheticSnapshot());
  for (const char* name : {kSessionManifestFile, kSessionKeyframesFile, kSessionGraphFile,
                           kSessionVocabularyFile, kSessionMapFile}) {
    const test::ScopedTempDir dir("session");
    fs::copy(source.path(), dir.path(), fs::copy_options::recursive);
    fs::remove(dir / generation / name);
    const std::string error = loadError(dir);
    EXPECT_EQ(error, "session " + (dir / generation / name).string() + ": missing");
  }
}

TEST(Session, ASessionOfANewerFormatIsRefusedNamingBothVersions) {
  const test::ScopedTempDir dir("session");
  const std::string generation = saveSession(dir, syntheticSnapshot());
  const fs::path manifest = dir / generation / kSessionManifestFile;
  rewriteManifestVersion(manifest, "slamd-session " + std::to_string(kSessionFormatVersion + 1));
  const std::string expected = "session " + manifest.string() +
                               ": the session was made by a newer slamd (format " +
                               std::to_string(kSessionFormatVersion + 1) + ", this slamd reads " +
                               std::to_string(kSessionFormatVersion) + ")";
  EXPECT_EQ(loadError(dir), expected);
  try {
    readSessionInfo(dir.string());
    ADD_FAILURE() << "readSessionInfo accepted a newer format";
  } catch (const SessionError& e) {
    EXPECT_EQ(std::string(e.what()), expected);
  }
}

TEST(Session, ASessionOfAnOlderFormatOrAForeignManifestIsRefused) {
  const test::ScopedTempDir dir("session");
  const std::string generation = saveSession(dir, syntheticSnapshot());
  const fs::path manifest = dir / generation / kSessionManifestFile;
  rewriteManifestVersion(manifest, "slamd-session 0");
  EXPECT_NE(loadError(dir).find("format 0, older than this slamd reads"), std::string::npos)
      << loadError(dir);
  rewriteManifestVersion(manifest, "some-other-tool 1");
  EXPECT_NE(loadError(dir).find("not a slamd session manifest"), std::string::npos)
      << loadError(dir);
}

// Format 1 (before the views were saved) still loads, without views. Made from a format-2 save:
// the same layout except the views at the end of graph.bin.
TEST(Session, ASessionOfFormatOneLoadsWithoutViews) {
  const test::ScopedTempDir dir("session");
  const BackendSnapshot snapshot = syntheticSnapshot();
  const std::string generation = saveSession(dir, snapshot);
  const fs::path folder = dir / generation;
  std::string manifest = readText(folder / kSessionManifestFile);
  for (const char* name : {kSessionKeyframesFile, kSessionGraphFile}) {
    std::string bytes = readText(folder / name);
    const std::uint32_t version = 1;
    std::memcpy(&bytes[8], &version, sizeof(version));  // after the magic; little-endian host
    if (std::string(name) == kSessionGraphFile) {
      bytes.resize(bytes.size() - 8 - 16 * snapshot.views.size());
    }
    writeBytes(folder / name, bytes);
    // Its manifest line: file <name> <bytes> <fnv1a64>.
    const std::string key = std::string("file ") + name + " ";
    const std::size_t start = manifest.find(key);
    ASSERT_NE(start, std::string::npos);
    const std::size_t end = manifest.find('\n', start);
    char hex[17];
    std::snprintf(hex, sizeof(hex), "%016llx",
                  static_cast<unsigned long long>(fnv1a64(bytes.data(), bytes.size())));
    manifest.replace(start, end - start, key + std::to_string(bytes.size()) + " " + hex);
  }
  writeBytes(folder / kSessionManifestFile, manifest);
  rewriteManifestVersion(folder / kSessionManifestFile, "slamd-session 1");

  const Session session = loadSession(dir.string());
  EXPECT_EQ(session.info.format_version, 1u);
  EXPECT_TRUE(session.backend.views.empty());
  BackendSnapshot without_views = snapshot;
  without_views.views.clear();
  expectSameSnapshot(without_views, session.backend);
}

// A key this slamd does not know (information a later slamd of the same format added) is skipped.
TEST(Session, AManifestLineWithAnUnknownKeyIsSkipped) {
  const test::ScopedTempDir dir("session");
  const std::string generation = saveSession(dir, syntheticSnapshot());
  const fs::path manifest = dir / generation / kSessionManifestFile;
  std::string text = readText(manifest);
  text.insert(text.find('\n') + 1, "robot_name turtle 7\n");
  writeBytes(manifest, text);
  rewriteManifestVersion(manifest, "slamd-session " + std::to_string(kSessionFormatVersion));
  EXPECT_EQ(loadError(dir), "");
}

TEST(Session, AManifestWithAValidChecksumButAWrongFileSizeIsRefused) {
  const test::ScopedTempDir dir("session");
  const std::string generation = saveSession(dir, syntheticSnapshot());
  const fs::path manifest = dir / generation / kSessionManifestFile;
  std::string text = readText(manifest);
  const std::string size = std::to_string(fs::file_size(dir / generation / kSessionGraphFile));
  const std::size_t at = text.find(std::string("file graph.bin ") + size);
  ASSERT_NE(at, std::string::npos);
  text.replace(at + 15, size.size(), std::to_string(std::stoull(size) + 1));
  writeBytes(manifest, text);
  rewriteManifestVersion(manifest, "slamd-session " + std::to_string(kSessionFormatVersion));
  EXPECT_NE(loadError(dir).find("graph.bin: " + size + " bytes where manifest.txt lists"),
            std::string::npos)
      << loadError(dir);
}

TEST(Session, AMissingOrForeignCurrentIsRefusedNamingIt) {
  const test::ScopedTempDir dir("session");
  EXPECT_EQ(loadError(dir), "session " + (dir / kSessionCurrentFile).string() +
                                ": missing (not a session folder, or no save of it completed)");
  EXPECT_THROW(readSessionInfo(dir.string()), SessionError);
  saveSession(dir, syntheticSnapshot());
  for (const std::string current : {"../generation-000001\n", "generation-000001/..\n", "/etc\n",
                                    "generation-\n", "generation-00000x\n", "\n"}) {
    writeBytes(dir / kSessionCurrentFile, current);
    const std::string error = loadError(dir);
    EXPECT_NE(error.find((dir / kSessionCurrentFile).string() + ": does not name a generation"),
              std::string::npos)
        << current << ": " << error;
  }
  writeBytes(dir / kSessionCurrentFile, "generation-000009\n");
  EXPECT_NE(loadError(dir).find((dir / "generation-000009" / kSessionManifestFile).string() +
                                ": missing"),
            std::string::npos)
      << loadError(dir);
}

TEST(Session, ReadSessionInfoReadsOnlyTheManifest) {
  const test::ScopedTempDir dir("session");
  const BackendSnapshot snapshot = syntheticSnapshot();
  const std::string generation = saveSession(dir, snapshot);
  // A damaged keyframes.bin is loadSession's business, not readSessionInfo's.
  writeBytes(dir / generation / kSessionKeyframesFile, "damaged");
  const SessionInfo info = readSessionInfo(dir.string());
  int landmarks = 0;
  for (const KeyframePtr& keyframe : snapshot.keyframes)
    landmarks += keyframe->features.num_with_depth;
  EXPECT_EQ(info.generation, generation);
  EXPECT_EQ(info.keyframes, 5);
  EXPECT_EQ(info.culled_keyframes, 2);
  EXPECT_EQ(info.landmarks, landmarks);
  EXPECT_EQ(info.edges, 6);
  EXPECT_EQ(info.segments, 2);
  EXPECT_EQ(info.loops, 1);
  EXPECT_EQ(info.map_voxels, 1234);
  EXPECT_EQ(info.files.size(), 5u);
  EXPECT_NE(loadError(dir).find(kSessionKeyframesFile), std::string::npos);
}

TEST(Session, SummarizeSnapshotCountsLandmarksSegmentsAndTheKeyframeExtent) {
  BackendSnapshot snapshot = syntheticSnapshot();
  for (std::size_t i = 0; i < snapshot.nodes.size(); ++i) {
    snapshot.nodes[i].T_world_camera.translation() =
        Eigen::Vector3d(static_cast<double>(i), -2.0 * static_cast<double>(i), 0.5);
  }
  SessionInfo info;
  summarizeSnapshot(snapshot, info);
  // 24 features per keyframe, every fourth without depth.
  EXPECT_EQ(info.landmarks, 5 * 18);
  EXPECT_EQ(info.keyframes, 5);
  EXPECT_EQ(info.culled_keyframes, 2);
  EXPECT_EQ(info.edges, 6);
  EXPECT_EQ(info.segments, 2);
  EXPECT_EQ(info.loops, 1);
  EXPECT_EQ(info.keyframe_min_m, Eigen::Vector3d(0.0, -8.0, 0.5));
  EXPECT_EQ(info.keyframe_max_m, Eigen::Vector3d(4.0, 0.0, 0.5));
}

TEST(Session, CameraMismatchIsEmptyForTheSameCameraAndSaysWhatDiffers) {
  CameraIntrinsics camera;
  camera.fx = 517.3;
  EXPECT_EQ(cameraMismatch(camera, camera), "");
  CameraIntrinsics close = camera;
  close.fx += 0.3;
  close.cy -= 0.4;
  EXPECT_EQ(cameraMismatch(camera, close), "");

  CameraIntrinsics other_focal = camera;
  other_focal.fx += 2.0;
  EXPECT_EQ(cameraMismatch(camera, other_focal), "fx 517.3 px in the session, 519.3 px now");

  EXPECT_EQ(cameraMismatch(camera, camera.scaled(320, 240)),
            "image size 640x480 in the session, 320x240 now; fx 517.3 px in the session, 258.65 "
            "px now; fy 525 px in the session, 262.5 px now; cx 319.5 px in the session, 159.5 px "
            "now; cy 239.5 px in the session, 119.5 px now");

  CameraIntrinsics distorted = camera;
  distorted.distortion_model = DistortionModel::kPlumbBob;
  distorted.distortion = {0.1, 0.0, 0.0, 0.0, 0.0};
  EXPECT_NE(cameraMismatch(camera, distorted).find("distortion model"), std::string::npos);
  CameraIntrinsics distorted_more = distorted;
  distorted_more.distortion[0] = 0.2;
  EXPECT_NE(cameraMismatch(distorted, distorted_more).find("distortion coefficients"),
            std::string::npos);
}

TEST(SessionWriter, RefusesAnInconsistentSnapshotAndSavesNothing) {
  struct Case {
    const char* name;
    void (*damage)(BackendSnapshot&);
    const char* expected;
  };
  const Case cases[] = {
      {"edge to a missing node", [](BackendSnapshot& s) { s.edges[1].to_id = 3; },
       "names a missing node"},
      {"node without keyframe", [](BackendSnapshot& s) { s.keyframes.pop_back(); },
       "has no keyframe in keyframes.bin"},
      {"keyframe without node", [](BackendSnapshot& s) { s.nodes.pop_back(); }, "is not a node"},
      {"duplicate keyframe", [](BackendSnapshot& s) { s.keyframes.push_back(s.keyframes.front()); },
       "twice"},
      {"culled anchors in a cycle", [](BackendSnapshot& s) { s.culled[0].anchor_id = 6; },
       "form a cycle"},
      {"culled anchor unknown", [](BackendSnapshot& s) { s.culled[1].anchor_id = 40; },
       "neither a node nor"},
      {"culled keyframe that is a node", [](BackendSnapshot& s) { s.culled[0].id = 4; },
       "is also a node"},
      {"segment parents in a cycle",
       [](BackendSnapshot& s) {
         s.segment_parents = {{0, 1}, {1, 0}};
       },
       "form a cycle"},
      {"next keyframe id reused", [](BackendSnapshot& s) { s.next_keyframe_id = 6; },
       "next keyframe id 6"},
      {"next segment reused", [](BackendSnapshot& s) { s.next_segment = 1; }, "next segment 1"},
      {"record of nothing", [](BackendSnapshot& s) { s.records[2].id = 77; }, "no such keyframe"},
      {"view of a culled keyframe",
       [](BackendSnapshot& s) {
         s.views[1] = {2, 3};
       },
       "view 2 - 3: not two keyframes of the graph"},
      {"view higher id first",
       [](BackendSnapshot& s) {
         s.views[1] = {2, 0};
       },
       "not lower id first"},
      {"view twice", [](BackendSnapshot& s) { s.views[1] = s.views[0]; }, "view 0 - 1 twice"},
      {"pose not finite",
       [](BackendSnapshot& s) {
         s.nodes[1].T_world_camera.translation().x() = std::numeric_limits<double>::infinity();
       },
       "not a finite rigid transform"},
      {"unknown edge kind", [](BackendSnapshot& s) { s.edges[0].kind = static_cast<EdgeKind>(9); },
       "unknown kind 9"},
      {"points missing",
       [](BackendSnapshot& s) {
         auto keyframe = std::make_shared<Keyframe>(*s.keyframes[2]);
         keyframe->features.points.pop_back();
         s.keyframes[2] = keyframe;
       },
       "23 points for 24 keypoints"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const test::ScopedTempDir dir("session");
    BackendSnapshot snapshot = syntheticSnapshot();
    c.damage(snapshot);
    SessionWriter writer(dir.string());
    try {
      writer.writeBackend(snapshot);
      ADD_FAILURE() << "saved";
    } catch (const SessionError& e) {
      EXPECT_NE(std::string(e.what()).find(c.expected), std::string::npos) << e.what();
    }
    EXPECT_FALSE(fs::exists(fs::path(writer.generationPath()) / kSessionKeyframesFile));
    EXPECT_THROW(writer.commit(SessionInfo()), SessionError);
    EXPECT_FALSE(fs::exists(dir / kSessionCurrentFile));
  }
}

TEST(SessionWriter, RefusesFileNamesOutsideTheGeneration) {
  const test::ScopedTempDir dir("session");
  SessionWriter writer(dir.string());
  for (const std::string name : {"../map.ot", "a/b", "", "..", "two words", kSessionManifestFile}) {
    EXPECT_THROW(writer.pathFor(name), SessionError) << name;
  }
  EXPECT_THROW(writer.addFile("absent.ot"), SessionError);
}

class SessionParse : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::string generation = saveSession(dir_, syntheticSnapshot(6));
    keyframes_ = fileBytes(dir_ / generation / kSessionKeyframesFile);
    graph_ = fileBytes(dir_ / generation / kSessionGraphFile);
  }
  /// "" when the bytes parse, else the SessionError's message; any other exception fails.
  std::string parseError(const std::vector<std::uint8_t>& keyframes,
                         const std::vector<std::uint8_t>& graph) {
    try {
      parseBackendFiles(keyframes, graph, "/s/generation-000001");
    } catch (const SessionError& e) {
      return e.what();
    } catch (const std::exception& e) {
      ADD_FAILURE() << "not a SessionError: " << e.what();
      return e.what();
    }
    return "";
  }

  test::ScopedTempDir dir_{"session"};
  std::vector<std::uint8_t> keyframes_;
  std::vector<std::uint8_t> graph_;
};

TEST_F(SessionParse, TheSavedFilesParse) {
  EXPECT_EQ(parseError(keyframes_, graph_), "");
  expectSameSnapshot(parseBackendFiles(keyframes_, graph_, "x"), syntheticSnapshot(6));
}

TEST_F(SessionParse, EveryTruncationIsRefusedNamingTheFile) {
  for (std::size_t length = 0; length < keyframes_.size(); ++length) {
    const std::vector<std::uint8_t> cut(keyframes_.begin(),
                                        keyframes_.begin() + static_cast<std::ptrdiff_t>(length));
    const std::string error = parseError(cut, graph_);
    ASSERT_EQ(error.rfind("session /s/generation-000001/keyframes.bin: ", 0), 0u)
        << "length " << length << ": '" << error << "'";
  }
  for (std::size_t length = 0; length < graph_.size(); ++length) {
    const std::vector<std::uint8_t> cut(graph_.begin(),
                                        graph_.begin() + static_cast<std::ptrdiff_t>(length));
    const std::string error = parseError(keyframes_, cut);
    ASSERT_EQ(error.rfind("session /s/generation-000001/graph.bin: ", 0), 0u)
        << "length " << length << ": '" << error << "'";
  }
}

TEST_F(SessionParse, ATruncationNamesTheRecordItCut) {
  // graph.bin: magic, version, six counters, the nodes, then the edges.
  const std::size_t nodes_end = 8 + 4 + 6 * 8 + 8 + 5 * (8 + 96 + 1);
  const std::size_t edge_bytes = 8 + 8 + 96 + 288 + 1;
  std::vector<std::uint8_t> cut(
      graph_.begin(),
      graph_.begin() + static_cast<std::ptrdiff_t>(nodes_end + 8 + edge_bytes + 20));
  EXPECT_EQ(parseError(keyframes_, cut),
            "session /s/generation-000001/graph.bin: truncated (edge 2 of 6)");
  std::vector<std::uint8_t> kind = graph_;
  kind[nodes_end + 8 + edge_bytes - 1] = 7;  // the first edge's kind
  EXPECT_EQ(parseError(keyframes_, kind),
            "session /s/generation-000001/graph.bin: edge 1 of 6: unknown kind 7");
  std::vector<std::uint8_t> extra = keyframes_;
  extra.push_back(0);
  EXPECT_EQ(parseError(extra, graph_),
            "session /s/generation-000001/keyframes.bin: 1 unexpected bytes after the last "
            "record");
}

TEST_F(SessionParse, HugeCountsAreRefusedBeforeAllocating) {
  // The keyframe count right after the magic and version, then the first keyframe's keypoint
  // count after its fixed fields.
  for (const std::size_t at : {std::size_t{12}, std::size_t{12 + 8 + 224}}) {
    std::vector<std::uint8_t> bytes = keyframes_;
    for (std::size_t i = 0; i < 8; ++i) bytes[at + i] = 0xff;
    bytes[at + 7] = 0x0f;
    const std::string error = parseError(bytes, graph_);
    EXPECT_NE(error.find("truncated"), std::string::npos) << at << ": " << error;
  }
}

TEST_F(SessionParse, RandomBytesAndDamagedFilesNeverCrash) {
  std::mt19937 rng(42);
  int accepted = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    std::vector<std::uint8_t> keyframes = keyframes_;
    std::vector<std::uint8_t> graph = graph_;
    std::vector<std::uint8_t>& target = trial % 2 == 0 ? keyframes : graph;
    const int flips = 1 + static_cast<int>(rng() % 4);
    for (int i = 0; i < flips; ++i) {
      target[rng() % target.size()] = static_cast<std::uint8_t>(rng());
    }
    if (parseError(keyframes, graph).empty()) ++accepted;
  }
  // Damage to feature values (a keypoint's response, a descriptor bit) still parses; damage to
  // structure does not.
  EXPECT_LT(accepted, 3000);
  for (int trial = 0; trial < 500; ++trial) {
    std::vector<std::uint8_t> noise(rng() % 4096);
    for (std::uint8_t& b : noise) b = static_cast<std::uint8_t>(rng());
    // With a valid magic and version too, so the counts are read.
    std::vector<std::uint8_t> headed = noise;
    if (headed.size() >= 12) std::copy(keyframes_.begin(), keyframes_.begin() + 12, headed.begin());
    EXPECT_NE(parseError(noise, graph_), "");
    EXPECT_NE(parseError(headed, graph_), "");
    std::vector<std::uint8_t> graph_headed = noise;
    if (graph_headed.size() >= 12)
      std::copy(graph_.begin(), graph_.begin() + 12, graph_headed.begin());
    EXPECT_NE(parseError(keyframes_, graph_headed), "");
  }
}

}  // namespace
}  // namespace slamd
