// Unit tests of the shield's ROS-free driver core and trajectory timing: states by name, limit tolerance, path
// tolerances from the tracking budget, what driver results mean, real-time windows, linear and min_jerk timing.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "moverl_shield/driver_core.h"
#include "moverl_shield/trajectory.h"

using namespace moverl_shield;

TEST(JointStateMapper, PicksControlledJointsByNameInAnyOrder) {
  JointStateMapper m({"j1", "j2", "j3"});
  std::vector<double> q, v;
  // A real driver: gripper joints included, names shuffled.
  EXPECT_EQ(m.extract({"finger", "j3", "j1", "j2"}, {0.04, 3.0, 1.0, 2.0}, {0.0, 0.3, 0.1, 0.2}, &q, &v), "");
  EXPECT_EQ(q, (std::vector<double>{1.0, 2.0, 3.0}));
  EXPECT_EQ(v, (std::vector<double>{0.1, 0.2, 0.3}));
  // Velocities are optional.
  EXPECT_EQ(m.extract({"j2", "j1", "j3"}, {2.0, 1.0, 3.0}, {}, &q, &v), "");
  EXPECT_EQ(v, (std::vector<double>{0.0, 0.0, 0.0}));
}

TEST(JointStateMapper, RefusesMissingDuplicatedMismatchedAndNonFinite) {
  JointStateMapper m({"j1", "j2"});
  std::vector<double> q, v;
  EXPECT_NE(m.extract({"j1"}, {1.0}, {}, &q, &v).find("lacks controlled joint(s) j2"), std::string::npos);
  EXPECT_NE(m.extract({"j1", "j1", "j2"}, {1, 1, 2}, {}, &q, &v).find("twice"), std::string::npos);
  EXPECT_NE(m.extract({"j1", "j2"}, {1.0}, {}, &q, &v).find("positions"), std::string::npos);
  EXPECT_NE(m.extract({"j1", "j2"}, {1.0, std::nan("")}, {}, &q, &v).find("not finite"), std::string::npos);
}

TEST(ClampToLimits, ClampsWithinToleranceAndRefusesBeyond) {
  std::vector<double> q{-1.0064, 0.5, 2.005};
  const std::vector<double> lo{-1.0, 0.0, 0.0}, hi{1.0, 1.0, 2.0};
  EXPECT_EQ(clampToLimits(&q, lo, hi, 0.01), "");
  EXPECT_EQ(q, (std::vector<double>{-1.0, 0.5, 2.0}));
  std::vector<double> far{0.0, 1.03, 1.0};
  const std::string err = clampToLimits(&far, lo, hi, 0.01);
  EXPECT_NE(err.find("joint 1"), std::string::npos) << err;
  EXPECT_EQ(far[1], 1.03);  // unchanged when refused
}

TEST(PathTolerances, EqualShareOfTheBudgetBoundsEveryPointsDeviation) {
  const std::vector<double> r{1.146, 1.146, 0.830, 0.748, 0.355, 0.355, 0.267};  // the Panda's (scene_benchmark)
  const std::vector<double> tol = pathTolerances(0.005, r);
  ASSERT_EQ(tol.size(), r.size());
  double bound = 0.0;
  for (std::size_t i = 0; i < r.size(); ++i) bound += r[i] * tol[i];
  EXPECT_NEAR(bound, 0.005, 1e-12);
  EXPECT_NEAR(tol[0], 0.005 / (7 * 1.146), 1e-12);
  EXPECT_THROW(pathTolerances(0.0, r), std::invalid_argument);
  EXPECT_THROW(pathTolerances(0.005, {1.0, 0.0}), std::invalid_argument);
}

