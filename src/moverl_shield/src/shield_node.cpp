// The MoveRL shield node: a thin ROS shell around moverl_shield's core.
//
// Per env step (service ~step): read the robot's current state from the driver, ask the planning scene ONE
// ValidateMotion question (a function call: by default the shield hosts the scene, see scene_access.h), then execute
// the direct move, the replacement plan or the truncated straight move through the driver, or hold still. ~strategy
// says what happens to an unsafe action (plan, discard, last_safe; see config/shield.yaml). ~reset brings the robot to
// an episode's start: the simulator's teleport when the driver has one, else a shield-checked move (straight, or an
// OMPL plan).
//
// Drivers (drivers.h): the standard control_msgs/FollowJointTrajectory action with the robot's joint states (real
// robots, the simulator in real time), or the simulator's lockstep services (training). The env sees no difference.
//
// Threads: ~step is served over TCPROS by a thread per client connection (tcpros.h), which also makes the step's
// calls to the simulator: no hand-offs between threads on the hot path. ~reset runs on the global callback queue; a
// mutex lets one step or reset run at a time. The driver's joint states and action callbacks run on their own queue
// and thread, so they arrive while a step waits. Every hop has a deadline, from configuration: a scene in its own
// process gets its planning time limit plus a margin (in process its calls are bounded by that planning time), the
// driver the move's duration plus goal_time plus a margin. When one passes the shield fails closed (cancels the goal,
// holds) and its verdict names the component.
//
// Moving obstacles: the scene checks the straight move against where they will be while it executes. In lockstep the
// window is [motion time of the current state, + the move's duration]; in real time it also covers the time the check
// may take (check_budget) and the start lead, and the move is stamped to start within it (driver_core.h).
#include <atomic>
#include <cmath>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <control_msgs/FollowJointTrajectoryResult.h>
#include <moverl_msgs/GetWorld.h>
#include <moverl_msgs/PlanPath.h>
#include <moverl_msgs/ResetRobot.h>
#include <moverl_msgs/ShieldEvent.h>
#include <moverl_msgs/ShieldStep.h>
#include <moverl_msgs/ValidateMotion.h>
#include <ros/callback_queue.h>
#include <ros/ros.h>
#include <trajectory_msgs/JointTrajectory.h>

#include "deadline.h"
#include "drivers.h"
#include "moverl_shield/driver_core.h"
#include "moverl_shield/shield_core.h"
#include "moverl_shield/trajectory.h"
#include "scene_access.h"
#include "tcpros.h"

