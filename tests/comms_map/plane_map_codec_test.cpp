#include "slamd/comms/plane_map_codec.hpp"

#include <cstring>
#include <limits>

#include <gtest/gtest.h>

#include "slamd/comms/message_codec.hpp"

namespace slamd {
namespace {

/// Two planes of a room, as a plane map publishes them: the floor and the wall x = 3 m.
planes::PlaneMapSnapshot twoPlanes() {
  planes::PlaneMapSnapshot snapshot;
  snapshot.utime = 1'600'000'000'123'456;
  snapshot.frame_id = "world";
  planes::WorldPlane floor;
  floor.id = 7;
  floor.normal_world = Eigen::Vector3d::UnitZ();
  floor.offset_m = 0.0;
  floor.polygon_world = {{0, 0, 0}, {4, 0, 0}, {4, 3, 0}, {0, 3, 0}};
  floor.area_m2 = 12.0;
  floor.keyframe_ids = {1, 2, 5};
  planes::WorldPlane wall;
  wall.id = 9;
  wall.normal_world = -Eigen::Vector3d::UnitX();
  wall.offset_m = 3.0;
  wall.polygon_world = {{3, 0, 0}, {3, 0, 2.5}, {3, 3, 2.5}};
  wall.area_m2 = 3.75;
  wall.keyframe_ids = {2};
  snapshot.planes = {floor, wall};
  return snapshot;
}

TEST(PlaneMapCodec, RoundTripKeepsEveryPlaneThroughTheEncodedBytes) {
  const planes::PlaneMapSnapshot sent = twoPlanes();
  const std::vector<std::uint8_t> bytes = encodeMessage(toPlaneMapMessage(sent));
  const auto message = decodeMessage<slamd::plane_map_t>(bytes.data(), bytes.size());
  ASSERT_TRUE(message);
  EXPECT_EQ(message->num_planes, 2);
  EXPECT_EQ(message->planes[0].num_keyframes, 3);
  std::string error;
  const auto received = fromPlaneMapMessage(*message, &error);
  ASSERT_TRUE(received) << error;
  EXPECT_EQ(received->utime, sent.utime);
  EXPECT_EQ(received->frame_id, "world");
  ASSERT_EQ(received->planes.size(), 2u);
  for (std::size_t i = 0; i < 2; ++i) {
    const planes::WorldPlane& a = sent.planes[i];
    const planes::WorldPlane& b = received->planes[i];
    EXPECT_EQ(b.id, a.id);
    EXPECT_EQ(b.normal_world, a.normal_world);
    EXPECT_EQ(b.offset_m, a.offset_m);
    EXPECT_EQ(b.area_m2, a.area_m2);
    EXPECT_EQ(b.members, static_cast<int>(a.keyframe_ids.size()));
    EXPECT_EQ(b.polygon_world, a.polygon_world);
  }
  EXPECT_EQ(received->planes[1].polygon_world[1], Eigen::Vector3d(3, 0, 2.5));
}

TEST(PlaneMapCodec, RejectsMalformedMessagesWithAReason) {
  const slamd::plane_map_t good = toPlaneMapMessage(twoPlanes());
  const auto rejected = [](slamd::plane_map_t message, const std::string& expected) {
    std::string error;
    EXPECT_FALSE(fromPlaneMapMessage(message, &error)) << expected;
    EXPECT_NE(error.find(expected), std::string::npos) << error;
  };
  slamd::plane_map_t bad = good;
  bad.num_planes = 3;
  rejected(bad, "num_planes");
  bad = good;
  bad.planes[0].normal[2] = 0.5;
  rejected(bad, "unit vector");
  bad = good;
  bad.planes[1].offset = std::numeric_limits<double>::quiet_NaN();
  rejected(bad, "non-finite offset");
  bad = good;
  bad.planes[0].area_m2 = -1.0;
  rejected(bad, "area");
  bad = good;
  bad.planes[1].vertices[2][0] = 3.5;  // 50 cm off the wall
  rejected(bad, "off the plane");
  bad = good;
  bad.planes[1].vertices.pop_back();
  rejected(bad, "num_vertices");
  bad = good;
  bad.planes[1].num_vertices = 2;
  bad.planes[1].vertices.resize(2);
  rejected(bad, "num_vertices");
  bad = good;
  bad.planes[0].vertices[1].resize(2);
  rejected(bad, "exactly 3 coordinates");
  bad = good;
  bad.planes[0].num_keyframes = -1;
  rejected(bad, "num_keyframes");
  bad = good;
  bad.frame_id.clear();
  rejected(bad, "frame_id");
}

TEST(PlaneMapCodec, TruncatedOrInflatedBytesAreRefusedBeforeDecoding) {
  const std::vector<std::uint8_t> bytes = encodeMessage(toPlaneMapMessage(twoPlanes()));
  std::string error;
  for (const std::size_t size :
       {std::size_t{0}, std::size_t{8}, bytes.size() / 2, bytes.size() - 1}) {
    EXPECT_FALSE(decodeMessage<slamd::plane_map_t>(bytes.data(), size, &error)) << size;
  }
  // A vertex count that claims more than the buffer holds: refused without allocating.
  std::vector<std::uint8_t> inflated = bytes;
  // hash, utime, frame_id (4 + 6 bytes), num_planes, then plane 0: id, normal, offset, area,
  // num_keyframes, num_vertices.
  const std::size_t num_vertices_at = 8 + 8 + 4 + 6 + 4 + 8 + 5 * 8 + 4;
  ASSERT_LT(num_vertices_at + 4, inflated.size());
  inflated[num_vertices_at] = 0x7f;
  EXPECT_FALSE(decodeMessage<slamd::plane_map_t>(inflated.data(), inflated.size(), &error));
  EXPECT_NE(error.find("plane_map_t"), std::string::npos) << error;
  // Trailing bytes are refused too.
  inflated = bytes;
  inflated.push_back(0);
  EXPECT_FALSE(decodeMessage<slamd::plane_map_t>(inflated.data(), inflated.size(), &error));
}

}  // namespace
}  // namespace slamd
