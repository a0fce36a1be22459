/**
 * \file planning_scene_node.cpp
 * \brief The planning scene in a process of its own (/planning_scene): a SceneServer under the node's private
 *        namespace. The shield usually hosts the same server in its process instead (see scene_server.h).
 */
#include <cstdlib>

#include <ros/ros.h>

#include "moverl_planning_scene/scene_server.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "planning_scene");
  ros::NodeHandle nh, pnh("~");
  moverl_planning_scene::SceneServer server(nh, pnh);
  std::string error;
  if (!server.init(&error)) {
    ROS_FATAL("planning_scene: %s", error.c_str());
    return EXIT_FAILURE;
  }
  ros::spin();
  return EXIT_SUCCESS;
}
