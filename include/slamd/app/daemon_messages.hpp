#pragma once
// LCM messages for the daemon's odometry and vanishing-point results.

#include "slamd/app/packets.hpp"
#include "slamd/odometry_t.hpp"
#include "slamd/vanishing_point_t.hpp"

namespace slamd {

slamd::odometry_t toOdometryMessage(const OdometryResult& odometry);
slamd::vanishing_point_t toVanishingPointMessage(Utime utime, const VanishingPointReport& report);

}  // namespace slamd
