/**
 * \file held_updates.h
 * \brief octomap/lockstep_lag, ROS-free: the map the checks read lags the integrated map by the updates held here.
 *        Each cloud's update is applied to the integrated map at once and held; the checks' map gets the held updates
 *        later, in the same order, so that it is the integrated map as it was (an update applied to the same state
 *        gives the same map: OccupancyMap::apply reads only the cells it sets). OctomapMonitor holds them;
 *        lockstepMapCutoff (sensed_margin.h) says up to which stamp a check takes them.
 */
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <string>
#include <vector>

#include "moverl_planning_scene/occupancy_map.h"

namespace moverl_planning_scene {

class HeldUpdates {
 public:
  /// \brief The most updates held: a lockstep step holds a few (3 cameras at 30 Hz: about 5 a step); without checks
  ///        (the shield off) they would pile up, so they go into the checks' map at once beyond it (full()).
  static constexpr std::size_t kMax = 64;

  struct Held {
    std::int64_t stamp_ns = 0;  ///< the cloud's stamp
    std::string frame;          ///< its camera's frame
    MapUpdate update;
  };

  /// \brief Hold the update just applied to the integrated map.
  void push(std::int64_t stamp_ns, const std::string& frame, const MapUpdate& update);
  /// \brief The held updates in their order, up to the first stamped after cutoff_ns, removed from here: apply them to
  ///        the checks' map in that order. A prefix: an earlier-stamped update behind a later one stays (it was
  ///        computed on a map that held the later one).
  std::vector<Held> takeUpTo(std::int64_t cutoff_ns);
  /// \brief Every held update, in order, removed.
  std::vector<Held> takeAll();
  /// \brief More than kMax held.
  bool full() const { return held_.size() > kMax; }
  std::size_t size() const { return held_.size(); }
  /// \brief Forget them (the map was cleared).
  void clear() { held_.clear(); }

 private:
  std::deque<Held> held_;
};

}  // namespace moverl_planning_scene
