/**
 * \file test_planning_scene.cpp
 * \brief Core tests on the real Panda URDF from pybullet_data (no roscore). Skipped when pybullet_data was not found
 *        at configure time.
 */
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <random>
#include <sstream>

#include <unistd.h>

#include "moverl_planning_scene/planning_scene.h"
#include "panda_support.h"

namespace mps = moverl_planning_scene;

namespace {

using Clock = std::chrono::steady_clock;
const std::string kPandaUrdf = MOVERL_PANDA_URDF;
const std::vector<double> kHome = {0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785};
// Elbow folded: the hand hits panda_link1 (found by sampling, stable).
const std::vector<double> kSelfCollision = {0.0, 0.2, 0.0, -3.0, 0.0, 1.0, 0.785};
// Leaning forward and down: the hand goes below the table top (z = 0).
const std::vector<double> kIntoTable = {0.0, 1.0, 0.0, -1.5, 0.0, 1.571, 0.785};
constexpr double kPlanTime = 1.0;  // s, around the wall
// s, allowed overrun of a planning time limit in wall time: what is tested is that planning is bounded (an unbounded
// planner would run for seconds), not how fast this machine is while other jobs share its 2 cores.
constexpr double kTimeSlack = 0.5;
constexpr double kFkTolerance = 1e-9;

using mps::panda::box;
using mps::panda::readFile;

mps::PlanningSceneOptions pandaOptions() {
  mps::PlanningSceneOptions o = mps::panda::options(kPandaUrdf);
  o.planner.planning_time = kPlanTime;
  return o;
}

mps::WorldObject table() { return box("table", 1.5, 0.8, 0.03, 0.35, 0.0, -0.015); }
// 5 mm wall in the plane y = 0, in front of the robot, between kLeft and kRight.
mps::WorldObject wall() { return box("wall", 0.4, 0.005, 0.5, 0.45, 0.0, 0.45); }
std::vector<double> withJoint1(double v) {
  std::vector<double> q = kHome;
  q[0] = v;
  return q;
}

bool hasPair(const std::vector<mps::ContactPair>& pairs, const std::string& a, const std::string& b) {
  for (const auto& p : pairs) {
    if ((p.a == a && p.b == b) || (p.a == b && p.b == a)) return true;
  }
  return false;
}

class PandaScene : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    if (kPandaUrdf.empty()) return;
    std::string error;
    scene_ = mps::PlanningScene::create(readFile(kPandaUrdf), pandaOptions(), &error).release();
    ASSERT_NE(scene_, nullptr) << error;
  }
  static void TearDownTestSuite() {
    delete scene_;
    scene_ = nullptr;
  }
  void SetUp() override {
    ASSERT_FALSE(kPandaUrdf.empty()) << "pybullet_data (franka_panda/panda.urdf) not found at configure time";
    ASSERT_NE(scene_, nullptr);
    std::string error;
    ASSERT_TRUE(scene_->setWorld({}, &error)) << error;
  }
  void setWorld(const std::vector<mps::WorldObject>& objects) {
    std::string error;
    ASSERT_TRUE(scene_->setWorld(objects, &error)) << error;
  }
  /// Every segment of a plan passes the (guaranteed) path check.
  void expectPathValid(const std::vector<std::vector<double>>& path) {
    ASSERT_GE(path.size(), 2u);
    for (std::size_t k = 0; k + 1 < path.size(); ++k) {
      mps::PathCheck pc;
      scene_->checkPath(path[k], path[k + 1], &pc);
      EXPECT_EQ(pc.outcome, mps::CheckOutcome::kValid) << "segment " << k << ": " << pc.message;
    }
  }
  static mps::PlanningScene* scene_;
};
mps::PlanningScene* PandaScene::scene_ = nullptr;

TEST_F(PandaScene, HomeIsFree) {
  setWorld({table()});
  mps::StateCheck sc;
  scene_->checkState(kHome, &sc);
  EXPECT_EQ(sc.outcome, mps::CheckOutcome::kValid) << sc.message;
  EXPECT_TRUE(sc.pairs.empty());
}

TEST_F(PandaScene, FoldedElbowSelfCollides) {
  mps::StateCheck sc;
  scene_->checkState(kSelfCollision, &sc);
  ASSERT_EQ(sc.outcome, mps::CheckOutcome::kSelfCollision) << sc.message;
  EXPECT_TRUE(hasPair(sc.pairs, "panda_link1", "panda_hand")) << sc.message;
  // No pair the ACM disables may be reported.
  for (const auto& p : sc.pairs) {
    EXPECT_EQ(scene_->checker().acmReason(p.a, p.b), mps::AcmReason::kEnabled) << p.a << " / " << p.b;
  }
}

TEST_F(PandaScene, TableCollision) {
  mps::StateCheck sc;
  scene_->checkState(kIntoTable, &sc);
  EXPECT_EQ(sc.outcome, mps::CheckOutcome::kValid) << "no world yet: " << sc.message;
  setWorld({table()});
  scene_->checkState(kIntoTable, &sc);
  ASSERT_EQ(sc.outcome, mps::CheckOutcome::kWorldCollision) << sc.message;
  ASSERT_FALSE(sc.pairs.empty());
  for (const auto& p : sc.pairs) {
    EXPECT_EQ(p.b, "table");
    EXPECT_EQ(p.depth, 0.0);  // not computed by default
  }
  // The base link sits on the table (static links are never checked against the world).
  EXPECT_FALSE(hasPair(sc.pairs, "panda_link0", "table"));
}

TEST_F(PandaScene, PaddingInflatesObstacles) {
  // A sphere just above the flange at home: free without padding margin, colliding once inflated more.
  std::vector<Eigen::Isometry3d> poses;
  std::string error;
  ASSERT_TRUE(scene_->fk(kHome, {"panda_link1"}, &poses, &error)) << error;
  mps::WorldObject s;
  s.id = "ball";
  s.type = mps::ShapeType::kSphere;
  // panda_link1 is a column of radius < 0.1 around the z axis; a ball centred 0.25 m away (radius 0.14 + padding
  // 0.01) reaches 0.1 m from the axis (no contact expected within 0.1, contact expected with radius 0.2).
  s.pose.translation() = Eigen::Vector3d(-0.25, 0.0, 0.25);
  s.dimensions = {0.14};
  setWorld({s});
  mps::StateCheck sc;
  scene_->checkState(kHome, &sc);
  EXPECT_EQ(sc.outcome, mps::CheckOutcome::kValid) << sc.message;
  s.dimensions = {0.2};
  setWorld({s});
  scene_->checkState(kHome, &sc);
  EXPECT_EQ(sc.outcome, mps::CheckOutcome::kWorldCollision) << sc.message;
  EXPECT_TRUE(hasPair(sc.pairs, "panda_link1", "ball"));
}

