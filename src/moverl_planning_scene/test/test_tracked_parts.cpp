/**
 * \file test_tracked_parts.cpp
 * \brief safety:=ssm with a tracker, without a roscore (tracked_parts.h): which parts a check may use and how far they
 *        reach, the map's traversal leaving a part's cells out, and the Panda's checks against a tracked hand.
 */
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <stdexcept>

#include "moverl_planning_scene/occupancy_map.h"
#include "moverl_planning_scene/planning_scene.h"
#include "moverl_planning_scene/tracked_parts.h"
#include "panda_support.h"

namespace mps = moverl_planning_scene;

namespace {

const std::string kPandaUrdf = MOVERL_PANDA_URDF;

mps::TrackingRule rule() {
  mps::TrackingRule r;
  r.motion.max_acceleration = 20.0;
  r.motion.max_speed = 2.0;
  r.position_error = 0.03;
  r.speed_error = 0.5;
  r.max_age = 0.2;
  return r;
}

mps::TrackedPart part(double stamp, double speed = 0.0, double radius = 0.05) {
  mps::TrackedPart p;
  p.id = "r_wrist_1";
  p.position = Eigen::Vector3d(0.6, 0.0, 0.3);
  p.speed = speed;
  p.stamp = stamp;
  p.radius = radius;
  return p;
}

}  // namespace

TEST(TrackedParts, APartReachesFromItsMeasurementAcceleratingUpToTheCap) {
  const mps::TrackingRule r = rule();
  // From 0.5 (+0.5 error) m/s at 20 m/s^2 the cap 2 m/s is reached after 0.05 s: 0.075 m, then 2 m/s.
  EXPECT_NEAR(r.motion.travel(1.0, 0.05), 0.05 + 10.0 * 0.0025, 1e-12);
  EXPECT_NEAR(r.motion.travel(1.0, 0.15), 0.075 + 0.2, 1e-12);
  EXPECT_NEAR(r.motion.travel(3.0, 0.1), 0.3, 1e-12) << "a part faster than the cap keeps its speed";
  // Measured at 1.00 s, the map's cells seen at 0.95 s, the check at 1.05 s of a move whose window ends at 1.15 s.
  const auto parts = mps::explainParts({part(1.0, 0.5)}, r, 1.05, 0.95, 1.15, 0.4, 0.01);
  ASSERT_EQ(parts.size(), 1u);
  EXPECT_EQ(parts[0].id, "r_wrist_1");
  EXPECT_NEAR(parts[0].explains, 0.05 + 0.03 + r.motion.travel(1.0, 0.05), 1e-12);
  EXPECT_NEAR(parts[0].keep_out, 0.05 + 0.03 + 0.01 + r.motion.travel(1.0, 0.15), 1e-12);
  // A map newer than the track: the part was there within the same bound.
  const auto later = mps::explainParts({part(1.0, 0.5)}, r, 1.05, 1.05, 1.15, 0.4, 0.01);
  ASSERT_EQ(later.size(), 1u);
  EXPECT_NEAR(later[0].explains, 0.05 + 0.03 + r.motion.travel(1.0, 0.05), 1e-12);
  // What a part explains always lies in its ball.
  const auto old_map = mps::explainParts({part(1.0)}, r, 1.0, 0.0, 1.0, 5.0, 0.0);
  ASSERT_EQ(old_map.size(), 1u);
  EXPECT_LE(old_map[0].explains, old_map[0].keep_out);
}

TEST(TrackedParts, ALostStaleFutureOrBrokenTrackExplainsNothing) {
  const mps::TrackingRule r = rule();
  EXPECT_EQ(mps::explainParts({part(1.0)}, r, 1.2, 1.0, 1.3, 1.0, 0.0).size(), 1u) << "at max_age";
  EXPECT_TRUE(mps::explainParts({part(1.0)}, r, 1.21, 1.0, 1.3, 1.0, 0.0).empty()) << "older than max_age";
  EXPECT_TRUE(mps::explainParts({part(1.1)}, r, 1.0, 1.0, 1.3, 1.0, 0.0).empty()) << "stamped after the check";
  mps::TrackedPart broken = part(1.0);
  broken.position.x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_TRUE(mps::explainParts({broken}, r, 1.0, 1.0, 1.1, 1.0, 0.0).empty());
  broken = part(1.0, -1.0);
  EXPECT_TRUE(mps::explainParts({broken}, r, 1.0, 1.0, 1.1, 1.0, 0.0).empty());
  broken = part(std::numeric_limits<double>::quiet_NaN());
  EXPECT_TRUE(mps::explainParts({broken}, r, 1.0, 1.0, 1.1, 1.0, 0.0).empty());
}

TEST(TrackedParts, APartWhoseBallHoldsIsosMarginIsNotUsed) {
  const mps::TrackingRule r = rule();
  // Fresh map, old track: the part's reach holds ISO's margin (0.05 m) of every cell it explains.
  EXPECT_TRUE(mps::explainParts({part(1.0)}, r, 1.15, 1.15, 1.2, 0.05, 0.0).empty());
  EXPECT_EQ(mps::explainParts({part(1.0)}, r, 1.15, 1.15, 1.2, 0.5, 0.0).size(), 1u);
}

