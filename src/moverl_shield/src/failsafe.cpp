#include "moverl_shield/failsafe.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace moverl_shield {

namespace {

void checkState(const std::vector<double>& q, const std::vector<double>& v, const StopLimits& limits) {
  const std::size_t n = q.size();
  if (v.size() != n || limits.velocity.size() != n || limits.deceleration.size() != n) {
    throw std::invalid_argument("failsafe stop: " + std::to_string(n) + " positions need as many velocities (" +
                                std::to_string(v.size()) + "), velocity limits (" +
                                std::to_string(limits.velocity.size()) + ") and deceleration limits (" +
                                std::to_string(limits.deceleration.size()) + ")");
  }
  for (std::size_t i = 0; i < n; ++i) {
    if (!std::isfinite(q[i]) || !std::isfinite(v[i])) {
      throw std::invalid_argument("failsafe stop: joint " + std::to_string(i) + "'s state is not finite");
    }
    if (!(limits.velocity[i] > 0.0) || !std::isfinite(limits.velocity[i]) || !(limits.deceleration[i] > 0.0) ||
        !std::isfinite(limits.deceleration[i])) {
      throw std::invalid_argument("failsafe stop: joint " + std::to_string(i) +
                                  "'s velocity and deceleration limits must be positive and finite");
    }
  }
  if (!(limits.reaction_time >= 0.0) || !std::isfinite(limits.reaction_time)) {
    throw std::invalid_argument("failsafe stop: the reaction time must be finite and >= 0");
  }
}

}  // namespace

StopBound failsafeStop(const std::vector<double>& q, const std::vector<double>& v, const StopLimits& limits) {
  checkState(q, v, limits);
  const std::size_t n = q.size();
  const double tr = limits.reaction_time;
  // Speeds at the brake's start, per joint: the lowest and highest signed value (a joint may accelerate either way
  // during the reaction, within its velocity limit; a measured speed beyond the limit is taken as it is).
  std::vector<double> u_lo(n), u_hi(n);
  double tb = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const double a = limits.deceleration[i], vmax = limits.velocity[i];
    u_hi[i] = std::max(v[i], std::min(v[i] + a * tr, vmax));
    u_lo[i] = std::min(v[i], std::max(v[i] - a * tr, -vmax));
    tb = std::max(tb, std::max(std::fabs(u_lo[i]), std::fabs(u_hi[i])) / a);
  }
  StopBound b;
  b.reaction_time = tr;
  b.braking_time = tb;
  b.lower.resize(n);
  b.upper.resize(n);
  b.travel.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    // Reaction: v t +- a t^2 / 2 (concave and convex in t: the extremes at t = 0, the start, or at T_r). Braking with
    // every joint at rest at tb: a joint starting at speed u travels u tb / 2 (its deceleration |u| / tb is within its
    // limit, as tb >= |u| / a), away from where the reaction left it.
    const double drift = 0.5 * limits.deceleration[i] * tr * tr;
    b.lower[i] = std::min(q[i], q[i] + v[i] * tr - drift + std::min(0.0, u_lo[i]) * 0.5 * tb);
    b.upper[i] = std::max(q[i], q[i] + v[i] * tr + drift + std::max(0.0, u_hi[i]) * 0.5 * tb);
    b.travel[i] = std::max(q[i] - b.lower[i], b.upper[i] - q[i]);
  }
  return b;
}

TimedTrajectory brakingTrajectory(const std::vector<double>& q, const std::vector<double>& v, const StopLimits& limits,
                                  double sample_period) {
  checkState(q, v, limits);
  if (!(sample_period > 0.0) || !std::isfinite(sample_period)) {
    throw std::invalid_argument("failsafe stop: the sample period must be positive");
  }
  const std::size_t n = q.size();
  double tb = 0.0;
  for (std::size_t i = 0; i < n; ++i) tb = std::max(tb, std::fabs(v[i]) / limits.deceleration[i]);
  TimedTrajectory t;
  std::vector<double> times{0.0};
  if (tb > 0.0) {
    const auto steps = static_cast<std::size_t>(std::ceil(tb / sample_period - 1e-9));
    for (std::size_t k = 1; k < steps; ++k) times.push_back(static_cast<double>(k) * sample_period);
    times.push_back(tb);
  }
  for (double s : times) {
    std::vector<double> p(n), dv(n), acc(n);
    for (std::size_t i = 0; i < n; ++i) {
      const double d = tb > 0.0 ? v[i] / tb : 0.0;  // the joint's deceleration (signed against its motion)
      p[i] = q[i] + v[i] * s - 0.5 * d * s * s;
      dv[i] = v[i] - d * s;
      acc[i] = -d;
    }
    if (s == tb) std::fill(dv.begin(), dv.end(), 0.0);  // exactly at rest (rounding)
    t.times.push_back(s);
    t.positions.push_back(p);
    t.velocities.push_back(dv);
    t.accelerations.push_back(acc);
  }
  return t;
}

double pointTravelBound(const std::vector<double>& travel, const std::vector<double>& radius_bounds) {
  if (travel.size() != radius_bounds.size()) {
    throw std::invalid_argument("point travel bound: " + std::to_string(travel.size()) + " joint travels but " +
                                std::to_string(radius_bounds.size()) + " radius bounds");
  }
  double d = 0.0;
  for (std::size_t i = 0; i < travel.size(); ++i) {
    if (!(travel[i] >= 0.0) || !(radius_bounds[i] >= 0.0)) {
      throw std::invalid_argument("point travel bound: travels and radius bounds must be >= 0");
    }
    d += travel[i] * radius_bounds[i];
  }
  return d;
}

}  // namespace moverl_shield
