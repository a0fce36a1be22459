/**
 * \file scene_server.h
 * \brief The planning scene's ROS side: parameters, world mirroring, the services, and the sensed-obstacle monitor.
 *
 * It runs in its own process (planning_scene_node) or inside the shield's, as MoveIt's move_group hosts its planning
 * scene: the shield then calls validateMotion() and plan() directly, one round trip less per env step, while every
 * other client reaches the same services under the server's namespace (/planning_scene/...).
 */
#pragma once

#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <moverl_msgs/CheckPath.h>
#include <moverl_msgs/CheckState.h>
#include <moverl_msgs/GetFK.h>
#include <moverl_msgs/GetWorld.h>
#include <moverl_msgs/PlanPath.h>
#include <moverl_msgs/ValidateMotion.h>
#include <moverl_msgs/World.h>
#include <ros/ros.h>

#include "moverl_planning_scene/planning_scene.h"

namespace moverl_planning_scene {

class OctomapMonitor;

/// \brief The robot as /robot (config/robots/<robot>.yaml) and /robot_description describe it; throws
///        std::runtime_error naming a missing parameter. Shared by every node that builds a RobotModel.
/// \param nh a handle in the namespace of /robot and /robot_description
/// \param urdf set to the URDF text
RobotModelOptions robotOptions(const ros::NodeHandle& nh, std::string* urdf);

class SceneServer {
 public:
  /// \param nh handle in the namespace of the robot description (/robot, /robot_description)
  /// \param pnh the server's namespace: its parameters (config/planning_scene.yaml; obstacles, world_service and
  ///        world_topic from its launch file) and its services live there
  SceneServer(ros::NodeHandle nh, ros::NodeHandle pnh);
  ~SceneServer();
  SceneServer(const SceneServer&) = delete;
  SceneServer& operator=(const SceneServer&) = delete;

  /// \brief Read the parameters, build the scene, fetch the world, start the sensed-obstacle monitor (octomap modes),
  ///        advertise the services. False with *error (nothing advertised) when something is missing or wrong.
  bool init(std::string* error);

  /// \brief The ValidateMotion question in plain types (what the service answers; thread-safe): the sensed map's
  ///        margins at the request's stamp, then the scene's validateMotion. A shield hosting the scene calls it
  ///        directly, without a message.
  void validate(const MotionRequest& request, MotionCheck* out);
  /// \brief The PlanPath question in plain types (thread-safe): a plan with the sensed margin of plan_horizon.
  void plan(const std::vector<double>& start, const std::vector<double>& goal, const std::string& planner,
            double time_limit, PlanResult* out);
  /// \brief The obstacles' motion epoch of the current world (driver clock).
  ros::Time motionEpoch() const;
  /// \brief The world as its source describes it (objects included in octomap mode), with its motion epoch.
  moverl_msgs::World world() const;

  /// \brief The robot model (immutable: thread-safe without the scene's lock) and the checker's options.
  const RobotModel& model() const { return scene_->model(); }
  const FclCheckerOptions& checkerOptions() const { return scene_->checker().options(); }
  /// \brief Per controlled joint, a bound (m per rad, 1 for prismatic) on how far any robot point moves per unit of
  ///        the joint's motion: a tracking budget in metres becomes per-joint path tolerances with it.
  std::vector<double> jointRadiusBounds() const;
  /// \brief The default planning time limit per call (s).
  double planningTime() const { return planning_time_; }

 private:
  bool applyWorld(const moverl_msgs::World& msg, std::string* error);
  void onWorld(const moverl_msgs::World::ConstPtr& msg);
  bool checkState(moverl_msgs::CheckState::Request& req, moverl_msgs::CheckState::Response& res);
  bool checkPath(moverl_msgs::CheckPath::Request& req, moverl_msgs::CheckPath::Response& res);
  bool fk(moverl_msgs::GetFK::Request& req, moverl_msgs::GetFK::Response& res);
  bool getWorld(moverl_msgs::GetWorld::Request& req, moverl_msgs::GetWorld::Response& res);
  bool unstampedMargin(bool plan, double* margin, std::string* why);
  bool serveValidateMotion(moverl_msgs::ValidateMotion::Request& req, moverl_msgs::ValidateMotion::Response& res);
  bool servePlan(moverl_msgs::PlanPath::Request& req, moverl_msgs::PlanPath::Response& res);

  ros::NodeHandle nh_, pnh_;
  std::string obstacles_;
  double planning_time_ = 0.0;
  std::unique_ptr<PlanningScene> scene_;
  mutable std::mutex mutex_;  // serializes world updates and queries (the scene keeps scratch buffers)
  moverl_msgs::World world_msg_;
  std::unique_ptr<OctomapMonitor> monitor_;
  ros::Subscriber world_sub_;
  std::vector<ros::ServiceServer> services_;
  ros::Publisher ready_pub_;
  StateCheck state_;
  PathCheck path_;
};

}  // namespace moverl_planning_scene