namespace moverl_shield {
namespace {

// The core's codes are the messages' codes: checked here, where both are visible, at compile time.
using StepRes = moverl_msgs::ShieldStep::Response;
using SceneRes = moverl_msgs::ValidateMotion::Response;
using FjtResult = control_msgs::FollowJointTrajectoryResult;
constexpr std::uint8_t code(Verdict v) { return static_cast<std::uint8_t>(v); }
static_assert(code(Verdict::kSafe) == StepRes::SAFE && code(Verdict::kReplanned) == StepRes::REPLANNED &&
                  code(Verdict::kDiscardedSelf) == StepRes::DISCARDED_SELF &&
                  code(Verdict::kDiscardedPose) == StepRes::DISCARDED_POSE &&
                  code(Verdict::kDiscardedPath) == StepRes::DISCARDED_PATH &&
                  code(Verdict::kDiscardedStart) == StepRes::DISCARDED_START &&
                  code(Verdict::kUnchecked) == StepRes::UNCHECKED && code(Verdict::kTruncated) == StepRes::TRUNCATED &&
                  code(Verdict::kAborted) == StepRes::ABORTED &&
                  code(Verdict::kDiscardedUnseen) == StepRes::DISCARDED_UNSEEN &&
                  code(Verdict::kInvalidRequest) == StepRes::INVALID_REQUEST &&
                  code(Verdict::kSceneUnavailable) == StepRes::SCENE_UNAVAILABLE &&
                  code(Verdict::kExecutionFailed) == StepRes::EXECUTION_FAILED &&
                  code(Verdict::kDriverUnavailable) == StepRes::DRIVER_UNAVAILABLE &&
                  code(Verdict::kStateUnavailable) == StepRes::STATE_UNAVAILABLE,
              "moverl_shield::Verdict differs from moverl_msgs/ShieldStep");
constexpr std::uint8_t code(SceneOutcome o) { return static_cast<std::uint8_t>(o); }
static_assert(code(SceneOutcome::kValid) == SceneRes::VALID &&
                  code(SceneOutcome::kSelfCollision) == SceneRes::SELF_COLLISION &&
                  code(SceneOutcome::kPoseCollision) == SceneRes::POSE_COLLISION &&
                  code(SceneOutcome::kPathCollision) == SceneRes::PATH_COLLISION &&
                  code(SceneOutcome::kStartInCollision) == SceneRes::START_IN_COLLISION &&
                  code(SceneOutcome::kInvalidRequest) == SceneRes::INVALID_REQUEST &&
                  code(SceneOutcome::kMapStale) == SceneRes::MAP_STALE,
              "moverl_shield::SceneOutcome differs from moverl_msgs/ValidateMotion");
constexpr std::int32_t code(TrajectoryError e) { return static_cast<std::int32_t>(e); }
static_assert(code(TrajectoryError::kSuccessful) == FjtResult::SUCCESSFUL &&
                  code(TrajectoryError::kInvalidGoal) == FjtResult::INVALID_GOAL &&
                  code(TrajectoryError::kInvalidJoints) == FjtResult::INVALID_JOINTS &&
                  code(TrajectoryError::kOldHeaderTimestamp) == FjtResult::OLD_HEADER_TIMESTAMP &&
                  code(TrajectoryError::kPathToleranceViolated) == FjtResult::PATH_TOLERANCE_VIOLATED &&
                  code(TrajectoryError::kGoalToleranceViolated) == FjtResult::GOAL_TOLERANCE_VIOLATED,
              "moverl_shield::TrajectoryError differs from control_msgs/FollowJointTrajectoryResult");

/// The longest duration a step may ask for (s): an env step lasts dt (0.05 s); anything near this is corrupt input.
constexpr double kMaxStepDuration = 3600.0;

/// A private parameter that config/shield.yaml must set (the YAML is where every tunable lives, with its comment).
template <class T>
T required(const ros::NodeHandle& pnh, const std::string& name) {
  T value;
  if (!pnh.getParam(name, value)) {
    throw std::runtime_error("parameter " + pnh.resolveName(name) + " is not set (load config/shield.yaml)");
  }
  return value;
}

std::string describe(CallEnd end, const std::string& service, double timeout) {
  return end == CallEnd::kTimedOut
             ? "service " + service + " did not answer within its deadline of " + std::to_string(timeout) + " s"
             : "service " + service + " is unreachable";
}

}  // namespace

class ShieldNode {
 public:
  ShieldNode(ros::NodeHandle& nh, ros::NodeHandle& pnh) : nh_(nh) {
    enabled_ = required<bool>(pnh, "enabled");
    const std::string strategy = required<std::string>(pnh, "strategy");
    if (!parseStrategy(strategy, &strategy_)) {
      throw std::runtime_error("unknown ~strategy '" + strategy + "' (expected one of: " + strategyNames() + ")");
    }
    const std::string profile = required<std::string>(pnh, "profile");
    if (!parseProfile(profile, &profile_)) {
      throw std::runtime_error("unknown ~profile '" + profile + "' (expected linear or min_jerk)");
    }
    limits_.velocity_scale = required<double>(pnh, "velocity_scale");
    reset_velocity_scale_ = required<double>(pnh, "reset_velocity_scale");
    sample_period_ = required<double>(pnh, "sample_period");
    scene_margin_ = required<double>(pnh, "scene_margin");
    check_budget_ = required<double>(pnh, "check_budget");
    reset_planning_time_ = required<double>(pnh, "reset_planning_time");
    tracking_budget_ = required<double>(pnh, "tracking_budget");
    DriverOptions driver;
    driver.result_margin = required<double>(pnh, "result_margin");
    driver.max_state_age = required<double>(pnh, "max_state_age");
    driver.limit_tolerance = required<double>(pnh, "limit_tolerance");
    driver.start_lead = required<double>(pnh, "start_lead");
    driver.goal_time = required<double>(pnh, "goal_time");
    driver.stopped_velocity_tolerance = required<double>(pnh, "stopped_velocity_tolerance");
    start_lead_ = driver.start_lead;
    goal_time_ = driver.goal_time;

    // The planning scene, in this process or behind its services; its robot model is the shield's too.
    scene_ =
        SceneAccess::create(required<std::string>(pnh, "scene"), nh, required<std::string>(pnh, "scene_namespace"));
    const moverl_planning_scene::RobotModel& model = scene_->model();
    joints_ = model.jointNames();
    ee_link_ = model.linkIndex(model.eeLink());
    limits_.velocity = model.velocityLimits();
    // Optional: the robot's joint acceleration limits (URDFs have none); min_jerk moves respect them.
    if (nh.getParam("robot/acceleration_limits", limits_.acceleration) &&
        limits_.acceleration.size() != joints_.size()) {
      throw std::runtime_error("/robot/acceleration_limits must have one value per controlled joint");
    }
    // Path tolerances: derived from the tracking budget and the scene's joint radius bounds on first use (the scene
    // publishes them when it is up).

    const std::string name = required<std::string>(pnh, "driver");
    // The driver's callbacks (joint states, action results) run on their own queue and thread.
    ros::NodeHandle driver_nh(nh);
    driver_nh.setCallbackQueue(&driver_queue_);
    if (name == "follow_joint_trajectory") {
      auto fjt = std::make_unique<FollowJointTrajectoryDriver>(
          driver_nh, joints_, model.lowerLimits(), model.upperLimits(), required<std::string>(pnh, "action"),
          required<std::string>(pnh, "joint_states"), driver);
      driver_spinner_ = std::make_unique<ros::AsyncSpinner>(1, &driver_queue_);
      driver_spinner_->start();
      std::string error;
      if (!fjt->waitUntilReady(required<double>(pnh, "startup_timeout"), &error)) {
        throw std::runtime_error("the robot's driver is not ready: " + error);
      }
      driver_ = std::move(fjt);
    } else if (name == "sim_service") {
      driver_ = std::make_unique<SimServiceDriver>(driver_nh, joints_, model.lowerLimits(), model.upperLimits(),
                                                   required<std::string>(pnh, "execute_service"),
                                                   required<std::string>(pnh, "reset_service"), driver);
      driver_spinner_ = std::make_unique<ros::AsyncSpinner>(1, &driver_queue_);
      driver_spinner_->start();
    } else {
      throw std::runtime_error("unknown ~driver '" + name + "' (expected follow_joint_trajectory or sim_service)");
    }

    reset_srv_ = pnh.advertiseService("reset", &ShieldNode::serveReset, this);
    events_pub_ = pnh.advertise<moverl_msgs::ShieldEvent>("events", 10);
    // ~step is served over TCPROS by threads of its own (tcpros.h: the hot path without roscpp's thread hand-offs),
    // from the moment it is advertised: last, once everything a step uses is built. ~reset runs on the global queue;
    // serve_mutex_ lets one of them run at a time.
    step_srv_ = advertiseDirect<moverl_msgs::ShieldStep>(
        pnh.resolveName("step"), [this](moverl_msgs::ShieldStep::Request& req, moverl_msgs::ShieldStep::Response& res) {
          std::lock_guard<std::mutex> lock(serve_mutex_);
          return step(req, res);
        });
    ROS_INFO("shield ready (%s, strategy %s, %s profile), %zu joints, scene %s, driver %s",
             enabled_ ? "enabled" : "DISABLED", strategyName(strategy_).c_str(), profileName(profile_).c_str(),
             joints_.size(), scene_->name().c_str(), driver_->name().c_str());
  }

