// The MoveRL shield node: a thin ROS shell around moverl_shield's core.
//
// Per env step (service ~step): read the current state, make ONE ValidateMotion call to the planning scene,
// then execute the direct move, the replacement plan or the truncated straight move through the driver's
// ExecuteTrajectory service, or hold still. ~strategy says what happens to an unsafe action (plan, discard,
// last_safe; see config/shield.yaml). With moving obstacles the scene checks the straight move against where they
// will be during its execution (motion time = state stamp - stamp of the last reset), and a held-still step
// executes a zero-motion trajectory of the step's duration so the world keeps moving. Connections are persistent; nothing waits for a service on the hot path. If the scene cannot
// be reached the shield fails closed: nothing moves and the verdict says SCENE_UNAVAILABLE.
//
// The shield talks to the robot only through what a driver offers: joint states in (the `joint_states`
// topic and the state returned by each execution) and joint trajectories out. ~reset forwards to a
// simulator's reset service, when the driver has one.
#include <chrono>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <moverl_msgs/ExecuteTrajectory.h>
#include <moverl_msgs/ResetRobot.h>
#include <moverl_msgs/ShieldEvent.h>
#include <trajectory_msgs/JointTrajectory.h>
#include <moverl_msgs/ShieldStep.h>
#include <moverl_msgs/ValidateMotion.h>
#include <ros/ros.h>
#include <sensor_msgs/JointState.h>

#include "moverl_shield/kinematics.h"
#include "moverl_shield/shield_core.h"

namespace moverl_shield {
namespace {

double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

/// A persistent service client that reconnects (without waiting) after its server went away.
template <class Srv>
class PersistentClient {
 public:
  PersistentClient(ros::NodeHandle& nh, std::string name) : nh_(nh), name_(std::move(name)) {}

  /// \brief Call the service; on a broken connection reconnect once if the server exists again.
  bool call(Srv& srv) {
    for (int attempt = 0; attempt < 2; ++attempt) {
      if (!client_.isValid()) {
        if (!ros::service::exists(name_, false)) return false;
        client_ = nh_.serviceClient<Srv>(name_, /*persistent=*/true);
      }
      if (client_.call(srv)) return true;
      client_.shutdown();
    }
    return false;
  }
  const std::string& name() const { return name_; }

 private:
  ros::NodeHandle& nh_;
  std::string name_;
  ros::ServiceClient client_;
};

class ShieldNode {
 public:
  ShieldNode(ros::NodeHandle& nh, ros::NodeHandle& pnh)
      : nh_(nh),
        scene_(nh_, pnh.param<std::string>("scene_service", "/planning_scene/validate_motion")),
        execute_(nh_, pnh.param<std::string>("execute_service", "/sim/execute")),
        reset_(nh_, pnh.param<std::string>("reset_service", "/sim/reset_robot")) {
    // false: pass targets straight to the driver without checks (the "shield off" baseline).
    enabled_ = pnh.param("enabled", true);
    // What happens to an unsafe action: plan (default, the paper's), discard, last_safe.
    const std::string strategy = pnh.param<std::string>("strategy", "plan");
    if (!parseStrategy(strategy, &strategy_)) {
      throw std::runtime_error("unknown ~strategy '" + strategy + "' (expected one of: " + strategyNames() + ")");
    }
    if (pnh.hasParam("plan_on_path_collision")) {
      ROS_WARN("shield: ~plan_on_path_collision is obsolete and ignored; use ~strategy (plan, discard, last_safe)");
    }
    // Fraction of the URDF velocity limits used to time plans and direct moves.
    velocity_scale_ = pnh.param("velocity_scale", 1.0);

    std::string urdf, base_link, ee_link;
    if (!nh.getParam("robot_description", urdf)) throw std::runtime_error("parameter /robot_description is not set");
    if (!nh.getParam("robot/joints", joints_) || joints_.empty()) {
      throw std::runtime_error("parameter /robot/joints is not set (load config/robots/<robot>.yaml)");
    }
    if (!nh.getParam("robot/base_link", base_link) || !nh.getParam("robot/ee_link", ee_link)) {
      throw std::runtime_error("parameters /robot/base_link and /robot/ee_link must be set");
    }
    std::map<std::string, double> fixed;
    nh.getParam("robot/fixed_joint_positions", fixed);
    kinematics_ = std::make_unique<ChainKinematics>(urdf, base_link, ee_link, joints_, fixed);
    for (size_t i = 0; i < joints_.size(); ++i) index_[joints_[i]] = i;

    state_sub_ = nh.subscribe("joint_states", 10, &ShieldNode::onJointState, this);
    step_srv_ = pnh.advertiseService("step", &ShieldNode::step, this);
    reset_srv_ = pnh.advertiseService("reset", &ShieldNode::reset, this);
    events_pub_ = pnh.advertise<moverl_msgs::ShieldEvent>("events", 10);
    ROS_INFO("shield ready (%s, strategy %s), %zu joints, scene %s, driver %s", enabled_ ? "enabled" : "DISABLED",
             strategyName(strategy_).c_str(), joints_.size(), scene_.name().c_str(), execute_.name().c_str());
  }

