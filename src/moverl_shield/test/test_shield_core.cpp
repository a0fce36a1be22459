// Unit tests of the shield's ROS-free core: decision table and trajectory timing.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "moverl_shield/shield_core.h"

using namespace moverl_shield;

namespace {
const std::vector<double> kStart{0, 0, 0};
const std::vector<double> kTarget{0.1, -0.2, 0.05};
}  // namespace

TEST(Decide, ValidMoveExecutesDirectly) {
  Decision d = decide(SceneOutcome::kValid, false, {}, kStart, kTarget);
  EXPECT_EQ(d.verdict, Verdict::kSafe);
  ASSERT_EQ(d.waypoints.size(), 2u);
  EXPECT_EQ(d.waypoints.front(), kStart);
  EXPECT_EQ(d.waypoints.back(), kTarget);
}

TEST(Decide, CollisionsAreDiscardedAndHoldStill) {
  EXPECT_EQ(decide(SceneOutcome::kSelfCollision, false, {}, kStart, kTarget).verdict, Verdict::kDiscardedSelf);
  EXPECT_EQ(decide(SceneOutcome::kPoseCollision, false, {}, kStart, kTarget).verdict, Verdict::kDiscardedPose);
  EXPECT_EQ(decide(SceneOutcome::kStartInCollision, false, {}, kStart, kTarget).verdict, Verdict::kDiscardedStart);
  Decision path = decide(SceneOutcome::kPathCollision, false, {}, kStart, kTarget);
  EXPECT_EQ(path.verdict, Verdict::kDiscardedPath);
  EXPECT_TRUE(path.waypoints.empty());
  EXPECT_TRUE(isDiscarded(path.verdict));
  EXPECT_FALSE(isDiscarded(Verdict::kSafe));
  EXPECT_FALSE(isDiscarded(Verdict::kReplanned));
}

TEST(Decide, PathCollisionWithPlanExecutesThePlanFromTheMeasuredState) {
  Waypoints plan{{0.001, 0, 0}, {0.05, 0.1, 0}, kTarget};
  Decision d = decide(SceneOutcome::kPathCollision, true, plan, kStart, kTarget);
  EXPECT_EQ(d.verdict, Verdict::kReplanned);
  ASSERT_EQ(d.waypoints.size(), 3u);
  EXPECT_EQ(d.waypoints.front(), kStart);
  EXPECT_EQ(d.waypoints.back(), kTarget);
  // A "plan" of fewer than two points cannot be executed: discard.
  EXPECT_EQ(decide(SceneOutcome::kPathCollision, true, {kTarget}, kStart, kTarget).verdict, Verdict::kDiscardedPath);
}

TEST(Decide, UnknownSceneCodeFailsClosed) {
  Decision d = decide(static_cast<SceneOutcome>(42), false, {}, kStart, kTarget);
  EXPECT_EQ(d.verdict, Verdict::kSceneUnavailable);
  EXPECT_TRUE(d.waypoints.empty());
}

TEST(ValidateTarget, RejectsWrongSizeAndNonFinite) {
  EXPECT_EQ(validateTarget(kTarget, 3), "");
  EXPECT_NE(validateTarget(kTarget, 7).find("3 values"), std::string::npos);
  EXPECT_NE(validateTarget({0, std::nan(""), 0}, 3), "");
  EXPECT_NE(validateTarget({0, std::numeric_limits<double>::infinity(), 0}, 3), "");
}

TEST(TimeWaypoints, RespectsVelocityLimitsAndMinimumDuration) {
  const std::vector<double> vmax{1.0, 2.0, 0.5};
  // Slowest joint: joint 2 needs 0.05 / 0.5 = 0.1 s; joint 1: 0.2 / 2 = 0.1 s.
  auto t = timeWaypoints({kStart, kTarget}, vmax, 0.05);
  ASSERT_EQ(t.size(), 2u);
  EXPECT_DOUBLE_EQ(t[0], 0.0);
  EXPECT_NEAR(t[1], 0.1, 1e-12);
  // A minimum duration longer than needed stretches the motion.
  t = timeWaypoints({kStart, kTarget}, vmax, 0.5);
  EXPECT_NEAR(t[1], 0.5, 1e-12);
  // Half speed doubles the time.
  t = timeWaypoints({kStart, kTarget}, vmax, 0.0, 0.5);
  EXPECT_NEAR(t[1], 0.2, 1e-12);
  // Every segment of a multi-point path is within the limits.
  Waypoints path{kStart, {0.3, 0, 0}, {0.3, 0.4, 0.1}};
  t = timeWaypoints(path, vmax, 0.0);
  for (size_t k = 1; k < path.size(); ++k) {
    for (size_t i = 0; i < vmax.size(); ++i) {
      EXPECT_LE(std::abs(path[k][i] - path[k - 1][i]) / (t[k] - t[k - 1]), vmax[i] * (1 + 1e-9));
    }
  }
  EXPECT_THROW(timeWaypoints({kStart, {0, 0}}, vmax, 0.0), std::invalid_argument);
  EXPECT_THROW(timeWaypoints({kStart, kTarget}, {1, 0, 1}, 0.0), std::invalid_argument);
}

TEST(VerdictName, NamesAreStable) {
  EXPECT_EQ(verdictName(Verdict::kSafe), "safe");
  EXPECT_EQ(verdictName(Verdict::kDiscardedPath), "discarded_path");
  EXPECT_EQ(verdictName(Verdict::kSceneUnavailable), "scene_unavailable");
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