TEST(TrackedParts, ABadRuleIsRefusedNamingTheValue) {
  mps::TrackingRule r = rule();
  r.motion.max_speed = 0.0;
  EXPECT_NE(r.problem().find("max_speed"), std::string::npos);
  EXPECT_THROW(mps::explainParts({}, r, 0.0, 0.0, 0.0, 0.1, 0.0), std::invalid_argument);
  r = rule();
  r.position_error = -0.01;
  EXPECT_NE(r.problem().find("position_error"), std::string::npos);
  r = rule();
  r.max_age = std::numeric_limits<double>::infinity();
  EXPECT_NE(r.problem().find("max_age"), std::string::npos);
  EXPECT_THROW(mps::explainParts({}, rule(), std::nan(""), 0.0, 0.0, 0.1, 0.0), std::invalid_argument);
}

namespace {

std::unique_ptr<mps::OccupancyMap> smallMap(bool unknown_occupied = false,
                                            const Eigen::AlignedBox3d& bounds = Eigen::AlignedBox3d(
                                                Eigen::Vector3d::Constant(-2.0), Eigen::Vector3d::Constant(2.0))) {
  mps::OccupancyMapOptions o = mps::panda::mapOptions();
  o.resolution = 0.02;
  o.max_range = 3.0;
  o.bounds = bounds;
  o.unknown_occupied = unknown_occupied;
  std::string error;
  auto m = mps::OccupancyMap::create(o, &error);
  EXPECT_TRUE(m) << error;
  return m;
}

/// A square patch of points (side `side`, spacing 5 mm) facing -x at `centre`, seen from `camera`.
void seePatch(mps::OccupancyMap* map, const Eigen::Vector3d& centre, double side, const Eigen::Vector3d& camera) {
  std::vector<Eigen::Vector3d> pts;
  for (double y = -side / 2; y <= side / 2 + 1e-9; y += 0.005) {
    for (double z = -side / 2; z <= side / 2 + 1e-9; z += 0.005) pts.push_back(centre + Eigen::Vector3d(0, y, z));
  }
  mps::MapUpdate u;
  map->computeUpdate(pts, {}, camera, &u);
  map->apply(u);
}

std::size_t visitedCells(const mps::OccupancyMap& map, const mps::OccupancyMap::ExcludeTest* exclude) {
  std::size_t cells = 0;
  const double r = map.options().resolution;
  map.visitOccupied(
      Eigen::AlignedBox3d(Eigen::Vector3d::Constant(-2.0), Eigen::Vector3d::Constant(2.0)),
      [](const Eigen::AlignedBox3d&) { return true; },
      [&](const Eigen::AlignedBox3d& box) {
        cells += static_cast<std::size_t>(std::lround(box.volume() / (r * r * r)));
        return false;
      },
      mps::CellClass::kAll, false, exclude);
  return cells;
}

}  // namespace

TEST(TrackedParts, TheMapsTraversalLeavesOutTheCellsWhollyExcluded) {
  auto map = smallMap();
  seePatch(map.get(), Eigen::Vector3d(0.61, 0.01, 0.31), 0.2, Eigen::Vector3d(-0.5, 0.0, 0.3));
  const std::size_t all = visitedCells(*map, nullptr);
  ASSERT_GT(all, 50u);
  // Everything out: nothing visited; half the patch (y > 0.01) out: the rest visited, cell by cell.
  const mps::OccupancyMap::ExcludeTest none = [](const Eigen::AlignedBox3d&) {
    return mps::OccupancyMap::Excluded::kWholly;
  };
  EXPECT_EQ(visitedCells(*map, &none), 0u);
  const mps::OccupancyMap::ExcludeTest upper = [](const Eigen::AlignedBox3d& box) {
    if (box.min().y() >= 0.01) return mps::OccupancyMap::Excluded::kWholly;
    if (box.max().y() > 0.01) return mps::OccupancyMap::Excluded::kPartly;
    return mps::OccupancyMap::Excluded::kNone;
  };
  std::size_t lower_cells = 0;
  std::vector<Eigen::Vector3d> centres;
  std::vector<std::uint64_t> keys;
  map->cellsIn(Eigen::AlignedBox3d(Eigen::Vector3d(-2, -2, -2), Eigen::Vector3d(2, 0.01, 2)), &centres, &keys);
  for (const auto& c : centres) lower_cells += map->occupied(c) ? 1 : 0;
  EXPECT_EQ(visitedCells(*map, &upper), lower_cells);
  EXPECT_GT(lower_cells, 0u);
  EXPECT_LT(lower_cells, all);
}

