/**
 * \file octomap_monitor_options.h
 * \brief The sensed-obstacle monitor's tunables (the octomap: section of config/planning_scene.yaml, where each is
 *        commented), as readOctomapMonitorOptions (tunables.h) reads and checks them for OctomapMonitor::init. No
 *        defaults: a value the YAML did not give is an error of the reader. ROS-free.
 */
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "moverl_planning_scene/cloud_integrator.h"
#include "moverl_planning_scene/occupancy_map.h"
#include "moverl_planning_scene/sensed_margin.h"
#include "moverl_planning_scene/tracked_parts.h"
#include "moverl_planning_scene/unset.h"

namespace moverl_planning_scene {

struct OctomapMonitorOptions {
  /// octomap/ssm/tracking/use (safety ssm only): the checks use the tracked people's parts (tracked_parts.h)
  bool track_people = false;
  /// octomap/ssm/tracking/max_speed, position_error, max_age (motion.max_acceleration 0: no velocity is reported)
  TrackingRule tracking;
  /// octomap/ssm/tracking/parts: the frames looked up per tracked body, each with its radius (m)
  std::vector<std::pair<std::string, double>> part_radii;
  /// octomap/resolution, max_range, prob_hit, prob_miss, clamp_min, clamp_max, occupancy_threshold, watch_time
  /// (readOccupancyMapTunables); the monitor sets the rest (bounds, unknown_occupied, hidden_space, speed_bound).
  OccupancyMapOptions map;
  std::string cloud_topic;                ///< octomap/cloud_topic
  std::string joint_states_topic;         ///< octomap/joint_states_topic
  int queue_size = 0;                     ///< octomap/queue_size, as written (the monitor keeps at least 1)
  double startup_timeout = kUnset;        ///< octomap/startup_timeout (s, wall)
  double camera_wait = kUnset;            ///< octomap/camera_wait (s, wall; >= 0)
  double batch_wait = kUnset;             ///< octomap/batch_wait (s, wall; >= 0)
  double transform_timeout = kUnset;      ///< octomap/transform_timeout (s)
  double joint_state_wait = kUnset;       ///< octomap/joint_state_wait (s)
  double future_tolerance = kUnset;       ///< octomap/future_tolerance (s; >= 0)
  double self_filter_padding = kUnset;    ///< octomap/self_filter_padding (m; >= 0)
  double static_filter_padding = kUnset;  ///< octomap/static_filter_padding (m; >= 0)
  Integration integration = Integration::kRayCasting;  ///< octomap/integration (the reader parses it)
  int integration_threads = 0;                         ///< octomap/integration_threads (>= 1)
  bool lockstep = false;                               ///< octomap/lockstep
  /// octomap/lockstep_lag, read in lockstep only (real time: false, and the key need not be set).
  bool lockstep_lag = false;
  double lockstep_lag_max_margin = kUnset;  ///< octomap/lockstep_lag_max_margin (m; >= 0)
  /// The sensed margin (readSensedMarginTunables): octomap/safety, speed_bound (a world's sensing: speed_bound
  /// replaces it), latency, plan_horizon, max_age, ssm/intrusion, ssm/sensor_uncertainty; max_margin is the monitor's.
  SensedMarginRule margin;
  double stale_wait = kUnset;  ///< octomap/stale_wait (s, wall; >= 0)
};

}  // namespace moverl_planning_scene
