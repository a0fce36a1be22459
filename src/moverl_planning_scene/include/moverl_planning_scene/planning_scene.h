/**
 * \file planning_scene.h
 * \brief ROS-free facade behind the planning_scene node: input validation and the five queries
 *        (check state, check path, plan, forward kinematics, validate motion).
 */
#pragma once

#include <chrono>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "moverl_planning_scene/collision_checker.h"
#include "moverl_planning_scene/fcl_collision_checker.h"
#include "moverl_planning_scene/motion_planner.h"
#include "moverl_planning_scene/robot_model.h"

namespace moverl_planning_scene {

/// \brief Everything needed to build a scene.
struct PlanningSceneOptions {
  RobotModelOptions robot;
  FclCheckerOptions checker;
  PlannerOptions planner;
};

/// \brief Result of checkState.
struct StateCheck {
  CheckOutcome outcome = CheckOutcome::kValid;
  std::vector<ContactPair> pairs;
  std::string message;
  double check_time = 0.0;
};

/// \brief Result of checkPath.
struct PathCheck {
  CheckOutcome outcome = CheckOutcome::kValid;
  std::vector<ContactPair> pairs;
  double collision_fraction = -1.0;
  std::size_t checked_states = 0;
  std::string message;
  double check_time = 0.0;
};

/// \brief The sensed obstacles' predictive margins (m) of one validateMotion (see
/// FclCollisionChecker::setOctreeMargin):
///        a sensed obstacle may have moved this far since it was seen, by the time the robot is at the start (start),
///        at any state of the straight move or its goal (end), or anywhere on a plan lasting at most plan_horizon s
///        (plan).
struct SensedMargins {
  double start = 0.0, end = 0.0, plan = 0.0;
  double map_age = -1.0;      ///< s (reported)
  double plan_horizon = 0.0;  ///< s (reported: a plan executed slower is not covered)
  /// safety:=ssm with a tracker: the tracked parts the start's and the end's checks use, for the move's window's end
  /// (tracked_parts.h; a plan's checks use none: ISO's margin)
  std::vector<ExplainedPart> parts;
  /// safety:=ssm: a threatened robot holds still, neither taking a commanded move that backs away nor proposing one
  /// (a person may touch a robot at rest, never a moving one: a hand at 2.0 m/s catches an arm backing away).
  bool hold_when_threatened = false;
};

/// \brief One validateMotion question (moverl_msgs/ValidateMotion's request, whose comments say more).
struct MotionRequest {
  std::vector<double> start, goal;
  /// The state as the driver measured it, when it was clamped onto the joint limits to give `start` (empty: `start`
  /// is the measured state). The robot stands there, not at `start`: it is checked too, with the segment to `start`.
  std::vector<double> measured_start;
  bool plan_on_path_collision = false;
  bool find_last_free = false;
  double start_time = 0.0;                                    ///< motion time (s) of the start state
  double duration = std::numeric_limits<double>::infinity();  ///< s the straight move's window lasts
  double stamp = 0.0;  ///< absolute time (s, driver clock) of start_time, for the sensed map's age; 0: the newest cloud
  /// Sensed obstacles (strategy retreat): the largest |goal - start| per joint (rad or m) of a move that backs away
  /// from the seen cells when the robot would rest within the predictive margin (ValidateMotion.srv). Empty: never.
  std::vector<double> retreat_reach;
  /// s the caller waits for the answer (the shield's deadline for the scene); 0: no limit. Work that may take long
  /// (the scene server's wait for clouds, the retreat search) ends early enough to answer within it, failing closed.
  double time_budget = 0.0;
};

/// \brief Result of validateMotion.
struct MotionCheck {
  MotionOutcome outcome = MotionOutcome::kValid;
  bool replanned = false;
  std::vector<std::vector<double>> path;  ///< when replanned: start .. goal
  std::vector<ContactPair> pairs;
  std::string message;
  double state_check_time = 0.0, path_check_time = 0.0, planning_time = 0.0;
  /// find_last_free only: t (0..1) of the last free checked state of the straight segment before its first
  /// collision (0: none beyond the start); -1 when not computed. last_free_state is the configuration at t.
  double last_free_fraction = -1.0;
  std::vector<double> last_free_state;
  bool moving_obstacles = false;  ///< the world has moving obstacles (or sensed ones, which may move)
  // Sensed obstacles, as the scene server reports them (0 / -1 without a sensed map):
  double map_age = -1.0;       ///< s: the map's age at the request's stamp
  double sensed_margin = 0.0;  ///< m: the predictive margin of the goal and the straight path
  double plan_horizon = 0.0;   ///< s: a returned plan is covered for a move lasting at most this long (0: any)
  // Retreat (a request with retreat_reach; ValidateMotion.srv):
  bool threatened = false;            ///< the robot would rest within the predictive margin of the seen cells
  double clearance = -1.0;            ///< threatened: m the start is clear of every occupied cell (-1: touching)
  std::vector<double> retreat_state;  ///< threatened and refused: the goal of a move that backs away (empty: none)
  double retreat_clearance = -1.0;    ///< m that goal (or a commanded move accepted as backing away) is at least clear
};

/// \brief The planning scene: robot model + FCL checker + OMPL planner. Not thread-safe (callers serialize).
class PlanningScene {
 public:
  /// \brief Build from URDF text; nullptr with *error on failure (URDF, joints, meshes, parameters).
  static std::unique_ptr<PlanningScene> create(const std::string& urdf_xml, const PlanningSceneOptions& options,
                                               std::string* error);

