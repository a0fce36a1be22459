/**
 * \file motion_planner.h
 * \brief OMPL joint-space planning on top of a CollisionChecker (ROS-free).
 */
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "moverl_planning_scene/collision_checker.h"
#include "moverl_planning_scene/outcomes.h"
#include "moverl_planning_scene/robot_model.h"
#include "moverl_planning_scene/unset.h"

namespace moverl_planning_scene {

/// \brief Tunables of the planner. Their values live in config/planning_scene.yaml (tunables.h reads them); unset ones
///        ("", NaN) are rejected by PlanningScene::create().
struct PlannerOptions {
  std::string planner;            ///< default planner name
  double planning_time = kUnset;  ///< default time limit per call (s)
  double range = kUnset;          ///< max extension of tree planners (rad); 0: OMPL default
  bool simplify = true;           ///< shortcut the solution within the remaining time
  unsigned seed = 0;              ///< OMPL global RNG seed (0: not seeded). Applied once per process.
};

/// \brief Result of a planning call.
struct PlanResult {
  PlanStatus status = PlanStatus::kNoSolution;
  std::vector<std::vector<double>> waypoints;  ///< start .. goal, each dof values
  double planning_time = 0.0;                  ///< seconds
  double path_length = 0.0;                    ///< sum of Euclidean joint-space segment lengths
  std::string message;
};

/// \brief OMPL SimpleSetup over a RealVectorStateSpace bounded by the URDF limits. OMPL sees the world only through
///        the CollisionChecker: a StateValidityChecker and a MotionValidator that uses the same straight-segment check
///        (same resolution guarantee) as the path check service.
class MotionPlanner {
 public:
  MotionPlanner(const RobotModel& model, CollisionChecker* checker, const PlannerOptions& options);
  ~MotionPlanner();

  /// \brief Names accepted by plan().
  static const std::vector<std::string>& knownPlanners();
  /// \brief True when name (or "" = default) is a known planner.
  static bool isKnownPlanner(const std::string& name);

  /// \brief Plan start -> goal (both already validated: sizes, finite, within limits). planner "" = default,
  ///        time_limit <= 0 = default. Checks both ends first; returns only exact, re-validated solutions.
  ///        If the straight segment is free it is returned directly.
  void plan(const std::vector<double>& start, const std::vector<double>& goal, const std::string& planner,
            double time_limit, PlanResult* result, bool try_straight = true);

  const PlannerOptions& options() const { return options_; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  PlannerOptions options_;
};

}  // namespace moverl_planning_scene