  ~ShieldNode() {
    step_srv_.reset();  // unregisters ~step and waits for a step that is running
    if (driver_spinner_) driver_spinner_->stop();
  }

 private:
  // ---------------------------------------------------------------------------------------------------- set-up
  /// Facts that come from the planning scene, fetched once on first use: the obstacles' motion epoch (from its world)
  /// and the path tolerances (its joint radius bounds and the tracking budget). False with *error if unavailable.
  bool ensureSceneFacts(std::string* error) {
    if (scene_facts_) return true;
    moverl_msgs::GetWorld gw;
    const double timeout = scene_margin_;
    const CallEnd end = scene_->world(gw, timeout);
    if (end != CallEnd::kAnswered) {
      *error = describe(end, scene_->name(), timeout);
      return false;
    }
    motion_epoch_ = gw.response.world.motion_epoch;
    SceneFacts facts;
    if (!scene_->facts(&facts, error)) return false;
    if (facts.joint_radius_bounds.size() != joints_.size()) {
      *error = "the planning scene's joint_radius_bounds has " + std::to_string(facts.joint_radius_bounds.size()) +
               " values for " + std::to_string(joints_.size()) + " joints";
      return false;
    }
    const double padding = facts.padding, resolution = facts.path_resolution;
    // The padding leaves padding - path_resolution / 2 between the robot and any obstacle along a checked path
    // (checked states are `padding` clear; between two of them no point moves more than path_resolution). Tracking
    // errors must stay within that.
    const double slack = padding - resolution / 2.0;
    if (tracking_budget_ > slack + 1e-12) {
      *error = "~tracking_budget " + std::to_string(tracking_budget_) +
               " m exceeds what the padding leaves along a path (" + std::to_string(slack) +
               " m = padding - path_resolution / 2)";
      return false;
    }
    driver_->setPathTolerance(pathTolerances(tracking_budget_, facts.joint_radius_bounds));
    planning_time_ = facts.planning_time;
    scene_facts_ = true;
    return true;
  }