TEST_F(PandaScene, ThinWallPathCollidesAndPlanningGoesAround) {
  setWorld({table(), wall()});
  const auto left = withJoint1(-0.8), right = withJoint1(0.8);
  mps::StateCheck sc;
  scene_->checkState(left, &sc);
  ASSERT_EQ(sc.outcome, mps::CheckOutcome::kValid) << sc.message;
  scene_->checkState(right, &sc);
  ASSERT_EQ(sc.outcome, mps::CheckOutcome::kValid) << sc.message;

  mps::PathCheck pc;
  scene_->checkPath(left, right, &pc);
  ASSERT_EQ(pc.outcome, mps::CheckOutcome::kWorldCollision) << pc.message;
  EXPECT_TRUE(pc.collision_fraction > 0.0 && pc.collision_fraction < 1.0) << pc.collision_fraction;
  EXPECT_EQ(pc.pairs.front().b, "wall");
  // First collision: the state just before it is free.
  EXPECT_GT(pc.checked_states, 2u);

  mps::PlanResult plan;
  scene_->plan(left, right, "RRTConnect", kPlanTime, &plan);
  ASSERT_EQ(plan.status, mps::PlanStatus::kSuccess) << plan.message;
  EXPECT_LE(plan.planning_time, kPlanTime + kTimeSlack);
  EXPECT_GT(plan.waypoints.size(), 2u);
  EXPECT_EQ(plan.waypoints.front(), left);
  EXPECT_EQ(plan.waypoints.back(), right);
  EXPECT_GT(plan.path_length, 1.6 - 1e-9);  // at least the straight distance
  expectPathValid(plan.waypoints);
}

TEST_F(PandaScene, ResolutionGuarantee) {
  // n = ceil(sum_i r_i |dq_i| / resolution) interior states; no robot point moves more than the resolution between
  // consecutive states: verify on sampled points (mesh-free bound check with link origins).
  const auto q0 = kHome;
  auto q1 = kHome;
  for (double& v : q1) v += 0.1;
  q1[3] = std::min(q1[3], scene_->model().upperLimits()[3]);
  double motion = 0.0;
  for (std::size_t i = 0; i < q0.size(); ++i)
    motion += scene_->checker().jointRadiusBound(i) * std::fabs(q1[i] - q0[i]);
  const std::size_t n = scene_->checker().interiorStateCount(q0.data(), q1.data());
  EXPECT_EQ(n, static_cast<std::size_t>(std::ceil(motion / scene_->checker().options().path_resolution)));
  mps::PathCheck pc;
  scene_->checkPath(q0, q1, &pc);
  EXPECT_EQ(pc.outcome, mps::CheckOutcome::kValid) << pc.message;
  EXPECT_EQ(pc.checked_states, n + 2);  // interior + both ends
  // Empirical: the fingertip (farthest point) moves less than the resolution between consecutive states.
  std::vector<Eigen::Isometry3d> a, b;
  std::string error;
  const std::vector<std::string> links = {"panda_leftfinger", "panda_rightfinger", "panda_grasptarget"};
  for (std::size_t k = 0; k <= n; ++k) {
    std::vector<double> qa(7), qb(7);
    for (std::size_t i = 0; i < 7; ++i) {
      qa[i] = q0[i] + (q1[i] - q0[i]) * k / (n + 1.0);
      qb[i] = q0[i] + (q1[i] - q0[i]) * (k + 1) / (n + 1.0);
    }
    ASSERT_TRUE(scene_->fk(qa, links, &a, &error));
    ASSERT_TRUE(scene_->fk(qb, links, &b, &error));
    for (std::size_t l = 0; l < links.size(); ++l) {
      EXPECT_LE((a[l].translation() - b[l].translation()).norm(), scene_->checker().options().path_resolution);
    }
  }
}

TEST_F(PandaScene, ValidateMotionOutcomes) {
  setWorld({table()});
  mps::MotionCheck mc;
  auto goal = kHome;
  goal[0] += 0.1;
  scene_->validateMotion(kHome, goal, true, &mc);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kValid) << mc.message;
  EXPECT_FALSE(mc.replanned);
  EXPECT_GT(mc.path_check_time, 0.0);

  scene_->validateMotion(kHome, kSelfCollision, true, &mc);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kSelfCollision) << mc.message;
  EXPECT_TRUE(hasPair(mc.pairs, "panda_link1", "panda_hand"));

  scene_->validateMotion(kHome, kIntoTable, true, &mc);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kPoseCollision) << mc.message;
  ASSERT_FALSE(mc.pairs.empty());
  EXPECT_EQ(mc.pairs.front().b, "table");

  scene_->validateMotion(kIntoTable, kHome, true, &mc);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kStartInCollision) << mc.message;

  setWorld({table(), wall()});
  scene_->validateMotion(withJoint1(-0.8), withJoint1(0.8), false, &mc);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kPathCollision) << mc.message;
  EXPECT_FALSE(mc.replanned);
  EXPECT_TRUE(mc.path.empty());
  scene_->validateMotion(withJoint1(-0.8), withJoint1(0.8), true, &mc);
  ASSERT_EQ(mc.outcome, mps::MotionOutcome::kPathCollision) << mc.message;
  ASSERT_TRUE(mc.replanned) << mc.message;
  EXPECT_GT(mc.planning_time, 0.0);
  expectPathValid(mc.path);
}

