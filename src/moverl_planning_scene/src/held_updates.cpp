#include "moverl_planning_scene/held_updates.h"

#include <limits>
#include <utility>

namespace moverl_planning_scene {

void HeldUpdates::push(std::int64_t stamp_ns, const std::string& frame, const MapUpdate& update) {
  held_.push_back({stamp_ns, frame, update});
}

std::vector<HeldUpdates::Held> HeldUpdates::takeUpTo(std::int64_t cutoff_ns) {
  std::vector<Held> out;
  while (!held_.empty() && held_.front().stamp_ns <= cutoff_ns) {
    out.push_back(std::move(held_.front()));
    held_.pop_front();
  }
  return out;
}

std::vector<HeldUpdates::Held> HeldUpdates::takeAll() { return takeUpTo(std::numeric_limits<std::int64_t>::max()); }

}  // namespace moverl_planning_scene
