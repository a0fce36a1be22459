// Timing of the shield's joint-space paths (ROS-free).
//
// A decision's waypoints (the straight move, a plan, a truncated move) are polylines in joint space whose every
// segment the planning scene checked. Timing must keep the robot ON those segments, whatever the controller
// interpolates:
//  - linear: positions only, each segment at constant velocity (the slowest joint at its velocity limit, stretched to
//    the step's duration). Velocity jumps at the waypoints: fine for the kinematic simulator (training, the default).
//  - min_jerk: each segment rest to rest with a quintic time law s(t) (zero velocity and acceleration at both ends),
//    sampled every sample_period with positions, velocities and accelerations. Every joint is an affine function of
//    the same s(t), so every sample lies on the segment, and a controller's spline through them (joint_trajectory_
//    controller: quintic with pos/vel/acc) does too. Velocity and acceleration are continuous and within the limits:
//    what a real arm and the dynamic simulator can follow closely.
#pragma once

#include <string>
#include <vector>

#include "moverl_shield/shield_core.h"

namespace moverl_shield {

/// \brief Time law of each segment.
enum class Profile { kLinear, kMinJerk };

/// \brief Parse "linear" / "min_jerk". False for an unknown name (*profile unchanged).
bool parseProfile(const std::string& name, Profile* profile);
/// \brief "linear" or "min_jerk".
std::string profileName(Profile profile);

/// \brief Joint limits a timing must respect.
struct TimingLimits {
  std::vector<double> velocity;      ///< per controlled joint, > 0
  std::vector<double> acceleration;  ///< per controlled joint, > 0; empty: no acceleration limit (linear ignores it)
  double velocity_scale = 1.0;       ///< fraction of the limits used (accelerations scale with its square)
};

/// \brief A timed trajectory: times[k] (s from its start) and positions[k]; velocities / accelerations have one row per
///        point for min_jerk and are empty for linear (the controller interpolates positions linearly).
struct TimedTrajectory {
  std::vector<double> times;
  Waypoints positions, velocities, accelerations;
  double duration() const { return times.empty() ? 0.0 : times.back(); }
};

/// Peak of |ds/dtau| (1.875) and |d2s/dtau2| (10 / sqrt(3)) of the quintic rest-to-rest law s = 10t^3 - 15t^4 + 6t^5.
constexpr double kMinJerkPeakVelocity = 1.875;
constexpr double kMinJerkPeakAcceleration = 5.773502691896258;

/// \brief Time the waypoints (first = the current state) with a profile.
///
/// Each segment takes the time its slowest joint needs within the limits (linear: velocity; min_jerk: peak velocity
/// and, when given, peak acceleration of the quintic). If the total is below min_duration every segment is stretched
/// proportionally (a direct move lasts at least the env step's duration). min_jerk samples each segment at intervals
/// of at most sample_period. A single waypoint (hold still) gives a two-point trajectory of min_duration.
/// \throws std::invalid_argument on size mismatches, non-positive limits, scale or sample period.
TimedTrajectory timeTrajectory(Profile profile, const Waypoints& waypoints, const TimingLimits& limits,
                               double min_duration, double sample_period = 0.01);

}  // namespace moverl_shield
