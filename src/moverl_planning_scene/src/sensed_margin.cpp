#include "moverl_planning_scene/sensed_margin.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace moverl_planning_scene {

double sensedMapAge(const std::vector<double>& last_cloud_stamps, double stamp, double epoch) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  if (last_cloud_stamps.empty()) return kInf;  // nothing seen (start, clear)
  double oldest = kInf;
  for (double s : last_cloud_stamps) {
    if (s < epoch - 1e-3) return kInf;  // seen only before the motions restarted
    oldest = std::min(oldest, s);
  }
  return std::max(0.0, stamp - oldest);
}

bool SensedMarginRule::compute(double map_age, double duration, SensedMargins* out, std::string* why) const {
  out->map_age = map_age;
  out->plan_horizon = plan_horizon;
  if (!std::isfinite(map_age)) {  // blind, even without an age limit
    *why = "no camera has been seen since the world's motions restarted (or at all): nothing is known to be free";
    return false;
  }
  if (!(map_age <= max_age)) {
    *why = "the sensed map is " + std::to_string(map_age) + " s old at the state's stamp (octomap/max_age " +
           std::to_string(max_age) + " s): a camera stopped publishing or integration fell behind";
    return false;
  }
  const double horizon = std::isfinite(duration) ? duration : plan_horizon;
  out->start = speed_bound * (map_age + latency);
  out->end = speed_bound * (map_age + horizon + latency);
  out->plan = speed_bound * (map_age + plan_horizon + latency);
  if (!(out->plan <= max_margin)) out->plan = std::numeric_limits<double>::infinity();  // no plan is covered
  if (!(out->end <= max_margin)) {
    *why = "the sensed margin would be " + std::to_string(out->end) + " m (speed bound " + std::to_string(speed_bound) +
           " m/s, map age " + std::to_string(map_age) + " s): beyond the largest the checker builds";
    return false;
  }
  return true;
}

}  // namespace moverl_planning_scene
