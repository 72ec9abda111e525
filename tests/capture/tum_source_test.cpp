#include "slamd/capture/tum_source.hpp"

#include <cmath>
#include <random>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "slamd/capture/tum_dataset.hpp"
#include "test_data.hpp"
#include "tum_fixture.hpp"

namespace slamd {
namespace {

// associate.py written out literally (quadratic, list removal), as the reference.
std::vector<std::pair<double, double>> referenceAssociate(std::vector<double> first,
                                                          std::vector<double> second,
                                                          double max_difference) {
  std::vector<std::tuple<double, double, double>> potential;
  for (double a : first) {
    for (double b : second) {
      if (std::abs(a - b) < max_difference) potential.emplace_back(std::abs(a - b), a, b);
    }
  }
  std::sort(potential.begin(), potential.end());
  std::vector<std::pair<double, double>> matches;
  for (const auto& [diff, a, b] : potential) {
    auto ia = std::find(first.begin(), first.end(), a);
    auto ib = std::find(second.begin(), second.end(), b);
    if (ia != first.end() && ib != second.end()) {
      first.erase(ia);
      second.erase(ib);
      matches.emplace_back(a, b);
    }
  }
  std::sort(matches.begin(), matches.end());
  return matches;
}

TEST(TumFileList, IgnoresCommentsAndAcceptsAnyWhitespaceAndCommas) {
  const TumFileList list = parseTumFileList(
      "# colour images\n"
      "   # indented comment\n"
      "\n"
      "1.5 rgb/a.png\n"
      "2.0\t\trgb/b.png  \r\n"
      "2.5,rgb/c.png\n"
      "3.0\n"  // one field: ignored, as associate.py does
      "  3.5   rgb/d.png extra fields\n",
      "rgb.txt");
  ASSERT_EQ(list.entries.size(), 4u);
  EXPECT_TRUE(list.rejected.empty());
  EXPECT_DOUBLE_EQ(list.entries[1].timestamp_s, 2.0);
  EXPECT_EQ(list.entries[1].path, "rgb/b.png");
  EXPECT_EQ(list.entries[2].path, "rgb/c.png");
  EXPECT_EQ(list.entries[3].path, "rgb/d.png");
  EXPECT_EQ(list.entries[3].line, 8);
}

TEST(TumFileList, RejectsNonIncreasingAndNonNumericTimestampsNamingFileAndLine) {
  const TumFileList list =
      parseTumFileList("1.0 a.png\n1.0 b.png\n0.5 c.png\nabc d.png\n2.0 e.png\n", "rgb.txt");
  ASSERT_EQ(list.entries.size(), 2u);
  ASSERT_EQ(list.rejected.size(), 3u);
  EXPECT_NE(list.rejected[0].find("rgb.txt line 2"), std::string::npos) << list.rejected[0];
  EXPECT_NE(list.rejected[0].find("does not increase"), std::string::npos);
  EXPECT_NE(list.rejected[2].find("line 4"), std::string::npos);
}

TEST(TumAssociation, GreedyMatchingTakesTheClosestPairFirst) {
  // 1.00 is closest to 1.015 (0.015) but 1.02 is closer to it (0.005): associate.py gives
  // (1.02, 1.015) and leaves 1.00 to 0.99.
  const auto matches = associateTimestamps({1.00, 1.02}, {0.99, 1.015}, 0.02);
  ASSERT_EQ(matches.size(), 2u);
  EXPECT_EQ(matches[0], std::make_pair(std::size_t{0}, std::size_t{0}));
  EXPECT_EQ(matches[1], std::make_pair(std::size_t{1}, std::size_t{1}));
}

TEST(TumAssociation, DifferenceMustBeStrictlyBelowTheMaximum) {
  EXPECT_TRUE(associateTimestamps({1.0}, {1.5}, 0.5).empty());
  EXPECT_EQ(associateTimestamps({1.0}, {1.25}, 0.5).size(), 1u);
}

TEST(TumAssociation, EqualsTheReferenceOnSeededRandomTimestamps) {
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> jitter(0.0, 0.03);
  for (int trial = 0; trial < 20; ++trial) {
    std::vector<double> a;
    std::vector<double> b;
    double ta = 100.0;
    double tb = 100.0;
    for (int i = 0; i < 200; ++i) {
      ta += 0.02 + jitter(rng);
      tb += 0.02 + jitter(rng);
      a.push_back(ta);
      b.push_back(tb);
    }
    const auto expected = referenceAssociate(a, b, 0.02);
    const auto matches = associateTimestamps(a, b, 0.02);
    ASSERT_EQ(matches.size(), expected.size()) << "trial " << trial;
    for (std::size_t i = 0; i < matches.size(); ++i) {
      EXPECT_EQ(a[matches[i].first], expected[i].first);
      EXPECT_EQ(b[matches[i].second], expected[i].second);
    }
  }
}

TEST(TumAssociation, ReadsAnAssociationsFileInEitherOrder) {
  const TumAssociationList list = parseTumAssociations(
      "# rgb depth\n1.0 rgb/1.png 1.01 depth/1.png\n"
      "2.01 depth/2.png 2.0 rgb/2.png\n"
      "3.0 rgb/3.png\n",
      "assoc.txt");
  ASSERT_EQ(list.pairs.size(), 2u);
  EXPECT_EQ(list.pairs[1].rgb_path, "rgb/2.png");
  EXPECT_DOUBLE_EQ(list.pairs[1].rgb_timestamp_s, 2.0);
  ASSERT_EQ(list.rejected.size(), 1u);
  EXPECT_NE(list.rejected[0].find("assoc.txt line 4"), std::string::npos);
}

TEST(TumSource, ReadsASmallFolderWithPngColour) {
  const auto folder = test::writeTumFolder("tum-png", 5, false);
  TumSource source(folder.dir.string(), test::smallTumConfig());
  source.open();
  EXPECT_FALSE(source.isLive());
  const auto all = test::readAll(source);
  ASSERT_EQ(all.frames.size(), 5u);
  EXPECT_TRUE(all.skip_messages.empty());
  const RgbdFrame& frame = *all.frames[2];
  EXPECT_EQ(frame.utime, secondsToUtime(folder.rgb_times[2]));
  EXPECT_EQ(frame.depth_utime, secondsToUtime(folder.depth_times[2]));
  EXPECT_EQ(frame.sequence, 2);
  EXPECT_EQ(frame.color_bgr.type(), CV_8UC3);
  EXPECT_EQ(frame.gray.type(), CV_8UC1);
  // PNG colour is lossless.
  const cv::Mat expected_color = test::makeColor(64, 48, 44u);
  EXPECT_EQ(cv::norm(frame.color_bgr, expected_color, cv::NORM_INF), 0.0);
  // Depth: raw / 5000 metres, 0 -> NaN.
  EXPECT_TRUE(std::isnan(frame.depth_m.at<float>(0, 0)));
  EXPECT_FLOAT_EQ(frame.depth_m.at<float>(10, 20), (5000.0f + 200.0f + 10.0f + 2.0f) / 5000.0f);
  EXPECT_EQ(source.stats().frames_read, 5u);
  EXPECT_EQ(source.stats().frames_skipped, 0u);
  EXPECT_FALSE(source.groundTruth().has_value());
}

TEST(TumSource, ReadsJpegColourAndAnAssociationsFile) {
  const auto folder = test::writeTumFolder("tum-jpeg", 3, true);
  {
    std::ofstream assoc(folder.dir / "assoc.txt");
    char line[256];
    for (int i = 0; i < 3; ++i) {
      std::snprintf(line, sizeof(line), "%.6f rgb/%.6f.jpg %.6f depth/%.6f.png\n",
                    folder.rgb_times[static_cast<std::size_t>(i)],
                    folder.rgb_times[static_cast<std::size_t>(i)],
                    folder.depth_times[static_cast<std::size_t>(i)],
                    folder.depth_times[static_cast<std::size_t>(i)]);
      assoc << line;
    }
  }
  TumSourceConfig config = test::smallTumConfig();
  config.associations = "assoc.txt";
  TumSource source(folder.dir.string(), config);
  source.open();
  const auto all = test::readAll(source);
  ASSERT_EQ(all.frames.size(), 3u);
  const cv::Mat expected_color = test::makeColor(64, 48, 43u);
  // JPEG is lossy: compare on average.
  EXPECT_LT(cv::norm(all.frames[1]->color_bgr, expected_color, cv::NORM_L1) / (64 * 48 * 3), 40.0);
}

TEST(TumSource, FreiburgXyzAssociationEqualsAssociatePy) {
  const auto dir = test::findDataset("tum_fr1_xyz");
  if (!dir) GTEST_SKIP() << test::missingDataMessage("tum_fr1_xyz");
  Config config = Config::fromFile(std::string(SLAMD_SOURCE_DIR) + "/config/tum_fr1.yaml");
  TumSource source(dir->string(), TumSourceConfig::load(config));
  source.open();
  const auto& pairs = source.pairs();
  // Pinned from associate.py's algorithm run by hand on this copy (798 colour, 798 depth).
  ASSERT_EQ(pairs.size(), 792u);
  EXPECT_EQ(pairs[0].rgb_path, "rgb/1305031102.175304.jpg");
  EXPECT_EQ(pairs[0].depth_path, "depth/1305031102.160407.png");
  // The greedy choice: 1305031102.194330 is 0.0169 s from the second colour image but the
  // nearer 1305031102.226738 (0.0155 s) wins.
  EXPECT_EQ(pairs[1].rgb_path, "rgb/1305031102.211214.jpg");
  EXPECT_EQ(pairs[1].depth_path, "depth/1305031102.226738.png");
  EXPECT_EQ(pairs[100].depth_path, "depth/1305031105.698235.png");
  EXPECT_EQ(pairs[397].rgb_path, "rgb/1305031115.611424.jpg");
  EXPECT_EQ(pairs[397].depth_path, "depth/1305031115.607428.png");
  EXPECT_EQ(pairs[791].rgb_path, "rgb/1305031128.747363.jpg");
  EXPECT_EQ(pairs[791].depth_path, "depth/1305031128.754646.png");
  // And from first principles: the literal reference algorithm on the listed timestamps.
  const TumFileList rgb = readTumFileList((*dir / "rgb.txt").string());
  const TumFileList depth = readTumFileList((*dir / "depth.txt").string());
  std::vector<double> a;
  std::vector<double> b;
  for (const auto& e : rgb.entries) a.push_back(e.timestamp_s);
  for (const auto& e : depth.entries) b.push_back(e.timestamp_s);
  const auto expected = referenceAssociate(a, b, 0.02);
  ASSERT_EQ(expected.size(), pairs.size());
  for (std::size_t i = 0; i < pairs.size(); ++i) {
    ASSERT_EQ(pairs[i].rgb_timestamp_s, expected[i].first) << i;
    ASSERT_EQ(pairs[i].depth_timestamp_s, expected[i].second) << i;
  }
  ASSERT_TRUE(source.groundTruth().has_value());
  EXPECT_EQ(source.groundTruth()->size(), 3000u);
}

TEST(TumSource, FreiburgXyzIntrinsicsAndDepthValuesAreCorrect) {
  const auto dir = test::findDataset("tum_fr1_xyz");
  if (!dir) GTEST_SKIP() << test::missingDataMessage("tum_fr1_xyz");
  Config config = Config::fromFile(std::string(SLAMD_SOURCE_DIR) + "/config/tum_fr1.yaml");
  TumSource source(dir->string(), TumSourceConfig::load(config));
  source.open();
  ASSERT_TRUE(source.intrinsics().has_value());
  EXPECT_DOUBLE_EQ(source.intrinsics()->fx, 517.3);
  EXPECT_DOUBLE_EQ(source.intrinsics()->fy, 516.5);
  EXPECT_DOUBLE_EQ(source.intrinsics()->cx, 318.6);
  EXPECT_DOUBLE_EQ(source.intrinsics()->cy, 255.3);
  EXPECT_EQ(source.intrinsics()->distortion_model, DistortionModel::kPlumbBob);
  EXPECT_DOUBLE_EQ(source.intrinsics()->distortion[4], 1.1633);
  const FrameRead read = source.next(std::chrono::milliseconds(1000));
  ASSERT_EQ(read.status, FrameRead::Status::kFrame) << read.message;
  const RgbdFrame& frame = *read.frame;
  EXPECT_EQ(frame.utime, 1305031102175304);
  // fr1's depth stream runs on its own clock: this pair's depth is 14.9 ms older.
  EXPECT_EQ(frame.depth_utime, 1305031102160407);
  EXPECT_EQ(frame.intrinsics, *source.intrinsics());
  ASSERT_EQ(frame.depth_m.size(), cv::Size(640, 480));
  const cv::Mat raw =
      cv::imread((*dir / "depth/1305031102.160407.png").string(), cv::IMREAD_ANYDEPTH);
  ASSERT_EQ(raw.type(), CV_16UC1);
  int checked = 0;
  for (int r = 0; r < 480; r += 37) {
    for (int c = 0; c < 640; c += 41) {
      const std::uint16_t value = raw.at<std::uint16_t>(r, c);
      const float depth = frame.depth_m.at<float>(r, c);
      if (value == 0) {
        EXPECT_TRUE(std::isnan(depth));
      } else {
        EXPECT_FLOAT_EQ(depth, static_cast<float>(value) / 5000.0f);
        EXPECT_GT(depth, 0.3f);  // a desk scene: everything between 0.3 and 5 m
        EXPECT_LT(depth, 5.0f);
        ++checked;
      }
    }
  }
  EXPECT_GT(checked, 100);
}

}  // namespace
}  // namespace slamd