class PandaTracked : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_FALSE(kPandaUrdf.empty()) << "pybullet_data (franka_panda/panda.urdf) not found at configure time";
    std::string error;
    scene_ = mps::PlanningScene::create(mps::panda::readFile(kPandaUrdf), mps::panda::options(kPandaUrdf), &error);
    ASSERT_TRUE(scene_) << error;
    // The hand's box at home; the person's "hand" a 6 cm patch 12 cm in front of it (+x).
    std::vector<Eigen::AlignedBox3d> boxes;
    scene_->checker().robotBoundingBoxes(kHome.data(), 0.0, &boxes);
    ASSERT_FALSE(boxes.empty());
    Eigen::AlignedBox3d robot;
    for (const auto& b : boxes) robot.extend(b);
    hand_ = Eigen::Vector3d(robot.max().x() + 0.12, 0.0, 0.45);
  }
  void TearDown() override {
    if (scene_) {
      scene_->checker().setTrackedParts(nullptr);
      scene_->checker().setOccupancy(nullptr);
    }
  }
  mps::CheckOutcome check(double margin) {
    EXPECT_TRUE(scene_->checker().setOctreeMargin(margin));
    mps::StateCheck sc;
    scene_->checkState(kHome, &sc);
    scene_->checker().setOctreeMargin(0.0);
    return sc.outcome;
  }
  const std::vector<double> kHome = {0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785};
  std::unique_ptr<mps::PlanningScene> scene_;
  Eigen::Vector3d hand_;
};

TEST_F(PandaTracked, ATrackedPartReplacesTheSeenCellsItExplains) {
  auto map = smallMap();
  seePatch(map.get(), hand_, 0.06, hand_ + Eigen::Vector3d(1.0, 0.0, 0.3));
  scene_->checker().setOccupancy(map.get());
  ASSERT_EQ(check(0.0), mps::CheckOutcome::kValid);
  const double iso = 0.3;  // the margin an unmonitored hand gets
  ASSERT_EQ(check(iso), mps::CheckOutcome::kWorldCollision);
  // A track where the hand is: its seen cells (2 cm cells around a 6 cm patch) lie within 0.08 m, its ball (0.09 m)
  // does not reach the robot: the hand is in neither's intersection with the robot, which may stay.
  std::vector<mps::ExplainedPart> parts = {{"r_wrist_1", hand_, 0.08, 0.09}};
  scene_->checker().setTrackedParts(&parts);
  EXPECT_EQ(check(iso), mps::CheckOutcome::kValid);
  // A ball as large as ISO's margin around its cells: the intersection is ISO's margin, which collides.
  parts[0].keep_out = iso + parts[0].explains;
  EXPECT_EQ(check(iso), mps::CheckOutcome::kWorldCollision);
  parts[0].keep_out = 0.09;
  // A track offset from the hand explains none of its cells; one too small explains some only.
  parts[0].centre = hand_ + Eigen::Vector3d(0.0, 0.5, 0.0);
  EXPECT_EQ(check(iso), mps::CheckOutcome::kWorldCollision);
  parts[0].centre = hand_;
  parts[0].explains = 0.02;
  EXPECT_EQ(check(iso), mps::CheckOutcome::kWorldCollision);
  // A move's checks take the parts from its margins, and leave none behind.
  scene_->checker().setTrackedParts(nullptr);
  std::vector<double> goal = kHome;
  goal[0] = 0.1;
  mps::MotionCheck mc;
  mps::SensedMargins sm;
  sm.start = sm.end = sm.plan = iso;
  scene_->validateMotion(kHome, goal, false, &mc, false, 0.0, 0.05, &sm);
  EXPECT_NE(mc.outcome, mps::MotionOutcome::kValid) << "no part: ISO's margin";
  sm.parts = {{"r_wrist_1", hand_, 0.08, 0.09}};
  scene_->validateMotion(kHome, goal, false, &mc, false, 0.0, 0.05, &sm);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kValid) << mc.message;
  EXPECT_EQ(check(iso), mps::CheckOutcome::kWorldCollision) << "validateMotion leaves no parts behind";
  sm.parts[0].keep_out = iso + sm.parts[0].explains;
  scene_->validateMotion(kHome, goal, false, &mc, false, 0.0, 0.05, &sm);
  EXPECT_NE(mc.outcome, mps::MotionOutcome::kValid) << mc.message;
}

TEST_F(PandaTracked, SpaceNoCameraSawIsNeverExplained) {
  // Only the space around the hand is mapped, and no camera has seen it (unknown_occupied).
  auto map = smallMap(true, Eigen::AlignedBox3d(hand_.array() - 0.04, hand_.array() + 0.04));
  scene_->checker().setOccupancy(map.get());
  ASSERT_EQ(check(0.0), mps::CheckOutcome::kValid);
  ASSERT_EQ(check(0.3), mps::CheckOutcome::kWorldCollision);
  std::vector<mps::ExplainedPart> parts = {{"r_wrist_1", hand_, 0.1, 0.1}};
  scene_->checker().setTrackedParts(&parts);
  EXPECT_EQ(check(0.3), mps::CheckOutcome::kWorldCollision);
}