  /// \brief Replace the world. False (previous world kept) when an object is invalid.
  bool setWorld(const std::vector<WorldObject>& objects, std::string* error) {
    return checker_->setWorld(objects, error);
  }

  /// \brief Validate a configuration: size, finite, within limits (+/- kLimitTolerance). Empty string when valid.
  std::string validateConfiguration(const std::vector<double>& q, const char* what) const;

  /// \brief Self (ACM applied) then world check of one configuration; all colliding pairs of the first kind found.
  void checkState(const std::vector<double>& q, StateCheck* out, bool compute_depth = false);
  /// \brief Check the straight segment including both ends; pairs at the first colliding state.
  void checkPath(const std::vector<double>& start, const std::vector<double>& goal, PathCheck* out);
  /// \brief Plan with OMPL (validates inputs, planner name and time limit).
  void plan(const std::vector<double>& start, const std::vector<double>& goal, const std::string& planner,
            double time_limit, PlanResult* out);
  /// \brief Poses of links (empty: the ee link) in the base frame. False with *error on bad input.
  bool fk(const std::vector<double>& q, const std::vector<std::string>& links, std::vector<Eigen::Isometry3d>* poses,
          std::string* error);
  /// \brief One shield query: goal self/world, start, straight path, optional replanning (see ValidateMotion.srv).
  /// \param find_last_free for a goal or path collision (start free): also find the last collision-free checked
  ///        state of the straight segment before its first collision (MotionCheck::last_free_*). That state
  ///        passed the state check and the segment start -> it passes checkPath.
  /// \param start_time, duration the motion-time window [start_time, start_time + duration] of the straight move:
  ///        its interior states are checked against the volume each moving obstacle sweeps in that window (widened
  ///        by kTimeSlack on both sides); the goal, the start, plans and the last free state against each moving
  ///        obstacle's whole motion envelope. Ignored without moving obstacles. duration = +inf: envelope only.
  /// \param sensed the sensed obstacles' margins (nullptr: none)
  void validateMotion(const MotionRequest& request, MotionCheck* out, const SensedMargins* sensed = nullptr);
  /// \brief validateMotion of the request with these fields (tests and tools).
  void validateMotion(const std::vector<double>& start, const std::vector<double>& goal, bool plan_on_path_collision,
                      MotionCheck* out, bool find_last_free = false, double start_time = 0.0,
                      double duration = std::numeric_limits<double>::infinity(), const SensedMargins* sensed = nullptr);

  const RobotModel& model() const { return *model_; }
  FclCollisionChecker& checker() { return *checker_; }
  MotionPlanner& planner() { return *planner_; }

  /// Tolerance on joint limits for requests (rad or m); values within it are clamped to the limits.
  static constexpr double kLimitTolerance = 1e-6;
  /// Motion-time slack (s) added on both sides of a straight move's window (stamp rounding, substep alignment).
  static constexpr double kTimeSlack = 1e-3;
  /// Longest accepted planning time limit (s).
  static constexpr double kMaxPlanningTime = 60.0;
  /// Retreat: m of robot-point motion between the states whose clearance is checked (points between them come at
  /// most half of it closer); m a retreat's goal must gain at least; random directions tried besides each joint's.
  static constexpr double kRetreatResolution = 0.005;
  static constexpr double kRetreatGain = 0.002;
  static constexpr int kRetreatDirections = 16;

 private:
  PlanningScene() = default;
  /// Validates and clamps into the scratch vector; returns the message ("" when fine).
  std::string prepare(const std::vector<double>& q, const char* what, std::vector<double>* clamped) const;
  /// find_last_free: from a find_first check of start_ -> goal_ (path_result_), fill out->last_free_*.
  void findLastFree(bool goal_checked, MotionCheck* out);
  /// Retreat: after the outcome of a request with retreat_reach is known (start_, goal_ set), decide whether the
  /// robot is threatened (a cell seen occupied within its padding + end_margin) and, if so, accept the commanded move
  /// when it backs away or propose one that does (out->retreat_state). Stops (holding) at `deadline`. hold: it holds
  /// when threatened (SensedMargins::hold_when_threatened).
  void retreat(const MotionRequest& request, double end_margin, bool hold,
               std::chrono::steady_clock::time_point deadline, MotionCheck* out);
  /// The clearance (m) of q from every occupied cell when it is at least `clearance` + kRetreatGain, else less.
  double clearanceAbove(const std::vector<double>& q, double clearance);
  /// True when the straight move start_ -> q backs away: q free of self collisions and the world objects, its path
  /// free of them (padded, at path_resolution), and its states every kRetreatResolution of robot-point motion (q
  /// included) at least `clearance` clear of every occupied cell, seen or unseen (q's own clearance is
  /// clearanceAbove's).
  bool pathBacksAway(const std::vector<double>& q, double clearance);

  std::unique_ptr<RobotModel> model_;
  std::unique_ptr<FclCollisionChecker> checker_;
  std::unique_ptr<MotionPlanner> planner_;
  std::vector<double> start_, goal_, measured_;
  CollisionRequest all_pairs_;
  CollisionRequest verdict_only_{true, true, 0, false};  ///< self + world, no pairs (fast)
  CollisionResult state_result_;
  PathCheckResult path_result_;
  CollisionResult retreat_result_;
  PathCheckResult retreat_path_;
  PlanResult plan_result_;
  std::vector<Eigen::Isometry3d> link_poses_;
};

}  // namespace moverl_planning_scene
