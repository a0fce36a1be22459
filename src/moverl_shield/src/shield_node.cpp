// The MoveRL shield node: the ROS shell around the shield's core (moverl_shield/shield.h, where every decision, timing
// rule and deadline of a step and a reset lives, tested without ROS in test/test_shield.cpp).
//
// This file only reads the parameters (config/shield.yaml and the launch file's arguments), builds the core's three
// interfaces with ROS (the driver: drivers.h; the planning scene, hosted in this process or reached through its
// services: scene_access.h; the clock), serves ~step and ~reset, and converts between the messages and the core's
// plain types (adding the end-effector pose of the state and the ~events for visualisers).
//
// Threads: ~step is served over TCPROS by a thread per client connection (moverl_tcpros), which also makes the step's
// calls to the simulator: no hand-offs between threads on the hot path. ~reset runs on the global callback queue; a
// mutex lets one step or reset run at a time. The driver's joint states and action callbacks run on their own queue
// and thread, so they arrive while a step waits.
#include <csignal>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <control_msgs/FollowJointTrajectoryResult.h>
#include <moverl_msgs/ResetRobot.h>
#include <moverl_msgs/ShieldEvent.h>
#include <moverl_msgs/ShieldStep.h>
#include <ros/callback_queue.h>
#include <ros/ros.h>
#include <trajectory_msgs/JointTrajectory.h>

#include "deadline.h"
#include "drivers.h"
#include "moverl_shield/shield.h"
#include "moverl_tcpros/server.h"
#include "scene_access.h"

namespace moverl_shield {
namespace {

// The core's codes are the messages' codes: checked here, where both are visible, at compile time.
using StepRes = moverl_msgs::ShieldStep::Response;
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
                  code(Verdict::kStateUnavailable) == StepRes::STATE_UNAVAILABLE &&
                  code(Verdict::kRetreated) == StepRes::RETREATED,
              "moverl_shield::Verdict differs from moverl_msgs/ShieldStep");
constexpr std::int32_t code(TrajectoryError e) { return static_cast<std::int32_t>(e); }
static_assert(code(TrajectoryError::kSuccessful) == FjtResult::SUCCESSFUL &&
                  code(TrajectoryError::kInvalidGoal) == FjtResult::INVALID_GOAL &&
                  code(TrajectoryError::kInvalidJoints) == FjtResult::INVALID_JOINTS &&
                  code(TrajectoryError::kOldHeaderTimestamp) == FjtResult::OLD_HEADER_TIMESTAMP &&
                  code(TrajectoryError::kPathToleranceViolated) == FjtResult::PATH_TOLERANCE_VIOLATED &&
                  code(TrajectoryError::kGoalToleranceViolated) == FjtResult::GOAL_TOLERANCE_VIOLATED,
              "moverl_shield::TrajectoryError differs from control_msgs/FollowJointTrajectoryResult");

/// A private parameter that config/shield.yaml must set (the YAML is where every tunable lives, with its comment).
template <class T>
T required(const ros::NodeHandle& pnh, const std::string& name) {
  T value;
  if (!pnh.getParam(name, value)) {
    throw std::runtime_error("parameter " + pnh.resolveName(name) + " is not set (load config/shield.yaml)");
  }
  return value;
}

/// The driver's clock is ROS time (/clock with use_sim_time, else the wall).
class RosClock : public Clock {
 public:
  double now() const override { return ros::Time::now().toSec(); }
  double wall() const override { return wallSeconds(); }
};

void toPairs(const std::vector<moverl_planning_scene::ContactPair>& in, std::vector<moverl_msgs::CollisionPair>* out) {
  out->resize(in.size());
  for (std::size_t k = 0; k < in.size(); ++k) {
    (*out)[k].a = in[k].a;
    (*out)[k].b = in[k].b;
    (*out)[k].depth = in[k].depth;
  }
}

}  // namespace

