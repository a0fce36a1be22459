// The failsafe stop's model (failsafe.h) and ISO/TS 15066's separation rule (ssm.h), without ROS.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <stdexcept>
#include <vector>

#include "moverl_shield/failsafe.h"
#include "moverl_shield/ssm.h"

namespace moverl_shield {
namespace {

StopLimits limits2(double reaction = 0.0) {
  StopLimits l;
  l.velocity = {2.0, 1.0};
  l.deceleration = {10.0, 4.0};
  l.reaction_time = reaction;
  return l;
}

TEST(FailsafeStop, FromStandstillItIsTheReactionsDriftOnly) {
  const StopBound b = failsafeStop({0.3, -0.2}, {0.0, 0.0}, limits2(0.1));
  // Each joint may accelerate during the reaction (0.1 s) and then brake: a T^2 / 2 + (a T) tb / 2, tb = max aT/a.
  EXPECT_NEAR(b.braking_time, 0.1, 1e-12);
  EXPECT_NEAR(b.upper[0] - 0.3, 0.05 + 1.0 * 0.05, 1e-12);
  EXPECT_NEAR(0.3 - b.lower[0], 0.05 + 1.0 * 0.05, 1e-12);
  EXPECT_NEAR(b.upper[1] + 0.2, 0.02 + 0.4 * 0.05, 1e-12);
  const StopBound still = failsafeStop({0.3, -0.2}, {0.0, 0.0}, limits2(0.0));
  EXPECT_EQ(still.duration(), 0.0);
  EXPECT_EQ(still.travel, (std::vector<double>{0.0, 0.0}));
}

TEST(FailsafeStop, WithoutReactionTheSlowestJointSetsTheTimeAndEveryJointKeepsTheLine) {
  // Joint 0 needs 1.0 / 10 = 0.1 s, joint 1 0.8 / 4 = 0.2 s: both stop at 0.2 s, on the line q + v t.
  const StopBound b = failsafeStop({0.0, 0.0}, {1.0, -0.8}, limits2());
  EXPECT_NEAR(b.braking_time, 0.2, 1e-12);
  EXPECT_NEAR(b.upper[0], 0.1, 1e-12);  // v tb / 2
  EXPECT_EQ(b.lower[0], 0.0);
  EXPECT_NEAR(b.lower[1], -0.08, 1e-12);
  EXPECT_EQ(b.upper[1], 0.0);
  EXPECT_NEAR(b.travel[0], 0.1, 1e-12);
  EXPECT_NEAR(b.travel[1], 0.08, 1e-12);
  // Its own stop (each joint alone) would be shorter for joint 0: 1 / 20 = 0.05 rad. The line costs travel.
  EXPECT_GT(b.travel[0], 1.0 * 1.0 / (2 * 10.0));
}

TEST(FailsafeStop, ABrakingTrajectoryStaysInTheBoundWithinTheLimitsAndEndsAtRest) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> speed(-1.0, 1.0);
  const StopLimits l = limits2();
  for (int k = 0; k < 200; ++k) {
    const std::vector<double> q{0.1, -0.4}, v{2.0 * speed(rng), speed(rng)};
    const StopBound b = failsafeStop(q, v, l);
    const TimedTrajectory t = brakingTrajectory(q, v, l, 0.01);
    ASSERT_NEAR(t.duration(), b.braking_time, 1e-12);
    for (std::size_t p = 0; p < t.times.size(); ++p) {
      if (p > 0) {
        ASSERT_GT(t.times[p], t.times[p - 1]);
        ASSERT_LE(t.times[p] - t.times[p - 1], 0.01 + 1e-12);
      }
      for (std::size_t i = 0; i < 2; ++i) {
        ASSERT_GE(t.positions[p][i], b.lower[i] - 1e-12);
        ASSERT_LE(t.positions[p][i], b.upper[i] + 1e-12);
        ASSERT_LE(std::fabs(t.accelerations[p][i]), l.deceleration[i] + 1e-9);
        ASSERT_LE(std::fabs(t.velocities[p][i]), std::fabs(v[i]) + 1e-12);  // only ever slower
      }
    }
    for (std::size_t i = 0; i < 2; ++i) {
      EXPECT_EQ(t.velocities.back()[i], 0.0);
      EXPECT_NEAR(t.positions.back()[i], q[i] + 0.5 * v[i] * b.braking_time, 1e-12);
    }
  }
}

TEST(FailsafeStop, FromStandstillTheTrajectoryIsOnePoint) {
  const TimedTrajectory t = brakingTrajectory({0.5, 0.5}, {0.0, 0.0}, limits2(), 0.01);
  ASSERT_EQ(t.times.size(), 1u);
  EXPECT_EQ(t.positions[0], (std::vector<double>{0.5, 0.5}));
}

TEST(FailsafeStop, AMeasuredSpeedBeyondTheLimitIsTakenAsItIs) {
  // 2.5 rad/s on a 2 rad/s joint (encoder noise, a push): braking starts from 2.5, not from the limit.
  const StopBound b = failsafeStop({0.0, 0.0}, {2.5, 0.0}, limits2(0.05));
  EXPECT_NEAR(b.braking_time, 0.25, 1e-12);
  EXPECT_NEAR(b.upper[0], 2.5 * 0.05 + 0.5 * 10.0 * 0.05 * 0.05 + 2.5 * 0.125, 1e-12);
  // Even braking as hard as it can during the reaction, the joint ends ahead of its start: the start bounds it.
  EXPECT_EQ(b.lower[0], 0.0);
}

TEST(FailsafeStop, BadInputIsRefused) {
  EXPECT_THROW(failsafeStop({0.0}, {0.0, 0.0}, limits2()), std::invalid_argument);
  EXPECT_THROW(failsafeStop({0.0, NAN}, {0.0, 0.0}, limits2()), std::invalid_argument);
  StopLimits l = limits2();
  l.deceleration[1] = 0.0;
  EXPECT_THROW(failsafeStop({0.0, 0.0}, {0.0, 0.0}, l), std::invalid_argument);
  EXPECT_THROW(failsafeStop({0.0, 0.0}, {0.0, 0.0}, limits2(-0.1)), std::invalid_argument);
  EXPECT_THROW(brakingTrajectory({0.0, 0.0}, {1.0, 0.0}, limits2(), 0.0), std::invalid_argument);
  EXPECT_THROW(pointTravelBound({0.1}, {0.5, 0.5}), std::invalid_argument);
}

TEST(FailsafeStop, PointTravelIsTheRadiusWeightedSum) {
  EXPECT_NEAR(pointTravelBound({0.1, 0.2}, {1.0, 0.5}), 0.2, 1e-12);
}

// ---- ISO/TS 15066's rule.

SsmParams iso() {
  SsmParams p;
  p.motion.max_acceleration = 20.0;
  p.motion.max_speed = 2.0;
  p.max_track_age = 0.2;
  p.sensor_uncertainty = 0.02;
  p.robot_uncertainty = 0.005;
  return p;
}

/// A part a track explains: its measured speed (m/s), the measurement's age (s), its radius (m).
PartState tracked(double speed, double age = 0.0, double radius = 0.0) {
  PartState part;
  part.tracked = true;
  part.speed = speed;
  part.age = age;
  part.radius = radius;
  return part;
}

TEST(Ssm, Iso13855SwitchesToTheBodySpeedBeyondReach) {
  SsmParams p = iso();
  EXPECT_NEAR(p.iso.distance(0.2), 0.4, 1e-12);   // 2.0 m/s: 0.4 m <= 0.5 m
  EXPECT_NEAR(p.iso.distance(0.4), 0.64, 1e-12);  // 2.0 would give 0.8 > 0.5: 1.6 m/s
  EXPECT_NEAR(p.iso.distance(0.26), 0.5, 1e-12);  // 1.6 m/s gives 0.416: at least 0.5
  p.iso.intrusion = 0.1;
  EXPECT_NEAR(p.iso.distance(0.1), 0.3, 1e-12);
}

TEST(Ssm, ATrackedPartAcceleratesUpToItsCap) {
  const SsmParams p = iso();
  const PartState part = tracked(0.5, 0.05, 0.1);
  // 0.05 + 0.05 = 0.1 s from 0.5 m/s at 20 m/s^2: the cap, 2 m/s, is reached at 0.075 s; 0.144 m, plus the radius.
  const double t_cap = 1.5 / 20.0;
  const double expect = 0.5 * t_cap + 10.0 * t_cap * t_cap + 2.0 * (0.1 - t_cap) + 0.1;
  EXPECT_NEAR(personReach(part, 0.05, p), expect, 1e-12);
  EXPECT_LT(personReach(part, 0.05, p), p.iso.distance(0.1) + 0.1);
}

TEST(Ssm, ALostOrStaleTrackFallsBackToIsoSpeeds) {
  const SsmParams p = iso();
  PartState part = tracked(0.0, 0.25);  // older than max_track_age (0.2)
  EXPECT_FALSE(monitored(part, p));
  EXPECT_NEAR(personReach(part, 0.1, p), p.iso.distance(0.35), 1e-12);
  part.tracked = false;
  part.age = 0.0;
  EXPECT_NEAR(personReach(part, 0.3, p), p.iso.distance(0.3), 1e-12);
}

TEST(Ssm, ATrackFasterThanTheCapKeepsItsSpeed) {
  const SsmParams p = iso();
  const PartState part = tracked(3.0);
  EXPECT_NEAR(personReach(part, 0.1, p), 0.3, 1e-12);
}

struct Arm {
  std::vector<double> q{0.0, 0.0}, v{1.0, -0.8}, radius{0.8, 0.4};
  StopLimits limits = limits2(0.02);
};

TEST(Ssm, JustOutsideSpGoesJustInsideSlowsFarInsideStops) {
  const Arm arm;
  const SsmParams p = iso();
  const PartState hand = tracked(1.0, 0.03, 0.06);
  const StopBound full = failsafeStop(arm.q, arm.v, arm.limits);
  const double sp = protectiveSeparation(hand, full, arm.radius, p);
  // S_p's terms: the hand over T_r + T_s (+ its age), the robot's travel, the uncertainties.
  EXPECT_NEAR(sp, personReach(hand, full.duration(), p) + pointTravelBound(full.travel, arm.radius) + 0.025, 1e-12);
  EXPECT_EQ(speedScale(sp + 1e-6, hand, arm.q, arm.v, arm.limits, arm.radius, p), 1.0);
  const double slowed = speedScale(sp - 0.02, hand, arm.q, arm.v, arm.limits, arm.radius, p);
  EXPECT_GT(slowed, 0.0);
  EXPECT_LT(slowed, 1.0);
  std::vector<double> vs{arm.v[0] * slowed, arm.v[1] * slowed};
  EXPECT_LE(protectiveSeparation(hand, failsafeStop(arm.q, vs, arm.limits), arm.radius, p), sp - 0.02);
  const double at_rest = protectiveSeparation(hand, failsafeStop(arm.q, {0.0, 0.0}, arm.limits), arm.radius, p);
  EXPECT_EQ(speedScale(at_rest - 1e-6, hand, arm.q, arm.v, arm.limits, arm.radius, p), 0.0);
}

TEST(Ssm, TheSameDistanceStopsForAnUnmonitoredPartThatATrackedOneAllows) {
  const Arm arm;
  const SsmParams p = iso();
  PartState hand = tracked(0.2);
  const double sp = protectiveSeparation(hand, failsafeStop(arm.q, arm.v, arm.limits), arm.radius, p);
  EXPECT_EQ(speedScale(sp, hand, arm.q, arm.v, arm.limits, arm.radius, p), 1.0);
  hand.tracked = false;  // the tracker lost it: ISO's 2.0 m/s
  EXPECT_LT(speedScale(sp, hand, arm.q, arm.v, arm.limits, arm.radius, p), 1.0);
}

TEST(Ssm, BadParametersAreRefused) {
  SsmParams p = iso();
  p.iso.hand_speed = 0.0;
  EXPECT_THROW(p.iso.distance(0.1), std::invalid_argument);
  p = iso();
  p.max_track_age = -1.0;
  EXPECT_THROW(personReach(PartState{}, 0.1, p), std::invalid_argument);
  PartState bad;
  bad.speed = NAN;
  EXPECT_THROW(personReach(bad, 0.1, iso()), std::invalid_argument);
  EXPECT_THROW(iso().iso.distance(-0.1), std::invalid_argument);
}

}  // namespace
}  // namespace moverl_shield

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
