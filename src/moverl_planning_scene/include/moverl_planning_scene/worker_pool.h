/**
 * \file worker_pool.h
 * \brief A fixed set of threads that run one batch of independent tasks at a time, with the calling thread (the
 *        cloud integration's block loop and self filter use it). ROS-free.
 *
 * Why not OpenMP: after a parallel region libgomp's threads spin for a while before they sleep, taking a core the
 * simulator or the env needs on a small machine; these threads sleep on a condition variable between batches. A thread
 * that wakes after the caller has run the batch's last task joins nothing (the caller never waits for a thread that has
 * not started a task of its batch), so a busy core delays no batch.
 */
#pragma once

#include <cstddef>
#include <functional>
#include <memory>

namespace moverl_planning_scene {

class WorkerPool {
 public:
  /// \brief `threads` >= 1 run each batch: the calling thread and threads - 1 started here (stopped and joined by the
  ///        destructor). Throws std::invalid_argument for fewer than 1.
  explicit WorkerPool(int threads);
  ~WorkerPool();
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  int threads() const { return threads_; }
  /// runParts' smallest part for a loop of a few arithmetic operations per element (a cloud's points, pixels).
  static constexpr std::size_t kCheapPart = 16384;
  /// \brief Run task(t, worker) for every t in [0, tasks), each exactly once, handed out in order one at a time to
  ///        whichever thread is free; returns when every started task has returned. `worker` is in [0, threads()), the
  ///        caller's 0, and no two tasks run at once with the same worker (per-worker scratch needs no lock). When a
  ///        task throws, no further task starts and the first exception is rethrown here. One batch at a time: calls
  ///        from several threads at once are refused (std::logic_error).
  void run(std::size_t tasks, const std::function<void(std::size_t task, int worker)>& task);

  /// \brief Run part(begin, end, worker) over consecutive parts of [0, n) that cover it once: up to 4 parts per thread
  ///        (the work of a cloud's points bunches in a part of the image) of at least min_part each (the elements
  ///        whose work is worth a thread's wake-up): part(0, n, 0) on the caller when that leaves one part, or with a
  ///        null pool. A part's position is [begin, end), not the worker: results kept per part and joined in order
  ///        do not depend on the threads.
  static void runParts(WorkerPool* pool, std::size_t n, std::size_t min_part,
                       const std::function<void(std::size_t begin, std::size_t end, int worker)>& part);

 private:
  struct Impl;
  /// Stop and join the threads started (the destructor; a constructor that could not start them all).
  void stop();
  int threads_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace moverl_planning_scene