// find_last_free (the shield's last_safe strategy): the last free checked state before the first collision.
TEST_F(PandaScene, ValidateMotionLastFree) {
  setWorld({table(), wall()});
  mps::MotionCheck mc;
  auto expectLastFreeSound = [&](const std::vector<double>& start, const std::vector<double>& goal) {
    ASSERT_EQ(mc.last_free_state.size(), start.size());
    for (std::size_t i = 0; i < start.size(); ++i) {
      EXPECT_NEAR(mc.last_free_state[i], start[i] + mc.last_free_fraction * (goal[i] - start[i]), 1e-12);
    }
    mps::StateCheck sc;
    scene_->checkState(mc.last_free_state, &sc);
    EXPECT_EQ(sc.outcome, mps::CheckOutcome::kValid) << sc.message;
    mps::PathCheck pc;
    scene_->checkPath(start, mc.last_free_state, &pc);
    EXPECT_EQ(pc.outcome, mps::CheckOutcome::kValid) << pc.message;
  };
  // Not requested / valid motion: not computed.
  scene_->validateMotion(withJoint1(-0.8), withJoint1(0.8), false, &mc);
  EXPECT_EQ(mc.last_free_fraction, -1.0);
  EXPECT_TRUE(mc.last_free_state.empty());
  scene_->validateMotion(withJoint1(-0.8), withJoint1(-0.7), false, &mc, true);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kValid) << mc.message;
  EXPECT_EQ(mc.last_free_fraction, -1.0);

  // Path collision across the wall: stop before it (roughly half way, the wall is at joint1 = 0).
  scene_->validateMotion(withJoint1(-0.8), withJoint1(0.8), false, &mc, true);
  ASSERT_EQ(mc.outcome, mps::MotionOutcome::kPathCollision) << mc.message;
  EXPECT_FALSE(mc.replanned);
  EXPECT_GT(mc.last_free_fraction, 0.1);
  EXPECT_LT(mc.last_free_fraction, 0.5);
  expectLastFreeSound(withJoint1(-0.8), withJoint1(0.8));
  mps::PathCheck full;
  scene_->checkPath(withJoint1(-0.8), withJoint1(0.8), &full);
  EXPECT_LT(mc.last_free_fraction, full.collision_fraction);

  // Goal into the table (pose collision): walk from the start to the last free state above the table.
  setWorld({table()});
  scene_->validateMotion(kHome, kIntoTable, true, &mc, true);
  ASSERT_EQ(mc.outcome, mps::MotionOutcome::kPoseCollision) << mc.message;
  EXPECT_FALSE(mc.replanned);
  EXPECT_GT(mc.last_free_fraction, 0.0);
  EXPECT_LT(mc.last_free_fraction, 1.0);
  expectLastFreeSound(kHome, kIntoTable);

  // Goal in self collision: the same.
  scene_->validateMotion(kHome, kSelfCollision, false, &mc, true);
  ASSERT_EQ(mc.outcome, mps::MotionOutcome::kSelfCollision) << mc.message;
  EXPECT_GT(mc.last_free_fraction, 0.0);
  EXPECT_LT(mc.last_free_fraction, 1.0);
  expectLastFreeSound(kHome, kSelfCollision);

  // Start not free: nothing computed (the shield holds still).
  scene_->validateMotion(kIntoTable, kHome, false, &mc, true);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kStartInCollision);
  EXPECT_EQ(mc.last_free_fraction, -1.0);
}

// Issue 23 item 5: a driver clamps a state a little beyond a limit (0.02 rad of joint 1, about 1.5 cm at the
// outstretched hand) onto it; the robot stands at the measured state. An obstacle that the measured state touches and
// the clamped one does not: checked with measured_start, the start is not free.
TEST_F(PandaScene, TheMeasuredStateBeyondALimitIsChecked) {
  std::vector<double> clamped = {2.8973, 0.6, 0.0, -1.2, 0.0, 1.8, 0.785};  // joint 1 at its upper limit, reaching out
  std::vector<double> measured = clamped;
  measured[0] += 0.02;
  std::vector<Eigen::Isometry3d> poses;
  std::string error;
  ASSERT_TRUE(scene_->fk(clamped, {}, &poses, &error)) << error;
  const Eigen::Vector3d at_clamped = poses[0].translation();
  // The measured state is beyond the limit: fk refuses it, so rotate the clamped flange by the same 0.02 rad.
  const Eigen::Vector3d at_measured = Eigen::AngleAxisd(0.02, Eigen::Vector3d::UnitZ()) * at_clamped;
  const Eigen::Vector3d u = (at_measured - at_clamped).normalized();
  // A 10 cm cube in the way, moved away until the clamped state is free: then the measured state still collides.
  mps::MotionCheck mc;
  bool found = false;
  setWorld({});
  mps::StateCheck free_check;
  scene_->checkState(clamped, &free_check);
  ASSERT_EQ(free_check.outcome, mps::CheckOutcome::kValid) << free_check.message;
  for (double t = 0.0; t < 0.3 && !found; t += 0.001) {
    const Eigen::Vector3d c = at_clamped + u * (0.05 + t);
    setWorld({box("cube", 0.1, 0.1, 0.1, c.x(), c.y(), c.z())});
    mps::StateCheck sc;
    scene_->checkState(clamped, &sc);
    if (sc.outcome != mps::CheckOutcome::kValid) continue;
    mps::MotionRequest req;
    req.start = clamped;
    req.goal = clamped;
    scene_->validateMotion(req, &mc);
    ASSERT_EQ(mc.outcome, mps::MotionOutcome::kValid) << mc.message;  // the clamped state alone: free
    req.measured_start = measured;
    scene_->validateMotion(req, &mc);
    ASSERT_EQ(mc.outcome, mps::MotionOutcome::kStartInCollision) << "offset " << t << ": " << mc.message;
    EXPECT_NE(mc.message.find("measured"), std::string::npos) << mc.message;
    found = true;
  }
  EXPECT_TRUE(found) << "no cube position where the clamped state is free";
  // A measured state equal to the start changes nothing; a malformed one is an invalid request.
  mps::MotionRequest req;
  req.start = req.goal = req.measured_start = kHome;
  setWorld({});
  scene_->validateMotion(req, &mc);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kValid) << mc.message;
  req.measured_start = {0.0};
  scene_->validateMotion(req, &mc);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kInvalidRequest);
}

TEST_F(PandaScene, BadInputsAreInvalidRequests) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  auto with = [](std::size_t i, double v) {
    auto q = kHome;
    q[i] = v;
    return q;
  };
  const std::vector<std::vector<double>> bad = {
      {0.0, 0.0}, with(2, nan), with(3, 0.5), with(0, 3.5), with(1, std::numeric_limits<double>::infinity())};
  for (const auto& q : bad) {
    mps::StateCheck sc;
    scene_->checkState(q, &sc);
    EXPECT_EQ(sc.outcome, mps::CheckOutcome::kInvalidRequest);
    EXPECT_FALSE(sc.message.empty());
    mps::PathCheck pc;
    scene_->checkPath(kHome, q, &pc);
    EXPECT_EQ(pc.outcome, mps::CheckOutcome::kInvalidRequest);
    mps::MotionCheck mc;
    scene_->validateMotion(q, kHome, true, &mc);
    EXPECT_EQ(mc.outcome, mps::MotionOutcome::kInvalidRequest);
    EXPECT_FALSE(mc.message.empty());
    mps::PlanResult pr;
    scene_->plan(kHome, q, "", 0.0, &pr);
    EXPECT_EQ(pr.status, mps::PlanStatus::kInvalidRequest);
    std::vector<Eigen::Isometry3d> poses;
    std::string error;
    EXPECT_FALSE(scene_->fk(q, {}, &poses, &error));
    EXPECT_FALSE(error.empty());
  }
  // Within the 1e-6 tolerance of a limit: accepted.
  mps::StateCheck sc;
  scene_->checkState(with(3, scene_->model().upperLimits()[3] + 5e-7), &sc);
  EXPECT_NE(sc.outcome, mps::CheckOutcome::kInvalidRequest) << sc.message;
  mps::MotionCheck mc;
  scene_->validateMotion(kHome, with(3, -3.2), false, &mc);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kInvalidRequest);
  EXPECT_NE(mc.message.find("panda_joint4"), std::string::npos) << mc.message;

  mps::PlanResult pr;
  scene_->plan(kHome, withJoint1(0.3), "NoSuchPlanner", 0.0, &pr);
  EXPECT_EQ(pr.status, mps::PlanStatus::kInvalidRequest);
  EXPECT_NE(pr.message.find("NoSuchPlanner"), std::string::npos);
  scene_->plan(kHome, withJoint1(0.3), "", -1.0, &pr);
  EXPECT_EQ(pr.status, mps::PlanStatus::kInvalidRequest);
  scene_->plan(kHome, withJoint1(0.3), "", nan, &pr);
  EXPECT_EQ(pr.status, mps::PlanStatus::kInvalidRequest);
  std::vector<Eigen::Isometry3d> poses;
  std::string error;
  EXPECT_FALSE(scene_->fk(kHome, {"no_such_link"}, &poses, &error));
  // Invalid world objects are rejected and the previous world is kept.
  setWorld({table()});
  mps::WorldObject broken = box("broken", 0.1, -1.0, 0.1, 0, 0, 0);
  EXPECT_FALSE(scene_->setWorld({broken}, &error));
  EXPECT_NE(error.find("broken"), std::string::npos);
  EXPECT_EQ(scene_->checker().worldSize(), 1u);
}

