#include "moverl_planning_scene/sensed_margin.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace moverl_planning_scene {

std::string safetyName(Safety safety) {
  switch (safety) {
    case Safety::kSeparation:
      return "separation";
    case Safety::kSsm:
      return "ssm";
  }
  return "unknown";
}

bool parseSafety(const std::string& name, Safety* safety) {
  for (Safety s : {Safety::kSeparation, Safety::kSsm}) {
    if (name == safetyName(s)) {
      *safety = s;
      return true;
    }
  }
  return false;
}

std::string safetyNames() { return "separation, ssm"; }

std::string Iso13855::problem() const {
  if (!(hand_speed > 0.0 && body_speed > 0.0 && std::isfinite(hand_speed) && std::isfinite(body_speed))) {
    return "ISO 13855's speeds must be finite and > 0";
  }
  if (!(reach_distance >= 0.0 && intrusion >= 0.0 && std::isfinite(reach_distance) && std::isfinite(intrusion))) {
    return "ISO 13855's reach distance and intrusion must be finite and >= 0";
  }
  return "";
}

double Iso13855::distance(double t) const {
  const std::string bad = problem();
  if (!bad.empty()) throw std::invalid_argument(bad);
  if (!(t >= 0.0) || !std::isfinite(t)) throw std::invalid_argument("ISO 13855: a time must be finite and >= 0");
  const double near = hand_speed * t + intrusion;
  if (near <= reach_distance) return near;
  return std::max(reach_distance, body_speed * t + intrusion);
}

double SensedMarginRule::speed() const { return safety == Safety::kSsm ? iso.hand_speed : speed_bound; }

double SensedMarginRule::reach(double seconds) const {
  if (safety == Safety::kSsm) {
    if (std::isinf(seconds)) return std::numeric_limits<double>::infinity();  // (max_age .inf: no age limit)
    return iso.distance(std::max(0.0, seconds)) + uncertainty;
  }
  return speed_bound * seconds;
}

std::string SensedMarginRule::problem() const {
  if (safety == Safety::kSsm) {
    const std::string bad = iso.problem();
    if (!bad.empty()) return "ssm: " + bad;
    if (!(uncertainty >= 0.0) || !std::isfinite(uncertainty)) return "ssm: the uncertainty must be finite and >= 0";
  }
  return "";
}

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
  out->hold_when_threatened = safety == Safety::kSsm;
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
  out->start = reach(map_age + latency);
  out->end = reach(map_age + horizon + latency);
  out->plan = reach(map_age + plan_horizon + latency);
  if (!(out->plan <= max_margin)) out->plan = std::numeric_limits<double>::infinity();  // no plan is covered
  if (!(out->end <= max_margin)) {
    *why = "the sensed margin would be " + std::to_string(out->end) + " m (" +
           (safety == Safety::kSsm ? std::string("ssm: ISO 13855's speeds")
                                   : "speed bound " + std::to_string(speed_bound) + " m/s") +
           ", map age " + std::to_string(map_age) + " s): beyond the largest the checker builds";
    return false;
  }
  return true;
}

double SensedMarginRule::largestMargin(double resolution) const {
  const double slack =
      speed() > 0.0 ? std::min(FclCollisionChecker::kMaxMargin, reach(max_age + plan_horizon + latency)) : 0.0;
  return slack + 2 * resolution;
}

Eigen::AlignedBox3d sensedMapBounds(double reach_radius, double largest_margin) {
  const double half = reach_radius + largest_margin;
  return Eigen::AlignedBox3d(Eigen::Vector3d::Constant(-half), Eigen::Vector3d::Constant(half));
}

}  // namespace moverl_planning_scene
