#include "moverl_shield/trajectory.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace moverl_shield {

bool parseProfile(const std::string& name, Profile* profile) {
  for (Profile p : {Profile::kLinear, Profile::kMinJerk}) {
    if (name == profileName(p)) {
      *profile = p;
      return true;
    }
  }
  return false;
}

std::string profileName(Profile profile) { return profile == Profile::kLinear ? "linear" : "min_jerk"; }

namespace {

void checkLimits(const Waypoints& waypoints, const TimingLimits& limits) {
  if (!(limits.velocity_scale > 0.0)) throw std::invalid_argument("velocity_scale must be positive");
  for (double v : limits.velocity) {
    if (!(v > 0.0)) throw std::invalid_argument("velocity limits must be positive");
  }
  if (!limits.acceleration.empty()) {
    if (limits.acceleration.size() != limits.velocity.size()) {
      throw std::invalid_argument("acceleration limits must have one value per joint, like the velocity limits");
    }
    for (double a : limits.acceleration) {
      if (!(a > 0.0)) throw std::invalid_argument("acceleration limits must be positive");
    }
  }
  for (const auto& w : waypoints) {
    if (w.size() != limits.velocity.size()) {
      throw std::invalid_argument("waypoint size does not match the number of velocity limits");
    }
  }
}

/// Rest-to-rest quintic: s, ds/dtau, d2s/dtau2 at tau in [0, 1].
void minJerk(double tau, double* s, double* ds, double* dds) {
  const double t2 = tau * tau, t3 = t2 * tau;
  *s = t3 * (10.0 - 15.0 * tau + 6.0 * t2);
  *ds = t2 * (30.0 - 60.0 * tau + 30.0 * t2);
  *dds = tau * (60.0 - 180.0 * tau + 120.0 * t2);
}

}  // namespace

TimedTrajectory timeTrajectory(Profile profile, const Waypoints& waypoints, const TimingLimits& limits,
                               double min_duration, double sample_period) {
  TimedTrajectory out;
  if (waypoints.empty()) return out;
  checkLimits(waypoints, limits);
  Waypoints points = waypoints;
  if (points.size() == 1) points.push_back(points.front());  // hold still for min_duration
  if (profile == Profile::kLinear) {
    out.times = timeWaypoints(points, limits.velocity, min_duration, limits.velocity_scale);
    out.positions = std::move(points);
    return out;
  }
  if (!(sample_period > 0.0)) throw std::invalid_argument("sample_period must be positive");
  // Segment durations: the slowest joint's peak velocity (and acceleration) of the quintic at the (scaled) limits.
  const std::size_t n = limits.velocity.size();
  const double scale = limits.velocity_scale;
  std::vector<double> seg(points.size() - 1, 0.0);
  double total = 0.0;
  for (std::size_t k = 0; k + 1 < points.size(); ++k) {
    for (std::size_t i = 0; i < n; ++i) {
      const double d = std::abs(points[k + 1][i] - points[k][i]);
      seg[k] = std::max(seg[k], kMinJerkPeakVelocity * d / (limits.velocity[i] * scale));
      if (!limits.acceleration.empty()) {
        seg[k] = std::max(seg[k], std::sqrt(kMinJerkPeakAcceleration * d / (limits.acceleration[i] * scale * scale)));
      }
    }
    total += seg[k];
  }
  if (total < min_duration) {
    if (total <= 0.0) {
      std::fill(seg.begin(), seg.end(), min_duration / seg.size());
    } else {
      for (double& t : seg) t *= min_duration / total;
    }
  }
  double t0 = 0.0;
  out.times.push_back(0.0);
  out.positions.push_back(points.front());
  out.velocities.emplace_back(n, 0.0);
  out.accelerations.emplace_back(n, 0.0);
  for (std::size_t k = 0; k < seg.size(); ++k) {
    const double T = seg[k];
    if (T <= 0.0) continue;  // a repeated waypoint
    const int samples = std::max(1, static_cast<int>(std::ceil(T / sample_period - 1e-9)));
    for (int j = 1; j <= samples; ++j) {
      const double tau = static_cast<double>(j) / samples;
      double s, ds, dds;
      minJerk(tau, &s, &ds, &dds);
      std::vector<double> q(n), v(n), a(n);
      for (std::size_t i = 0; i < n; ++i) {
        const double delta = points[k + 1][i] - points[k][i];
        q[i] = j == samples ? points[k + 1][i] : points[k][i] + s * delta;  // waypoints exactly
        v[i] = j == samples ? 0.0 : ds / T * delta;
        a[i] = j == samples ? 0.0 : dds / (T * T) * delta;
      }
      out.times.push_back(t0 + tau * T);
      out.positions.push_back(std::move(q));
      out.velocities.push_back(std::move(v));
      out.accelerations.push_back(std::move(a));
    }
    t0 += T;
  }
  return out;
}

}  // namespace moverl_shield
