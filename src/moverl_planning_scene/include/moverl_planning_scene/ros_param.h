/**
 * \file ros_param.h
 * \brief Parameters without code defaults: every tunable is set in one commented YAML file under config/ or by its
 *        launch file, and a missing one is an error that names where it belongs.
 */
#pragma once

#include <stdexcept>
#include <string>

#include <ros/node_handle.h>

#include "moverl_planning_scene/tunables.h"

namespace moverl_planning_scene {

/// \brief The parameter `name` of `nh`; throws std::runtime_error naming it and `source` (where it is set) when it is
///        missing or of another type.
template <class T>
T requiredParam(const ros::NodeHandle& nh, const std::string& name, const std::string& source) {
  T value;
  if (!nh.getParam(name, value)) {
    throw std::runtime_error("parameter " + nh.resolveName(name) + " is not set or has the wrong type (" + source +
                             ")");
  }
  return value;
}

/// \brief Tunables from the parameters under a node handle (what its launch file loaded from a YAML file).
class RosTunables : public Tunables {
 public:
  /// \param source where the parameters come from, for error messages ("load config/planning_scene.yaml")
  RosTunables(const ros::NodeHandle& nh, std::string source) : nh_(nh), source_(std::move(source)) {}
  bool get(const std::string& key, double* value) const override { return nh_.getParam(key, *value); }
  bool get(const std::string& key, int* value) const override { return nh_.getParam(key, *value); }
  bool get(const std::string& key, bool* value) const override { return nh_.getParam(key, *value); }
  bool get(const std::string& key, std::string* value) const override { return nh_.getParam(key, *value); }
  std::string describe(const std::string& key) const override {
    return "parameter " + nh_.resolveName(key) + " (" + source_ + ")";
  }

 private:
  ros::NodeHandle nh_;
  std::string source_;
};

}  // namespace moverl_planning_scene
