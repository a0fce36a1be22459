#include "moverl_shield/shield_core.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace moverl_shield {

std::string verdictName(Verdict verdict) {
  switch (verdict) {
    case Verdict::kSafe:
      return "safe";
    case Verdict::kReplanned:
      return "replanned";
    case Verdict::kDiscardedSelf:
      return "discarded_self";
    case Verdict::kDiscardedPose:
      return "discarded_pose";
    case Verdict::kDiscardedPath:
      return "discarded_path";
    case Verdict::kDiscardedStart:
      return "discarded_start";
    case Verdict::kUnchecked:
      return "unchecked";
    case Verdict::kInvalidRequest:
      return "invalid_request";
    case Verdict::kSceneUnavailable:
      return "scene_unavailable";
    case Verdict::kExecutionFailed:
      return "execution_failed";
  }
  return "unknown";
}

bool isDiscarded(Verdict verdict) {
  return verdict == Verdict::kDiscardedSelf || verdict == Verdict::kDiscardedPose ||
         verdict == Verdict::kDiscardedPath || verdict == Verdict::kDiscardedStart;
}

std::string validateTarget(const std::vector<double>& target, size_t num_joints) {
  if (target.size() != num_joints) {
    return "target has " + std::to_string(target.size()) + " values, the robot has " + std::to_string(num_joints) +
           " controlled joints";
  }
  for (size_t i = 0; i < target.size(); ++i) {
    if (!std::isfinite(target[i])) return "target value " + std::to_string(i) + " is not finite";
  }
  return "";
}

Decision decide(SceneOutcome outcome, bool replanned, const Waypoints& plan, const std::vector<double>& start,
                const std::vector<double>& target) {
  Decision d;
  switch (outcome) {
    case SceneOutcome::kValid:
      d.verdict = Verdict::kSafe;
      d.waypoints = {start, target};
      break;
    case SceneOutcome::kSelfCollision:
      d.verdict = Verdict::kDiscardedSelf;
      break;
    case SceneOutcome::kPoseCollision:
      d.verdict = Verdict::kDiscardedPose;
      break;
    case SceneOutcome::kPathCollision:
      if (replanned && plan.size() >= 2) {
        d.verdict = Verdict::kReplanned;
        d.waypoints = plan;
        // The plan starts at the state the scene checked; execute from the measured state exactly.
        d.waypoints.front() = start;
      } else {
        d.verdict = Verdict::kDiscardedPath;
      }
      break;
    case SceneOutcome::kStartInCollision:
      d.verdict = Verdict::kDiscardedStart;
      break;
    case SceneOutcome::kInvalidRequest:
      d.verdict = Verdict::kInvalidRequest;
      break;
    default:
      d.verdict = Verdict::kSceneUnavailable;  // unknown code: fail closed
  }
  return d;
}

Decision passThrough(const std::vector<double>& start, const std::vector<double>& target) {
  Decision d;
  d.verdict = Verdict::kUnchecked;
  d.waypoints = {start, target};
  return d;
}

std::vector<double> timeWaypoints(const Waypoints& waypoints, const std::vector<double>& velocity_limits,
                                  double min_duration, double velocity_scale) {
  if (waypoints.empty()) return {};
  if (!(velocity_scale > 0.0)) throw std::invalid_argument("velocity_scale must be positive");
  for (double v : velocity_limits) {
    if (!(v > 0.0)) throw std::invalid_argument("velocity limits must be positive");
  }
  std::vector<double> times(waypoints.size(), 0.0);
  for (size_t k = 1; k < waypoints.size(); ++k) {
    const auto& a = waypoints[k - 1];
    const auto& b = waypoints[k];
    if (a.size() != velocity_limits.size() || b.size() != velocity_limits.size()) {
      throw std::invalid_argument("waypoint size does not match the number of velocity limits");
    }
    double segment = 0.0;
    for (size_t i = 0; i < a.size(); ++i) {
      segment = std::max(segment, std::abs(b[i] - a[i]) / (velocity_limits[i] * velocity_scale));
    }
    times[k] = times[k - 1] + segment;
  }
  const double total = times.back();
  if (total < min_duration) {
    if (total <= 0.0) {
      // No motion at all: spread the waypoints evenly over min_duration.
      for (size_t k = 1; k < times.size(); ++k) times[k] = min_duration * k / (times.size() - 1);
    } else {
      const double stretch = min_duration / total;
      for (double& t : times) t *= stretch;
    }
  }
  return times;
}

}  // namespace moverl_shield
