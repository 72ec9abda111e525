#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

#include "box_room.hpp"
#include "scoped_temp_dir.hpp"
#include "slamd/mapping/map_io.hpp"
#include "slamd/mapping/mapper.hpp"
#include "test_data.hpp"

namespace slamd {
namespace {

namespace fs = std::filesystem;

MappingConfig quietConfig() {
  MappingConfig c;
  c.update_rate_hz = 0.0;
  c.full_map_period_s = 0.0;
  c.snapshot_period_s = 0.0;
  return c;
}

void mapSomeRoom(Mapper& mapper, int frames) {
  const test::BoxRoom room;
  const auto poses = test::lookAroundPoses(8);
  for (int i = 0; i < frames; ++i) {
    const SE3& T = poses[static_cast<std::size_t>(i) % poses.size()];
    RgbdFrame frame = room.render(T);
    frame.utime = 1'000'000 + i * 33'333;
    ASSERT_EQ(mapper.integrate(frame, T, i).status, IntegrationStatus::kOk);
  }
}

/// Every finest voxel's state in a tree: -1/0/1 per key, pruned leaves expanded.
std::map<octomap::OcTreeKey, int, bool (*)(const octomap::OcTreeKey&, const octomap::OcTreeKey&)>
voxelStates(const octomap::AbstractOccupancyOcTree& any_tree) {
  const auto less = +[](const octomap::OcTreeKey& a, const octomap::OcTreeKey& b) {
    return std::tie(a[0], a[1], a[2]) < std::tie(b[0], b[1], b[2]);
  };
  std::map<octomap::OcTreeKey, int, bool (*)(const octomap::OcTreeKey&, const octomap::OcTreeKey&)>
      states(less);
  const auto& tree = dynamic_cast<const octomap::OcTree&>(any_tree);
  for (auto it = tree.begin_leafs(); it != tree.end_leafs(); ++it) {
    const int n = 1 << (tree.getTreeDepth() - it.getDepth());
    const octomap::OcTreeKey base = it.getIndexKey();
    for (int i = 0; i < n; ++i) {
      for (int j = 0; j < n; ++j) {
        for (int k = 0; k < n; ++k) {
          octomap::OcTreeKey key(static_cast<octomap::key_type>(base[0] + i),
                                 static_cast<octomap::key_type>(base[1] + j),
                                 static_cast<octomap::key_type>(base[2] + k));
          states[key] = tree.isNodeOccupied(*it) ? 1 : 0;
        }
      }
    }
  }
  return states;
}

TEST(MapPersistence, SavedBtReadsBackWithTheSameOccupancyEverywhere) {
  Mapper mapper(quietConfig());
  mapSomeRoom(mapper, 12);
  const test::ScopedTempDir dir("bt");
  const std::string path = (dir / "room.bt").string();
  const MapFileResult saved = mapper.saveMap(path);
  ASSERT_TRUE(saved.ok) << saved.error;
  EXPECT_FALSE(fs::exists(temporaryPathFor(path)));
  octomap::OcTree back(0.1);
  ASSERT_TRUE(back.readBinary(path));
  EXPECT_DOUBLE_EQ(back.getResolution(), 0.05);
  const auto original = voxelStates(*mapper.ocTree());
  const auto loaded = voxelStates(back);
  ASSERT_GT(original.size(), 10000u);
  EXPECT_TRUE(original == loaded);
}

TEST(MapPersistence, SavedOtKeepsEveryLogOddsAndLoadsToContinueMapping) {
  Mapper mapper(quietConfig());
  mapSomeRoom(mapper, 6);
  const test::ScopedTempDir dir("ot");
  const MapFileResult saved = mapper.saveMaps((dir / "room").string());
  ASSERT_TRUE(saved.ok) << saved.error;
  ASSERT_TRUE(fs::exists(dir / "room.bt"));
  std::unique_ptr<octomap::AbstractOcTree> any(
      octomap::AbstractOcTree::read((dir / "room.ot").string()));
  auto* back = dynamic_cast<octomap::OcTree*>(any.get());
  ASSERT_NE(back, nullptr);
  const octomap::OcTree& tree = *mapper.ocTree();
  ASSERT_EQ(back->getNumLeafNodes(), tree.getNumLeafNodes());
  for (auto it = tree.begin_leafs(); it != tree.end_leafs(); ++it) {
    const auto* node = back->search(it.getKey(), static_cast<unsigned>(it.getDepth()));
    ASSERT_NE(node, nullptr);
    ASSERT_FLOAT_EQ(node->getLogOdds(), it->getLogOdds());
  }

  // Continue mapping on the loaded .ot: the result equals mapping everything in one go.
  MappingConfig config = quietConfig();
  config.load_path = (dir / "room.ot").string();
  Mapper resumed(config);
  EXPECT_EQ(resumed.nextUpdateSequence(), 1);  // subscribers must resynchronise
  EXPECT_TRUE(resumed.fullMapRequested());
  Mapper straight(quietConfig());
  mapSomeRoom(straight, 12);
  const test::BoxRoom room;
  const auto poses = test::lookAroundPoses(8);
  for (int i = 6; i < 12; ++i)
    resumed.integrate(room.render(poses[static_cast<std::size_t>(i)]),
                      poses[static_cast<std::size_t>(i)]);
  EXPECT_TRUE(voxelStates(*resumed.ocTree()) == voxelStates(*straight.ocTree()));

  MappingConfig missing = quietConfig();
  missing.load_path = (dir / "nope.ot").string();
  EXPECT_THROW(Mapper{missing}, std::runtime_error);
  EXPECT_FALSE(resumed.loadMap((dir / "room.txt").string()).ok);
}

TEST(MapPersistence, AColourMapSavedAsOtLoadsBackWithItsColours) {
  MappingConfig config = quietConfig();
  config.color = true;
  Mapper colored(config);
  mapSomeRoom(colored, 3);
  const test::ScopedTempDir dir("color");
  const std::string path = (dir / "color.ot").string();
  ASSERT_TRUE(colored.saveMap(path).ok);
  Mapper plain(quietConfig());  // configured without colour: the file's tree type wins
  const MapFileResult loaded = plain.loadMap(path);
  ASSERT_TRUE(loaded.ok) << loaded.error;
  ASSERT_TRUE(plain.hasColor());
  const PointCloud a = colored.occupiedCloud();
  const PointCloud b = plain.occupiedCloud();
  ASSERT_EQ(a.size(), b.size());
  EXPECT_TRUE(a.colors_bgr == b.colors_bgr);
}

TEST(MapPersistence, AWriteThatFailsLeavesThePreviousFileIntact) {
  const test::ScopedTempDir dir("atomic");
  const std::string path = (dir / "file.txt").string();
  ASSERT_TRUE(writeFileAtomically(path, [](std::ostream& out) {
    out << "version one\n";
    return true;
  }));
  std::string error;
  EXPECT_FALSE(writeFileAtomically(
      path,
      [](std::ostream& out) {
        out << std::string(1 << 20, 'x');  // half written, then the writer gives up
        return false;
      },
      &error));
  EXPECT_FALSE(error.empty());
  EXPECT_FALSE(writeFileAtomically(
      path, [](std::ostream&) -> bool { throw std::runtime_error("disk on fire"); }));
  std::ifstream in(path);
  std::string line;
  std::getline(in, line);
  EXPECT_EQ(line, "version one");
  EXPECT_FALSE(fs::exists(temporaryPathFor(path)));
  EXPECT_FALSE(writeFileAtomically((dir / "no" / "such" / "dir.txt").string(),
                                   [](std::ostream&) { return true; }, &error));
}

TEST(MapPersistence, ASnapshotKilledMidWriteLeavesThePreviousSnapshotIntact) {
  const test::ScopedTempDir dir("snapshot");
  MappingConfig config = quietConfig();
  config.snapshot_path = (dir / "snapshot.bt").string();
  config.snapshot_period_s = 1.0;
  Mapper mapper(config);
  mapSomeRoom(mapper, 3);
  ASSERT_FALSE(mapper.poll(1'000'000).snapshot.has_value());  // starts the clock
  const MapperOutputs out = mapper.poll(2'100'000);
  ASSERT_TRUE(out.snapshot.has_value());
  ASSERT_TRUE(out.snapshot->ok) << out.snapshot->error;
  const auto first = voxelStates(*mapper.ocTree());

  // More mapping, then a snapshot process killed (SIGKILL) halfway through writing the file.
  mapSomeRoom(mapper, 9);
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    writeFileAtomically(config.snapshot_path, [&mapper](std::ostream& stream) {
      std::ostringstream full;
      mapper.ocTree()->writeBinaryConst(full);
      const std::string bytes = full.str();
      stream.write(bytes.data(), static_cast<std::streamsize>(bytes.size() / 2));
      stream.flush();
      raise(SIGKILL);
      return true;
    });
    _exit(0);
  }
  int status = 0;
  ASSERT_EQ(waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFSIGNALED(status));
  EXPECT_TRUE(fs::exists(temporaryPathFor(config.snapshot_path)));  // the torn temporary
  octomap::OcTree previous(0.05);
  ASSERT_TRUE(previous.readBinary(config.snapshot_path));
  EXPECT_TRUE(voxelStates(previous) == first);

