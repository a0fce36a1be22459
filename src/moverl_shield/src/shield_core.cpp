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
    case Verdict::kTruncated:
      return "truncated";
    case Verdict::kInvalidRequest:
      return "invalid_request";
    case Verdict::kSceneUnavailable:
      return "scene_unavailable";
    case Verdict::kExecutionFailed:
      return "execution_failed";
    case Verdict::kAborted:
      return "aborted";
    case Verdict::kDiscardedUnseen:
      return "discarded_unseen";
    case Verdict::kDriverUnavailable:
      return "driver_unavailable";
    case Verdict::kStateUnavailable:
      return "state_unavailable";
    case Verdict::kRetreated:
      return "retreated";
  }
  return "unknown";
}

bool isDiscarded(Verdict verdict) {
  return verdict == Verdict::kDiscardedSelf || verdict == Verdict::kDiscardedPose ||
         verdict == Verdict::kDiscardedPath || verdict == Verdict::kDiscardedStart || verdict == Verdict::kTruncated ||
         verdict == Verdict::kDiscardedUnseen || verdict == Verdict::kRetreated;
}

std::string strategyName(Strategy strategy) {
  switch (strategy) {
    case Strategy::kPlan:
      return "plan";
    case Strategy::kDiscard:
      return "discard";
    case Strategy::kLastSafe:
      return "last_safe";
    case Strategy::kRetreat:
      return "retreat";
  }
  return "unknown";
}

bool parseStrategy(const std::string& name, Strategy* strategy) {
  for (Strategy s : {Strategy::kPlan, Strategy::kDiscard, Strategy::kLastSafe, Strategy::kRetreat}) {
    if (name == strategyName(s)) {
      *strategy = s;
      return true;
    }
  }
  return false;
}

std::string strategyNames() { return "plan, discard, last_safe, retreat"; }

bool wantsPlan(Strategy strategy) { return strategy == Strategy::kPlan || strategy == Strategy::kRetreat; }
bool wantsLastFree(Strategy strategy) { return strategy == Strategy::kLastSafe; }

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

Decision decide(Strategy strategy, const SceneAnswer& answer, const std::vector<double>& start,
                const std::vector<double>& target) {
  Decision d;
  const MotionOutcome outcome = answer.outcome;
  // Unsafe outcomes: what was found, and the verdict when the robot holds still.
  Verdict held;
  switch (outcome) {
    case MotionOutcome::kValid:
      d.verdict = Verdict::kSafe;
      d.waypoints = {start, target};
      return d;
    case MotionOutcome::kSelfCollision:
      held = Verdict::kDiscardedSelf;
      break;
    case MotionOutcome::kPoseCollision:
      held = Verdict::kDiscardedPose;
      break;
    case MotionOutcome::kPathCollision:
      held = Verdict::kDiscardedPath;
      break;
    case MotionOutcome::kStartInCollision:
      held = Verdict::kDiscardedStart;
      break;
    case MotionOutcome::kInvalidRequest:
      d.verdict = Verdict::kInvalidRequest;
      return d;
    case MotionOutcome::kMapStale:  // blind: fail closed, as a discarded action (the episode goes on)
      d.verdict = Verdict::kDiscardedUnseen;
      d.unsafe_cause = static_cast<uint8_t>(outcome);
      return d;
    default:
      d.verdict = Verdict::kSceneUnavailable;  // unknown code: fail closed
      return d;
  }
  d.unsafe_cause = static_cast<uint8_t>(outcome);
  d.verdict = held;
  switch (strategy) {
    case Strategy::kPlan:
    case Strategy::kRetreat:
      if (outcome == MotionOutcome::kPathCollision && answer.replanned && answer.plan.size() >= 2) {
        d.verdict = Verdict::kReplanned;
        d.waypoints = answer.plan;
        // The plan starts at the state the scene checked; execute from the measured state exactly.
        d.waypoints.front() = start;
      } else if (strategy == Strategy::kRetreat && answer.retreat_state.size() == start.size()) {
        d.verdict = Verdict::kRetreated;
        d.waypoints = {start, answer.retreat_state};
      }
      break;
    case Strategy::kDiscard:
      break;  // never execute anything for an unsafe action (a plan, if any, is ignored)
    case Strategy::kLastSafe:
      if (outcome != MotionOutcome::kStartInCollision && answer.last_free_fraction > 0.0 &&
          answer.last_free_fraction <= 1.0 && answer.last_free_state.size() == start.size()) {
        d.verdict = Verdict::kTruncated;
        d.waypoints = {start, answer.last_free_state};
        d.truncated_fraction = answer.last_free_fraction;
      }
      break;
  }
  return d;
}

Decision decide(MotionOutcome outcome, bool replanned, const Waypoints& plan, const std::vector<double>& start,
                const std::vector<double>& target) {
  SceneAnswer answer;
  answer.outcome = outcome;
  answer.replanned = replanned;
  answer.plan = plan;
  return decide(Strategy::kPlan, answer, start, target);
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