  double sceneTimeout() const { return planning_time_ + scene_margin_; }

  // ----------------------------------------------------------------------------------------------------- step
  bool step(moverl_msgs::ShieldStep::Request& req, moverl_msgs::ShieldStep::Response& res) {
    res.strategy = enabled_ ? strategyName(strategy_) : "";
    res.unsafe_cause = 0;
    res.truncated_fraction = -1.0;
    res.driver_error_code = 0;
    res.contacts.available = driver_->sensesContacts();
    const bool publish = events_pub_.getNumSubscribers() > 0;  // visualisation only: nothing extra otherwise
    executed_.points.clear();
    RobotState start;
    res.verdict = code(run(req, res, &start));
    if (publish) publishEvent(req, res, start);
    if (have_state_) fillState(last_, res.state, res.ee_pose);
    if (res.contacts.header.stamp.isZero()) {
      // No motion this step: no contacts, as far as the driver's last report goes.
      res.contacts.header.stamp = last_.stamp;
      res.contacts.total_contact_substeps = total_contact_substeps_;
    }
    return true;
  }

  Verdict run(const moverl_msgs::ShieldStep::Request& req, moverl_msgs::ShieldStep::Response& res, RobotState* s) {
    if (abandoned(req.not_after)) {
      res.message = "request served after its caller gave up on it (the shield was stalled): nothing moves";
      ROS_WARN("shield: %s", res.message.c_str());
      return Verdict::kInvalidRequest;
    }
    std::string bad = validateTarget(req.target, joints_.size());
    if (bad.empty() && !(std::isfinite(req.duration) && req.duration >= 0.0 && req.duration <= kMaxStepDuration)) {
      bad = "duration must be finite, >= 0 and <= " + std::to_string(kMaxStepDuration) + " s, got " +
            std::to_string(req.duration);
    }
    if (!bad.empty()) {
      res.message = bad;
      return Verdict::kInvalidRequest;
    }
    std::string error;
    if (!driver_->currentState(s, &error)) {
      res.message = "joint states: " + error;
      return Verdict::kStateUnavailable;
    }
    adopt(*s);
    const bool real_time = driver_->realTime();
    if (!ensureSceneFacts(&error)) {
      res.message = "planning scene: " + error + ": failing closed, robot held";
      return Verdict::kSceneUnavailable;
    }
    Decision decision;
    if (!enabled_) {
      decision = passThrough(s->q, req.target);
    } else {
      moverl_msgs::ValidateMotion vm;
      vm.request.start = s->q;
      vm.request.goal = req.target;
      vm.request.plan_on_path_collision = wantsPlan(strategy_);
      vm.request.find_last_free = wantsLastFree(strategy_);
      double straight;
      try {
        straight = timeTrajectory(profile_, {s->q, req.target}, limits_, req.duration, sample_period_).duration();
      } catch (const std::exception& e) {
        res.message = std::string("cannot time the move: ") + e.what();
        return Verdict::kExecutionFailed;
      }
      const ros::Time check_begin = real_time ? ros::Time::now() : ros::Time();
      setWindow(*s, check_begin, straight, &vm.request);
      const double timeout = sceneTimeout();
      const CallEnd end = scene_->validate(vm, timeout);
      if (end != CallEnd::kAnswered) {
        res.message = "planning scene: " + describe(end, scene_->name(), timeout) + ": failing closed, robot held";
        ROS_WARN_THROTTLE(5.0, "%s", res.message.c_str());
        return Verdict::kSceneUnavailable;
      }
      res.pairs = vm.response.pairs;
      res.state_check_time = vm.response.state_check_time;
      res.path_check_time = vm.response.path_check_time;
      res.planning_time = vm.response.planning_time;
      res.message = vm.response.message;
      SceneAnswer answer;
      answer.outcome = static_cast<SceneOutcome>(vm.response.outcome);
      answer.replanned = vm.response.replanned;
      answer.plan.reserve(vm.response.path.points.size());
      for (const auto& p : vm.response.path.points) answer.plan.push_back(p.positions);
      answer.last_free_fraction = vm.response.last_free_fraction;
      answer.last_free_state = vm.response.last_free_state;
      decision = decide(strategy_, answer, s->q, req.target);
      res.unsafe_cause = decision.unsafe_cause;
      res.truncated_fraction = decision.truncated_fraction;
      const bool windowed = decision.verdict == Verdict::kSafe || decision.verdict == Verdict::kTruncated;
      if (real_time && windowed && (ros::Time::now() - check_begin).toSec() > check_budget_) {
        // The window checked assumed the move starts within check_budget + start_lead of the check: too late now.
        res.message = "planning scene answered after " + std::to_string((ros::Time::now() - check_begin).toSec()) +
                      " s, beyond the real-time check_budget of " + std::to_string(check_budget_) +
                      " s: the move was not sent (failing closed)";
        return Verdict::kSceneUnavailable;
      }
      if (!real_time && decision.waypoints.empty() && vm.response.moving_obstacles && req.duration > 0.0 &&
          decision.verdict != Verdict::kSceneUnavailable && decision.verdict != Verdict::kInvalidRequest) {
        // Lockstep: hold still for the step's duration through the driver, so that the obstacles keep moving.
        // Safe: the robot rests at a state checked free of every obstacle's whole motion envelope.
        decision.waypoints = {s->q};
      }
      if (decision.verdict == Verdict::kReplanned && vm.response.plan_horizon > 0.0) {
        // Sensed obstacles: the plan was checked with the margin of a move lasting plan_horizon; a slower one is not
        // covered by that check.
        double planned = 0.0;
        try {
          planned = timeTrajectory(profile_, decision.waypoints, limits_, req.duration, sample_period_).duration();
        } catch (const std::exception& e) {
          res.message = std::string("cannot time the plan: ") + e.what();
          return Verdict::kExecutionFailed;
        }
        if (planned > vm.response.plan_horizon) {
          res.message += "; the plan lasts " + std::to_string(planned) + " s, longer than the sensed margin covers (" +
                         std::to_string(vm.response.plan_horizon) + " s): held still";
          decision.verdict = Verdict::kDiscardedPath;
          decision.waypoints.clear();
          if (!real_time && vm.response.moving_obstacles && req.duration > 0.0) decision.waypoints = {s->q};
        }
      }
      if (decision.verdict == Verdict::kTruncated) {
        res.message += "; truncated: moved to the last safe state at fraction " +
                       std::to_string(decision.truncated_fraction) + " of the straight path";
      }
    }
    if (decision.waypoints.empty()) return decision.verdict;
    return move(decision.waypoints, decision.verdict, req.duration, limits_, res);
  }

