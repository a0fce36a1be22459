#include "moverl_planning_scene/worker_pool.h"

#include <pthread.h>
#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <exception>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace moverl_planning_scene {

struct WorkerPool::Impl {
  std::mutex mutex;
  std::condition_variable start, done;
  const std::function<void(std::size_t, int)>* task = nullptr;  ///< the open batch's (under mutex while open)
  std::size_t tasks = 0;
  std::atomic<std::size_t> next{0};  ///< the next task to hand out
  std::atomic<bool> failed{false};   ///< a task threw: start no more
  std::exception_ptr error;          ///< the first one's (under mutex)
  std::uint64_t batch = 0;           ///< counts the batches run
  bool open = false;                 ///< threads may still join the batch
  int joined = 0;                    ///< threads running the open batch's tasks
  bool stop = false;
  std::atomic<bool> running{false};  ///< a run() is under way
  std::vector<std::thread> threads;

  /// Take tasks until none is left (or one threw).
  void work(int worker) {
    while (!failed.load(std::memory_order_relaxed)) {
      const std::size_t t = next.fetch_add(1, std::memory_order_relaxed);
      if (t >= tasks) return;
      try {
        (*task)(t, worker);
      } catch (...) {
        std::lock_guard<std::mutex> lock(mutex);
        if (!error) error = std::current_exception();
        failed = true;
      }
    }
  }

  void loop(int worker) {
    // Named for the tools that split a process's CPU by thread (step_cost.py); at most 15 characters.
    pthread_setname_np(pthread_self(), "mps_pool");
    std::uint64_t seen = 0;
    std::unique_lock<std::mutex> lock(mutex);
    for (;;) {
      start.wait(lock, [&] { return stop || (open && batch != seen); });
      if (stop) return;
      seen = batch;
      ++joined;
      lock.unlock();
      work(worker);
      lock.lock();
      if (--joined == 0) done.notify_one();
    }
  }
};

WorkerPool::WorkerPool(int threads) : threads_(threads), impl_(new Impl) {
  if (threads < 1) throw std::invalid_argument("WorkerPool: threads must be >= 1, not " + std::to_string(threads));
  try {
    for (int w = 1; w < threads; ++w) impl_->threads.emplace_back([this, w] { impl_->loop(w); });
  } catch (...) {  // a thread could not be started: stop the ones that were
    stop();
    throw;
  }
}

void WorkerPool::stop() {
  {
    std::lock_guard<std::mutex> lock(impl_->mutex);
    impl_->stop = true;
  }
  impl_->start.notify_all();
  for (std::thread& t : impl_->threads) t.join();
  impl_->threads.clear();
}

WorkerPool::~WorkerPool() { stop(); }

void WorkerPool::runParts(WorkerPool* pool, std::size_t n, std::size_t min_part,
                          const std::function<void(std::size_t, std::size_t, int)>& part) {
  const std::size_t parts =
      pool == nullptr ? 1
                      : std::min(4 * static_cast<std::size_t>(pool->threads()), n / std::max<std::size_t>(1, min_part));
  if (parts <= 1) {
    part(0, n, 0);
    return;
  }
  // Part i: [i n / parts, (i + 1) n / parts), at least floor(n / parts) >= min_part long.
  pool->run(parts, [&](std::size_t i, int worker) { part(i * n / parts, (i + 1) * n / parts, worker); });
}

void WorkerPool::run(std::size_t tasks, const std::function<void(std::size_t, int)>& task) {
  if (impl_->running.exchange(true)) throw std::logic_error("WorkerPool::run: one batch at a time");
  struct Done {
    std::atomic<bool>* running;
    ~Done() { running->store(false); }
  } done{&impl_->running};
  if (threads_ == 1 || tasks <= 1) {
    for (std::size_t t = 0; t < tasks; ++t) task(t, 0);
    return;
  }
  Impl& p = *impl_;
  {
    std::lock_guard<std::mutex> lock(p.mutex);
    p.task = &task;
    p.tasks = tasks;
    p.next = 0;
    p.failed = false;
    p.error = nullptr;
    ++p.batch;
    p.open = true;
  }
  p.start.notify_all();
  p.work(0);
  std::exception_ptr error;
  {
    std::unique_lock<std::mutex> lock(p.mutex);
    p.open = false;  // a thread that wakes from here on joins nothing
    p.done.wait(lock, [&] { return p.joined == 0; });
    p.task = nullptr;
    error = p.error;
    p.error = nullptr;
  }
  if (error) std::rethrow_exception(error);
}

}  // namespace moverl_planning_scene
