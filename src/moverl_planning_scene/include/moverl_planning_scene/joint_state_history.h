/**
 * \file joint_state_history.h
 * \brief The robot's recent joint states by stamp, to filter a point cloud with the configurations it may have been
 *        taken in. ROS-free (stamps are integer nanoseconds on the driver's clock).
 */
#pragma once

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <mutex>
#include <utility>
#include <vector>

namespace moverl_planning_scene {

/// \brief A bounded, thread-safe history of (stamp, configuration): states are added by a subscriber thread and read
///        by the thread that integrates clouds.
class JointStateHistory {
 public:
  /// \param capacity states kept (the oldest go first)
  explicit JointStateHistory(std::size_t capacity) : capacity_(capacity) {}

  /// \brief Add a state (stamps need not increase: a lockstep reset changes the configuration without advancing
  ///        time). Wakes a waiting around().
  void add(std::int64_t stamp_ns, std::vector<double> q);

  /// \brief The configurations a cloud stamped `stamp_ns` may have been taken in: the last state stamped before it,
  ///        every state stamped exactly at it (several can share a stamp in lockstep) and the first one after it (the
  ///        robot moved between two states). Waits up to `wait_s` seconds for a state stamped at or after the cloud
  ///        (the driver may publish the state a render saw after the cloud).
  /// \return false (out empty) when none came in time: filtering with older states only could leave the robot
  ///         behind as an obstacle, so the caller drops the cloud.
  bool around(std::int64_t stamp_ns, double wait_s, std::vector<std::vector<double>>* out);

  std::size_t size() const;

 private:
  std::size_t capacity_;
  mutable std::mutex mutex_;
  std::condition_variable cv_;
  std::deque<std::pair<std::int64_t, std::vector<double>>> states_;
};

}  // namespace moverl_planning_scene