  /// The ValidateMotion window of the straight move from state s (see driver_core.h realTimeWindow).
  void setWindow(const RobotState& s, const ros::Time& check_begin, double duration,
                 moverl_msgs::ValidateMotion::Request* vm) const {
    if (driver_->realTime()) {
      const MotionWindow w = realTimeWindow(s.stamp.toSec(), motion_epoch_.toSec(),
                                            check_begin.toSec() + check_budget_ + start_lead_, duration, goal_time_);
      vm->start_time = w.start_time;
      vm->duration = w.duration;
    } else {
      vm->start_time = s.stamp.toSec() - motion_epoch_.toSec();  // in doubles: any stamp a driver sends is safe
      vm->duration = duration;
    }
    // The absolute time of start_time (the sensed map's age is measured against it).
    const double stamp = motion_epoch_.toSec() + vm->start_time;
    vm->stamp = stamp > 0.0 ? ros::Time(stamp) : ros::Time(0, 1);
  }

  /// Time and execute waypoints (the first is the current state); the verdict after the driver's result.
  Verdict move(const Waypoints& waypoints, Verdict decided, double min_duration, const TimingLimits& limits,
               moverl_msgs::ShieldStep::Response& res) {
    TimedTrajectory trajectory;
    try {
      trajectory = timeTrajectory(profile_, waypoints, limits, min_duration, sample_period_);
    } catch (const std::exception& e) {
      res.message = std::string("cannot time the trajectory: ") + e.what();
      return Verdict::kExecutionFailed;
    }
    if (!(trajectory.duration() > 0.0)) return decided;  // nothing to move (e.g. a reset to where the robot stands)
    if (events_pub_.getNumSubscribers() > 0) {
      executed_.joint_names = joints_;
      executed_.points.resize(trajectory.positions.size());
      for (std::size_t k = 0; k < trajectory.positions.size(); ++k) {
        executed_.points[k].positions = trajectory.positions[k];
        executed_.points[k].time_from_start = ros::Duration(trajectory.times[k]);
      }
    }
    const ros::Time start = driver_->realTime() ? ros::Time::now() + ros::Duration(start_lead_) : ros::Time();
    MoveResult r = driver_->execute(trajectory, start);
    setExecution(r, res);
    const Verdict verdict = verdictForDriverEnd(decided, r.end, r.error_code);
    if (verdict != decided) {
      res.message =
          "driver " + driver_->name() + ": " + r.message + (res.message.empty() ? "" : " (" + res.message + ")");
    }
    RobotState after;
    std::string error;
    if (r.end != DriverEnd::kTimedOut && r.end != DriverEnd::kUnreachable) {
      if (!driver_->currentState(&after, &error)) {
        res.message = "joint states after the move: " + error;
        return Verdict::kStateUnavailable;
      }
      adopt(after);
    }
    return verdict;
  }

