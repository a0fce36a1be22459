/**
 * \file collision_checker.h
 * \brief Abstract collision checking interface (in the spirit of MoveIt's CollisionEnv), ROS-free.
 *
 * Path-check resolution guarantee
 * -------------------------------
 * For every controlled joint i the checker precomputes a configuration-independent bound r_i on how far any
 * collision-geometry point of the links moved by joint i can be from the joint's axis: the sum of the joint-origin
 * offsets along the kinematic chain (plus prismatic travel) down to each link, plus the maximal radius of that link's
 * collision geometry about its frame (for a prismatic joint r_i = 1, points move exactly |dq_i|). Along the straight
 * joint-space segment q(t) = q0 + t (q1 - q0), every robot point therefore travels at most L = sum_i r_i |dq_i| metres.
 * The checker tests n = ceil(L / path_resolution) interior states evenly spaced in t (plus the end points when
 * requested), so no point of the robot moves more than path_resolution between two consecutive checked states.
 * World obstacles are inflated by `padding`; with path_resolution < 2 * padding, an obstacle (even a 0-thickness wall)
 * cannot slip between two checked states without one of them colliding with the inflated obstacle.
 */
#pragma once

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "moverl_planning_scene/robot_model.h"

namespace moverl_planning_scene {

/// \brief How an obstacle moves over motion time t (moverl_msgs/ObstacleMotion, where the formulas are): a translation
///        along a unit axis, pose(t) = pose(0) + axis * displacement(t), displacement(t) = offset(t) - offset(0).
///        kOscillate: offset = amplitude sin(2 pi t / period + phase). kReach: seeded cycles of rest, a reach out to
///        amplitude in `move` s, a hold, the way back (moverl_sim.world.ObjectMotion is the Python twin).
struct ObstacleMotion {
  enum class Type { kNone = 0, kOscillate = 1, kReach = 2 };
  Type type = Type::kNone;
  Eigen::Vector3d axis = Eigen::Vector3d::UnitX();  ///< unit vector, world frame
  double amplitude = 0.0;                           ///< m
  double period = 1.0;                              ///< s
  double phase = 0.0;                               ///< rad
  double move = 0.0;                                ///< s (kReach): each way
  double hold = 0.0;                                ///< s (kReach): at the far end
  double chance = 0.0;                              ///< kReach: the fraction of cycles that reach
  std::uint32_t seed = 0;                           ///< kReach

