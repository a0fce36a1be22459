#include "moverl_shield/ssm.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace moverl_shield {

namespace {

bool finiteNonNegative(double x) { return std::isfinite(x) && x >= 0.0; }

void checkParams(const SsmParams& p) {
  const std::string bad = p.iso.problem();
  if (!bad.empty()) throw std::invalid_argument("ssm: " + bad);
  const std::string motion = p.motion.problem();
  if (!motion.empty()) throw std::invalid_argument("ssm: " + motion);
  for (double x : {p.max_track_age, p.sensor_uncertainty, p.robot_uncertainty}) {
    if (!finiteNonNegative(x)) {
      throw std::invalid_argument("ssm: max_track_age and the uncertainties must be finite and >= 0");
    }
  }
}

void checkPart(const PartState& part) {
  if (!finiteNonNegative(part.age) || !finiteNonNegative(part.speed) || !finiteNonNegative(part.radius)) {
    throw std::invalid_argument("ssm: a part's age, speed and radius must be finite and >= 0");
  }
}

}  // namespace

bool monitored(const PartState& part, const SsmParams& params) {
  return part.tracked && part.age <= params.max_track_age;
}

namespace {

// The rule's terms for checked parameters and parts (the public functions check them once).
double reachOf(const PartState& part, double t, const SsmParams& params) {
  if (!finiteNonNegative(t)) throw std::invalid_argument("ssm: a time must be finite and >= 0");
  const double horizon = part.age + t;
  if (!monitored(part, params)) return params.iso.distance(horizon);
  return params.motion.travel(part.speed, horizon) + part.radius;
}

double separationOf(const PartState& part, const StopBound& stop, const std::vector<double>& radius_bounds,
                    const SsmParams& params) {
  return reachOf(part, stop.duration(), params) + pointTravelBound(stop.travel, radius_bounds) +
         params.sensor_uncertainty + params.robot_uncertainty;
}

}  // namespace

double personReach(const PartState& part, double t, const SsmParams& params) {
  checkParams(params);
  checkPart(part);
  return reachOf(part, t, params);
}

double protectiveSeparation(const PartState& part, const StopBound& stop, const std::vector<double>& radius_bounds,
                            const SsmParams& params) {
  checkParams(params);
  checkPart(part);
  return separationOf(part, stop, radius_bounds, params);
}

double speedScale(double distance, const PartState& part, const std::vector<double>& q, const std::vector<double>& v,
                  const StopLimits& limits, const std::vector<double>& radius_bounds, const SsmParams& params,
                  double resolution) {
  if (!(resolution > 0.0)) throw std::invalid_argument("ssm: the speed scale's resolution must be positive");
  checkParams(params);  // once: the bisection below evaluates S_p about log2(1 / resolution) times
  checkPart(part);
  auto separation = [&](double s) {
    std::vector<double> vs(v);
    for (double& x : vs) x *= s;
    return separationOf(part, failsafeStop(q, vs, limits), radius_bounds, params);
  };
  if (!(distance >= separation(0.0))) return 0.0;  // (NaN: stop)
  if (separation(1.0) <= distance) return 1.0;
  double ok = 0.0, bad = 1.0;  // S_p grows with the speed: bisect
  while (bad - ok > resolution) {
    const double mid = 0.5 * (ok + bad);
    (separation(mid) <= distance ? ok : bad) = mid;
  }
  return ok;
}

}  // namespace moverl_shield