  void setExecution(const MoveResult& r, moverl_msgs::ShieldStep::Response& res) {
    res.execution_time = r.seconds;
    res.driver_error_code = r.error_code;
    if (r.contacts.available) {
      res.contacts = r.contacts;
      total_contact_substeps_ = r.contacts.total_contact_substeps;
    }
  }

  void adopt(const RobotState& s) {
    last_ = s;
    have_state_ = true;
  }

  void fillState(const RobotState& s, sensor_msgs::JointState& state, geometry_msgs::Pose& ee) const {
    state.header.stamp = s.stamp;
    state.name = joints_;
    state.position = s.q;
    scene_->model().computeLinkTransforms(s.q.data(), &link_poses_);
    const Eigen::Isometry3d& pose = link_poses_[static_cast<std::size_t>(ee_link_)];
    const Eigen::Quaterniond q(pose.linear());
    ee.position.x = pose.translation().x();
    ee.position.y = pose.translation().y();
    ee.position.z = pose.translation().z();
    ee.orientation.x = q.x();
    ee.orientation.y = q.y();
    ee.orientation.z = q.z();
    ee.orientation.w = q.w();
  }

  /// Tell visualisers and loggers what this step did (only called while ~events has subscribers).
  void publishEvent(const moverl_msgs::ShieldStep::Request& req, const moverl_msgs::ShieldStep::Response& res,
                    const RobotState& start) {
    moverl_msgs::ShieldEvent ev;
    ev.header.stamp = start.stamp;
    ev.verdict = res.verdict;
    ev.verdict_name = verdictName(static_cast<Verdict>(res.verdict));
    ev.joint_names = joints_;
    ev.start = start.q;
    ev.target = req.target;
    ev.executed = executed_;
    ev.pairs = res.pairs;
    events_pub_.publish(ev);
  }