TEST_F(PandaScene, PlanningIsBounded) {
  setWorld({table(), wall()});
  // Colliding goal: rejected at once.
  mps::PlanResult pr;
  scene_->plan(withJoint1(-0.8), kIntoTable, "RRT", 0.5, &pr);
  EXPECT_EQ(pr.status, mps::PlanStatus::kGoalInvalid) << pr.message;
  EXPECT_LT(pr.planning_time, 0.05);
  scene_->plan(kIntoTable, withJoint1(-0.8), "RRT", 0.5, &pr);
  EXPECT_EQ(pr.status, mps::PlanStatus::kStartInvalid) << pr.message;
  // Hard problems within a short limit, for several planners: return in time with NO_SOLUTION or a valid path.
  const double limit = 0.1;
  for (const std::string planner : {"RRT", "RRTConnect", "RRTstar", "BiTRRT", "PRM", "EST", "KPIECE1", "LBKPIECE1",
                                    "SBL", "FMT", "TRRT", "PDST", "STRIDE"}) {
    const auto t0 = Clock::now();
    scene_->plan(withJoint1(-0.8), withJoint1(0.8), planner, limit, &pr);
    const double elapsed = std::chrono::duration<double>(Clock::now() - t0).count();
    EXPECT_LE(elapsed, limit + kTimeSlack) << planner;
    EXPECT_TRUE(pr.status == mps::PlanStatus::kSuccess || pr.status == mps::PlanStatus::kNoSolution)
        << planner << ": " << pr.message;
    if (pr.status == mps::PlanStatus::kSuccess) expectPathValid(pr.waypoints);
  }
  // A free goal RRT cannot reach within a tiny limit: NO_SOLUTION, still within the bound.
  const auto t0 = Clock::now();
  scene_->plan(withJoint1(-0.8), withJoint1(0.8), "RRT", 0.01, &pr);
  const double elapsed = std::chrono::duration<double>(Clock::now() - t0).count();
  EXPECT_LE(elapsed, 0.01 + kTimeSlack);
  EXPECT_EQ(pr.status, mps::PlanStatus::kNoSolution) << pr.message;
}

TEST_F(PandaScene, FkAgreesWithKdlAndHandValue) {
  std::vector<Eigen::Isometry3d> poses;
  std::string error;
  // All joints at 0: flange at x = 0.0825 - 0.0825 + 0.088, z = 0.333 + 0.316 + 0.384 - 0.107 (pointing down).
  ASSERT_TRUE(scene_->fk(std::vector<double>(7, 0.0), {}, &poses, &error)) << error;
  EXPECT_NEAR(poses[0].translation().x(), 0.088, 1e-6);
  EXPECT_NEAR(poses[0].translation().y(), 0.0, 1e-6);
  EXPECT_NEAR(poses[0].translation().z(), 0.926, 1e-6);
  EXPECT_NEAR(poses[0].linear()(2, 2), -1.0, 1e-6);  // flange z axis points down
  std::mt19937 rng(42);
  const auto& lo = scene_->model().lowerLimits();
  const auto& hi = scene_->model().upperLimits();
  for (int k = 0; k < 50; ++k) {
    std::vector<double> q(7);
    for (std::size_t i = 0; i < 7; ++i) q[i] = std::uniform_real_distribution<double>(lo[i], hi[i])(rng);
    for (const std::string link : {"panda_link8", "panda_hand", "panda_leftfinger", "panda_link4"}) {
      ASSERT_TRUE(scene_->fk(q, {link}, &poses, &error)) << error;
      Eigen::Isometry3d kdl;
      ASSERT_TRUE(scene_->model().linkPoseKdl(q, link, &kdl));
      EXPECT_LT((poses[0].matrix() - kdl.matrix()).cwiseAbs().maxCoeff(), kFkTolerance) << link;
    }
  }
}

TEST_F(PandaScene, AcmDisablesAdjacentPairs) {
  const auto& c = scene_->checker();
  for (int i = 0; i < 7; ++i) {
    const std::string a = "panda_link" + std::to_string(i), b = "panda_link" + std::to_string(i + 1);
    EXPECT_EQ(c.acmReason(a, b), mps::AcmReason::kAdjacent) << a << " / " << b;
  }
  // Looking through panda_link8 (no geometry, fixed joint).
  EXPECT_EQ(c.acmReason("panda_link7", "panda_hand"), mps::AcmReason::kAdjacent);
  EXPECT_EQ(c.acmReason("panda_hand", "panda_leftfinger"), mps::AcmReason::kAdjacent);
  // Fingers are held fixed: rigidly attached to each other.
  EXPECT_EQ(c.acmReason("panda_leftfinger", "panda_rightfinger"), mps::AcmReason::kRigid);
  // The hand can hit the base: checked.
  EXPECT_EQ(c.acmReason("panda_link0", "panda_hand"), mps::AcmReason::kEnabled);
  EXPECT_EQ(c.acmReason("panda_link1", "panda_hand"), mps::AcmReason::kEnabled);
  EXPECT_EQ(c.acmReason("panda_link8", "panda_hand"), mps::AcmReason::kNoGeometry);
}

