// The shield's decisions, ROS-free: one env step and one episode reset, from the robot's measured state through the
// planning scene's question to the move the driver executes, with every verdict, timing rule and deadline.
//
// The shield sees the world only through three interfaces, which its node (shield_node.cpp) implements with ROS and
// its tests (test/test_shield.cpp) with fakes that inject faults:
//   Driver  the robot: its measured state, executing a timed trajectory, teleporting (a simulator only);
//   Scene   the planning scene: the ValidateMotion question, a plan, the obstacles' motion epoch, its facts;
//   Clock   the driver's clock (simulated time in simulation, the wall on a real robot) and the wall clock.
// A ROS 2 front (or none: a test) builds a Shield from the same three and calls step() and reset().
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "moverl_planning_scene/planning_scene.h"
#include "moverl_shield/driver_core.h"
#include "moverl_shield/shield_core.h"
#include "moverl_shield/trajectory.h"

namespace moverl_shield {

/// \brief Time in nanoseconds on a clock (exact, as ROS stamps are; seconds() for arithmetic).
using Nanos = std::int64_t;
inline double seconds(Nanos t) { return static_cast<double>(t) * 1e-9; }
/// \brief Seconds -> nanoseconds, rounded to the nearest.
Nanos toNanos(double seconds);

/// \brief The clocks the shield reads (injected: the tests set them).
class Clock {
 public:
  virtual ~Clock() = default;
  /// \brief Now on the driver's clock (s): simulated time in simulation, the wall on a real robot.
  virtual double now() const = 0;
  /// \brief Wall-clock seconds since the epoch: `not_after` of requests, comparable across processes on one host.
  virtual double wall() const = 0;
};

/// \brief The robot state a decision starts from.
struct RobotState {
  std::vector<double> q;  ///< controlled joints, configured order, clamped into the limits
  /// As measured, when the driver clamped it onto a limit to give q (within its limit tolerance); empty: q is the
  /// measured state. The robot stands here: the scene checks it too (ValidateMotion.measured_start).
  std::vector<double> measured;
  Nanos stamp = 0;  ///< measurement time on the driver's clock
};

/// \brief Ground-truth contacts of one move (moverl_msgs/ContactReport in plain types; documented there).
struct ContactReport {
  bool available = false;  ///< the driver measures contacts (a simulator)
  Nanos stamp = 0;         ///< simulation time at the end of the motion; 0: no motion reported
  std::uint32_t substeps = 0, substeps_in_contact = 0, world_contacts = 0, self_contacts = 0;
  std::uint32_t moving_contacts = 0, resting_contacts = 0;  ///< who moved (ContactReport.msg)
  std::vector<moverl_planning_scene::ContactPair> pairs;
  std::uint64_t total_contact_substeps = 0;
};

/// \brief How a move ended, as the shield reports it.
struct MoveResult {
  DriverEnd end = DriverEnd::kUnreachable;
  std::int32_t error_code = 0;  ///< control_msgs/FollowJointTrajectoryResult code (0 when none)
  std::string message;          ///< the driver's error string, or why the shield gave up
  ContactReport contacts;       ///< ground truth (available=false when the driver has none)
  double seconds = 0.0;         ///< wall time spent waiting for the driver
};

/// \brief Tunables of the drivers (set from config/shield.yaml, where each is commented; no defaults here).
struct DriverOptions {
  double result_margin = 0.0;    ///< s a result may come after the move's planned end before the move counts as lost
  double max_state_age = 0.0;    ///< s: older joint states (by arrival, and by stamp vs this node's clock) are refused
  double limit_tolerance = 0.0;  ///< rad (m): states this far beyond a joint limit are clamped onto it
  double start_lead = 0.0;       ///< s between sending a goal and its start stamp (transport to the controller)
  double goal_time = 0.0;        ///< s the controller may take after the trajectory's end to settle
  double stopped_velocity_tolerance = 0.0;  ///< rad/s: goal velocity tolerance (at rest)
};

/// \brief A robot driver as the shield uses it.
class Driver {
 public:
  virtual ~Driver() = default;
  /// \brief "follow_joint_trajectory" or "sim_service" (messages).
  virtual std::string name() const = 0;
  /// \brief Time passes while the shield thinks (moves are stamped ahead and windows cover the latency).
  virtual bool realTime() const = 0;
  /// \brief The simulator can place the robot instantly (ResetRobot) and restarts the obstacles' motions then.
  virtual bool canTeleport() const = 0;
  /// \brief Contacts are measured (a simulator) rather than unknown.
  virtual bool sensesContacts() const = 0;
  /// \brief The state to decide a move from. False with *error (fail closed: no move) when there is none that is
  ///        fresh, complete and within the limit tolerance. May wait up to max_state_age for a fresh one (real time).
  virtual bool currentState(RobotState* state, std::string* error) = 0;
  /// \brief Execute a timed trajectory whose first point is the current state, starting at `start` (driver clock, s;
  ///        ignored by lockstep drivers). Blocks until it ended, failed or passed its deadline (then it is cancelled).
  virtual MoveResult execute(const TimedTrajectory& trajectory, double start) = 0;
  /// \brief Teleport (canTeleport() only): *after is the state there; *motion_epoch when the obstacles' motion time is
  ///        0 from now on (the teleport's stamp when it restarted their motions; unchanged when it did not: with
  ///        sensed obstacles a person does not jump back to the start of its walk). False with *error when the driver
  ///        is unreachable or refused; *unreachable = true when it refused the target itself (it touches an obstacle
  ///        where the motions restart: try another).
  virtual bool teleport(const std::vector<double>& q, RobotState* after, Nanos* motion_epoch, std::string* error,
                        bool* unreachable) = 0;
  /// \brief Path (and goal position) tolerance per controlled joint sent with every move from now on.
  virtual void setPathTolerance(const std::vector<double>& tolerance) = 0;
};

/// \brief What the shield needs to know about the scene besides its answers: read from the scene (its YAML), never
///        defaulted here (kUnset until read).
struct SceneFacts {
  std::vector<double> joint_radius_bounds;                 ///< per joint, m of robot motion per unit of joint motion
  double padding = moverl_planning_scene::kUnset;          ///< obstacle inflation (m)
  double path_resolution = moverl_planning_scene::kUnset;  ///< max motion of a robot point between checked states (m)
  double planning_time = moverl_planning_scene::kUnset;    ///< the scene's planning time limit (s)
};

/// \brief The planning scene as the shield uses it. Calls to a scene in another process end at `timeout` (s); one in
///        the shield's process is bounded by its planning time and always answers.
class Scene {
 public:
  virtual ~Scene() = default;
  /// \brief For messages: the service or the in-process server's namespace.
  virtual std::string name() const = 0;
  /// \brief The ValidateMotion question.
  virtual CallEnd validate(const moverl_planning_scene::MotionRequest& request,
                           moverl_planning_scene::MotionCheck* answer, double timeout) = 0;
  /// \brief A plan (the scene's default planner) from start to goal within time_limit (s).
  virtual CallEnd plan(const std::vector<double>& start, const std::vector<double>& goal, double time_limit,
                       moverl_planning_scene::PlanResult* answer, double timeout) = 0;
  /// \brief When the world's obstacle motions last (re)started (the driver's clock).
  virtual CallEnd motionEpoch(Nanos* epoch, double timeout) = 0;
  /// \brief False with *error when the scene has not published them (service mode, scene not up yet).
  virtual bool facts(SceneFacts* facts, std::string* error) = 0;
  /// \brief The robot model the scene checks with (immutable, thread-safe).
  virtual const moverl_planning_scene::RobotModel& model() const = 0;
};

/// \brief The shield's tunables (config/shield.yaml, where each is commented; the node reads them; no defaults here).
struct ShieldOptions {
  bool enabled = true;                  ///< false: pass every action through unchecked (the baseline)
  Strategy strategy = Strategy::kPlan;  ///< what happens to an unsafe action
  Profile profile = Profile::kLinear;   ///< trajectory time law
  TimingLimits limits;                  ///< velocity (from the model), acceleration (robot config), velocity_scale
  double reset_velocity_scale = 0.0;    ///< fraction of the limits for planned resets
  double sample_period = 0.0;           ///< s between min_jerk samples
  double scene_margin = 0.0;            ///< s beyond the scene's planning time before a call is abandoned
  double check_budget = 0.0;            ///< s a real-time check may take before its window no longer holds
  double reset_planning_time = 0.0;     ///< s for OMPL in planned resets
  double reset_horizon = 0.0;           ///< s: sensed obstacles: a planned reset runs in moves of at most this long
  double tracking_budget = 0.0;         ///< m a robot point may leave the checked path
  double start_lead = 0.0;              ///< s: real-time goals start this long after they are sent
  double goal_time = 0.0;               ///< s the controller may take after a trajectory's end
};

/// \brief One env step (moverl_msgs/ShieldStep's request).
struct StepRequest {
  std::vector<double> target;  ///< one per controlled joint
  double duration = 0.0;       ///< s, desired duration of a direct move
  double not_after = 0.0;      ///< wall seconds after which the caller has given up on it (0: none)
};

/// \brief What one step did (moverl_msgs/ShieldStep's response, without the FK the node adds).
struct StepResult {
  Verdict verdict = Verdict::kSceneUnavailable;
  std::string message;
  std::vector<moverl_planning_scene::ContactPair> pairs;  ///< the collision the scene found
  RobotState start;                                       ///< the state the step decided from (empty q: none)
  ContactReport contacts;  ///< ground truth of the step's motion (stamp 0 when nothing moved)
  double state_check_time = 0.0, path_check_time = 0.0, planning_time = 0.0, execution_time = 0.0;
  std::uint8_t unsafe_cause = 0;       ///< MotionOutcome code of what made the action unsafe; 0: none
  double truncated_fraction = -1.0;    ///< TRUNCATED: fraction of the straight path executed; else -1
  std::int32_t driver_error_code = 0;  ///< control_msgs/FollowJointTrajectoryResult code, 0: none
  double map_age = -1.0;               ///< s: the sensed map's age at the check (-1: no check against a sensed map)
  double sensed_margin = 0.0;          ///< m: the predictive margin of the target and the straight path (0: none)
  TimedTrajectory executed;            ///< what was sent to the driver (filled only when StepRequest asks: see step())
};

/// \brief An episode's reset (moverl_msgs/ResetRobot's request): empty positions: start where the robot stands.
struct ResetRequest {
  std::vector<double> positions;
  double not_after = 0.0;  ///< wall seconds (0: none)
};

/// \brief What a reset did (moverl_msgs/ResetRobot's response, without the FK the node adds).
struct ResetResult {
  bool success = false;
  bool unreachable = false;  ///< no collision-free path to the target (the env samples another start)
  std::string message;
  Nanos motion_epoch = 0;         ///< when the obstacles' motions last restarted (driver clock)
  std::uint32_t moves = 0;        ///< planned resets: the moves the reset was executed in
  double planned_duration = 0.0;  ///< planned resets: s the executed path lasts at its timing (0: teleport / none)
};

/// \brief The safety shield. Not thread-safe: its node serializes step() and reset().
class Shield {
 public:
  /// \param driver, scene, clock must outlive the shield
  Shield(const ShieldOptions& options, Driver* driver, Scene* scene, const Clock* clock);

