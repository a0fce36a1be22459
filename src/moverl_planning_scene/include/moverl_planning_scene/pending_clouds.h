/**
 * \file pending_clouds.h
 * \brief ROS-free: which of a camera's clouds wait for the sensed map's integration thread when a new one comes
 *        (OctomapMonitor keeps one such queue per camera).
 *
 * Lockstep: every view, in order (a step's answers are the simulation's, not the CPU's), up to `depth`; a long move's
 * backlog drops its oldest (the map stays young). Real time: the newest view is what counts and an older one waiting is
 * replaced, except a cloud of the batch being integrated (the instant of the map's open batch, or of the cloud in
 * flight): it is kept, with the newest behind it. So a batch falling behind is still integrated whole and closed once,
 * rather than each camera's newest cloud making a batch of its own, each close paying the hidden space's watch over a
 * longer interval.
 */
#pragma once

#include <cstddef>
#include <deque>
#include <utility>

namespace moverl_planning_scene {

/// \brief Queue `cloud` behind a camera's waiting clouds, dropping what the rule above drops.
/// \param stamp_of the time a cloud was taken (s), as `double stamp_of(const Cloud&)`.
/// \param lockstep_depth the most clouds a camera keeps waiting in lockstep (octomap/queue_size, at least 1).
/// \param batch the stamp of the map's open batch, NaN when none; in_flight the stamp of the cloud being integrated,
///        NaN when none (both unused in lockstep).
/// \return how many waiting clouds were dropped unintegrated (0, or 1 when the queue was full).
template <typename Cloud, typename StampOf>
std::size_t admitCloud(std::deque<Cloud>* queue, Cloud cloud, StampOf stamp_of, bool lockstep,
                       std::size_t lockstep_depth, double batch, double in_flight) {
  bool keep_front = false;
  if (!lockstep && !queue->empty()) {
    const double front = stamp_of(queue->front());
    keep_front = front == batch || front == in_flight;  // (NaN equals nothing)
  }
  const std::size_t depth = lockstep ? (lockstep_depth > 0 ? lockstep_depth : 1) : (keep_front ? 2 : 1);
  std::size_t dropped = 0;
  for (; queue->size() >= depth; ++dropped) {
    if (keep_front) {
      queue->pop_back();
    } else {
      queue->pop_front();
    }
  }
  queue->push_back(std::move(cloud));
  return dropped;
}

}  // namespace moverl_planning_scene