// Issue 23: a pair of links that touch only in a tiny part of the joint space. A 2 m arm (joints about z, then y) ends
// in a 2 mm ball that meets a 4 mm pin on the base only when both joints are within ~5 mrad of 0: about one in 300,000
// random configurations, so 20,000 samples call the pair "never" and the old ACM stopped checking it. The search from
// the samples where the pair came closest finds the touch, and the pair stays checked.
TEST(Acm, ANeverPairIsConfirmedBySearchNotSampling) {
  const std::string urdf = R"(<robot name="pin">
    <link name="base"><collision><origin xyz="2.0 0 0.3"/><geometry><box size="0.004 0.004 0.004"/></geometry>
      </collision></link>
    <link name="hub"><collision><geometry><box size="0.02 0.02 0.02"/></geometry></collision></link>
    <link name="arm"><collision><origin xyz="2.0 0 0"/><geometry><sphere radius="0.001"/></geometry></collision>
      </link>
    <joint name="j1" type="revolute"><parent link="base"/><child link="hub"/><axis xyz="0 0 1"/>
      <limit lower="-3" upper="3" velocity="1" effort="1"/></joint>
    <joint name="j2" type="revolute"><parent link="hub"/><child link="arm"/><origin xyz="0 0 0.3"/><axis xyz="0 1 0"/>
      <limit lower="-3" upper="3" velocity="1" effort="1"/></joint>
  </robot>)";
  mps::PlanningSceneOptions o = pandaOptions();  // the shipped tunables (self_padding, acm_samples, acm_seed)
  o.robot = mps::RobotModelOptions();
  o.robot.joint_names = {"j1", "j2"};
  std::string error;
  auto scene = mps::PlanningScene::create(urdf, o, &error);
  ASSERT_NE(scene, nullptr) << error;
  EXPECT_EQ(scene->checker().acmReason("base", "arm"), mps::AcmReason::kEnabled);
  EXPECT_EQ(scene->checker().acmStats().never_refuted, 1);
  // And the check flags the touch.
  mps::StateCheck sc;
  scene->checkState({0.0, 0.0}, &sc);
  EXPECT_EQ(sc.outcome, mps::CheckOutcome::kSelfCollision) << sc.message;
  scene->checkState({0.1, 0.0}, &sc);
  EXPECT_EQ(sc.outcome, mps::CheckOutcome::kValid) << sc.message;
}

TEST(PandaModel, ErrorsNameTheProblem) {
  ASSERT_FALSE(kPandaUrdf.empty()) << "pybullet_data not found at configure time";
  std::string error;
  auto o = pandaOptions();
  EXPECT_EQ(mps::PlanningScene::create("<robot name='x'><link", o, &error), nullptr);
  EXPECT_NE(error.find("URDF"), std::string::npos) << error;
  o.robot.joint_names.push_back("no_such_joint");
  EXPECT_EQ(mps::PlanningScene::create(readFile(kPandaUrdf), o, &error), nullptr);
  EXPECT_NE(error.find("no_such_joint"), std::string::npos) << error;
  o = pandaOptions();
  o.robot.mesh_base_dir = "/nonexistent";
  EXPECT_EQ(mps::PlanningScene::create(readFile(kPandaUrdf), o, &error), nullptr);
  EXPECT_NE(error.find("mesh"), std::string::npos) << error;
  o = pandaOptions();
  o.planner.planner = "Nope";
  EXPECT_EQ(mps::PlanningScene::create(readFile(kPandaUrdf), o, &error), nullptr);
  EXPECT_NE(error.find("Nope"), std::string::npos) << error;
}

TEST(PandaModel, TriangleMeshModeAndAcmCache) {
  ASSERT_FALSE(kPandaUrdf.empty()) << "pybullet_data not found at configure time";
  auto o = pandaOptions();
  o.checker.mesh_mode = mps::MeshMode::kTriangles;
  o.checker.acm_samples = 2000;
  char dir_template[] = "/tmp/moverl_acm_test_XXXXXX";
  ASSERT_NE(mkdtemp(dir_template), nullptr);
  o.checker.acm_cache_dir = dir_template;
  std::string error;
  auto s = mps::PlanningScene::create(readFile(kPandaUrdf), o, &error);
  ASSERT_NE(s, nullptr) << error;
  EXPECT_FALSE(s->checker().acmStats().from_cache);
  mps::StateCheck sc;
  s->checkState(kHome, &sc);
  EXPECT_EQ(sc.outcome, mps::CheckOutcome::kValid) << sc.message;
  s->checkState(kSelfCollision, &sc);
  EXPECT_EQ(sc.outcome, mps::CheckOutcome::kSelfCollision) << sc.message;
  // Second build: the ACM comes from the cache and is identical.
  auto s2 = mps::PlanningScene::create(readFile(kPandaUrdf), o, &error);
  ASSERT_NE(s2, nullptr) << error;
  EXPECT_TRUE(s2->checker().acmStats().from_cache);
  EXPECT_EQ(s2->checker().acmStats().cache_file, s->checker().acmStats().cache_file);
  EXPECT_EQ(s2->checker().acmStats().enabled, s->checker().acmStats().enabled);
  EXPECT_EQ(s2->checker().acmStats().never, s->checker().acmStats().never);
  std::remove(s->checker().acmStats().cache_file.c_str());
  rmdir(dir_template);
}

}  // namespace

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}

// Self padding inflates links for self checks: every configuration that self-collides unpadded still does, and
// near misses (links closer than the padding) are now flagged too.
TEST(SelfPadding, FlagsASupersetIncludingNearMisses) {
  ASSERT_FALSE(kPandaUrdf.empty()) << "pybullet_data not found at configure time";
  std::string error;
  mps::PlanningSceneOptions plain = pandaOptions();
  plain.checker.self_padding = 0.0;
  mps::PlanningSceneOptions padded = pandaOptions();
  padded.checker.self_padding = 0.008;
  auto a = mps::PlanningScene::create(readFile(kPandaUrdf), plain, &error);
  ASSERT_NE(a, nullptr) << error;
  auto b = mps::PlanningScene::create(readFile(kPandaUrdf), padded, &error);
  ASSERT_NE(b, nullptr) << error;
  std::mt19937 rng(7);
  int plain_hits = 0, padded_hits = 0;
  for (int k = 0; k < 2000; ++k) {
    std::vector<double> q(7);
    for (int i = 0; i < 7; ++i) {
      std::uniform_real_distribution<double> d(a->model().lowerLimits()[i], a->model().upperLimits()[i]);
      q[i] = d(rng);
    }
    mps::StateCheck sa, sb;
    a->checkState(q, &sa);
    b->checkState(q, &sb);
    const bool ha = sa.outcome == mps::CheckOutcome::kSelfCollision;
    const bool hb = sb.outcome == mps::CheckOutcome::kSelfCollision;
    plain_hits += ha;
    padded_hits += hb;
    EXPECT_TRUE(!ha || hb) << "padding lost a self collision at sample " << k;
  }
  EXPECT_GT(plain_hits, 0);
  EXPECT_GT(padded_hits, plain_hits) << "8 mm of padding should flag some near misses";
}

