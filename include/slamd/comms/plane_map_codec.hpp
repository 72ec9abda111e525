#pragma once
// Conversions between the plane map (planes::PlaneMapSnapshot) and slamd.plane_map_t, the
// message on SLAMD_PLANE_MAP (channels.plane_map).
//
//   bus.publishMessage(channels.plane_map, toPlaneMapMessage(plane_map.snapshot("world")));
//   on SLAMD_PLANE_MAP: if (auto planes = fromPlaneMapMessage(msg, &why)) use(*planes);
//
// Decoding never trusts the message: counts must match the arrays, every number must be finite,
// normals of unit length, polygons of at least 3 vertices lying on their plane, areas and
// keyframe counts not negative; otherwise nullopt with a sentence saying why. WorldPlane's
// centroid and member keyframe ids are not in the message (centroid_world is the polygon's
// vertex mean after decoding; keyframe_ids is empty and members = num_keyframes).

#include <optional>
#include <string>

#include "slamd/plane_map_t.hpp"
#include "slamd/planes/plane_map.hpp"

namespace slamd {

slamd::plane_map_t toPlaneMapMessage(const planes::PlaneMapSnapshot& snapshot);

std::optional<planes::PlaneMapSnapshot> fromPlaneMapMessage(const slamd::plane_map_t& message,
                                                            std::string* error = nullptr);

/// Polygon vertices may lie this far off their plane in a well-formed message, metres (the
/// publisher's vertices lie on it to rounding).
inline constexpr double kPlaneMapVertexToleranceM = 1e-3;

}  // namespace slamd