  /// \brief One env step (see moverl_msgs/ShieldStep.srv): the verdict, and the state after it in lastState().
  /// \param record_executed fill StepResult::executed (for visualisers; a copy otherwise not made)
  void step(const StepRequest& request, StepResult* result, bool record_executed = false);
  /// \brief An episode's reset (see moverl_msgs/ResetRobot.srv): the simulator's teleport when the driver has one,
  ///        else a move there checked as a step is (straight, or an OMPL plan), at reset_velocity_scale. With sensed
  ///        obstacles the move runs in pieces of at most reset_horizon s, each checked from the state it starts at
  ///        with the margin of its whole window (a plan lasting seconds is covered all the way).
  void reset(const ResetRequest& request, ResetResult* result);

  /// \brief The latest state the shield knows (after the last step or reset); false before the first.
  bool lastState(RobotState* state) const;
  const ShieldOptions& options() const { return options_; }
  const std::vector<std::string>& joints() const { return joints_; }
  std::uint64_t totalContactSubsteps() const { return total_contact_substeps_; }

  /// \brief The longest a step may ask for (s): an env step lasts dt (0.05 s); anything near this is corrupt input.
  static constexpr double kMaxStepDuration = 3600.0;

 private:
  Verdict run(const StepRequest& request, StepResult* result, bool record_executed);
  bool ensureSceneFacts(std::string* error);
  double sceneTimeout() const { return planning_time_ + options_.scene_margin; }
  void setWindow(const RobotState& s, double check_begin, double duration,
                 moverl_planning_scene::MotionRequest* request) const;
  Verdict move(const Waypoints& waypoints, Verdict decided, double min_duration, const TimingLimits& limits,
               StepResult* result, bool record_executed);
  void plannedReset(const std::vector<double>& target, ResetResult* result);
  void adopt(const RobotState& s);
  std::string describe(CallEnd end, double timeout) const;

  ShieldOptions options_;
  Driver* driver_;
  Scene* scene_;
  const Clock* clock_;
  std::vector<std::string> joints_;
  double planning_time_ = 0.0;
  bool scene_facts_ = false;
  RobotState last_;  ///< the latest state the shield knows
  bool have_state_ = false;
  Nanos motion_epoch_ = 0;    ///< when the obstacles' motion time was 0 (driver clock)
  bool epoch_known_ = false;  ///< from a teleport, or else from the scene's world (ensureSceneFacts)
  std::uint64_t total_contact_substeps_ = 0;
  moverl_planning_scene::MotionRequest query_;  ///< scratch of the step's question and answer (no allocation per step)
  moverl_planning_scene::MotionCheck answer_;
};

}  // namespace moverl_shield
