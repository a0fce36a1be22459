// Speed and separation monitoring (ROS-free): ISO/TS 15066's protective separation distance between the robot and one
// part of a person, and the speed at which the robot may still move.
//
//   S_p = S_h + S_r + S_s + C + Z_d + Z_r
//   S_h      how far the person's part can come while the robot reacts and stops (T_r + T_s), plus the age of what is
//            known of it: a tracked part (its speed monitored) |v| t + a t^2 / 2, capped at max_speed; an unmonitored
//            one (a lost or stale track, or anything the tracker does not explain) ISO 13855's K t + C with K = 2.0 m/s
//            while that is at most 0.5 m, else K = 1.6 m/s (and at least 0.5 m): the scene's Iso13855
//   S_r+S_s  how far any robot point moves until standstill (failsafe.h: pointTravelBound of the stop's bound)
//   C        intrusion distance (ISO 13855's C of the sensor, for an unmonitored part; a tracked part's own radius)
//   Z_d, Z_r the sensor's and the robot's position uncertainty
// A robot that keeps S_p to every part of every person stands still before any part can touch it (ISO/TS 15066: a
// robot at standstill is not a moving hazard). Below S_p at full speed, a slower step may still keep it (the robot's
// travel and stopping time shrink with its speed): speedScale() finds the fastest; none means stop.
#pragma once

#include <vector>

#include "moverl_planning_scene/sensed_margin.h"
#include "moverl_planning_scene/tracked_parts.h"
#include "moverl_shield/failsafe.h"

namespace moverl_shield {

/// \brief The person model: ISO 13855's speeds and what a tracked part can do.
struct SsmParams {
  moverl_planning_scene::Iso13855 iso;  ///< an unmonitored part (the scene's rule: its speeds, C of the sensors)
  /// how far a tracked part may travel (the scene's tracked_parts.h, the one copy of the formula)
  moverl_planning_scene::PartMotionBound motion;
  double max_track_age = 0.0;       ///< s: an older track is lost (ISO's speeds)
  double sensor_uncertainty = 0.0;  ///< m, Z_d
  double robot_uncertainty = 0.0;   ///< m, Z_r (the shield's tracking_budget)
};

/// \brief What is known of one part of a person.
struct PartState {
  bool tracked = false;  ///< a track explains it (else: unmonitored, ISO's speeds)
  double age = 0.0;      ///< s since the measurement (tracked) or since the cell was last seen (unmonitored)
  double speed = 0.0;    ///< m/s, the tracked part's measured speed (its noise included by the tracker's error)
  double radius = 0.0;   ///< m, the tracked part's own extent beyond its measured point
};

/// \brief Whether a part counts as monitored: tracked, with a track no older than max_track_age.
bool monitored(const PartState& part, const SsmParams& params);

/// \brief S_h + C of a part over horizon t (s, after the measurement's age): how far it may be from where it was known.
double personReach(const PartState& part, double t, const SsmParams& params);

/// \brief S_p between the part and a robot whose stop is `stop` (radius_bounds: the scene's joint_radius_bounds).
/// \throws std::invalid_argument on bad sizes or values (failsafe.h), or a negative time or parameter.
double protectiveSeparation(const PartState& part, const StopBound& stop, const std::vector<double>& radius_bounds,
                            const SsmParams& params);

/// \brief The fastest fraction s in [0, 1] of the robot's velocity v at which S_p (of the stop from (q, s v)) is at
///        most `distance`, to within `resolution`; 0 when even standstill keeps less (the robot must stop; a robot at
///        rest the part reaches within T_r is not moving).
double speedScale(double distance, const PartState& part, const std::vector<double>& q, const std::vector<double>& v,
                  const StopLimits& limits, const std::vector<double>& radius_bounds, const SsmParams& params,
                  double resolution = 1e-3);

}  // namespace moverl_shield
