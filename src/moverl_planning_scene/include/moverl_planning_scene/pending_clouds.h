/**
 * \file pending_clouds.h
 * \brief ROS-free: which of a camera's clouds wait for the sensed map's integration thread when a new one comes
 *        (OctomapMonitor keeps one such queue per camera).
 *
 * Lockstep: every view, in order (a step's answers are the simulation's, not the CPU's), up to `depth`; a long move's
 * backlog drops its oldest (the map stays young). Real time: the newest views are what count. A camera keeps its two
 * newest clouds (the one before the newest, so that an instant whose later cameras are still arriving can be taken
 * whole), and a cloud of the batch being integrated (the instant of the map's open batch, or of the cloud in flight)
 * is kept before the newest. The integrator opens its next batch at the newest instant every expected camera has a
 * cloud of (newestWholeInstant) and drops the older clouds (dropOlderThan). So a map falling behind skips whole
 * instants and closes whole batches, rather than each camera's newest cloud making a batch of its own: a batch that
 * misses a camera finds what only that camera sees unseen, and at ISO's speeds such a close turned most of the map
 * possibly occupied at once.
 */
#pragma once

#include <cmath>
#include <cstddef>
#include <deque>
#include <iterator>
#include <limits>
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
  const std::size_t depth = lockstep ? (lockstep_depth > 0 ? lockstep_depth : 1) : 2;
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

/// \brief Real time: the instant to open the map's next batch at: the newest stamp at which every camera in `expected`
///        has a cloud waiting in `pending` (a map from camera to its queue). NaN when there is none (no camera
///        expected, or no instant all of them have: the caller takes the oldest cloud, as lockstep does).
/// \param expected the cameras the batch needs (the ones sending: heard lately, or with clouds waiting).
template <typename Queues, typename Names, typename StampOf>
double newestWholeInstant(const Queues& pending, const Names& expected, StampOf stamp_of) {
  double best = std::numeric_limits<double>::quiet_NaN();
  if (expected.empty()) return best;
  const auto first = pending.find(*expected.begin());
  if (first == pending.end()) return best;
  for (const auto& candidate : first->second) {
    const double t = stamp_of(candidate);
    if (!(std::isnan(best) || t > best)) continue;
    bool whole = true;
    for (const auto& name : expected) {
      const auto it = pending.find(name);
      bool has = false;
      if (it != pending.end()) {
        for (const auto& c : it->second) has = has || stamp_of(c) == t;
      }
      if (!has) {
        whole = false;
        break;
      }
    }
    if (whole) best = t;
  }
  return best;
}

/// \brief Drop every waiting cloud taken before `stamp` (s); queues left empty are erased.
/// \return how many clouds were dropped unintegrated.
template <typename Queues, typename StampOf>
std::size_t dropOlderThan(Queues* pending, double stamp, StampOf stamp_of) {
  std::size_t dropped = 0;
  for (auto it = pending->begin(); it != pending->end();) {
    auto& queue = it->second;
    for (auto c = queue.begin(); c != queue.end();) {
      if (stamp_of(*c) < stamp) {
        c = queue.erase(c);
        ++dropped;
      } else {
        ++c;
      }
    }
    it = queue.empty() ? pending->erase(it) : std::next(it);
  }
  return dropped;
}

}  // namespace moverl_planning_scene
