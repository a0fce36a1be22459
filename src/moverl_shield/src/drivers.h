// The shield's two ways of driving a robot (ROS part of the shield node).
//
//  - FollowJointTrajectoryDriver: the standard interface of every ROS 1 arm (ros_control's joint_trajectory_controller,
//    franka_ros, ur_robot_driver, gazebo_ros_control, moverl_sim in real time): an actionlib client of
//    control_msgs/FollowJointTrajectory and the robot's sensor_msgs/JointState topic, joints matched by name. Time
//    passes while the shield thinks: moves are stamped to start a little ahead, the state a move starts from must be
//    fresh (a watchdog), every goal carries the path and goal tolerances the padding covers.
//  - SimServiceDriver: the simulator's lockstep services (moverl_msgs/ExecuteTrajectory, ResetRobot), a speed extension
//    for training: simulated time stands still between calls, the state comes back with every response, and the
//    simulator reports ground-truth contacts.
#pragma once

#include <condition_variable>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <actionlib/client/simple_action_client.h>
#include <control_msgs/FollowJointTrajectoryAction.h>
#include <moverl_msgs/ContactReport.h>
#include <moverl_msgs/ExecuteTrajectory.h>
#include <moverl_msgs/ResetRobot.h>
#include <ros/callback_queue.h>
#include <ros/ros.h>
#include <sensor_msgs/JointState.h>

#include "deadline.h"
#include "moverl_shield/driver_core.h"
#include "moverl_shield/shield.h"
#include "moverl_shield/trajectory.h"
#include "moverl_tcpros/client.h"

namespace moverl_shield {

/// \brief The joint-state message's stamp as the core's time.
inline Nanos toNanos(const ros::Time& t) { return static_cast<Nanos>(t.toNSec()); }
/// \brief moverl_msgs/ContactReport -> the core's (and back).
void fromMsg(const moverl_msgs::ContactReport& msg, ContactReport* out);
void toMsg(const ContactReport& report, moverl_msgs::ContactReport* out);

/// \brief What both drivers share: the path tolerance sent with every move.
class RosDriver : public Driver {
 public:
  void setPathTolerance(const std::vector<double>& tolerance) override { path_tolerance_ = tolerance; }

 protected:
  std::vector<double> path_tolerance_;
};

/// \brief The simulator's lockstep services.
class SimServiceDriver : public RosDriver {
 public:
  SimServiceDriver(ros::NodeHandle nh, const std::vector<std::string>& joints, const std::vector<double>& lower,
                   const std::vector<double>& upper, const std::string& execute_service,
                   const std::string& reset_service, const DriverOptions& options);
  std::string name() const override { return "sim_service"; }
  bool realTime() const override { return false; }
  bool canTeleport() const override { return true; }
  bool sensesContacts() const override { return true; }
  bool currentState(RobotState* state, std::string* error) override;
  MoveResult execute(const TimedTrajectory& trajectory, double start) override;
  bool teleport(const std::vector<double>& q, RobotState* after, Nanos* motion_epoch, std::string* error,
                bool* unreachable) override;

 private:
  bool adopt(const sensor_msgs::JointState& msg, std::string* error);
  void onJointState(const sensor_msgs::JointStateConstPtr& msg);

  JointStateMapper mapper_;
  std::vector<double> lower_, upper_;
  DriverOptions options_;
  // Called by the thread that serves the step, over TCPROS directly (moverl_tcpros: no hand-offs between threads;
  // a move is sent at most once).
  moverl_tcpros::DirectServiceClient<moverl_msgs::ExecuteTrajectory> execute_;
  moverl_tcpros::DirectServiceClient<moverl_msgs::ResetRobot> reset_;
  ros::Subscriber state_sub_;  ///< the first state only (the others come with the responses)
  std::mutex mutex_;           ///< guards the state against the subscriber
  RobotState state_;
  bool have_state_ = false;
  std::string state_error_;
};

/// \brief control_msgs/FollowJointTrajectory + sensor_msgs/JointState.
class FollowJointTrajectoryDriver : public RosDriver {
 public:
  /// \param nh a handle whose callbacks run on their own queue and thread (the shield serves its step meanwhile)
  FollowJointTrajectoryDriver(ros::NodeHandle nh, const std::vector<std::string>& joints,
                              const std::vector<double>& lower, const std::vector<double>& upper,
                              const std::string& action, const std::string& joint_states, const DriverOptions& options);
  std::string name() const override { return "follow_joint_trajectory"; }
  bool realTime() const override { return true; }
  bool canTeleport() const override { return false; }
  bool sensesContacts() const override { return false; }
  bool currentState(RobotState* state, std::string* error) override;
  MoveResult execute(const TimedTrajectory& trajectory, double start) override;
  bool teleport(const std::vector<double>&, RobotState*, Nanos*, std::string* error, bool*) override {
    *error = "a FollowJointTrajectory driver cannot teleport";
    return false;
  }
  /// \brief Wait (up to `timeout` s of wall time) until the action server is connected and a joint state arrived.
  bool waitUntilReady(double timeout, std::string* error);

 private:
  using Client = actionlib::SimpleActionClient<control_msgs::FollowJointTrajectoryAction>;
  void onJointState(const sensor_msgs::JointStateConstPtr& msg);
  double goal_time_plus_margin() const { return options_.goal_time + options_.result_margin; }
  /// Wait for a state received after `after` (steady clock), up to `until`. False on timeout.
  bool waitForStateAfter(SteadyClock::time_point after, SteadyClock::time_point until);

  JointStateMapper mapper_;
  std::vector<double> lower_, upper_;
  std::string action_name_, joint_states_topic_;
  DriverOptions options_;
  std::unique_ptr<Client> client_;
  ros::Subscriber state_sub_;
  std::mutex mutex_;
  std::condition_variable state_cv_, result_cv_;
  // Latest measured state (controlled joints, unclamped), its stamp and arrival; the error of the last message, if any.
  std::vector<double> q_;
  ros::Time stamp_;
  SteadyClock::time_point received_{};
  std::string state_error_;
  std::uint64_t states_ = 0;
  SteadyClock::time_point last_move_end_{};  ///< arrival of the last move's result: states must be newer
  // The goal in flight: its end and result.
  std::uint64_t goal_id_ = 0;
  bool goal_done_ = false;
  actionlib::SimpleClientGoalState goal_state_{actionlib::SimpleClientGoalState::LOST};
  control_msgs::FollowJointTrajectoryResult goal_result_;
};

}  // namespace moverl_shield