// ------------------------------------------------------------------------------------------ moving obstacles
namespace {

mps::ObstacleMotion oscillation(const Eigen::Vector3d& axis, double amplitude, double period, double phase) {
  mps::ObstacleMotion m;
  m.type = mps::ObstacleMotion::Type::kOscillate;
  m.axis = axis.normalized();
  m.amplitude = amplitude;
  m.period = period;
  m.phase = phase;
  return m;
}

// Vertical 5 mm wall in the plane y = 0 (x 0.25 .. 0.65), swinging along z: at t = 0 (phase pi/2) it is at its
// top (centre z = 1.95, far above the arm), half a period later at its bottom (centre z = 0.45, across the path
// of the arm's hand from joint1 = -0.8 to +0.8). Period 1 s.
mps::WorldObject fallingWall() {
  mps::WorldObject w = box("wall", 0.4, 0.005, 0.5, 0.45, 0.0, 1.95);
  w.motion = oscillation(Eigen::Vector3d::UnitZ(), 0.75, 1.0, M_PI / 2);
  return w;
}

}  // namespace

TEST(ObstacleMotion, RangeIsExact) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int trial = 0; trial < 2000; ++trial) {
    const auto m = oscillation(Eigen::Vector3d::UnitY(), 0.05 + u(rng), 0.2 + 3 * u(rng), -4 + 8 * u(rng));
    const double t0 = 10 * u(rng), t1 = t0 + (trial % 10 == 0 ? 2 * m.period : u(rng) * m.period);
    double lo, hi;
    m.range(t0, t1, &lo, &hi);
    double mn = 1e9, mx = -1e9;
    for (int k = 0; k <= 2000; ++k) {
      const double d = m.displacement(t0 + (t1 - t0) * k / 2000.0);
      mn = std::min(mn, d);
      mx = std::max(mx, d);
    }
    ASSERT_LE(lo, mn + 1e-12);
    ASSERT_GE(hi, mx - 1e-12);
    ASSERT_NEAR(lo, mn, 1e-5 * m.amplitude * 10);  // tight (sampling error only)
    ASSERT_NEAR(hi, mx, 1e-5 * m.amplitude * 10);
  }
  const auto m = oscillation(Eigen::Vector3d::UnitX(), 0.3, 2.0, 0.5);
  double lo, hi;
  m.range(1.0, std::numeric_limits<double>::infinity(), &lo, &hi);
  EXPECT_NEAR(lo, 0.3 * (-1 - std::sin(0.5)), 1e-12);
  EXPECT_NEAR(hi, 0.3 * (1 - std::sin(0.5)), 1e-12);
  EXPECT_DOUBLE_EQ(m.displacement(0.0), 0.0);
}

// Every point of every shape at its pose at any time of a window lies inside the checker's swept obstacle
// (padding included), and the aligned sweeps are tight.
TEST_F(PandaScene, SweptInflationContainsTheMotion) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double pad = scene_->checker().options().padding;
  for (int trial = 0; trial < 60; ++trial) {
    mps::WorldObject o;
    o.id = "o";
    const int shape = trial % 3;
    o.type = shape == 0 ? mps::ShapeType::kBox : shape == 1 ? mps::ShapeType::kSphere : mps::ShapeType::kCylinder;
    o.dimensions = shape == 0   ? std::vector<double>{0.1 + 0.05 * u(rng), 0.2, 0.05}
                   : shape == 1 ? std::vector<double>{0.07}
                                : std::vector<double>{0.3, 0.05};
    o.pose.linear() =
        Eigen::Quaterniond(Eigen::AngleAxisd(3 * u(rng), Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized()))
            .toRotationMatrix();
    if (trial % 4 == 0) o.pose.linear().setIdentity();  // axis-aligned motions too
    o.pose.translation() = Eigen::Vector3d(0.5 * u(rng), 0.5 * u(rng), 1.0 + 0.3 * u(rng));
    Eigen::Vector3d axis = trial % 4 == 0 ? Eigen::Vector3d::Unit(trial % 3) : Eigen::Vector3d(u(rng), u(rng), u(rng));
    o.motion = oscillation(axis, 0.2 + 0.1 * u(rng), 1.0 + 0.5 * u(rng), 3 * u(rng));
    setWorld({o});
    auto& checker = scene_->checker();
    const double t0 = 2 + u(rng),
                 t1 = trial % 5 == 0 ? std::numeric_limits<double>::infinity() : t0 + 0.2 + 0.2 * u(rng);
    if (trial % 5 != 0) checker.setMotionWindow(t0, t1);
    // Surface points of the padded shape in its own frame.
    std::vector<Eigen::Vector3d> pts;
    const auto& d = o.dimensions;
    if (shape == 0) {
      for (int c = 0; c < 8; ++c) {
        pts.emplace_back((c & 1 ? 1 : -1) * (d[0] / 2 + pad), (c & 2 ? 1 : -1) * (d[1] / 2 + pad),
                         (c & 4 ? 1 : -1) * (d[2] / 2 + pad));
      }
    } else if (shape == 1) {
      for (int k = 0; k < 3; ++k) {
        pts.push_back(Eigen::Vector3d::Unit(k) * (d[0] + pad));
        pts.push_back(-Eigen::Vector3d::Unit(k) * (d[0] + pad));
      }
    } else {
      for (int k = 0; k < 8; ++k) {
        const double a = k * M_PI / 4;
        for (double z : {-1.0, 1.0}) {
          pts.emplace_back((d[1] + pad) * std::cos(a), (d[1] + pad) * std::sin(a), z * (d[0] / 2 + pad));
        }
      }
    }
    const double tend = std::isfinite(t1) ? t1 : t0 + 2 * o.motion.period;
    for (int k = 0; k <= 40; ++k) {
      const double t = t0 + (tend - t0) * k / 40.0;
      Eigen::Isometry3d pose = o.pose;
      pose.translation() += o.motion.axis * o.motion.displacement(t);
      for (const auto& p : pts) {
        const Eigen::Vector3d q = pose * (0.999 * p);
        ASSERT_TRUE(checker.obstacleContains(0, q)) << "trial " << trial << " shape " << shape << " t " << t;
      }
    }
  }
  // Tight for a box moving along one of its axes: the swept box ends (padded) where the travel ends.
  mps::WorldObject b = box("b", 0.1, 0.1, 0.1, 0.0, 0.0, 1.0);
  b.motion = oscillation(Eigen::Vector3d::UnitX(), 0.2, 2.0, 0.0);
  setWorld({b});
  scene_->checker().setMotionWindow(0.0, 0.5);  // displacement 0 .. 0.2 along x
  const double edge = 0.05 + pad;
  EXPECT_TRUE(scene_->checker().obstacleContains(0, Eigen::Vector3d(0.2 + edge - 1e-4, 0, 1)));
  EXPECT_FALSE(scene_->checker().obstacleContains(0, Eigen::Vector3d(0.2 + edge + 1e-3, 0, 1)));
  EXPECT_FALSE(scene_->checker().obstacleContains(0, Eigen::Vector3d(-edge - 1e-3, 0, 1)));
  EXPECT_FALSE(scene_->checker().obstacleContains(0, Eigen::Vector3d(0.1, edge + 1e-3, 1)));
  scene_->checker().setMotionWindow(0.0, std::numeric_limits<double>::infinity());  // envelope: -0.2 .. 0.2
  EXPECT_TRUE(scene_->checker().obstacleContains(0, Eigen::Vector3d(-0.2 - edge + 1e-4, 0, 1)));
  EXPECT_FALSE(scene_->checker().obstacleContains(0, Eigen::Vector3d(-0.2 - edge - 1e-3, 0, 1)));
}

