#include "slamd/comms/plane_map_codec.hpp"

#include <cmath>
#include <vector>

namespace slamd {

slamd::plane_map_t toPlaneMapMessage(const planes::PlaneMapSnapshot& snapshot) {
  slamd::plane_map_t message;
  message.utime = snapshot.utime;
  message.frame_id = snapshot.frame_id;
  message.num_planes = static_cast<std::int32_t>(snapshot.planes.size());
  message.planes.resize(snapshot.planes.size());
  for (std::size_t i = 0; i < snapshot.planes.size(); ++i) {
    const planes::WorldPlane& plane = snapshot.planes[i];
    slamd::plane_t& out = message.planes[i];
    out.id = plane.id;
    for (int k = 0; k < 3; ++k) out.normal[k] = plane.normal_world[k];
    out.offset = plane.offset_m;
    out.area_m2 = plane.area_m2;
    out.num_keyframes = static_cast<std::int32_t>(plane.keyframe_ids.size());
    out.num_vertices = static_cast<std::int32_t>(plane.polygon_world.size());
    // lcm-gen's encoder reads 3 values of each inner vector: each must hold them.
    out.vertices.assign(plane.polygon_world.size(), std::vector<double>(3));
    for (std::size_t v = 0; v < plane.polygon_world.size(); ++v) {
      for (int k = 0; k < 3; ++k) out.vertices[v][k] = plane.polygon_world[v][k];
    }
  }
  return message;
}

std::optional<planes::PlaneMapSnapshot> fromPlaneMapMessage(const slamd::plane_map_t& message,
                                                            std::string* error) {
  const auto fail = [error](const std::string& why) {
    if (error) *error = "plane_map_t: " + why;
    return std::nullopt;
  };
  if (message.num_planes < 0 ||
      static_cast<std::size_t>(message.num_planes) != message.planes.size()) {
    return fail("num_planes does not match the planes");
  }
  if (message.frame_id.empty()) return fail("empty frame_id");
  planes::PlaneMapSnapshot snapshot;
  snapshot.utime = message.utime;
  snapshot.frame_id = message.frame_id;
  snapshot.planes.reserve(message.planes.size());
  for (const slamd::plane_t& in : message.planes) {
    const std::string which = "plane " + std::to_string(in.id) + ": ";
    planes::WorldPlane plane;
    plane.id = in.id;
    plane.normal_world = Eigen::Vector3d(in.normal[0], in.normal[1], in.normal[2]);
    plane.offset_m = in.offset;
    plane.area_m2 = in.area_m2;
    if (!plane.normal_world.allFinite() || std::abs(plane.normal_world.norm() - 1.0) > 1e-6) {
      return fail(which + "the normal is not a finite unit vector");
    }
    if (!std::isfinite(in.offset) || !std::isfinite(in.area_m2) || in.area_m2 < 0.0) {
      return fail(which + "non-finite offset, or an area that is not finite and >= 0");
    }
    if (in.num_keyframes < 0) return fail(which + "negative num_keyframes");
    if (in.num_vertices < 3 || static_cast<std::size_t>(in.num_vertices) != in.vertices.size()) {
      return fail(which + "num_vertices below 3 or not matching the vertices");
    }
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    for (const std::vector<double>& vertex : in.vertices) {
      if (vertex.size() != 3) return fail(which + "a vertex without exactly 3 coordinates");
      const Eigen::Vector3d p(vertex[0], vertex[1], vertex[2]);
      if (!p.allFinite()) return fail(which + "a non-finite vertex");
      if (std::abs(plane.normal_world.dot(p) + plane.offset_m) > kPlaneMapVertexToleranceM) {
        return fail(which + "a vertex off the plane");
      }
      plane.polygon_world.push_back(p);
      sum += p;
    }
    plane.centroid_world = sum / static_cast<double>(plane.polygon_world.size());
    plane.members = in.num_keyframes;
    snapshot.planes.push_back(std::move(plane));
  }
  return snapshot;
}

}  // namespace slamd
