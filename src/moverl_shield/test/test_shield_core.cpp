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
  Decision d = decide(MotionOutcome::kValid, false, {}, kStart, kTarget);
  EXPECT_EQ(d.verdict, Verdict::kSafe);
  ASSERT_EQ(d.waypoints.size(), 2u);
  EXPECT_EQ(d.waypoints.front(), kStart);
  EXPECT_EQ(d.waypoints.back(), kTarget);
}

TEST(Decide, CollisionsAreDiscardedAndHoldStill) {
  EXPECT_EQ(decide(MotionOutcome::kSelfCollision, false, {}, kStart, kTarget).verdict, Verdict::kDiscardedSelf);
  EXPECT_EQ(decide(MotionOutcome::kPoseCollision, false, {}, kStart, kTarget).verdict, Verdict::kDiscardedPose);
  EXPECT_EQ(decide(MotionOutcome::kStartInCollision, false, {}, kStart, kTarget).verdict, Verdict::kDiscardedStart);
  Decision path = decide(MotionOutcome::kPathCollision, false, {}, kStart, kTarget);
  EXPECT_EQ(path.verdict, Verdict::kDiscardedPath);
  EXPECT_TRUE(path.waypoints.empty());
  EXPECT_TRUE(isDiscarded(path.verdict));
  EXPECT_FALSE(isDiscarded(Verdict::kSafe));
  EXPECT_FALSE(isDiscarded(Verdict::kReplanned));
}

TEST(Decide, AStaleSensedMapDiscardsWhateverTheStrategy) {
  for (Strategy s : {Strategy::kPlan, Strategy::kDiscard, Strategy::kLastSafe}) {
    SceneAnswer a;
    a.outcome = MotionOutcome::kMapStale;
    a.replanned = true;  // even with a plan or a last free state on offer: nothing is known free
    a.plan = {kStart, kTarget};
    a.last_free_fraction = 0.5;
    a.last_free_state = kTarget;
    const Decision d = decide(s, a, kStart, kTarget);
    EXPECT_EQ(d.verdict, Verdict::kDiscardedUnseen) << strategyName(s);
    EXPECT_TRUE(d.waypoints.empty());
    EXPECT_TRUE(isDiscarded(d.verdict));
    EXPECT_EQ(d.unsafe_cause, static_cast<uint8_t>(MotionOutcome::kMapStale));
  }
  EXPECT_EQ(verdictName(Verdict::kDiscardedUnseen), "discarded_unseen");
}

TEST(Decide, PathCollisionWithPlanExecutesThePlanFromTheMeasuredState) {
  Waypoints plan{{0.001, 0, 0}, {0.05, 0.1, 0}, kTarget};
  Decision d = decide(MotionOutcome::kPathCollision, true, plan, kStart, kTarget);
  EXPECT_EQ(d.verdict, Verdict::kReplanned);
  ASSERT_EQ(d.waypoints.size(), 3u);
  EXPECT_EQ(d.waypoints.front(), kStart);
  EXPECT_EQ(d.waypoints.back(), kTarget);
  // A "plan" of fewer than two points cannot be executed: discard.
  EXPECT_EQ(decide(MotionOutcome::kPathCollision, true, {kTarget}, kStart, kTarget).verdict, Verdict::kDiscardedPath);
}

TEST(Decide, UnknownSceneCodeFailsClosed) {
  Decision d = decide(static_cast<MotionOutcome>(42), false, {}, kStart, kTarget);
  EXPECT_EQ(d.verdict, Verdict::kSceneUnavailable);
  EXPECT_TRUE(d.waypoints.empty());
}

// ---- Strategies x outcomes -------------------------------------------------------------------------------

