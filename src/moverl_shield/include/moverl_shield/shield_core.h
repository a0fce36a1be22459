// The ROS-free core of the MoveRL safety shield.
//
// The shield turns the planning scene's classification of one commanded move (ValidateMotion) into
// what the robot does: the direct move, a collision-free replacement plan, or nothing. It also gives the
// executed waypoints a timing that respects the joint velocity limits. No ROS headers here: the node in
// shield_node.cpp is a thin shell around these functions.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace moverl_shield {

/// Verdicts of one shield step. Values equal the constants of moverl_msgs/ShieldStep.srv.
enum class Verdict : uint8_t {
  kSafe = 0,              ///< straight move free: executed directly
  kReplanned = 1,         ///< straight path collided: a collision-free plan was executed
  kDiscardedSelf = 2,     ///< target in self collision: held still
  kDiscardedPose = 3,     ///< target collides with the world: held still
  kDiscardedPath = 4,     ///< path collided and no plan was found: held still
  kDiscardedStart = 5,    ///< the current state is not free: held still
  kUnchecked = 6,         ///< shield disabled: executed straight without checks
  kInvalidRequest = 10,   ///< malformed target: nothing moves
  kSceneUnavailable = 11, ///< planning scene unreachable or failed: fail closed
  kExecutionFailed = 12,  ///< the driver refused or failed the trajectory
};

/// Outcome codes of moverl_msgs/ValidateMotion.srv, as the scene reports them.
enum class SceneOutcome : uint8_t {
  kValid = 0,
  kSelfCollision = 1,
  kPoseCollision = 2,
  kPathCollision = 3,
  kStartInCollision = 4,
  kInvalidRequest = 5,
};

using Waypoints = std::vector<std::vector<double>>;

/// \brief What the shield does for one step.
struct Decision {
  Verdict verdict = Verdict::kSceneUnavailable;  ///< fail closed unless decided otherwise
  Waypoints waypoints;  ///< joint configurations to execute, current state first; empty: hold still
};

/// \brief Short lower-case name of a verdict ("safe", "replanned", "discarded_self", ...).
std::string verdictName(Verdict verdict);

/// \brief True for the verdicts in which the robot was kept from an unsafe action (the agent is punished).
bool isDiscarded(Verdict verdict);

/// \brief Check a target: right size and finite values. Returns an empty string when fine, else the reason.
std::string validateTarget(const std::vector<double>& target, size_t num_joints);

/// \brief Map the scene's classification to the shield's decision.
/// \param outcome      ValidateMotion outcome
/// \param replanned    whether the scene found a replacement plan (PATH_COLLISION only)
/// \param plan         the replacement plan's waypoints (start..goal) when replanned
/// \param start,target the current and the commanded configuration
Decision decide(SceneOutcome outcome, bool replanned, const Waypoints& plan, const std::vector<double>& start,
                const std::vector<double>& target);

/// \brief Decision of a disabled shield: execute the straight move, unchecked.
Decision passThrough(const std::vector<double>& start, const std::vector<double>& target);

/// \brief Time stamps (time_from_start, s) for waypoints so that no joint exceeds its velocity limit.
///
/// Each segment takes the time its slowest joint needs at velocity_limit * velocity_scale; if the whole
/// motion is shorter than min_duration, every segment is stretched proportionally so that it lasts
/// min_duration. The first waypoint gets t = 0.
/// \throws std::invalid_argument on size mismatches, non-positive limits or scale.
std::vector<double> timeWaypoints(const Waypoints& waypoints, const std::vector<double>& velocity_limits,
                                  double min_duration, double velocity_scale = 1.0);

}  // namespace moverl_shield
