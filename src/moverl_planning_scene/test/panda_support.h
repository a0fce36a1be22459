/**
 * \file panda_support.h
 * \brief Shared by the gtests and scene_benchmark: the Panda's scene options (pybullet_data's URDF) and a few
 *        helpers. Header-only, ROS-free.
 */
#pragma once

#include <fstream>
#include <sstream>
#include <string>

#include "moverl_planning_scene/planning_scene.h"

namespace moverl_planning_scene {
namespace panda {

inline std::string readFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

/// Scene options of the Panda in config/robots/panda.yaml (fingers held open), meshes next to urdf_path.
inline PlanningSceneOptions options(const std::string& urdf_path) {
  PlanningSceneOptions o;
  o.robot.joint_names = {"panda_joint1", "panda_joint2", "panda_joint3", "panda_joint4",
                         "panda_joint5", "panda_joint6", "panda_joint7"};
  o.robot.fixed_joint_positions = {{"panda_finger_joint1", 0.04}, {"panda_finger_joint2", 0.04}};
  o.robot.base_link = "panda_link0";
  o.robot.ee_link = "panda_link8";
  o.robot.mesh_base_dir = urdf_path.substr(0, urdf_path.rfind('/'));
  return o;
}

/// An axis-aligned box obstacle centred at (x, y, z).
inline WorldObject box(const std::string& id, double sx, double sy, double sz, double x, double y, double z) {
  WorldObject o;
  o.id = id;
  o.type = ShapeType::kBox;
  o.dimensions = {sx, sy, sz};
  o.pose.translation() = Eigen::Vector3d(x, y, z);
  return o;
}

}  // namespace panda
}  // namespace moverl_planning_scene
