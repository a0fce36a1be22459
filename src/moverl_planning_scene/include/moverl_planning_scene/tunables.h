/**
 * \file tunables.h
 * \brief The scene's tunables are written once, in config/planning_scene.yaml: the option structs hold no defaults
 *        (unset values are rejected by the cores' create()), and these readers fill them from that file's keys, through
 *        ROS parameters in the node or straight from the file in tools and tests. ROS-free.
 */
#pragma once

#include <memory>
#include <string>

#include "moverl_planning_scene/occupancy_map.h"
#include "moverl_planning_scene/octomap_monitor_options.h"
#include "moverl_planning_scene/planning_scene.h"

namespace moverl_planning_scene {

/// \brief Where tunables come from: a key ("padding", "octomap/resolution") -> a typed value.
class Tunables {
 public:
  virtual ~Tunables() = default;
  /// \brief False when the key is missing or holds another type.
  virtual bool get(const std::string& key, double* value) const = 0;
  virtual bool get(const std::string& key, int* value) const = 0;
  virtual bool get(const std::string& key, bool* value) const = 0;
  virtual bool get(const std::string& key, std::string* value) const = 0;
  /// \brief Where a key lives, for error messages ("parameter /planning_scene/padding", "config/x.yaml: padding").
  virtual std::string describe(const std::string& key) const = 0;

  /// \brief The value of a key; throws std::runtime_error naming where it should have been.
  template <class T>
  T require(const std::string& key) const {
    T value{};
    if (!get(key, &value)) throw std::runtime_error(describe(key) + " is not set or has the wrong type");
    return value;
  }
};

/// \brief Tunables read from a YAML file (nested maps address as "a/b").
class YamlTunables : public Tunables {
 public:
  /// \brief nullptr with *error when the file cannot be read or parsed.
  static std::unique_ptr<YamlTunables> fromFile(const std::string& path, std::string* error);
  ~YamlTunables() override;
  bool get(const std::string& key, double* value) const override;
  bool get(const std::string& key, int* value) const override;
  bool get(const std::string& key, bool* value) const override;
  bool get(const std::string& key, std::string* value) const override;
  std::string describe(const std::string& key) const override;

 private:
  struct Impl;
  explicit YamlTunables(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// \brief Fill the checker's and the planner's tunables (padding, self_padding, path_resolution, acm_samples, acm_seed,
///        mesh_mode, planner, planning_time, planner_range, simplify, planner_seed). Robot options are not touched.
///        Throws std::runtime_error naming a missing or invalid key.
void readSceneTunables(const Tunables& t, PlanningSceneOptions* o);

/// \brief Fill the occupancy map's tunables (octomap/resolution, max_range, prob_hit, prob_miss, clamp_min, clamp_max,
///        occupancy_threshold, watch_time; static_filter_padding as fixture_pullback). Throws std::runtime_error naming
///        a missing key.
void readOccupancyMapTunables(const Tunables& t, OccupancyMapOptions* o);

/// \brief Fill the sensed margin's rule (octomap/safety, speed_bound, latency, plan_horizon, max_age, ssm/intrusion,
///        ssm/sensor_uncertainty; not max_margin) and check it. Throws std::runtime_error naming a
///        missing key or a value out of its range (an unknown safety names the valid ones).
void readSensedMarginTunables(const Tunables& t, SensedMarginRule* rule);

/// \brief Fill the sensed-obstacle monitor's tunables (every key of the octomap: section: the map's by
///        readOccupancyMapTunables, octomap/lockstep_lag in lockstep only) and check them. False with *error naming the
///        first missing key, or the first value out of its range (readSensedMarginTunables's; stale_wait, the filters'
///        paddings, future_tolerance, camera_wait, batch_wait and lockstep_lag_max_margin finite and >= 0; integration
///        projective or ray_casting; integration_threads >= 1); *o may then be partly filled.
bool readOctomapMonitorOptions(const Tunables& t, OctomapMonitorOptions* o, std::string* error);

/// \brief The robot's options from a robot config (config/robots/<robot>.yaml: robot/joints, base_link, ee_link,
///        fixed_joint_positions), for tools and tests without a ROS parameter server; *urdf_uri gets robot/urdf as
///        written (the caller resolves it). False with *error naming a missing or malformed key.
bool loadRobotConfig(const std::string& path, RobotModelOptions* o, std::string* urdf_uri, std::string* error);
/// \brief A box of a world file (worlds/<name>.yaml: the object `id`, shape box, size, xyz and rpy as written there;
///        a motion is not read: its pose at motion time 0), for tools and tests that place the world's table without
///        the world server. False with *error naming the file and what is missing or not a box (the ids it has).
bool loadWorldBox(const std::string& path, const std::string& id, WorldObject* box, std::string* error);

}  // namespace moverl_planning_scene
