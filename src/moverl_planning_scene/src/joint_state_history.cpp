#include "moverl_planning_scene/joint_state_history.h"

#include <chrono>

namespace moverl_planning_scene {

void JointStateHistory::add(std::int64_t stamp_ns, std::vector<double> q) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    states_.emplace_back(stamp_ns, std::move(q));
    while (states_.size() > capacity_) states_.pop_front();
  }
  cv_.notify_all();
}

bool JointStateHistory::around(std::int64_t stamp_ns, double wait_s, std::vector<std::vector<double>>* out) {
  out->clear();
  std::unique_lock<std::mutex> lock(mutex_);
  // The newest state by arrival, not by stamp: what matters is that the driver has published past the cloud.
  const bool arrived = cv_.wait_for(lock, std::chrono::duration<double>(wait_s),
                                    [&] { return !states_.empty() && states_.back().first >= stamp_ns; });
  if (!arrived) return false;
  const std::vector<double>* before = nullptr;
  const std::vector<double>* after = nullptr;
  std::int64_t before_stamp = 0, after_stamp = 0;
  for (const auto& s : states_) {
    if (s.first < stamp_ns) {
      if (before == nullptr || s.first >= before_stamp) {  // the last one stamped before
        before = &s.second;
        before_stamp = s.first;
      }
    } else if (s.first == stamp_ns) {
      out->push_back(s.second);
    } else if (after == nullptr || s.first < after_stamp) {  // the first one stamped after
      after = &s.second;
      after_stamp = s.first;
    }
  }
  if (before != nullptr) out->push_back(*before);
  if (after != nullptr) out->push_back(*after);
  return true;
}

std::size_t JointStateHistory::size() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return states_.size();
}

}  // namespace moverl_planning_scene