  // ---------------------------------------------------------------------------------------------------- reset
  bool serveReset(moverl_msgs::ResetRobot::Request& req, moverl_msgs::ResetRobot::Response& res) {
    std::lock_guard<std::mutex> lock(serve_mutex_);
    return reset(req, res);
  }
  bool reset(moverl_msgs::ResetRobot::Request& req, moverl_msgs::ResetRobot::Response& res) {
    res.success = false;
    res.unreachable = false;
    std::string error;
    if (abandoned(req.not_after)) {
      res.message = "reset served after its caller gave up on it (the shield was stalled): nothing moves";
      ROS_WARN("shield: %s", res.message.c_str());
      return true;
    }
    if (req.positions.empty()) {  // start the episode where the robot is
      RobotState s;
      if (!driver_->currentState(&s, &error)) {
        res.message = "joint states: " + error;
        return true;
      }
      adopt(s);
      if (!ensureSceneFacts(&error)) {
        res.message = "planning scene: " + error;
        return true;
      }
      res.success = true;
      res.motion_epoch = motion_epoch_;
      geometry_msgs::Pose unused;
      fillState(last_, res.state, unused);
      return true;
    }
    const std::string bad = validateTarget(req.positions, joints_.size());
    if (!bad.empty()) {
      res.message = bad;
      return true;
    }
    if (driver_->canTeleport()) {
      if (!driver_->teleport(req.positions, &res, &error)) {
        res.success = false;
        res.message = error;
        return true;
      }
      motion_epoch_ = res.state.header.stamp;  // the simulator restarted the obstacles' motions at this stamp
      RobotState s;
      driver_->currentState(&s, &error);
      adopt(s);
    } else if (!ensureSceneFacts(&error)) {
      res.message = "planning scene: " + error;
      return true;
    } else {
      plannedReset(req.positions, res);
    }
    res.motion_epoch = motion_epoch_;
    if (have_state_) {
      geometry_msgs::Pose unused;
      res.state = sensor_msgs::JointState();
      fillState(last_, res.state, unused);
    }
    return true;
  }

