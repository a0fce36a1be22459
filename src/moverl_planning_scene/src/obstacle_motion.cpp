// ObstacleMotion (collision_checker.h): a moving obstacle's displacement over motion time and its exact range over a
// window. The formulas are moverl_msgs/ObstacleMotion's; moverl_sim.world.ObjectMotion is the Python twin, checked on
// the same cases (moverl_sim/test/fixtures: obstacle_motion_cases.txt, reach_motion_cases.txt).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include "moverl_planning_scene/collision_checker.h"

namespace moverl_planning_scene {
namespace {

/// A reach cycle's offset at tau s since its reach began (<= 0: resting before it).
double reachProfile(const ObstacleMotion& m, double tau) {
  if (tau <= 0.0) return 0.0;
  if (tau < m.move) return 0.5 * m.amplitude * (1.0 - std::cos(M_PI * tau / m.move));
  if (tau <= m.move + m.hold) return m.amplitude;
  const double back = std::min(1.0, (tau - m.move - m.hold) / m.move);
  return 0.5 * m.amplitude * (1.0 + std::cos(M_PI * back));
}

}  // namespace

double ObstacleMotion::cycleDraw(std::uint32_t seed, std::uint64_t k) {
  std::uint64_t z = ((static_cast<std::uint64_t>(seed) << 32) ^ k) + 0x9E3779B97F4A7C15ULL;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  z ^= z >> 31;
  return static_cast<double>(z >> 11) * (1.0 / 9007199254740992.0);  // 2^53
}

double ObstacleMotion::offset(double t) const {
  switch (type) {
    case Type::kNone:
      return 0.0;
    case Type::kOscillate:
      return amplitude * std::sin(2.0 * M_PI * t / period + phase);
    case Type::kReach: {
      const double c = t / period + phase / (2.0 * M_PI);
      const double k = std::floor(c);
      if (!(k >= 0.0) || cycleDraw(seed, static_cast<std::uint64_t>(k)) >= chance) return 0.0;
      return reachProfile(*this, (c - k) * period - (period - 2.0 * move - hold));
    }
  }
  return 0.0;
}

void ObstacleMotion::range(double t0, double t1, double* lo, double* hi) const {
  if (!moving()) {
    *lo = *hi = 0.0;
    return;
  }
  const double o0 = offset(0.0);
  if (type == Type::kReach) {
    // Piecewise monotone: rest, out (rising), hold, back (falling). Its extremes over [t0, t1] lie at the window's
    // ends or at a piece's boundary inside it.
    if (!(t1 - t0 <= kMaxRangeCycles * period)) {  // (inf, NaN: the envelope)
      *lo = -o0;
      *hi = amplitude - o0;
      return;
    }
    double mn = std::min(offset(t0), offset(t1)), mx = std::max(offset(t0), offset(t1));
    const double shift = phase / (2.0 * M_PI);
    const double rest = period - 2.0 * move - hold;
    for (double k = std::floor(t0 / period + shift); (k - shift) * period <= t1; k += 1.0) {
      const double begin = (k - shift) * period + rest;  // this cycle's reach starts (if it reaches)
      for (double b : {begin, begin + move, begin + move + hold, begin + 2.0 * move + hold}) {
        if (b > t0 && b < t1) {
          const double v = offset(b);
          mn = std::min(mn, v);
          mx = std::max(mx, v);
        }
      }
    }
    *lo = mn - o0;
    *hi = mx - o0;
    return;
  }
  const double s0 = std::sin(phase);
  if (!(t1 - t0 < period)) {  // a full period or more (or inf/NaN: be conservative)
    *lo = amplitude * (-1.0 - s0);
    *hi = amplitude * (1.0 - s0);
    return;
  }
  const double w = 2.0 * M_PI / period;
  const double a0 = w * t0 + phase, a1 = w * t1 + phase;
  double mn = std::min(std::sin(a0), std::sin(a1)), mx = std::max(std::sin(a0), std::sin(a1));
  // Extrema of sin at pi/2 + k pi inside [a0, a1].
  for (double k = std::ceil((a0 - M_PI / 2) / M_PI); M_PI / 2 + k * M_PI <= a1; k += 1.0) {
    if (std::fmod(std::fabs(k), 2.0) == 0.0) {
      mx = 1.0;
    } else {
      mn = -1.0;
    }
  }
  *lo = amplitude * (mn - s0);
  *hi = amplitude * (mx - s0);
}

}  // namespace moverl_planning_scene
