#include "moverl_planning_scene/sensed_margin.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace moverl_planning_scene {

double sensedMapAge(const std::vector<CameraSeen>& cameras, double stamp, double epoch, std::string* deciding) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  std::string oldest_frame;
  double oldest = kInf;
  for (const CameraSeen& c : cameras) {
    if (!(c.stamp >= epoch - kEpochSlack)) {  // never heard from, or seen only before the motions restarted
      if (deciding != nullptr) *deciding = c.frame;
      return kInf;
    }
    if (c.stamp < oldest) {
      oldest = c.stamp;
      oldest_frame = c.frame;
    }
  }
  if (deciding != nullptr) *deciding = oldest_frame;
  if (cameras.empty()) return kInf;  // nothing seen (start, clear)
  return std::max(0.0, stamp - oldest);
}

double lockstepMapCutoff(double previous, double stamp, double epoch, double speed_bound, double max_margin) {
  if (!(previous < stamp)) return stamp;  // the first check (NaN), or the same state again
  const double cutoff = std::min(stamp, std::max(previous, epoch + kEpochSlack));
  return std::max(0.0, speed_bound) * (stamp - cutoff) <= max_margin ? cutoff : stamp;
}

double sensedMapAge(const std::vector<double>& last_cloud_stamps, double stamp, double epoch) {
  std::vector<CameraSeen> cameras(last_cloud_stamps.size());
  for (std::size_t k = 0; k < cameras.size(); ++k) cameras[k].stamp = last_cloud_stamps[k];
  return sensedMapAge(cameras, stamp, epoch);
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

double SensedMarginRule::largestMargin(double resolution) const {
  const double slack = speed_bound > 0.0
                           ? std::min(FclCollisionChecker::kMaxMargin, speed_bound * (max_age + plan_horizon + latency))
                           : 0.0;
  return slack + 2 * resolution;
}

Eigen::AlignedBox3d sensedMapBounds(double reach_radius, double largest_margin) {
  const double half = reach_radius + largest_margin;
  return Eigen::AlignedBox3d(Eigen::Vector3d::Constant(-half), Eigen::Vector3d::Constant(half));
}

}  // namespace moverl_planning_scene