// The straight move is checked against where the obstacle will be DURING the move, not where it was when the move
// began; the goal against the obstacle's whole motion envelope.
TEST_F(PandaScene, ValidateMotionAgainstAMovingWall) {
  const auto left = withJoint1(-0.8), right = withJoint1(0.8);
  // Static wall at the bottom of the swing: the straight path collides (sanity check of the geometry).
  setWorld({table(), box("wall", 0.4, 0.005, 0.5, 0.45, 0.0, 0.45)});
  mps::MotionCheck mc;
  scene_->validateMotion(left, right, false, &mc);
  ASSERT_EQ(mc.outcome, mps::MotionOutcome::kPathCollision) << mc.message;
  EXPECT_FALSE(mc.moving_obstacles);
  // The same wall up at z = 1.95: free.
  setWorld({table(), box("wall", 0.4, 0.005, 0.5, 0.45, 0.0, 1.95)});
  scene_->validateMotion(left, right, false, &mc);
  ASSERT_EQ(mc.outcome, mps::MotionOutcome::kValid) << mc.message;

  setWorld({table(), fallingWall()});
  // A check against the wall's pose at the start of the move (an instant) passes ...
  scene_->validateMotion(left, right, false, &mc, false, 0.0, 0.0);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kValid) << mc.message;
  EXPECT_TRUE(mc.moving_obstacles);
  // ... a short move early in the swing too (wall still high: it falls 0.75 (1 - cos(2 pi 0.05)) = 3.6 cm) ...
  scene_->validateMotion(left, right, false, &mc, false, 0.0, 0.05);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kValid) << mc.message;
  // ... but a move lasting half a period meets the wall on its way down: caught.
  scene_->validateMotion(left, right, false, &mc, false, 0.0, 0.5);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kPathCollision) << mc.message;
  ASSERT_FALSE(mc.pairs.empty());
  EXPECT_EQ(mc.pairs.front().b, "wall") << mc.message;
  // The same short move starting when the wall is at the bottom (t = 0.5) collides; a bit later (back up) it does not.
  scene_->validateMotion(left, right, false, &mc, false, 0.5, 0.05);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kPathCollision) << mc.message;
  scene_->validateMotion(left, right, false, &mc, false, 0.95, 0.05);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kValid) << mc.message;
  // Default (no window): the whole envelope.
  scene_->validateMotion(left, right, false, &mc);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kPathCollision) << mc.message;
  // A goal inside the swing collides whatever the window (holding there would be hit later): home's hand (about
  // (0.31, 0, 0.59)) is in the plane y = 0 under the wall's swing, though the wall is far above it now.
  scene_->validateMotion(left, kHome, false, &mc, false, 0.0, 0.0);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kPoseCollision) << mc.message;
  // Replanning avoids the whole envelope: its segments pass the (envelope) path check.
  scene_->validateMotion(left, right, true, &mc, false, 0.0, 0.5);
  ASSERT_EQ(mc.outcome, mps::MotionOutcome::kPathCollision) << mc.message;
  if (mc.replanned) expectPathValid(mc.path);
  // Bad times.
  scene_->validateMotion(left, right, false, &mc, false, std::nan(""), 0.1);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kInvalidRequest);
  scene_->validateMotion(left, right, false, &mc, false, 0.0, -1.0);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kInvalidRequest);
}

// A goal in the swing of a moving obstacle is a pose collision even when the obstacle is far away right now.
TEST_F(PandaScene, GoalMustBeFreeOfTheWholeEnvelope) {
  // A ball swinging along y through the resting hand at home (about (0.307, 0, 0.59)), now far away (y = 0.5).
  mps::WorldObject ball;
  ball.id = "ball";
  ball.type = mps::ShapeType::kSphere;
  ball.dimensions = {0.05};
  ball.pose.translation() = Eigen::Vector3d(0.307, 0.5, 0.59);
  ball.motion = oscillation(Eigen::Vector3d::UnitY(), 0.25, 2.0, M_PI / 2);  // y in [0.0, 0.5]
  setWorld({table(), ball});
  mps::MotionCheck mc;
  scene_->validateMotion(withJoint1(-0.8), kHome, false, &mc, false, 0.0, 0.0);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kPoseCollision) << mc.message;
  mps::StateCheck sc;
  scene_->checkState(kHome, &sc);
  EXPECT_EQ(sc.outcome, mps::CheckOutcome::kWorldCollision) << sc.message;
  // A static ball at y = 0.5 leaves home free.
  ball.motion = mps::ObstacleMotion();
  setWorld({table(), ball});
  scene_->checkState(kHome, &sc);
  EXPECT_EQ(sc.outcome, mps::CheckOutcome::kValid) << sc.message;
}

// The C++ twin of the obstacle-motion formula gives the shared cases the Python one is checked on (one formula per
// language, moverl_sim/test/fixtures/obstacle_motion_cases.txt).
TEST(ObstacleMotion, DisplacementMatchesTheSharedCases) {
  std::ifstream in(MOVERL_MOTION_CASES);
  ASSERT_TRUE(in.good()) << "cannot read " << MOVERL_MOTION_CASES;
  std::string line;
  int cases = 0;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream row(line);
    double amplitude, period, phase, t, expected;
    ASSERT_TRUE(row >> amplitude >> period >> phase >> t >> expected) << line;
    mps::ObstacleMotion m;
    m.type = mps::ObstacleMotion::Type::kOscillate;
    m.amplitude = amplitude;
    m.period = period;
    m.phase = phase;
    EXPECT_NEAR(m.displacement(t), expected, 1e-12) << line;
    ++cases;
  }
  EXPECT_EQ(cases, 40);
}

