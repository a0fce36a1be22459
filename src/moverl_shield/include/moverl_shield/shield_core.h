// The ROS-free core of the MoveRL safety shield.
//
// The shield turns the planning scene's classification of one commanded move (ValidateMotion) into
// what the robot does: the direct move, a collision-free replacement plan, the straight move truncated
// at its last safe state, or nothing. What happens to an unsafe action is the shield's Strategy. It also gives the
// executed waypoints a timing that respects the joint velocity limits. No ROS headers here: the node in
// shield_node.cpp is a thin shell around these functions.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "moverl_planning_scene/outcomes.h"

namespace moverl_shield {

/// The planning scene's ValidateMotion outcome (its one definition: moverl_planning_scene/outcomes.h).
using moverl_planning_scene::MotionOutcome;

/// Verdicts of one shield step. Values equal the constants of moverl_msgs/ShieldStep.srv.
enum class Verdict : uint8_t {
  kSafe = 0,                ///< straight move free: executed directly
  kReplanned = 1,           ///< straight path collided: a collision-free plan was executed
  kDiscardedSelf = 2,       ///< target in self collision: held still
  kDiscardedPose = 3,       ///< target collides with the world: held still
  kDiscardedPath = 4,       ///< path collided and no plan was found: held still
  kDiscardedStart = 5,      ///< the current state is not free: held still
  kUnchecked = 6,           ///< shield disabled: executed straight without checks
  kTruncated = 7,           ///< unsafe target (last_safe): moved straight to the last safe state before the collision
  kAborted = 8,             ///< the driver stopped the move on the way (path/goal tolerance): the episode should end
  kDiscardedUnseen = 9,     ///< the sensed map is too old: nothing is known to be free, held still
  kInvalidRequest = 10,     ///< malformed target: nothing moves
  kSceneUnavailable = 11,   ///< planning scene unreachable, failed or late: fail closed
  kExecutionFailed = 12,    ///< the driver refused the trajectory
  kDriverUnavailable = 13,  ///< the driver is unreachable or gave no result by the deadline: fail closed
  kStateUnavailable = 14,   ///< no fresh, complete, in-limits joint state: fail closed
  kRetreated = 15,          ///< unsafe target (retreat) while resting within the sensed margin: backed away instead
};

/// What the shield does with an unsafe action (param ~strategy).
enum class Strategy : uint8_t {
  kPlan = 0,      ///< "plan" (the paper's): self/pose collisions held still; a path collision replaced by a plan
  kDiscard = 1,   ///< "discard": every unsafe action held still, no planning
  kLastSafe = 2,  ///< "last_safe": move straight to the last safe state before the first collision
  /// "retreat": as plan; and with sensed obstacles, a robot that would rest within the predictive margin of the seen
  /// cells backs away instead of holding still (ValidateMotion.retreat_reach), and a commanded move that backs away
  /// is accepted.
  kRetreat = 3,
};

/// \brief Name of a strategy as used in ~strategy and the ShieldStep response ("plan", "discard", "last_safe",
///        "retreat").
std::string strategyName(Strategy strategy);
/// \brief Parse a strategy name (exact, lower case). False for an unknown name (*strategy unchanged).
bool parseStrategy(const std::string& name, Strategy* strategy);
/// \brief The names accepted by parseStrategy, for messages ("plan, discard, last_safe, retreat").
std::string strategyNames();

using Waypoints = std::vector<std::vector<double>>;

/// \brief The planning scene's answer for one move (the fields of ValidateMotion's response the shield uses).
struct SceneAnswer {
  MotionOutcome outcome = MotionOutcome::kInvalidRequest;
  bool replanned = false;               ///< PATH_COLLISION: a replacement plan was found
  Waypoints plan;                       ///< the replacement plan (start..goal) when replanned
  double last_free_fraction = -1;       ///< t of the last free checked state before the first collision; -1: none
  std::vector<double> last_free_state;  ///< the configuration at last_free_fraction
  std::vector<double> retreat_state;    ///< a move that backs away from the seen cells (retreat); empty: none
};

/// \brief What the scene must compute for a strategy (ValidateMotion request flags).
bool wantsPlan(Strategy strategy);      ///< plan_on_path_collision
bool wantsLastFree(Strategy strategy);  ///< find_last_free

/// \brief What the shield does for one step.
struct Decision {
  Verdict verdict = Verdict::kSceneUnavailable;  ///< fail closed unless decided otherwise
  Waypoints waypoints;  ///< joint configurations to execute, current state first; empty: hold still
  /// The collision that made the action unsafe (MotionOutcome code: 1 self, 2 pose, 3 path, 4 start); 0: none.
  uint8_t unsafe_cause = 0;
  double truncated_fraction = -1.0;  ///< kTruncated: fraction of the straight path executed; else -1
};

/// \brief Short lower-case name of a verdict ("safe", "replanned", "discarded_self", ...).
std::string verdictName(Verdict verdict);

/// \brief True for the verdicts in which the robot was kept from an unsafe action (the agent is punished),
///        including kTruncated (the commanded action was unsafe; only its safe part was executed).
bool isDiscarded(Verdict verdict);

/// \brief Check a target: right size and finite values. Returns an empty string when fine, else the reason.
std::string validateTarget(const std::vector<double>& target, size_t num_joints);

/// \brief Map the scene's classification to the shield's decision under a strategy.
///
/// | outcome         | plan                          | discard         | last_safe                              |
/// |-----------------|-------------------------------|-----------------|----------------------------------------|
/// | VALID           | SAFE (straight)               | SAFE            | SAFE                                   |
/// | SELF_COLLISION  | DISCARDED_SELF                | DISCARDED_SELF  | TRUNCATED if t > 0, else DISCARDED_SELF|
/// | POSE_COLLISION  | DISCARDED_POSE                | DISCARDED_POSE  | TRUNCATED if t > 0, else DISCARDED_POSE|
/// | PATH_COLLISION  | REPLANNED if a plan, else     | DISCARDED_PATH  | TRUNCATED if t > 0, else DISCARDED_PATH|
/// |                 | DISCARDED_PATH                | (plan ignored)  |                                        |
/// | START_IN_COLL.  | DISCARDED_START               | DISCARDED_START | DISCARDED_START                        |
/// t = last_free_fraction (with a last_free_state of the start's size); TRUNCATED executes start -> that state.
/// retreat: as plan, but where plan holds still and the scene found a retreat_state (of the start's size), RETREATED
/// executes start -> that state (the unsafe cause is kept).
/// \param start,target the current and the commanded configuration
Decision decide(Strategy strategy, const SceneAnswer& answer, const std::vector<double>& start,
                const std::vector<double>& target);

/// \brief decide() with the plan strategy (the paper's behaviour).
/// \param outcome      ValidateMotion outcome
/// \param replanned    whether the scene found a replacement plan (PATH_COLLISION only)
/// \param plan         the replacement plan's waypoints (start..goal) when replanned
Decision decide(MotionOutcome outcome, bool replanned, const Waypoints& plan, const std::vector<double>& start,
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