namespace {
const std::vector<double> kLastFree{0.04, -0.08, 0.02};  // 40 % of the way to kTarget
const Strategy kAllStrategies[] = {Strategy::kPlan, Strategy::kDiscard, Strategy::kLastSafe, Strategy::kRetreat};

// What a scene asked with the strategy's flags would answer (plan / last free state only when requested).
SceneAnswer answer(Strategy s, MotionOutcome outcome, bool plan_found = true, double last_free = 0.4) {
  SceneAnswer a;
  a.outcome = outcome;
  const bool unsafe = outcome == MotionOutcome::kSelfCollision || outcome == MotionOutcome::kPoseCollision ||
                      outcome == MotionOutcome::kPathCollision;
  if (outcome == MotionOutcome::kPathCollision && wantsPlan(s) && plan_found) {
    a.replanned = true;
    a.plan = {kStart, {0.05, 0.1, 0}, kTarget};
  }
  if (unsafe && wantsLastFree(s)) {
    a.last_free_fraction = last_free;
    a.last_free_state = last_free > 0.0 ? kLastFree : kStart;
  }
  return a;
}
}  // namespace

TEST(Strategy, NamesParseAndRoundTrip) {
  for (Strategy s : kAllStrategies) {
    Strategy parsed = Strategy::kPlan;
    ASSERT_TRUE(parseStrategy(strategyName(s), &parsed)) << strategyName(s);
    EXPECT_EQ(parsed, s);
  }
  EXPECT_EQ(strategyName(Strategy::kPlan), "plan");
  EXPECT_EQ(strategyName(Strategy::kDiscard), "discard");
  EXPECT_EQ(strategyName(Strategy::kLastSafe), "last_safe");
  EXPECT_EQ(strategyName(Strategy::kRetreat), "retreat");
  EXPECT_EQ(strategyNames(), "plan, discard, last_safe, retreat");
  Strategy s = Strategy::kDiscard;
  EXPECT_FALSE(parseStrategy("Plan", &s));
  EXPECT_FALSE(parseStrategy("hold", &s));
  EXPECT_FALSE(parseStrategy("", &s));
  EXPECT_EQ(s, Strategy::kDiscard);  // unchanged
  EXPECT_TRUE(wantsPlan(Strategy::kPlan));
  EXPECT_FALSE(wantsPlan(Strategy::kDiscard));
  EXPECT_FALSE(wantsPlan(Strategy::kLastSafe));
  EXPECT_TRUE(wantsPlan(Strategy::kRetreat));
  EXPECT_FALSE(wantsLastFree(Strategy::kRetreat));
  EXPECT_TRUE(wantsLastFree(Strategy::kLastSafe));
  EXPECT_FALSE(wantsLastFree(Strategy::kPlan));
  EXPECT_FALSE(wantsLastFree(Strategy::kDiscard));
}

TEST(Strategy, ValidStartInvalidAndUnknownAreTheSameForEveryStrategy) {
  for (Strategy s : kAllStrategies) {
    Decision d = decide(s, answer(s, MotionOutcome::kValid), kStart, kTarget);
    EXPECT_EQ(d.verdict, Verdict::kSafe) << strategyName(s);
    EXPECT_EQ(d.waypoints, (Waypoints{kStart, kTarget}));
    EXPECT_EQ(d.unsafe_cause, 0);
    EXPECT_EQ(d.truncated_fraction, -1.0);
    // A start in collision is held even if the scene (wrongly) sent a last free state.
    SceneAnswer start = answer(s, MotionOutcome::kStartInCollision);
    start.last_free_fraction = 0.5;
    start.last_free_state = kLastFree;
    d = decide(s, start, kStart, kTarget);
    EXPECT_EQ(d.verdict, Verdict::kDiscardedStart);
    EXPECT_TRUE(d.waypoints.empty());
    EXPECT_EQ(d.unsafe_cause, 4);
    d = decide(s, answer(s, MotionOutcome::kInvalidRequest), kStart, kTarget);
    EXPECT_EQ(d.verdict, Verdict::kInvalidRequest);
    EXPECT_TRUE(d.waypoints.empty());
    d = decide(s, answer(s, static_cast<MotionOutcome>(42)), kStart, kTarget);
    EXPECT_EQ(d.verdict, Verdict::kSceneUnavailable);
    EXPECT_TRUE(d.waypoints.empty());
  }
}