namespace {

mps::ObstacleMotion reach(double amplitude, double period, double phase, double move, double hold, double chance,
                          std::uint32_t seed) {
  mps::ObstacleMotion m;
  m.type = mps::ObstacleMotion::Type::kReach;
  m.axis = Eigen::Vector3d::UnitZ();
  m.amplitude = amplitude;
  m.period = period;
  m.phase = phase;
  m.move = move;
  m.hold = hold;
  m.chance = chance;
  m.seed = seed;
  return m;
}

}  // namespace

// The reach motion's C++ twin gives the Python one's cases (moverl_sim/test/fixtures/reach_motion_cases.txt; the
// first ones follow by hand, the seeded ones test the cycles' draw as well).
TEST(ObstacleMotion, ReachMatchesTheSharedCases) {
  std::ifstream in(MOVERL_REACH_CASES);
  ASSERT_TRUE(in.good()) << "cannot read " << MOVERL_REACH_CASES;
  std::string line;
  int cases = 0, reached = 0;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream row(line);
    double amplitude, period, phase, move, hold, chance, t, expected;
    std::uint32_t seed;
    ASSERT_TRUE(row >> amplitude >> period >> phase >> move >> hold >> chance >> seed >> t >> expected) << line;
    EXPECT_NEAR(reach(amplitude, period, phase, move, hold, chance, seed).displacement(t), expected, 1e-12) << line;
    ++cases;
    reached += chance > 0.0 && chance < 1.0 && expected > 0.0;
  }
  EXPECT_EQ(cases, 33);
  EXPECT_GT(reached, 0);  // some seeded cycles reach, and (below 16) not all
  EXPECT_LT(reached, 16);
}

// The reach's range over a window is exact: it holds every sampled displacement, and is as tight as sampling shows;
// over an unbounded window it is the envelope [0, amplitude] (less the offset at t = 0).
TEST(ObstacleMotion, ReachRangeIsExact) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int trial = 0; trial < 2000; ++trial) {
    const double period = 1.0 + 3 * u(rng), move = 0.05 + 0.3 * u(rng), hold = (period - 2 * move) * u(rng);
    const auto m = reach(0.05 + u(rng), period, 6.28 * u(rng), move, hold, 0.6, trial);
    const double t0 = 20 * u(rng), t1 = t0 + (trial % 10 == 0 ? 5 * period : 1.5 * u(rng) * period);
    double lo, hi;
    m.range(t0, t1, &lo, &hi);
    double mn = 1e9, mx = -1e9;
    for (int k = 0; k <= 4000; ++k) {
      const double d = m.displacement(t0 + (t1 - t0) * k / 4000.0);
      mn = std::min(mn, d);
      mx = std::max(mx, d);
    }
    ASSERT_LE(lo, mn + 1e-12) << trial;
    ASSERT_GE(hi, mx - 1e-12) << trial;
    ASSERT_NEAR(lo, mn, 2e-3 * m.amplitude) << trial;  // tight (sampling error only)
    ASSERT_NEAR(hi, mx, 2e-3 * m.amplitude) << trial;
  }
  const auto m = reach(0.3, 4.0, M_PI, 0.25, 0.5, 1.0, 0);  // half a cycle gone at t = 0: resting, offset 0
  double lo, hi;
  m.range(1.0, std::numeric_limits<double>::infinity(), &lo, &hi);
  EXPECT_DOUBLE_EQ(lo, 0.0);
  EXPECT_DOUBLE_EQ(hi, 0.3);
  m.range(0.0, 0.9, &lo, &hi);  // still resting
  EXPECT_DOUBLE_EQ(lo, 0.0);
  EXPECT_DOUBLE_EQ(hi, 0.0);
  m.range(1.0, 1.125, &lo, &hi);  // the first half of the way out
  EXPECT_DOUBLE_EQ(lo, 0.0);
  EXPECT_NEAR(hi, 0.15, 1e-12);
}

TEST(WorldFile, ABoxIsReadAsTheWorldServerPlacesItAndAnythingElseIsRefusedNamingIt) {
  // The tools' table: worlds/table.yaml's (scene_benchmark places it so), and a rotated box of a file written here
  // (rpy fixed-axis roll, pitch, yaw, as the world files and URDF).
  mps::WorldObject table;
  std::string error;
  ASSERT_TRUE(mps::loadWorldBox(MOVERL_CONFIG_DIR "/../worlds/table.yaml", "table", &table, &error)) << error;
  EXPECT_EQ(table.id, "table");
  EXPECT_EQ(table.type, mps::ShapeType::kBox);
  EXPECT_EQ(table.dimensions.size(), 3u);
  // This process's own file (several test runs may share the machine), removed at the end.
  const std::string path = ::testing::TempDir() + "moverl_world_box_" + std::to_string(::getpid()) + ".yaml";
  {
    std::ofstream out(path);
    out << "objects:\n"
           "  - {id: ball, shape: sphere, size: [0.1], xyz: [0, 0, 0]}\n"
           "  - {id: tilted, shape: box, size: [0.2, 0.1, 0.05], xyz: [1, 2, 3], rpy: [0.3, -0.2, 1.1]}\n"
           "  - {id: flat, shape: box, size: [0.2, 0.1], xyz: [0, 0, 0]}\n";
  }
  mps::WorldObject tilted;
  ASSERT_TRUE(mps::loadWorldBox(path, "tilted", &tilted, &error)) << error;
  EXPECT_EQ(tilted.dimensions, (std::vector<double>{0.2, 0.1, 0.05}));
  const Eigen::Matrix3d r =
      (Eigen::AngleAxisd(1.1, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(-0.2, Eigen::Vector3d::UnitY()) *
       Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitX()))
          .toRotationMatrix();
  EXPECT_TRUE(tilted.pose.linear().isApprox(r));
  EXPECT_TRUE(tilted.pose.translation().isApprox(Eigen::Vector3d(1, 2, 3)));
  mps::WorldObject none;
  EXPECT_FALSE(mps::loadWorldBox(path, "table", &none, &error));
  EXPECT_NE(error.find("no object table (objects: ball, tilted, flat)"), std::string::npos) << error;
  EXPECT_FALSE(mps::loadWorldBox(path, "ball", &none, &error));
  EXPECT_NE(error.find("ball is not a box"), std::string::npos) << error;
  EXPECT_FALSE(mps::loadWorldBox(path, "flat", &none, &error));
  EXPECT_NE(error.find("3 numbers"), std::string::npos) << error;
  EXPECT_FALSE(mps::loadWorldBox(path + ".missing", "table", &none, &error));
  EXPECT_NE(error.find(".missing"), std::string::npos) << error;
  std::remove(path.c_str());
}