  bool moving() const { return type != Type::kNone && amplitude > 0.0; }
  /// \brief Offset along the axis from the object's reference position (oscillate: its swing's centre; reach: where
  ///        it rests) at motion time t.
  double offset(double t) const;
  /// \brief Scalar displacement along axis from the pose at t = 0.
  double displacement(double t) const { return moving() ? offset(t) - offset(0.0) : 0.0; }
  /// \brief Exact range [*lo, *hi] of displacement(t) over t in [t0, t1]; t1 = +inf (or a window of a period or
  ///        more for oscillate, of more than kMaxRangeCycles cycles for reach): the whole motion envelope.
  void range(double t0, double t1, double* lo, double* hi) const;
  /// \brief kReach: the uniform number in [0, 1) that decides whether cycle k reaches (splitmix64, ObstacleMotion.msg).
  static double cycleDraw(std::uint32_t seed, std::uint64_t k);
  static constexpr double kMaxRangeCycles = 10000.0;
};

/// \brief One obstacle of the world (shape_msgs/SolidPrimitive conventions).
struct WorldObject {
  std::string id;
  ShapeType type = ShapeType::kBox;  ///< kBox, kSphere, kCylinder or kCone
  /// BOX [x, y, z]; SPHERE [radius]; CYLINDER/CONE [height, radius].
  std::vector<double> dimensions;
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();  ///< pose of the shape's centre, base frame (at t = 0)
  ObstacleMotion motion;                                   ///< kNone: static
};

/// \brief Verdict of a state or path check.
enum class CollisionStatus { kFree = 0, kSelf = 1, kWorld = 2 };

/// \brief One colliding pair: robot link names or world object ids.
struct ContactPair {
  std::string a;
  std::string b;
  double depth = 0.0;  ///< penetration depth when computed, else 0
};

/// \brief What to check in one state.
struct CollisionRequest {
  bool check_self = true;     ///< self collisions (allowed-collision matrix applied)
  bool check_world = true;    ///< robot vs (inflated) world objects
  std::size_t max_pairs = 1;  ///< stop after this many colliding pairs; 0: verdict only (no names filled)
  /// Fill ContactPair::depth from FCL's contact (libccd MPR). Approximate: unreliable for vertex-only convex hulls.
  bool compute_depth = false;
  bool check_occupancy = true;  ///< with check_world: robot vs the sensed occupancy map (FclCollisionChecker)
};

/// \brief Result of one state check. Self collisions are checked first; world pairs only when the state is
///        self-collision free.
struct CollisionResult {
  CollisionStatus status = CollisionStatus::kFree;
  std::vector<ContactPair> pairs;
  /// \brief Reset to free, keeping the capacity of pairs.
  void clear() {
    status = CollisionStatus::kFree;
    pairs.clear();
  }
  bool collision() const { return status != CollisionStatus::kFree; }
};

/// \brief What to check along a straight joint-space segment.
struct PathCheckRequest {
  CollisionRequest state;   ///< per-state request (the pairs reported are those of the first colliding state)
  bool check_start = true;  ///< also check the start state (t = 0)
  bool check_goal = true;   ///< also check the goal state (t = 1)
  /// true: states are checked in order from start to goal, so the reported fraction is the first collision.
  /// false: goal first then bisection order (faster rejection; the fraction is then *a* colliding one).
  bool find_first = true;
};

/// \brief Result of a path check.
struct PathCheckResult {
  CollisionStatus status = CollisionStatus::kFree;
  std::vector<ContactPair> pairs;    ///< pairs at the reported colliding state
  double collision_fraction = -1.0;  ///< t of the reported colliding state, -1 when free
  double last_valid_fraction = 1.0;  ///< t of the last free checked state before it (find_first), 1 when free
  std::size_t checked_states = 0;    ///< number of states actually checked
  void clear() {
    status = CollisionStatus::kFree;
    pairs.clear();
    collision_fraction = -1.0;
    last_valid_fraction = 1.0;
    checked_states = 0;
  }
};

/// \brief Collision checking of robot states and straight joint-space segments against itself and the world.
///        Implementations keep scratch buffers: one instance must not be used by two threads at once.
class CollisionChecker {
 public:
  virtual ~CollisionChecker() = default;

  /// \brief Replace all world objects (inflated by the checker's padding). Returns false and keeps the previous
  ///        world when an object is invalid (message in *error). Moving objects start as their whole motion
  ///        envelope (see setMotionWindow).
  virtual bool setWorld(const std::vector<WorldObject>& objects, std::string* error) = 0;
  /// \brief What moving obstacles stand for in the following checks: the volume each sweeps over the motion-time
  ///        window [t0, t1] (t1 = +inf: its whole motion envelope, the default). Static obstacles are unaffected.
  virtual void setMotionWindow(double t0, double t1) = 0;
  /// \brief True when the world has at least one moving obstacle.
  virtual bool hasMovingObstacles() const = 0;
  /// \brief Check one configuration q (dof values, not validated).
  virtual void checkState(const double* q, const CollisionRequest& request, CollisionResult* result) = 0;
  /// \brief Check the straight segment q0 -> q1 with the resolution guarantee above.
  virtual void checkPath(const double* q0, const double* q1, const PathCheckRequest& request,
                         PathCheckResult* result) = 0;
  /// \brief Number of interior states checked on q0 -> q1: ceil(sum_i r_i |dq_i| / path_resolution).
  virtual std::size_t interiorStateCount(const double* q0, const double* q1) const = 0;
  /// \brief True when q is free (fast path: no names, early exit).
  bool isStateValid(const double* q) {
    scratch_result_.clear();
    checkState(q, verdict_only_, &scratch_result_);
    return !scratch_result_.collision();
  }

 private:
  CollisionRequest verdict_only_{true, true, 0, false};
  CollisionResult scratch_result_;
};

}  // namespace moverl_planning_scene
