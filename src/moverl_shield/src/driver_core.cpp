#include "moverl_shield/driver_core.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace moverl_shield {

JointStateMapper::JointStateMapper(std::vector<std::string> joints) : joints_(std::move(joints)) {
  for (std::size_t i = 0; i < joints_.size(); ++i) index_[joints_[i]] = i;
}

std::string JointStateMapper::extract(const std::vector<std::string>& names, const std::vector<double>& positions,
                                      const std::vector<double>& velocities, std::vector<double>* q,
                                      std::vector<double>* v) const {
  if (positions.size() != names.size()) {
    return "joint state has " + std::to_string(names.size()) + " names but " + std::to_string(positions.size()) +
           " positions";
  }
  const bool with_velocity = velocities.size() == names.size();
  q->assign(joints_.size(), 0.0);
  v->assign(joints_.size(), 0.0);
  std::vector<bool> seen(joints_.size(), false);
  for (std::size_t k = 0; k < names.size(); ++k) {
    auto it = index_.find(names[k]);
    if (it == index_.end()) continue;  // another joint of the robot (gripper, ...)
    if (seen[it->second]) return "joint state lists " + names[k] + " twice";
    seen[it->second] = true;
    (*q)[it->second] = positions[k];
    if (with_velocity) (*v)[it->second] = velocities[k];
  }
  std::string missing;
  for (std::size_t i = 0; i < joints_.size(); ++i) {
    if (!seen[i]) missing += (missing.empty() ? "" : ", ") + joints_[i];
  }
  if (!missing.empty()) return "joint state lacks controlled joint(s) " + missing;
  for (std::size_t i = 0; i < joints_.size(); ++i) {
    if (!std::isfinite((*q)[i])) return "joint state: " + joints_[i] + " is not finite";
  }
  return "";
}

std::string clampToLimits(std::vector<double>* q, const std::vector<double>& lower, const std::vector<double>& upper,
                          double tolerance) {
  for (std::size_t i = 0; i < q->size(); ++i) {
    const double x = (*q)[i];
    if (!(x >= lower[i] - tolerance && x <= upper[i] + tolerance)) {
      std::ostringstream m;
      m << "joint " << i << " is at " << x << ", beyond its limits [" << lower[i] << ", " << upper[i]
        << "] by more than the tolerance " << tolerance;
      return m.str();
    }
  }
  for (std::size_t i = 0; i < q->size(); ++i) (*q)[i] = std::min(std::max((*q)[i], lower[i]), upper[i]);
  return "";
}

std::string clampToLimits(std::vector<double>* q, std::vector<double>* measured, const std::vector<double>& lower,
                          const std::vector<double>& upper, double tolerance) {
  *measured = *q;
  std::string bad = clampToLimits(q, lower, upper, tolerance);
  if (!bad.empty() || *measured == *q) measured->clear();
  return bad;
}

std::vector<double> pathTolerances(double budget, const std::vector<double>& radius_bounds) {
  if (!(budget > 0.0)) throw std::invalid_argument("the tracking budget must be positive");
  std::vector<double> out;
  out.reserve(radius_bounds.size());
  for (double r : radius_bounds) {
    if (!(r > 0.0)) throw std::invalid_argument("joint radius bounds must be positive");
    out.push_back(budget / (static_cast<double>(radius_bounds.size()) * r));
  }
  return out;
}

Verdict verdictForDriverEnd(Verdict decided, DriverEnd end, std::int32_t code) {
  switch (end) {
    case DriverEnd::kSucceeded:
      return decided;
    case DriverEnd::kAborted:
      if (code == static_cast<std::int32_t>(TrajectoryError::kPathToleranceViolated) ||
          code == static_cast<std::int32_t>(TrajectoryError::kGoalToleranceViolated)) {
        return Verdict::kAborted;
      }
      return Verdict::kExecutionFailed;
    case DriverEnd::kRejected:
    case DriverEnd::kPreempted:
      return Verdict::kExecutionFailed;
    case DriverEnd::kTimedOut:
    case DriverEnd::kUnreachable:
    case DriverEnd::kLost:
      return Verdict::kDriverUnavailable;
  }
  return Verdict::kDriverUnavailable;
}

DriverEnd driverEndForCall(CallEnd end) {
  switch (end) {
    case CallEnd::kAnswered:
      return DriverEnd::kSucceeded;
    case CallEnd::kTimedOut:
      return DriverEnd::kTimedOut;
    case CallEnd::kUnreachable:
      return DriverEnd::kUnreachable;
    case CallEnd::kClosed:
    case CallEnd::kFailed:
      return DriverEnd::kLost;
  }
  return DriverEnd::kLost;
}

bool resultKnown(DriverEnd end) {
  return end != DriverEnd::kTimedOut && end != DriverEnd::kUnreachable && end != DriverEnd::kLost;
}

std::string trajectoryErrorName(std::int32_t code) {
  switch (static_cast<TrajectoryError>(code)) {
    case TrajectoryError::kSuccessful:
      return "SUCCESSFUL";
    case TrajectoryError::kInvalidGoal:
      return "INVALID_GOAL";
    case TrajectoryError::kInvalidJoints:
      return "INVALID_JOINTS";
    case TrajectoryError::kOldHeaderTimestamp:
      return "OLD_HEADER_TIMESTAMP";
    case TrajectoryError::kPathToleranceViolated:
      return "PATH_TOLERANCE_VIOLATED";
    case TrajectoryError::kGoalToleranceViolated:
      return "GOAL_TOLERANCE_VIOLATED";
  }
  return "CODE " + std::to_string(code);
}

MotionWindow realTimeWindow(double state_stamp, double motion_epoch, double start, double duration, double goal_time) {
  MotionWindow w;
  w.start_time = state_stamp - motion_epoch;
  w.duration = std::max(0.0, start - state_stamp) + duration + goal_time;
  return w;
}

}  // namespace moverl_shield