TEST(Strategy, PlanHoldsSelfAndPoseAndReplansThePath) {
  const Strategy s = Strategy::kPlan;
  Decision d = decide(s, answer(s, MotionOutcome::kSelfCollision), kStart, kTarget);
  EXPECT_EQ(d.verdict, Verdict::kDiscardedSelf);
  EXPECT_TRUE(d.waypoints.empty());
  EXPECT_EQ(d.unsafe_cause, 1);
  d = decide(s, answer(s, MotionOutcome::kPoseCollision), kStart, kTarget);
  EXPECT_EQ(d.verdict, Verdict::kDiscardedPose);
  EXPECT_TRUE(d.waypoints.empty());
  EXPECT_EQ(d.unsafe_cause, 2);
  d = decide(s, answer(s, MotionOutcome::kPathCollision), kStart, kTarget);
  EXPECT_EQ(d.verdict, Verdict::kReplanned);
  ASSERT_EQ(d.waypoints.size(), 3u);
  EXPECT_EQ(d.waypoints.front(), kStart);
  EXPECT_EQ(d.waypoints.back(), kTarget);
  EXPECT_EQ(d.unsafe_cause, 3);
  d = decide(s, answer(s, MotionOutcome::kPathCollision, /*plan_found=*/false), kStart, kTarget);
  EXPECT_EQ(d.verdict, Verdict::kDiscardedPath);
  EXPECT_TRUE(d.waypoints.empty());
  // A last free state sent anyway is ignored by plan.
  SceneAnswer a = answer(s, MotionOutcome::kPoseCollision);
  a.last_free_fraction = 0.4;
  a.last_free_state = kLastFree;
  EXPECT_EQ(decide(s, a, kStart, kTarget).verdict, Verdict::kDiscardedPose);
}

TEST(Strategy, DiscardNeverExecutesAPlanOrATruncatedMove) {
  const Strategy s = Strategy::kDiscard;
  const std::pair<MotionOutcome, Verdict> cases[] = {{MotionOutcome::kSelfCollision, Verdict::kDiscardedSelf},
                                                     {MotionOutcome::kPoseCollision, Verdict::kDiscardedPose},
                                                     {MotionOutcome::kPathCollision, Verdict::kDiscardedPath}};
  for (const auto& c : cases) {
    // Even if the scene sent a plan and a last free state (it was not asked to), nothing moves.
    SceneAnswer a = answer(s, c.first);
    a.replanned = true;
    a.plan = {kStart, {0.05, 0.1, 0}, kTarget};
    a.last_free_fraction = 0.4;
    a.last_free_state = kLastFree;
    Decision d = decide(s, a, kStart, kTarget);
    EXPECT_EQ(d.verdict, c.second);
    EXPECT_TRUE(d.waypoints.empty());
    EXPECT_EQ(d.unsafe_cause, static_cast<uint8_t>(c.first));
    EXPECT_EQ(d.truncated_fraction, -1.0);
    EXPECT_TRUE(isDiscarded(d.verdict));
  }
}

TEST(Strategy, LastSafeTruncatesEveryUnsafeActionWithProgress) {
  const Strategy s = Strategy::kLastSafe;
  for (MotionOutcome o :
       {MotionOutcome::kSelfCollision, MotionOutcome::kPoseCollision, MotionOutcome::kPathCollision}) {
    Decision d = decide(s, answer(s, o), kStart, kTarget);
    EXPECT_EQ(d.verdict, Verdict::kTruncated) << static_cast<int>(o);
    EXPECT_EQ(d.waypoints, (Waypoints{kStart, kLastFree}));
    EXPECT_EQ(d.unsafe_cause, static_cast<uint8_t>(o));
    EXPECT_DOUBLE_EQ(d.truncated_fraction, 0.4);
    EXPECT_TRUE(isDiscarded(d.verdict));  // the action was unsafe: punished
  }
  // A plan sent anyway is never executed by last_safe.
  SceneAnswer a = answer(s, MotionOutcome::kPathCollision);
  a.replanned = true;
  a.plan = {kStart, {0.05, 0.1, 0}, kTarget};
  EXPECT_EQ(decide(s, a, kStart, kTarget).verdict, Verdict::kTruncated);
}