  /// A reset with a driver that cannot teleport: move there, checked as a step is, at reset_velocity_scale.
  void plannedReset(const std::vector<double>& target, moverl_msgs::ResetRobot::Response& res) {
    RobotState s;
    std::string error;
    if (!driver_->currentState(&s, &error)) {
      res.message = "joint states: " + error;
      return;
    }
    adopt(s);
    TimingLimits limits = limits_;
    limits.velocity_scale = reset_velocity_scale_;
    Waypoints waypoints{s.q, target};
    if (enabled_) {
      moverl_msgs::ValidateMotion vm;
      vm.request.start = s.q;
      vm.request.goal = target;
      vm.request.plan_on_path_collision = false;  // planned below with the reset's own time limit
      vm.request.find_last_free = false;
      const double straight = timeTrajectory(profile_, waypoints, limits, 0.0, sample_period_).duration();
      const ros::Time check_begin = ros::Time::now();
      setWindow(s, check_begin, straight, &vm.request);
      const double timeout = sceneTimeout();
      const CallEnd end = scene_->validate(vm, timeout);
      if (end != CallEnd::kAnswered) {
        res.message = "planning scene: " + describe(end, scene_->name(), timeout);
        return;
      }
      switch (vm.response.outcome) {
        case SceneRes::VALID:
          if ((ros::Time::now() - check_begin).toSec() > check_budget_) {
            res.message = "planning scene answered beyond the real-time check_budget: reset move not sent";
            return;
          }
          break;
        case SceneRes::PATH_COLLISION: {
          moverl_msgs::PlanPath plan;
          plan.request.start = s.q;
          plan.request.goal = target;
          plan.request.time_limit = reset_planning_time_;
          const double plan_timeout = reset_planning_time_ + scene_margin_;
          const CallEnd pend = scene_->plan(plan, plan_timeout);
          if (pend != CallEnd::kAnswered) {
            res.message = "planning scene: " + describe(pend, scene_->name(), plan_timeout);
            return;
          }
          if (plan.response.outcome != moverl_msgs::PlanPath::Response::SUCCESS) {
            res.unreachable = plan.response.outcome == moverl_msgs::PlanPath::Response::NO_SOLUTION;
            res.message = "no collision-free path to the reset target: " + plan.response.message;
            return;
          }
          waypoints.clear();
          for (const auto& p : plan.response.path.points) waypoints.push_back(p.positions);
          waypoints.front() = s.q;
          break;
        }
        case SceneRes::START_IN_COLLISION:
          res.message = "the robot is not free where it stands (" + vm.response.message +
                        "): a planned reset cannot start from there; move the robot out by hand (or with its "
                        "teach pendant) and reset again";
          return;
        default:
          res.message = "reset target refused: " + vm.response.message;
          return;
      }
    }
    moverl_msgs::ShieldStep::Response step_res;  // the move's report, for its message
    const Verdict v = move(waypoints, enabled_ ? Verdict::kSafe : Verdict::kUnchecked, 0.0, limits, step_res);
    res.success = v == Verdict::kSafe || v == Verdict::kUnchecked;
    res.message = step_res.message;
  }

  ros::NodeHandle& nh_;
  ros::CallbackQueue driver_queue_;
  std::unique_ptr<ros::AsyncSpinner> driver_spinner_;
  std::unique_ptr<SceneAccess> scene_;
  std::unique_ptr<Driver> driver_;
  ros::Publisher events_pub_;
  trajectory_msgs::JointTrajectory executed_;  // what this step sent to the driver (for ~events)
  std::mutex serve_mutex_;                     ///< one step or reset at a time
  std::unique_ptr<TcprosServiceServer> step_srv_;
  ros::ServiceServer reset_srv_;
  std::vector<std::string> joints_;
  int ee_link_ = -1;                                   ///< index of the end-effector link in the model's links
  mutable std::vector<Eigen::Isometry3d> link_poses_;  ///< FK scratch
  bool enabled_ = true;
  Strategy strategy_ = Strategy::kPlan;
  Profile profile_ = Profile::kLinear;
  TimingLimits limits_;
  double reset_velocity_scale_ = 0.0, sample_period_ = 0.0, scene_margin_ = 0.0, check_budget_ = 0.0;
  double reset_planning_time_ = 0.0, tracking_budget_ = 0.0, start_lead_ = 0.0, goal_time_ = 0.0;
  double planning_time_ = 0.0;
  bool scene_facts_ = false;
  RobotState last_;  ///< the latest state the shield knows (reported in responses)
  bool have_state_ = false;
  ros::Time motion_epoch_;  ///< when the obstacles' motion time was 0 (driver clock)
  std::uint64_t total_contact_substeps_ = 0;
};

}  // namespace moverl_shield

int main(int argc, char** argv) {
  ros::init(argc, argv, "shield");
  ros::NodeHandle nh, pnh("~");
  try {
    moverl_shield::ShieldNode node(nh, pnh);
    ros::spin();
  } catch (const std::exception& e) {
    ROS_FATAL("shield: %s", e.what());
    return 1;
  }
  return 0;
}