  // The next snapshot overwrites the leftover temporary and replaces the file.
  const MapFileResult next = mapper.saveSnapshot();
  ASSERT_TRUE(next.ok) << next.error;
  EXPECT_FALSE(fs::exists(temporaryPathFor(config.snapshot_path)));
  octomap::OcTree latest(0.05);
  ASSERT_TRUE(latest.readBinary(config.snapshot_path));
  EXPECT_TRUE(voxelStates(latest) == voxelStates(*mapper.ocTree()));
  EXPECT_EQ(mapper.stats().snapshots_written, 2);
}

TEST(MapPersistence, AFailedSnapshotIsRetriedSoonerThanThePeriodUntilItSucceeds) {
  const test::ScopedTempDir dir("snapshot-retry");
  MappingConfig config = quietConfig();
  config.snapshot_path = (dir / "gone" / "snapshot.bt").string();  // the folder is missing
  config.snapshot_period_s = 30.0;
  Mapper mapper(config);
  mapSomeRoom(mapper, 2);
  const Utime t0 = 1'000'000;
  ASSERT_FALSE(mapper.poll(t0).snapshot.has_value());  // starts the clock
  const MapperOutputs first = mapper.poll(t0 + 30'000'000);
  ASSERT_TRUE(first.snapshot.has_value());
  EXPECT_FALSE(first.snapshot->ok);
  EXPECT_NE(first.snapshot->error.find("No such file or directory"), std::string::npos)
      << first.snapshot->error;
  // Retries after 1 s, then 2 s (not after the 30 s period), and nothing in between.
  EXPECT_FALSE(mapper.poll(t0 + 30'500'000).snapshot.has_value());
  const MapperOutputs retry1 = mapper.poll(t0 + 31'000'000);
  ASSERT_TRUE(retry1.snapshot.has_value());
  EXPECT_FALSE(retry1.snapshot->ok);
  EXPECT_FALSE(mapper.poll(t0 + 32'500'000).snapshot.has_value());
  fs::create_directories(dir / "gone");
  const MapperOutputs retry2 = mapper.poll(t0 + 33'000'000);
  ASSERT_TRUE(retry2.snapshot.has_value());
  EXPECT_TRUE(retry2.snapshot->ok) << retry2.snapshot->error;
  EXPECT_EQ(mapper.stats().snapshot_retries, 2);
  EXPECT_EQ(mapper.stats().snapshot_failures, 2);
  // Back to the period.
  EXPECT_FALSE(mapper.poll(t0 + 40'000'000).snapshot.has_value());
  EXPECT_TRUE(mapper.poll(t0 + 63'000'000).snapshot.has_value());
}

// OctoMap's readers trust their input: a stream whose every node claims children made them recurse
// without bound. Map files are checked first (octree_stream.hpp) and refused with the reason.
TEST(MapPersistence, CorruptMapFilesAreRefusedWithAReasonNotACrash) {
  const test::ScopedTempDir dir("corrupt-map");
  const std::string header = "# Octomap OcTree binary file\nid OcTree\nsize 1\nres 0.05\ndata\n";
  const std::pair<std::string, std::string> files[] = {
      {"deep.bt", header + std::string(200000, '\xff')},
      {"truncated.bt", header + std::string("\xc0\x00", 2)},
      {"no-newline.bt", "# Octomap OcTree binary file\nid OcTree\nres 0.05\ndata"},
      {"bad-res.bt", "# Octomap OcTree binary file\nid OcTree\nres nan\ndata\n"},
      {"wrong-kind.bt", "# Octomap OcTree file\nid OcTree\nres 0.05\ndata\n"},
      {"other-tree.ot", "# Octomap OcTree file\nid CountingOcTree\nres 0.05\ndata\n"},
      {"not-a-map.bt", "hello"},
  };
  for (const auto& [name, content] : files) {
    const auto path = dir / name;
    std::ofstream(path, std::ios::binary) << content;
    MappingConfig config = quietConfig();
    config.load_path = path.string();
    try {
      Mapper mapper(config);
      ADD_FAILURE() << name << " loaded";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find(name), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace slamd