TEST(Strategy, LastSafeWithoutProgressHoldsStill) {
  const Strategy s = Strategy::kLastSafe;
  const std::pair<MotionOutcome, Verdict> cases[] = {{MotionOutcome::kSelfCollision, Verdict::kDiscardedSelf},
                                                     {MotionOutcome::kPoseCollision, Verdict::kDiscardedPose},
                                                     {MotionOutcome::kPathCollision, Verdict::kDiscardedPath}};
  for (const auto& c : cases) {
    for (double t : {0.0, -1.0}) {  // no free state beyond the start; not computed
      Decision d = decide(s, answer(s, c.first, true, t), kStart, kTarget);
      EXPECT_EQ(d.verdict, c.second) << t;
      EXPECT_TRUE(d.waypoints.empty());
      EXPECT_EQ(d.unsafe_cause, static_cast<uint8_t>(c.first));
      EXPECT_EQ(d.truncated_fraction, -1.0);
    }
    // Malformed last free state (wrong size, fraction beyond 1): fail closed, hold still.
    SceneAnswer a = answer(s, c.first);
    a.last_free_state = {0.1};
    EXPECT_EQ(decide(s, a, kStart, kTarget).verdict, c.second);
    a = answer(s, c.first);
    a.last_free_fraction = 1.5;
    EXPECT_EQ(decide(s, a, kStart, kTarget).verdict, c.second);
  }
}

TEST(Strategy, RetreatBacksAwayWherePlanWouldHold) {
  const Strategy s = Strategy::kRetreat;
  const std::vector<double> away{-0.02, 0.01, 0.0};
  // As plan without a retreat state: replans a path, holds the rest.
  EXPECT_EQ(decide(s, answer(s, MotionOutcome::kPathCollision), kStart, kTarget).verdict, Verdict::kReplanned);
  EXPECT_EQ(decide(s, answer(s, MotionOutcome::kPoseCollision), kStart, kTarget).verdict, Verdict::kDiscardedPose);
  // A plan beats a retreat (the scene sends none then).
  SceneAnswer a = answer(s, MotionOutcome::kPathCollision);
  a.retreat_state = away;
  EXPECT_EQ(decide(s, a, kStart, kTarget).verdict, Verdict::kReplanned);
  const MotionOutcome refused[] = {MotionOutcome::kSelfCollision, MotionOutcome::kPoseCollision,
                                   MotionOutcome::kPathCollision, MotionOutcome::kStartInCollision};
  for (MotionOutcome o : refused) {
    a = answer(s, o, /*plan_found=*/false);
    a.retreat_state = away;
    Decision d = decide(s, a, kStart, kTarget);
    EXPECT_EQ(d.verdict, Verdict::kRetreated) << static_cast<int>(o);
    EXPECT_EQ(d.waypoints, (Waypoints{kStart, away}));
    EXPECT_EQ(d.unsafe_cause, static_cast<uint8_t>(o));  // what was refused
    EXPECT_TRUE(isDiscarded(d.verdict));                 // the action was unsafe: punished
    a.retreat_state = {0.1};                             // malformed: fail closed, hold still
    EXPECT_TRUE(decide(s, a, kStart, kTarget).waypoints.empty());
  }
  // Never for a blind map, an invalid request or a valid move; and never by the other strategies.
  for (MotionOutcome o : {MotionOutcome::kMapStale, MotionOutcome::kInvalidRequest, MotionOutcome::kValid}) {
    a = answer(s, o);
    a.retreat_state = away;
    EXPECT_NE(decide(s, a, kStart, kTarget).verdict, Verdict::kRetreated);
  }
  for (Strategy other : {Strategy::kPlan, Strategy::kDiscard, Strategy::kLastSafe}) {
    a = answer(other, MotionOutcome::kPoseCollision, true, 0.0);
    a.retreat_state = away;
    EXPECT_NE(decide(other, a, kStart, kTarget).verdict, Verdict::kRetreated) << strategyName(other);
  }
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
  EXPECT_EQ(verdictName(Verdict::kTruncated), "truncated");
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
