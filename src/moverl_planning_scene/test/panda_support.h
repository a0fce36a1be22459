/**
 * \file panda_support.h
 * \brief Shared by the gtests: the Panda's scene options as the repo ships them (config/robots/panda.yaml,
 *        config/planning_scene.yaml; pybullet_data's URDF) and a few helpers. Header-only, ROS-free.
 */
#pragma once

#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>

#include "moverl_planning_scene/planning_scene.h"
#include "moverl_planning_scene/tunables.h"

#ifndef MOVERL_CONFIG_DIR
#error "MOVERL_CONFIG_DIR (the repo's config/ folder) must be defined by the build"
#endif

namespace moverl_planning_scene {
namespace panda {

inline std::string readFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

/// The scene's tunables as config/planning_scene.yaml ships them (throws when it cannot be read).
inline const Tunables& shippedTunables() {
  static const std::unique_ptr<YamlTunables> t = [] {
    std::string error;
    auto loaded = YamlTunables::fromFile(MOVERL_CONFIG_DIR "/planning_scene.yaml", &error);
    if (!loaded) throw std::runtime_error(error);
    return loaded;
  }();
  return *t;
}

/// Scene options of the Panda as config/robots/panda.yaml and config/planning_scene.yaml give them, meshes next to
/// urdf_path.
inline PlanningSceneOptions options(const std::string& urdf_path) {
  PlanningSceneOptions o;
  std::string error, uri;
  if (!loadRobotConfig(MOVERL_CONFIG_DIR "/robots/panda.yaml", &o.robot, &uri, &error)) {
    throw std::runtime_error(error);
  }
  readSceneTunables(shippedTunables(), &o);
  o.robot.mesh_base_dir = urdf_path.substr(0, urdf_path.rfind('/'));
  return o;
}

/// The occupancy map's options as config/planning_scene.yaml ships them.
inline OccupancyMapOptions mapOptions() {
  OccupancyMapOptions o;
  readOccupancyMapTunables(shippedTunables(), &o);
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