TEST(VerdictForDriverEnd, DecidesWhatEndsTheEpisodeAndWhatRaises) {
  const auto path = static_cast<std::int32_t>(TrajectoryError::kPathToleranceViolated);
  const auto goal = static_cast<std::int32_t>(TrajectoryError::kGoalToleranceViolated);
  const auto joints = static_cast<std::int32_t>(TrajectoryError::kInvalidJoints);
  EXPECT_EQ(verdictForDriverEnd(Verdict::kReplanned, DriverEnd::kSucceeded, 0), Verdict::kReplanned);
  EXPECT_EQ(verdictForDriverEnd(Verdict::kSafe, DriverEnd::kAborted, path), Verdict::kAborted);
  EXPECT_EQ(verdictForDriverEnd(Verdict::kSafe, DriverEnd::kAborted, goal), Verdict::kAborted);
  EXPECT_EQ(verdictForDriverEnd(Verdict::kSafe, DriverEnd::kAborted, -1), Verdict::kExecutionFailed);
  EXPECT_EQ(verdictForDriverEnd(Verdict::kSafe, DriverEnd::kRejected, joints), Verdict::kExecutionFailed);
  EXPECT_EQ(verdictForDriverEnd(Verdict::kSafe, DriverEnd::kPreempted, 0), Verdict::kExecutionFailed);
  EXPECT_EQ(verdictForDriverEnd(Verdict::kSafe, DriverEnd::kTimedOut, 0), Verdict::kDriverUnavailable);
  EXPECT_EQ(verdictForDriverEnd(Verdict::kSafe, DriverEnd::kUnreachable, 0), Verdict::kDriverUnavailable);
  EXPECT_EQ(verdictForDriverEnd(Verdict::kSafe, DriverEnd::kLost, 0), Verdict::kDriverUnavailable);
  EXPECT_EQ(trajectoryErrorName(path), "PATH_TOLERANCE_VIOLATED");
  EXPECT_EQ(trajectoryErrorName(-42), "CODE -42");
}

TEST(DriverEndForCall, AMoveSentAndNotAnsweredIsLostNotUnreachable) {
  // Only a call that never delivered its request says the driver is not there; a connection closed while the answer
  // was awaited, or an error answer, may follow a move that was made: lost (and never sent again by the transport).
  EXPECT_EQ(driverEndForCall(CallEnd::kAnswered), DriverEnd::kSucceeded);
  EXPECT_EQ(driverEndForCall(CallEnd::kTimedOut), DriverEnd::kTimedOut);
  EXPECT_EQ(driverEndForCall(CallEnd::kUnreachable), DriverEnd::kUnreachable);
  EXPECT_EQ(driverEndForCall(CallEnd::kClosed), DriverEnd::kLost);
  EXPECT_EQ(driverEndForCall(CallEnd::kFailed), DriverEnd::kLost);
  for (CallEnd end : {CallEnd::kTimedOut, CallEnd::kUnreachable, CallEnd::kClosed, CallEnd::kFailed}) {
    EXPECT_EQ(verdictForDriverEnd(Verdict::kSafe, driverEndForCall(end), 0), Verdict::kDriverUnavailable)
        << moverl_tcpros::callEndName(end);
    EXPECT_FALSE(resultKnown(driverEndForCall(end))) << moverl_tcpros::callEndName(end);
  }
  for (DriverEnd end : {DriverEnd::kSucceeded, DriverEnd::kAborted, DriverEnd::kRejected, DriverEnd::kPreempted}) {
    EXPECT_TRUE(resultKnown(end));
  }
}

TEST(RealTimeWindow, CoversFromTheStateToTheSettledEnd) {
  // State stamped 10.0 (motion epoch 4.0), move stamped to start 10.12, 0.3 s long, 0.5 s to settle.
  const MotionWindow w = realTimeWindow(10.0, 4.0, 10.12, 0.3, 0.5);
  EXPECT_DOUBLE_EQ(w.start_time, 6.0);
  EXPECT_NEAR(w.duration, 0.12 + 0.3 + 0.5, 1e-12);
  // A start "before" the state (clock skew) never shortens the window below the move itself.
  EXPECT_NEAR(realTimeWindow(10.0, 0.0, 9.9, 0.3, 0.0).duration, 0.3, 1e-12);
}

namespace {
TimingLimits limits(std::vector<double> acc = {}) {
  TimingLimits l;
  l.velocity = {2.0, 1.0};
  l.acceleration = std::move(acc);
  return l;
}
/// Distance of q from the segment a-b (joint space).
double offSegment(const std::vector<double>& q, const std::vector<double>& a, const std::vector<double>& b) {
  double dot = 0, len2 = 0;
  for (std::size_t i = 0; i < q.size(); ++i) {
    dot += (q[i] - a[i]) * (b[i] - a[i]);
    len2 += (b[i] - a[i]) * (b[i] - a[i]);
  }
  const double t = len2 > 0 ? std::min(1.0, std::max(0.0, dot / len2)) : 0.0;
  double d2 = 0;
  for (std::size_t i = 0; i < q.size(); ++i) d2 += std::pow(q[i] - (a[i] + t * (b[i] - a[i])), 2);
  return std::sqrt(d2);
}
}  // namespace

