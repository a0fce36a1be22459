// How the shield reaches the planning scene (ROS shell of the core's Scene interface, moverl_shield/shield.h).
//
//   in_process  the shield hosts the scene server (moverl_planning_scene::SceneServer), as MoveIt's move_group hosts
//               its planning scene: one ValidateMotion per step is a function call in plain types, not a round trip
//               nor a message. The server still offers every service under its namespace (/planning_scene/...) to
//               other clients.
//   service     the scene runs in its own process (planning_scene_node); the shield calls its services with deadlines.
//
// Either way the robot model (forward kinematics, joint limits) is the scene core's RobotModel: one FK in the graph.
#pragma once

#include <memory>
#include <string>

#include <ros/ros.h>

#include "moverl_shield/shield.h"

namespace moverl_shield {

/// \brief The scene as ~scene says ("in_process" or "service"), its server's namespace `ns` (parameters and services).
///        Throws std::runtime_error when it cannot be built.
std::unique_ptr<Scene> createScene(const std::string& mode, ros::NodeHandle nh, const std::string& ns);

}  // namespace moverl_shield
