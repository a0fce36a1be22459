/**
 * \file outcomes.h
 * \brief The outcome codes of the planning scene's queries, the one definition (ROS-free, no other includes): the
 *        scene's core returns them, the scene server and the shield check them against the messages' constants
 *        (moverl_msgs CheckState, CheckPath, PlanPath, ValidateMotion) at compile time, and the shield's core decides
 *        on them.
 */
#pragma once

namespace moverl_planning_scene {

/// \brief Outcome of a state or path check (values match moverl_msgs/CheckState and CheckPath).
enum class CheckOutcome { kValid = 0, kSelfCollision = 1, kWorldCollision = 2, kInvalidRequest = 3, kMapStale = 4 };

/// \brief Outcome of validateMotion (values match moverl_msgs/ValidateMotion).
enum class MotionOutcome {
  kValid = 0,
  kSelfCollision = 1,
  kPoseCollision = 2,
  kPathCollision = 3,
  kStartInCollision = 4,
  kInvalidRequest = 5,
  kMapStale = 6
};

/// \brief Outcome of a planning call (moverl_msgs/PlanPath's codes). kMapStale: the scene server's sensed map is too
///        old (or a plan's sensed margin too large) to plan in; the planner itself never returns it.
enum class PlanStatus {
  kSuccess = 0,
  kStartInvalid = 1,
  kGoalInvalid = 2,
  kNoSolution = 3,
  kInvalidRequest = 4,
  kMapStale = 5
};

}  // namespace moverl_planning_scene