TEST(TimeTrajectory, LinearIsTheVelocityLimitedTimingWithPositionsOnly) {
  const Waypoints w{{0, 0}, {0.4, 0.1}, {0.4, 0.6}};
  const TimedTrajectory t = timeTrajectory(Profile::kLinear, w, limits(), 0.05);
  EXPECT_EQ(t.positions, w);
  EXPECT_TRUE(t.velocities.empty());
  EXPECT_EQ(t.times, timeWaypoints(w, {2.0, 1.0}, 0.05));
  // A single waypoint holds still for the minimum duration.
  const TimedTrajectory hold = timeTrajectory(Profile::kLinear, {{0.3, 0.2}}, limits(), 0.05);
  ASSERT_EQ(hold.positions.size(), 2u);
  EXPECT_DOUBLE_EQ(hold.duration(), 0.05);
}

TEST(TimeTrajectory, MinJerkStaysOnTheSegmentsWithinVelocityAndAccelerationLimits) {
  const Waypoints w{{0, 0}, {0.4, 0.1}, {0.4, 0.6}};
  const TimingLimits l = limits({5.0, 3.0});
  const TimedTrajectory t = timeTrajectory(Profile::kMinJerk, w, l, 0.05, 0.01);
  ASSERT_EQ(t.velocities.size(), t.positions.size());
  ASSERT_EQ(t.accelerations.size(), t.positions.size());
  EXPECT_EQ(t.positions.front(), w.front());
  EXPECT_EQ(t.positions.back(), w.back());
  // Every sample lies on one of the checked segments, and the waypoints are hit exactly and at rest.
  int hits = 0;
  for (std::size_t k = 0; k < t.positions.size(); ++k) {
    const double d = std::min(offSegment(t.positions[k], w[0], w[1]), offSegment(t.positions[k], w[1], w[2]));
    EXPECT_LT(d, 1e-12) << "sample " << k;
    if (t.positions[k] == w[1]) {
      ++hits;
      EXPECT_EQ(t.velocities[k], (std::vector<double>{0, 0}));
    }
    for (std::size_t i = 0; i < 2; ++i) {
      EXPECT_LE(std::fabs(t.velocities[k][i]), l.velocity[i] + 1e-9);
      EXPECT_LE(std::fabs(t.accelerations[k][i]), l.acceleration[i] + 1e-9);
    }
    if (k > 0) {
      EXPECT_GT(t.times[k], t.times[k - 1]);
      EXPECT_LE(t.times[k] - t.times[k - 1], 0.01 + 1e-12);
    }
  }
  EXPECT_EQ(hits, 1);
  // Segment 2 is limited by joint 2's acceleration: sqrt(5.7735 * 0.5 / 3) s; segment 1 by joint 1's.
  const double seg1 = std::max(1.875 * 0.4 / 2.0, std::sqrt(kMinJerkPeakAcceleration * 0.4 / 5.0));
  const double seg2 = std::max(1.875 * 0.5 / 1.0, std::sqrt(kMinJerkPeakAcceleration * 0.5 / 3.0));
  EXPECT_NEAR(t.duration(), seg1 + seg2, 1e-9);
}

TEST(TimeTrajectory, MinJerkStretchesToTheMinimumDurationAndRejectsBadLimits) {
  const TimedTrajectory t = timeTrajectory(Profile::kMinJerk, {{0, 0}, {0.01, 0}}, limits(), 0.2, 0.01);
  EXPECT_NEAR(t.duration(), 0.2, 1e-12);
  EXPECT_THROW(timeTrajectory(Profile::kMinJerk, {{0, 0}, {1, 1}}, limits({1.0}), 0.0), std::invalid_argument);
  EXPECT_THROW(timeTrajectory(Profile::kMinJerk, {{0, 0}, {1, 1}}, limits(), 0.0, 0.0), std::invalid_argument);
  TimingLimits zero = limits();
  zero.velocity_scale = 0.0;
  EXPECT_THROW(timeTrajectory(Profile::kLinear, {{0, 0}, {1, 1}}, zero, 0.0), std::invalid_argument);
  Profile p = Profile::kLinear;
  EXPECT_TRUE(parseProfile("min_jerk", &p));
  EXPECT_EQ(p, Profile::kMinJerk);
  EXPECT_FALSE(parseProfile("cubic", &p));
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
