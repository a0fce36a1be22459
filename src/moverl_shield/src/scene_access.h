// How the shield reaches the planning scene (ROS shell).
//
//   in_process  the shield hosts the scene server (moverl_planning_scene::SceneServer), as MoveIt's move_group hosts
//               its planning scene: one ValidateMotion per step is a function call, not a round trip. The server
//               still offers every service under its namespace (/planning_scene/...) to other clients.
//   service     the scene runs in its own process (planning_scene_node); the shield calls its services with deadlines.
//
// Either way the robot model (forward kinematics, joint limits) is the scene core's RobotModel: one FK in the graph.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <moverl_msgs/GetWorld.h>
#include <moverl_msgs/PlanPath.h>
#include <moverl_msgs/ValidateMotion.h>
#include <ros/ros.h>

#include "deadline.h"
#include "moverl_planning_scene/robot_model.h"
#include "moverl_planning_scene/unset.h"
#include "tcpros.h"

namespace moverl_shield {

/// \brief What the shield needs to know about the scene besides its answers: read from the scene (its YAML), never
///        defaulted here (kUnset until read).
struct SceneFacts {
  std::vector<double> joint_radius_bounds;                 ///< per joint, m of robot motion per unit of joint motion
  double padding = moverl_planning_scene::kUnset;          ///< obstacle inflation (m)
  double path_resolution = moverl_planning_scene::kUnset;  ///< max motion of a robot point between checked states (m)
  double planning_time = moverl_planning_scene::kUnset;    ///< the scene's planning time limit (s)
};

class SceneAccess {
 public:
  virtual ~SceneAccess() = default;
  /// \brief For messages: the service or the in-process server's namespace.
  virtual std::string name() const = 0;
  /// \brief The calls; in-process ones always answer (the timeout bounds only service calls).
  virtual CallEnd validate(moverl_msgs::ValidateMotion& vm, double timeout) = 0;
  virtual CallEnd plan(moverl_msgs::PlanPath& plan, double timeout) = 0;
  virtual CallEnd world(moverl_msgs::GetWorld& world, double timeout) = 0;
  /// \brief False with *error when the scene has not published them (service mode, scene not up yet).
  virtual bool facts(SceneFacts* facts, std::string* error) = 0;
  /// \brief The robot model the scene checks with (immutable, thread-safe).
  virtual const moverl_planning_scene::RobotModel& model() const = 0;

  /// \brief The scene as ~scene says ("in_process" or "service"), its server's namespace `ns` (parameters and
  ///        services). Throws std::runtime_error when it cannot be built.
  static std::unique_ptr<SceneAccess> create(const std::string& mode, ros::NodeHandle nh, const std::string& ns);
};

}  // namespace moverl_shield
