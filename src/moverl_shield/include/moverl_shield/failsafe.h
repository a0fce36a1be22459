// The robot's failsafe stop (ROS-free): what the robot does from a joint state when the shield stops it, how long that
// takes and how far it can go meanwhile.
//
// Speed and separation monitoring (ISO/TS 15066) needs the robot's reaction travel S_r, its stopping time T_s and its
// stopping distance S_s; a failsafe shield (SaRA, Thumm & Althoff 2022) lets a step run only if the stop that would
// follow it is safe. The model, per controlled joint i, from a measured state (q, v):
//  - reaction: for reaction_time T_r (the stop command on its way to the motors) the joint keeps moving and may still
//    accelerate at its limit a_i: at the brake's start its speed is at most w_i = min(|v_i| + a_i T_r, vmax_i), and it
//    has travelled at most |v_i| T_r + a_i T_r^2 / 2 (either way);
//  - braking: every joint decelerates so that all of them stand still at the same instant t_b = max_i w_i / a_i (the
//    robot stays on its line in joint space, as a controller's stop along the path does); joint i travels w_i t_b / 2.
// With T_r = 0 the braking trajectory is exact: brakingTrajectory() is what the shield sends, and a controller that
// follows it ends at q + v t_b / 2. A real (or the dynamic simulator's) controller lags: how far any robot point may
// leave the model is the shield's tracking_budget, measured against the dynamic simulator in
// src/moverl_shield/test/test_failsafe_stop.py.
#pragma once

#include <vector>

#include "moverl_shield/trajectory.h"

namespace moverl_shield {

/// \brief What the stop may use: the robot's limits and the driver's reaction time.
struct StopLimits {
  std::vector<double> velocity;      ///< per controlled joint, > 0 (the URDF's limits)
  std::vector<double> deceleration;  ///< per controlled joint, > 0 (the robot config's acceleration_limits)
  double reaction_time = 0.0;        ///< s, >= 0: from the stop's decision until the motors brake
};

/// \brief A failsafe stop from one joint state: its time bound and, per joint, the interval the joint stays in.
struct StopBound {
  double reaction_time = 0.0;        ///< T_r
  double braking_time = 0.0;         ///< t_b (0 from standstill)
  std::vector<double> lower, upper;  ///< per joint: every position the joint can take until standstill
  /// Per joint: the largest travel from the start in either direction (max(q - lower, upper - q)).
  std::vector<double> travel;
  double duration() const { return reaction_time + braking_time; }  ///< T_r + T_s: the robot stands still after it
};

/// \brief The stop's bound from state (q, v).
/// \throws std::invalid_argument on size mismatches, non-finite values, non-positive limits or a negative reaction
///         time.
StopBound failsafeStop(const std::vector<double>& q, const std::vector<double>& v, const StopLimits& limits);

/// \brief The braking part as a trajectory from (q, v) (reaction time 0: the state the stop starts from), every joint
///        decelerating uniformly to standstill at t_b = max_i |v_i| / a_i: positions, velocities and accelerations
///        every sample_period (and at t_b). From standstill: one point, (q, 0, 0) at t = 0.
/// \throws std::invalid_argument as failsafeStop, or a non-positive sample_period.
TimedTrajectory brakingTrajectory(const std::vector<double>& q, const std::vector<double>& v, const StopLimits& limits,
                                  double sample_period);

/// \brief A bound on how far any robot point moves when each joint i moves by at most travel[i]: sum_i r_i travel_i,
///        with r_i the planning scene's joint_radius_bounds (the largest distance of a robot point from joint i's axis,
///        or 1 for a prismatic joint). ISO/TS 15066's S_r + S_s for this robot, in metres.
/// \throws std::invalid_argument on a size mismatch or a negative value.
double pointTravelBound(const std::vector<double>& travel, const std::vector<double>& radius_bounds);

}  // namespace moverl_shield