class ShieldNode {
 public:
  ShieldNode(ros::NodeHandle& nh, ros::NodeHandle& pnh) {
    ShieldOptions o;
    o.enabled = required<bool>(pnh, "enabled");
    const std::string strategy = required<std::string>(pnh, "strategy");
    if (!parseStrategy(strategy, &o.strategy)) {
      throw std::runtime_error("unknown ~strategy '" + strategy + "' (expected one of: " + strategyNames() + ")");
    }
    const std::string profile = required<std::string>(pnh, "profile");
    if (!parseProfile(profile, &o.profile)) {
      throw std::runtime_error("unknown ~profile '" + profile + "' (expected linear or min_jerk)");
    }
    o.limits.velocity_scale = required<double>(pnh, "velocity_scale");
    o.reset_velocity_scale = required<double>(pnh, "reset_velocity_scale");
    o.sample_period = required<double>(pnh, "sample_period");
    o.scene_margin = required<double>(pnh, "scene_margin");
    o.check_budget = required<double>(pnh, "check_budget");
    o.reset_planning_time = required<double>(pnh, "reset_planning_time");
    o.reset_horizon = required<double>(pnh, "reset_horizon");
    o.tracking_budget = required<double>(pnh, "tracking_budget");
    DriverOptions driver;
    driver.result_margin = required<double>(pnh, "result_margin");
    driver.max_state_age = required<double>(pnh, "max_state_age");
    driver.limit_tolerance = required<double>(pnh, "limit_tolerance");
    driver.start_lead = required<double>(pnh, "start_lead");
    driver.goal_time = required<double>(pnh, "goal_time");
    driver.stopped_velocity_tolerance = required<double>(pnh, "stopped_velocity_tolerance");
    o.start_lead = driver.start_lead;
    o.goal_time = driver.goal_time;
    // Optional: the robot's joint acceleration limits (URDFs have none); min_jerk moves respect them.
    nh.getParam("robot/acceleration_limits", o.limits.acceleration);

    // The planning scene, in this process or behind its services; its robot model is the shield's too.
    scene_ = createScene(required<std::string>(pnh, "scene"), nh, required<std::string>(pnh, "scene_namespace"));
    const moverl_planning_scene::RobotModel& model = scene_->model();
    ee_link_ = model.linkIndex(model.eeLink());

    const std::string name = required<std::string>(pnh, "driver");
    // The driver's callbacks (joint states, action results) run on their own queue and thread.
    ros::NodeHandle driver_nh(nh);
    driver_nh.setCallbackQueue(&driver_queue_);
    if (name == "follow_joint_trajectory") {
      auto fjt = std::make_unique<FollowJointTrajectoryDriver>(
          driver_nh, model.jointNames(), model.lowerLimits(), model.upperLimits(), required<std::string>(pnh, "action"),
          required<std::string>(pnh, "joint_states"), driver);
      driver_spinner_ = std::make_unique<ros::AsyncSpinner>(1, &driver_queue_);
      driver_spinner_->start();
      std::string error;
      if (!fjt->waitUntilReady(required<double>(pnh, "startup_timeout"), &error)) {
        throw std::runtime_error("the robot's driver is not ready: " + error);
      }
      driver_ = std::move(fjt);
    } else if (name == "sim_service") {
      driver_ = std::make_unique<SimServiceDriver>(driver_nh, model.jointNames(), model.lowerLimits(),
                                                   model.upperLimits(), required<std::string>(pnh, "execute_service"),
                                                   required<std::string>(pnh, "reset_service"), driver);
      driver_spinner_ = std::make_unique<ros::AsyncSpinner>(1, &driver_queue_);
      driver_spinner_->start();
    } else {
      throw std::runtime_error("unknown ~driver '" + name + "' (expected follow_joint_trajectory or sim_service)");
    }
    shield_ = std::make_unique<Shield>(o, driver_.get(), scene_.get(), &clock_);

    reset_srv_ = pnh.advertiseService("reset", &ShieldNode::serveReset, this);
    events_pub_ = pnh.advertise<moverl_msgs::ShieldEvent>("events", 10);
    // ~step is served over TCPROS by threads of its own (moverl_tcpros: the hot path without roscpp's thread
    // hand-offs), from the moment it is advertised: last, once everything a step uses is built. ~reset runs on the
    // global queue; serve_mutex_ lets one of them run at a time.
    moverl_tcpros::ServerOptions step_options;
    const int step_clients = required<int>(pnh, "step_clients");
    if (step_clients < 1) {
      throw std::runtime_error("~step_clients must be at least 1, not " + std::to_string(step_clients));
    }
    step_options.max_clients = static_cast<std::size_t>(step_clients);
    step_srv_ = moverl_tcpros::advertiseDirect<moverl_msgs::ShieldStep>(
        pnh.resolveName("step"),
        [this](moverl_msgs::ShieldStep::Request& req, moverl_msgs::ShieldStep::Response& res) {
          std::lock_guard<std::mutex> lock(serve_mutex_);
          return step(req, res);
        },
        step_options);
    ROS_INFO("shield ready (%s, strategy %s, %s profile), %zu joints, scene %s, driver %s",
             o.enabled ? "enabled" : "DISABLED", strategyName(o.strategy).c_str(), profileName(o.profile).c_str(),
             shield_->joints().size(), scene_->name().c_str(), driver_->name().c_str());
  }

  ~ShieldNode() {
    step_srv_.reset();  // unregisters ~step and waits for a step that is running
    if (driver_spinner_) driver_spinner_->stop();
  }