 private:
  /// Adopt a measured state if it is newer than what we know (stamps from the driver's clock).
  void onJointState(const sensor_msgs::JointStateConstPtr& msg) {
    if (have_state_ && msg->header.stamp <= state_stamp_) return;
    adoptState(*msg);
  }

  /// Copy a JointState into q_ (controlled joints only). Returns false if a joint is missing.
  bool adoptState(const sensor_msgs::JointState& msg) {
    std::vector<double> q(joints_.size(), 0.0);
    size_t found = 0;
    for (size_t k = 0; k < msg.name.size() && k < msg.position.size(); ++k) {
      auto it = index_.find(msg.name[k]);
      if (it == index_.end()) continue;
      q[it->second] = msg.position[k];
      ++found;
    }
    if (found != joints_.size()) return false;
    q_ = std::move(q);
    state_stamp_ = msg.header.stamp;
    have_state_ = true;
    return true;
  }

  void fillState(sensor_msgs::JointState& state, geometry_msgs::Pose& ee) const {
    state.header.stamp = state_stamp_;
    state.name = joints_;
    state.position = q_;
    const Pose pose = kinematics_->endEffectorPose(q_);
    ee.position.x = pose.position[0];
    ee.position.y = pose.position[1];
    ee.position.z = pose.position[2];
    ee.orientation.x = pose.orientation[0];
    ee.orientation.y = pose.orientation[1];
    ee.orientation.z = pose.orientation[2];
    ee.orientation.w = pose.orientation[3];
  }

  bool step(moverl_msgs::ShieldStep::Request& req, moverl_msgs::ShieldStep::Response& res) {
    res.strategy = enabled_ ? strategyName(strategy_) : "";
    res.unsafe_cause = 0;
    res.truncated_fraction = -1.0;
    const bool publish = events_pub_.getNumSubscribers() > 0;  // visualisation only: nothing extra otherwise
    std::vector<double> start;
    if (publish) start = q_;
    const ros::Time start_stamp = state_stamp_;
    executed_.points.clear();
    res.verdict = static_cast<uint8_t>(run(req, res));
    if (publish) publishEvent(req, res, start, start_stamp);
    if (have_state_) fillState(res.state, res.ee_pose);
    if (!res.contacts.header.stamp.isZero()) return true;
    // No motion this step: no contacts, as far as the driver's last report goes.
    res.contacts.header.stamp = state_stamp_;
    res.contacts.available = contacts_available_;
    res.contacts.total_contact_substeps = total_contact_substeps_;
    return true;
  }

  /// Tell visualisers and loggers what this step did (only called while ~events has subscribers).
  void publishEvent(const moverl_msgs::ShieldStep::Request& req, const moverl_msgs::ShieldStep::Response& res,
                    const std::vector<double>& start, const ros::Time& stamp) {
    moverl_msgs::ShieldEvent ev;
    ev.header.stamp = stamp;
    ev.verdict = res.verdict;
    ev.verdict_name = verdictName(static_cast<Verdict>(res.verdict));
    ev.joint_names = joints_;
    ev.start = start;
    ev.target = req.target;
    ev.executed = executed_;
    ev.pairs = res.pairs;
    events_pub_.publish(ev);
  }

