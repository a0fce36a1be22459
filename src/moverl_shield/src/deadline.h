// Deadlines for ROS 1 calls, which have none of their own (roscpp service calls block until the server answers or
// its connection drops). ROS part of the shield node.
//
// A Watchdog thread runs an action when an armed deadline passes. A DeadlineClient uses it to abandon a service call:
// at the deadline it drops the call's persistent connection, which makes the blocked call return false at once; the
// next call opens a new connection. A stalled server that wakes up can only answer on the dropped connection, so its
// late reply is never read as the answer to a later request. Deadlines run on the steady (wall) clock: a stalled
// simulator also stops /clock, and sim-time deadlines would never pass.
#pragma once

#include <chrono>
#include <condition_variable>
#include <functional>
#include <map>
#include <mutex>
#include <string>
#include <thread>

#include <ros/ros.h>

namespace moverl_shield {

using SteadyClock = std::chrono::steady_clock;

inline SteadyClock::time_point after(double seconds) {
  return SteadyClock::now() + std::chrono::duration_cast<SteadyClock::duration>(std::chrono::duration<double>(seconds));
}

/// \brief Wall-clock seconds since the epoch: the `not_after` of requests, comparable across processes on one host.
inline double wallSeconds() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

/// \brief True when a request's `not_after` (wall seconds, 0: none) has passed: its caller gave up on it.
inline bool abandoned(double not_after) { return not_after > 0.0 && wallSeconds() > not_after; }

/// \brief One thread that runs an action when its deadline passes, unless it was disarmed before.
class Watchdog {
 public:
  Watchdog() : thread_([this] { run(); }) {}
  ~Watchdog() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stop_ = true;
    }
    cv_.notify_all();
    thread_.join();
  }
  Watchdog(const Watchdog&) = delete;
  Watchdog& operator=(const Watchdog&) = delete;

  /// \brief Run `action` (on the watchdog thread) at `deadline` unless disarm(token) comes first.
  std::uint64_t arm(SteadyClock::time_point deadline, std::function<void()> action) {
    std::lock_guard<std::mutex> lock(mutex_);
    const std::uint64_t token = ++next_;
    // Wake the thread only when it must wait less than it does now (hot path: calls arm and disarm every step; a
    // thread that wakes at an old deadline and finds it disarmed simply waits for the next).
    const bool earlier = deadline < waiting_until_;
    armed_.emplace(token, Entry{deadline, std::move(action)});
    if (earlier) cv_.notify_all();
    return token;
  }
  /// \brief Cancel an armed action. If it is running, waits until it finished. Returns true if it had fired.
  bool disarm(std::uint64_t token) {
    std::unique_lock<std::mutex> lock(mutex_);
    if (armed_.erase(token) > 0) return false;
    cv_.wait(lock, [&] { return running_ != token; });
    return true;
  }

 private:
  struct Entry {
    SteadyClock::time_point deadline;
    std::function<void()> action;
  };
  void run() {
    std::unique_lock<std::mutex> lock(mutex_);
    while (!stop_) {
      if (armed_.empty()) {
        waiting_until_ = SteadyClock::time_point::max();
        cv_.wait(lock);
        continue;
      }
      auto next = armed_.begin();
      for (auto it = armed_.begin(); it != armed_.end(); ++it) {
        if (it->second.deadline < next->second.deadline) next = it;
      }
      if (SteadyClock::now() < next->second.deadline) {
        waiting_until_ = next->second.deadline;
        cv_.wait_until(lock, waiting_until_);
        continue;
      }
      std::function<void()> action = std::move(next->second.action);
      running_ = next->first;
      armed_.erase(next);
      lock.unlock();
      action();
      lock.lock();
      running_ = 0;
      cv_.notify_all();
    }
  }

  std::mutex mutex_;
  std::condition_variable cv_;
  std::map<std::uint64_t, Entry> armed_;
  std::uint64_t next_ = 0, running_ = 0;
  SteadyClock::time_point waiting_until_ = SteadyClock::time_point::max();  // when the thread wakes up next
  bool stop_ = false;
  std::thread thread_;
};

/// \brief How a call with a deadline ended.
enum class CallEnd { kAnswered, kUnreachable, kTimedOut };

/// \brief A persistent service client whose calls have a deadline (see the file comment).
template <class Srv>
class DeadlineClient {
 public:
  DeadlineClient(ros::NodeHandle nh, std::string name, Watchdog* watchdog)
      : nh_(std::move(nh)), name_(std::move(name)), watchdog_(watchdog) {}

  /// \brief Call with a deadline `timeout` seconds from now. A broken connection is re-opened once (a restarted
  ///        server), never waited for.
  CallEnd call(Srv& srv, double timeout) {
    const SteadyClock::time_point deadline = after(timeout);
    for (int attempt = 0; attempt < 2; ++attempt) {
      if (!client_.isValid()) {
        // Creating a persistent client looks the service up at the master and connects; an unknown service leaves it
        // invalid, and the call below fails at once.
        client_ = nh_.serviceClient<Srv>(name_, /*persistent=*/true);
      }
      bool fired = false;
      ros::ServiceClient client = client_;  // the watchdog shuts down this handle, never a newer one
      const std::uint64_t token = watchdog_->arm(deadline, [client, &fired]() mutable {
        fired = true;
        client.shutdown();  // drops the connection: the blocked call returns false
      });
      const bool ok = client.call(srv);
      const bool timed_out = watchdog_->disarm(token) || fired;
      if (timed_out) {
        client_.shutdown();
        client_ = ros::ServiceClient();
        return CallEnd::kTimedOut;
      }
      if (ok) return CallEnd::kAnswered;
      client_.shutdown();
      client_ = ros::ServiceClient();
      if (SteadyClock::now() >= deadline) return CallEnd::kTimedOut;
    }
    return CallEnd::kUnreachable;
  }
  const std::string& name() const { return name_; }

 private:
  ros::NodeHandle nh_;
  std::string name_;
  Watchdog* watchdog_;
  ros::ServiceClient client_;
};

}  // namespace moverl_shield