 private:
  bool step(moverl_msgs::ShieldStep::Request& req, moverl_msgs::ShieldStep::Response& res) {
    const bool publish = events_pub_.getNumSubscribers() > 0;  // visualisation only: nothing extra otherwise
    request_.target.swap(req.target);
    request_.duration = req.duration;
    request_.not_after = req.not_after;
    StepResult& r = result_;
    shield_->step(request_, &r, publish);
    res.verdict = static_cast<std::uint8_t>(r.verdict);
    res.message = r.message;
    toPairs(r.pairs, &res.pairs);
    res.state_check_time = r.state_check_time;
    res.path_check_time = r.path_check_time;
    res.planning_time = r.planning_time;
    res.execution_time = r.execution_time;
    res.strategy = shield_->options().enabled ? strategyName(shield_->options().strategy) : "";
    res.unsafe_cause = r.unsafe_cause;
    res.truncated_fraction = r.truncated_fraction;
    res.driver_error_code = r.driver_error_code;
    res.map_age = r.map_age;
    res.sensed_margin = r.sensed_margin;
    toMsg(r.contacts, &res.contacts);
    if (shield_->lastState(&last_)) fillState(last_, res.state, res.ee_pose);
    if (r.verdict == Verdict::kSceneUnavailable || r.verdict == Verdict::kInvalidRequest) {
      ROS_WARN_THROTTLE(5.0, "shield: %s", r.message.c_str());
    }
    if (publish) publishEvent(r);
    return true;
  }

  void fillState(const RobotState& s, sensor_msgs::JointState& state, geometry_msgs::Pose& ee) const {
    state.header.stamp.fromNSec(static_cast<std::uint64_t>(s.stamp));
    state.name = shield_->joints();
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
  void publishEvent(const StepResult& r) {
    moverl_msgs::ShieldEvent ev;
    ev.header.stamp.fromNSec(static_cast<std::uint64_t>(r.start.stamp));
    ev.verdict = static_cast<std::uint8_t>(r.verdict);
    ev.verdict_name = verdictName(r.verdict);
    ev.joint_names = shield_->joints();
    ev.start = r.start.q;
    ev.target = request_.target;
    ev.executed.joint_names = shield_->joints();
    ev.executed.points.resize(r.executed.positions.size());
    for (std::size_t k = 0; k < r.executed.positions.size(); ++k) {
      ev.executed.points[k].positions = r.executed.positions[k];
      ev.executed.points[k].time_from_start = ros::Duration(r.executed.times[k]);
    }
    toPairs(r.pairs, &ev.pairs);
    events_pub_.publish(ev);
  }

  bool serveReset(moverl_msgs::ResetRobot::Request& req, moverl_msgs::ResetRobot::Response& res) {
    std::lock_guard<std::mutex> lock(serve_mutex_);
    ResetRequest request;
    request.positions = req.positions;
    request.not_after = req.not_after;
    ResetResult r;
    shield_->reset(request, &r);
    res.success = r.success;
    res.unreachable = r.unreachable;
    res.message = r.message;
    res.motion_epoch.fromNSec(static_cast<std::uint64_t>(r.motion_epoch));
    res.moves = r.moves;
    res.path_duration = r.planned_duration;
    if (!r.success) ROS_WARN_THROTTLE(5.0, "shield: reset: %s", r.message.c_str());
    geometry_msgs::Pose unused;
    if (shield_->lastState(&last_)) fillState(last_, res.state, unused);
    return true;
  }

  RosClock clock_;
  ros::CallbackQueue driver_queue_;
  std::unique_ptr<ros::AsyncSpinner> driver_spinner_;
  std::unique_ptr<Scene> scene_;
  std::unique_ptr<Driver> driver_;
  std::unique_ptr<Shield> shield_;
  ros::Publisher events_pub_;
  std::mutex serve_mutex_;  ///< one step or reset at a time
  std::unique_ptr<moverl_tcpros::ServiceServer> step_srv_;
  ros::ServiceServer reset_srv_;
  StepRequest request_;  ///< the step's request and result, reused (no allocation per step once grown)
  StepResult result_;
  RobotState last_;
  int ee_link_ = -1;                                   ///< index of the end-effector link in the model's links
  mutable std::vector<Eigen::Isometry3d> link_poses_;  ///< FK scratch
};

}  // namespace moverl_shield

namespace {
volatile std::sig_atomic_t g_stop = 0;     ///< SIGINT came
volatile std::sig_atomic_t g_serving = 0;  ///< the node is built and spinning
void onSigint(int) {
  g_stop = 1;
  if (!g_serving) ros::requestShutdown();  // while the node is built: what roscpp's own handler does
}
}  // namespace

int main(int argc, char** argv) {
  // SIGINT (roslaunch's stop) ends the spin below instead of shutting roscpp down at once, so that ~step is
  // unregistered from the master while the node is still up (the node's destructor), before ros::shutdown().
  ros::init(argc, argv, "shield", ros::init_options::NoSigintHandler);
  std::signal(SIGINT, onSigint);
  int rc = 0;
  {
    ros::NodeHandle nh, pnh("~");
    try {
      moverl_shield::ShieldNode node(nh, pnh);
      g_serving = 1;
      ros::CallbackQueue* queue = ros::getGlobalCallbackQueue();
      while (!g_stop && ros::ok()) queue->callAvailable(ros::WallDuration(0.1));  // ros::spin(), ending on SIGINT too
    } catch (const std::exception& e) {
      ROS_FATAL("shield: %s", e.what());
      rc = 1;
    }
  }
  ros::shutdown();
  return rc;
}
