#pragma once
// Conversions from tracking's odometry and the filter's vanishing points to the messages slamd
// publishes (SLAMD_ODOMETRY, SLAMD_VANISHING_POINT).

#include "slamd/filter/vanishing_point_filter.hpp"
#include "slamd/odometry_t.hpp"
#include "slamd/tracking/visual_odometry.hpp"
#include "slamd/vanishing_point_t.hpp"

namespace slamd {

slamd::odometry_t toOdometryMessage(const OdometryResult& odometry);
slamd::vanishing_point_t toVanishingPointMessage(Utime utime, const VanishingPointReport& report);

}  // namespace slamd