  Verdict run(const moverl_msgs::ShieldStep::Request& req, moverl_msgs::ShieldStep::Response& res) {
    const std::string bad = validateTarget(req.target, joints_.size());
    if (!bad.empty()) {
      res.message = bad;
      return Verdict::kInvalidRequest;
    }
    if (!have_state_) {
      res.message = "no joint state received yet from the driver (topic joint_states or ~reset)";
      return Verdict::kExecutionFailed;
    }
    Decision decision;
    if (!enabled_) {
      decision = passThrough(q_, req.target);
    } else {
      moverl_msgs::ValidateMotion vm;
      vm.request.start = q_;
      vm.request.goal = req.target;
      vm.request.plan_on_path_collision = wantsPlan(strategy_);
      vm.request.find_last_free = wantsLastFree(strategy_);
      // Moving obstacles: the straight move is checked against where they will be while it executes, i.e. over
      // [motion time of the current state, + the move's executed duration] (timed exactly as execute() will).
      vm.request.start_time = (state_stamp_ - motion_epoch_).toSec();
      try {
        vm.request.duration =
            timeWaypoints({q_, req.target}, kinematics_->velocityLimits(), req.duration, velocity_scale_).back();
      } catch (const std::exception& e) {
        res.message = std::string("cannot time the move: ") + e.what();
        return Verdict::kExecutionFailed;
      }
      if (!scene_.call(vm)) {
        res.message = "planning scene service " + scene_.name() + " is unreachable: failing closed, robot held";
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
      decision = decide(strategy_, answer, q_, req.target);
      res.unsafe_cause = decision.unsafe_cause;
      res.truncated_fraction = decision.truncated_fraction;
      if (decision.waypoints.empty() && vm.response.moving_obstacles && req.duration > 0.0 &&
          decision.verdict != Verdict::kSceneUnavailable) {
        // Hold still for the step's duration through the driver, so that the obstacles keep moving in lockstep
        // time. Safe: the robot rests at a state checked free of every obstacle's whole motion envelope.
        decision.waypoints = {q_, q_};
      }
      if (decision.verdict == Verdict::kTruncated) {
        res.message += "; truncated: moved to the last safe state at fraction " +
                       std::to_string(decision.truncated_fraction) + " of the straight path";
      }
    }
    if (decision.waypoints.empty()) return decision.verdict;
    return execute(decision, req.duration, res);
  }

  Verdict execute(const Decision& decision, double duration, moverl_msgs::ShieldStep::Response& res) {
    std::vector<double> times;
    try {
      times = timeWaypoints(decision.waypoints, kinematics_->velocityLimits(), duration, velocity_scale_);
    } catch (const std::exception& e) {
      res.message = std::string("cannot time the trajectory: ") + e.what();
      return Verdict::kExecutionFailed;
    }
    moverl_msgs::ExecuteTrajectory ex;
    ex.request.trajectory.joint_names = joints_;
    ex.request.trajectory.points.resize(decision.waypoints.size());
    for (size_t k = 0; k < decision.waypoints.size(); ++k) {
      ex.request.trajectory.points[k].positions = decision.waypoints[k];
      ex.request.trajectory.points[k].time_from_start = ros::Duration(times[k]);
    }
    if (events_pub_.getNumSubscribers() > 0) executed_ = ex.request.trajectory;  // for ~events only
    const auto start = std::chrono::steady_clock::now();
    const bool called = execute_.call(ex);
    res.execution_time = secondsSince(start);
    if (!called) {
      res.message = "driver service " + execute_.name() + " is unreachable";
      return Verdict::kExecutionFailed;
    }
    adoptState(ex.response.state);
    res.contacts = ex.response.contacts;
    contacts_available_ = ex.response.contacts.available;
    total_contact_substeps_ = ex.response.contacts.total_contact_substeps;
    if (ex.response.outcome != moverl_msgs::ExecuteTrajectory::Response::SUCCESS) {
      res.message = "driver refused the trajectory: " + ex.response.message;
      return Verdict::kExecutionFailed;
    }
    return decision.verdict;
  }

  bool reset(moverl_msgs::ResetRobot::Request& req, moverl_msgs::ResetRobot::Response& res) {
    const std::string bad = validateTarget(req.positions, joints_.size());
    if (!bad.empty()) {
      res.success = false;
      res.message = bad;
      return true;
    }
    moverl_msgs::ResetRobot fwd;
    fwd.request = req;
    if (!reset_.call(fwd)) {
      res.success = false;
      res.message = "driver reset service " + reset_.name() + " is unreachable (hardware drivers have none)";
      return true;
    }
    res = fwd.response;
    if (res.success && adoptState(res.state)) {
      motion_epoch_ = res.state.header.stamp;  // the driver restarted the obstacles' motions at this stamp
      // Report the controlled joints only, in their configured order (as ~step does).
      res.state.name = joints_;
      res.state.position = q_;
      res.state.velocity.clear();
      res.state.effort.clear();
    }
    return true;
  }

  ros::NodeHandle& nh_;
  PersistentClient<moverl_msgs::ValidateMotion> scene_;
  PersistentClient<moverl_msgs::ExecuteTrajectory> execute_;
  PersistentClient<moverl_msgs::ResetRobot> reset_;
  ros::Subscriber state_sub_;
  ros::Publisher events_pub_;
  trajectory_msgs::JointTrajectory executed_;  // what this step sent to the driver
  ros::ServiceServer step_srv_, reset_srv_;
  std::unique_ptr<ChainKinematics> kinematics_;
  std::vector<std::string> joints_;
  std::map<std::string, size_t> index_;
  bool enabled_ = true;
  Strategy strategy_ = Strategy::kPlan;
  double velocity_scale_ = 1.0;
  std::vector<double> q_;
  ros::Time state_stamp_;
  ros::Time motion_epoch_;  ///< stamp of the last successful reset: motion time 0 of moving obstacles
  bool have_state_ = false;
  bool contacts_available_ = false;
  uint64_t total_contact_substeps_ = 0;
};

}  // namespace
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
