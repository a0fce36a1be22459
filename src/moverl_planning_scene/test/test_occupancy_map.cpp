/**
 * \file test_occupancy_map.cpp
 * \brief Sensed obstacles without a roscore: the occupancy map's update rule, clearing, robot self-filtering and
 *        FCL checks of the Panda against the octree.
 */
#include <gtest/gtest.h>
#include <array>

#include <octomap/OcTree.h>

#include <chrono>
#include <cmath>
#include <limits>
#include <random>
#include <unordered_map>

#include "moverl_planning_scene/held_updates.h"
#include "moverl_planning_scene/occupancy_map.h"
#include "moverl_planning_scene/planning_scene.h"
#include "moverl_planning_scene/sensed_margin.h"
#include "panda_support.h"

namespace mps = moverl_planning_scene;

namespace {

using Clock = std::chrono::steady_clock;
const std::string kPandaUrdf = MOVERL_PANDA_URDF;
const std::vector<double> kHome = {0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785};
const std::vector<double> kIntoTable = {0.0, 1.0, 0.0, -1.5, 0.0, 1.571, 0.785};  // the hand below z = 0
const Eigen::Vector3d kCamera(0.35, 0.0, 1.5);

std::unique_ptr<mps::OccupancyMap> makeMap(double resolution = 0.02, double max_range = 3.0) {
  mps::OccupancyMapOptions o = mps::panda::mapOptions();
  o.resolution = resolution;
  o.max_range = max_range;
  o.bounds = Eigen::AlignedBox3d(Eigen::Vector3d::Constant(-2.0), Eigen::Vector3d::Constant(2.0));
  std::string error;
  auto m = mps::OccupancyMap::create(o, &error);
  EXPECT_TRUE(m) << error;
  return m;
}

/// Points on the rectangle [x0, x1] x [y0, y1] at height z, spacing h.
std::vector<Eigen::Vector3d> plane(double x0, double x1, double y0, double y1, double z, double h) {
  std::vector<Eigen::Vector3d> pts;
  for (double x = x0; x <= x1 + 1e-9; x += h) {
    for (double y = y0; y <= y1 + 1e-9; y += h) pts.emplace_back(x, y, z);
  }
  return pts;
}

void integrate(mps::OccupancyMap* map, const std::vector<Eigen::Vector3d>& pts, const Eigen::Vector3d& origin,
               const std::vector<std::uint8_t>& mask = {}) {
  mps::MapUpdate u;
  map->computeUpdate(pts, mask, origin, &u);
  map->apply(u);
}

}  // namespace

TEST(OccupancyMap, RejectsBadOptions) {
  std::string error;
  mps::OccupancyMapOptions o = mps::panda::mapOptions();
  o.resolution = 0.0;
  EXPECT_FALSE(mps::OccupancyMap::create(o, &error));
  EXPECT_NE(error.find("resolution"), std::string::npos) << error;
  o = mps::panda::mapOptions();
  o.prob_hit = 0.4;
  EXPECT_FALSE(mps::OccupancyMap::create(o, &error));
  EXPECT_NE(error.find("prob_hit"), std::string::npos) << error;
  o = mps::panda::mapOptions();
  o.max_range = -1.0;
  EXPECT_FALSE(mps::OccupancyMap::create(o, &error));
  EXPECT_NE(error.find("max_range"), std::string::npos) << error;
  o = mps::panda::mapOptions();
  o.prob_hit = 0.7;  // octomap_server's: 3 hits to turn a cell clamped free occupied
  EXPECT_FALSE(mps::OccupancyMap::create(o, &error));
  EXPECT_NE(error.find("one hit"), std::string::npos) << error;
  o = mps::panda::mapOptions();  // no bounds: the dense grid needs them
  EXPECT_FALSE(mps::OccupancyMap::create(o, &error));
  EXPECT_NE(error.find("bounds"), std::string::npos) << error;
  o.bounds = Eigen::AlignedBox3d(Eigen::Vector3d::Constant(-100.0), Eigen::Vector3d::Constant(100.0));
  EXPECT_FALSE(mps::OccupancyMap::create(o, &error));  // 10^12 cells
  EXPECT_NE(error.find("cells"), std::string::npos) << error;
}

TEST(OccupancyMap, HitsFreeSpaceRangeAndRobotPoints) {
  auto map = makeMap();
  const Eigen::Vector3d origin(0.0, 0.0, 1.0);
  const std::vector<Eigen::Vector3d> pts = {{0.5, 0.0, 0.0},            // obstacle
                                            {-0.5, 0.0, 0.0},           // on the robot (masked)
                                            {0.0, 5.0, 1.0},            // beyond max_range
                                            {std::nan(""), 0.0, 0.0}};  // invalid
  mps::MapUpdate u;
  map->computeUpdate(pts, {0, 1, 0, 0}, origin, &u);
  EXPECT_EQ(u.stats.points, 4u);
  EXPECT_EQ(u.stats.robot, 1u);
  EXPECT_EQ(u.stats.beyond_range, 1u);
  EXPECT_EQ(u.stats.invalid, 1u);
  EXPECT_EQ(u.stats.hit_cells, 1u);
  map->apply(u);
  EXPECT_TRUE(map->occupied({0.5, 0.0, 0.0}));
  EXPECT_FALSE(map->occupied({-0.5, 0.0, 0.0}));  // robot point: nothing marked
  EXPECT_FALSE(map->occupied({0.0, 2.9, 1.0}));   // cleared up to max_range, no end point
  EXPECT_FALSE(map->occupied({0.25, 0.0, 0.5}));  // half way along the beam: free
  EXPECT_EQ(map->occupiedLeafCount(), 1u);
  // The half-way cell is known free, a cell off every beam is unknown.
  EXPECT_TRUE(map->observed({0.25, 0.0, 0.5}));
  EXPECT_FALSE(map->observed({0.0, -1.0, 0.0}));
}

/// Issue 23, no blind layer: a point of something else that ends in a cell where robot points end too marks the cell
/// (a hand held next to a link); the old rule let any robot point silence its cell.
TEST(OccupancyMap, ACellWithAnObstaclePointIsHitWhateverElseEndsThere) {
  auto map = makeMap();
  const Eigen::Vector3d origin(0.0, 0.0, 1.0);
  // Two points in the cell [0.50, 0.52) x [0, 0.02) x [0, 0.02): one on the robot, one not.
  integrate(map.get(), {{0.505, 0.005, 0.005}, {0.515, 0.015, 0.015}}, origin,
            {mps::kPointOnRobot, mps::kPointObstacle});
  EXPECT_TRUE(map->occupied({0.51, 0.01, 0.01}));
  // Robot points alone mark nothing, and leave the end cell as it was seen (occupied here: the hand that came close).
  integrate(map.get(), {{0.505, 0.005, 0.005}}, origin, {mps::kPointOnRobot});
  EXPECT_TRUE(map->occupied({0.51, 0.01, 0.01}));
}

/// Issue 23, no blind layer: points on a static object the scene knows (obstacles: sensed) clear the space down to it,
/// their end cell included: the table's surface cells are seen free, so that only the filter's few millimetres above a
/// fixture are blind, and a hand lying on the table (its top, centimetres above) marks its cells.
TEST(OccupancyMap, FixturePointsClearTheirEndCell) {
  mps::OccupancyMapOptions o = mps::panda::mapOptions();
  o.bounds = Eigen::AlignedBox3d(Eigen::Vector3d::Constant(-2.0), Eigen::Vector3d::Constant(2.0));
  o.unknown_occupied = true;
  std::string error;
  auto map = mps::OccupancyMap::create(o, &error);
  ASSERT_TRUE(map) << error;
  const Eigen::Vector3d origin(0.0, 0.0, 1.0);
  const auto table = plane(0.3, 0.7, -0.2, 0.2, 0.0005, 0.01);  // the table top (z 0.5 mm: cells [0, 0.02))
  std::vector<std::uint8_t> mask(table.size(), mps::kPointOnFixture);
  mps::MapUpdate u;
  map->computeUpdate(table, mask, origin, &u);
  EXPECT_EQ(u.stats.fixture, table.size());
  EXPECT_EQ(u.stats.hit_cells, 0u);
  map->apply(u);
  EXPECT_FALSE(map->occupied({0.5, 0.0, 0.01}));  // the cell the table's surface points end in: seen free
  // A hand lying on it, 2.5 cm thick: its top points are obstacles, the table's around it fixture points.
  auto points = table;
  for (const auto& p : plane(0.45, 0.55, -0.05, 0.05, 0.025, 0.01)) {
    points.push_back(p);
    mask.push_back(mps::kPointObstacle);
  }
  integrate(map.get(), points, origin, mask);
  EXPECT_TRUE(map->occupied({0.5, 0.0, 0.03}));    // the hand's top
  EXPECT_FALSE(map->occupied({0.35, 0.0, 0.01}));  // the table beside it
}

/// Something that steps into space seen free many times is occupied in the very next view.
TEST(OccupancyMap, OneViewMarksAnObstacleInSpaceSeenFree) {
  auto map = makeMap();
  const Eigen::Vector3d origin(0.4, 0.0, 1.0);
  const auto floor = plane(0.0, 0.8, -0.4, 0.4, 0.0, 0.01);
  for (int k = 0; k < 10; ++k) integrate(map.get(), floor, origin);  // the space above the floor: clamped free
  EXPECT_FALSE(map->occupied({0.4, 0.0, 0.4}));
  auto with_box = floor;
  const auto top = plane(0.3, 0.5, -0.1, 0.1, 0.4, 0.01);
  with_box.insert(with_box.end(), top.begin(), top.end());
  integrate(map.get(), with_box, origin);
  EXPECT_TRUE(map->occupied({0.4, 0.0, 0.4}));
}

TEST(OccupancyMap, ForgetsAnObstacleThatMovedAway) {
  auto map = makeMap();
  const Eigen::Vector3d origin(0.4, 0.0, 1.0);
  // A box face at z = 0.4 above a floor at z = 0: the camera right above sees the box top.
  const auto box_top = plane(0.3, 0.5, -0.1, 0.1, 0.4, 0.01);
  for (int k = 0; k < 3; ++k) integrate(map.get(), box_top, origin);
  ASSERT_TRUE(map->occupied({0.4, 0.0, 0.4}));
  // The box leaves: the same pixels now see the floor through the box's old cells.
  int scans = 0;
  const auto floor_below = plane(0.3, 0.5, -0.1, 0.1, 0.0, 0.01);
  while (map->occupied({0.4, 0.0, 0.4}) && scans < 20) {
    integrate(map.get(), floor_below, origin);
    ++scans;
  }
  EXPECT_FALSE(map->occupied({0.4, 0.0, 0.4}));
  EXPECT_LE(scans, 10) << "clamping should let a cell flip within a few scans";
  EXPECT_TRUE(map->occupied({0.4, 0.0, 0.0}));
  map->clear();
  EXPECT_EQ(map->occupiedLeafCount(), 0u);
}

/// octomap/lockstep_lag: the checks' map gets each update later, in the same order, and is then the integrated map as
/// it was after that update (an update applied to the same state gives the same map), though the integrated map has
/// moved on meanwhile.
TEST(OccupancyMap, UpdatesAppliedLaterToASecondMapGiveTheSameMap) {
  auto integrated = makeMap(), checked = makeMap();
  const Eigen::Vector3d origin(0.4, 0.0, 1.0);
  auto leaves = [](const mps::OccupancyMap& m) {
    std::vector<Eigen::Vector3d> centers;
    std::vector<double> sizes;
    m.occupiedLeaves(&centers, &sizes);
    std::vector<std::array<double, 3>> out;
    for (const auto& c : centers) out.push_back({c.x(), c.y(), c.z()});
    std::sort(out.begin(), out.end());
    return out;
  };
  // A box top that moves along x over a floor, then leaves: cells turn occupied, free and occupied again.
  std::vector<std::vector<Eigen::Vector3d>> clouds;
  for (int k = 0; k < 8; ++k) {
    auto pts = plane(0.2 + 0.03 * k, 0.4 + 0.03 * k, -0.1, 0.1, 0.4, 0.01);
    const auto floor = plane(-0.2, 1.0, -0.3, 0.3, 0.0, 0.02);
    pts.insert(pts.end(), floor.begin(), floor.end());
    clouds.push_back(pts);
  }
  for (int k = 0; k < 6; ++k) clouds.push_back(plane(-0.2, 1.0, -0.3, 0.3, 0.0, 0.02));
  mps::HeldUpdates held;
  std::vector<std::vector<std::array<double, 3>>> after;  // the integrated map after each update
  std::vector<std::size_t> unobserved;
  for (std::size_t k = 0; k < clouds.size(); ++k) {
    mps::MapUpdate u;
    integrated->computeUpdate(clouds[k], {}, origin, &u);
    integrated->apply(u);
    after.push_back(leaves(*integrated));
    unobserved.push_back(integrated->unobservedCount());
    const auto stamp = static_cast<std::int64_t>(k) * 50'000'000;  // a cloud every 0.05 s
    held.push(stamp, "camera", u);
    if (k == 0) continue;  // one step behind: the updates up to the previous cloud's go in now
    for (const auto& h : held.takeUpTo(stamp - 50'000'000)) checked->apply(h.update);
    EXPECT_EQ(held.size(), 1u);
    EXPECT_EQ(leaves(*checked), after[k - 1]) << "after update " << k - 1;
    EXPECT_EQ(checked->unobservedCount(), unobserved[k - 1]);
  }
  // The maps did change from update to update (the comparison above is not between empty maps).
  EXPECT_GT(after[3].size(), 0u);
  EXPECT_NE(after[3], after[7]);
  EXPECT_NE(after[7], after.back());
}

/// The held updates go out as a prefix, in their order: one stamped earlier behind a later one waits for it (it was
/// computed on a map that held the later one), and beyond HeldUpdates::kMax the holder says it is full.
TEST(HeldUpdates, APrefixInOrderUpToTheCutoff) {
  mps::HeldUpdates held;
  mps::MapUpdate u;
  for (std::int64_t stamp : {10, 20, 40, 30, 50}) {
    u.hits = {static_cast<std::uint64_t>(stamp)};
    held.push(stamp, "camera", u);
  }
  auto stamps = [](const std::vector<mps::HeldUpdates::Held>& v) {
    std::vector<std::int64_t> out;
    for (const auto& h : v) {
      EXPECT_EQ(h.update.hits, std::vector<std::uint64_t>{static_cast<std::uint64_t>(h.stamp_ns)});
      out.push_back(h.stamp_ns);
    }
    return out;
  };
  EXPECT_EQ(stamps(held.takeUpTo(5)), std::vector<std::int64_t>{});
  EXPECT_EQ(stamps(held.takeUpTo(20)), (std::vector<std::int64_t>{10, 20}));
  EXPECT_EQ(stamps(held.takeUpTo(30)), std::vector<std::int64_t>{});  // 30 waits behind 40
  EXPECT_EQ(stamps(held.takeUpTo(40)), (std::vector<std::int64_t>{40, 30}));
  EXPECT_EQ(stamps(held.takeAll()), std::vector<std::int64_t>{50});
  EXPECT_EQ(held.size(), 0u);
  for (std::size_t k = 0; k <= mps::HeldUpdates::kMax; ++k) {
    EXPECT_FALSE(held.full());
    held.push(static_cast<std::int64_t>(k), "camera", u);
  }
  EXPECT_TRUE(held.full());
  held.clear();
  EXPECT_EQ(held.size(), 0u);
}

TEST(OccupancyMap, ACellOnAPointsLineOfSightIsSeenFree) {
  // A camera of the repo's worlds (worlds/human.yaml's `left`) that sees one table point whose line of sight crosses
  // the cell at (0.49, 0.01, 0.05), where a person's foot stood; the line to the centre of the point's cell passes
  // beside it. Cast to the centre (octomap's discretized insertion), a static scene crosses the same cells every view
  // and this one would stay occupied for ever; the point's own beam sees it free within clamp_max's views.
  auto map = makeMap();
  const Eigen::Vector3d origin(-0.05, 0.95, 1.15);
  const Eigen::Vector3d foot(0.49, 0.01, 0.05), table_point(0.527, -0.046, 0.0005);
  for (int k = 0; k < 3; ++k) integrate(map.get(), {foot}, origin);
  ASSERT_TRUE(map->occupied(foot));
  int views = 0;
  while (map->occupied(foot) && views < 20) {
    integrate(map.get(), {table_point}, origin);
    ++views;
  }
  EXPECT_FALSE(map->occupied(foot)) << "never seen free in " << views << " views";
  EXPECT_LE(views, 6);
}

class PandaOctomap : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    if (kPandaUrdf.empty()) return;
    mps::PlanningSceneOptions o = mps::panda::options(kPandaUrdf);
    std::string error;
    scene_ = mps::PlanningScene::create(mps::panda::readFile(kPandaUrdf), o, &error).release();
    ASSERT_NE(scene_, nullptr) << error;
  }
  static void TearDownTestSuite() {
    delete scene_;
    scene_ = nullptr;
  }
  void SetUp() override {
    ASSERT_FALSE(kPandaUrdf.empty()) << "pybullet_data (franka_panda/panda.urdf) not found at configure time";
    std::string error;
    ASSERT_TRUE(scene_->setWorld({}, &error)) << error;
    scene_->checker().setOccupancy(nullptr);
  }
  static mps::PlanningScene* scene_;
};
mps::PlanningScene* PandaOctomap::scene_ = nullptr;

TEST_F(PandaOctomap, RobotPointMask) {
  // Link origins are inside (or on) the robot; points far away are not.
  std::vector<Eigen::Isometry3d> poses;
  std::string error;
  const auto& links = scene_->model().linkNames();
  ASSERT_TRUE(scene_->fk(kHome, {"panda_link3", "panda_link5", "panda_hand"}, &poses, &error)) << error;
  std::vector<Eigen::Vector3d> pts;
  for (const auto& p : poses) pts.push_back(p.translation());
  pts.emplace_back(0.8, 0.5, 0.1);
  pts.emplace_back(0.35, 0.0, 0.0);  // table top in front of the base, ~25 cm from the link0 centre
  std::vector<std::uint8_t> mask;
  scene_->checker().robotPointMask(kHome.data(), pts, 0.03, &mask);
  ASSERT_EQ(mask.size(), pts.size());
  EXPECT_EQ(mask[0], 1);
  EXPECT_EQ(mask[1], 1);
  EXPECT_EQ(mask[2], 1);
  EXPECT_EQ(mask[3], 0);
  EXPECT_EQ(mask[4], 0);
  EXPECT_GT(links.size(), 0u);
  // The reach bound holds for every configuration (Panda: ~1.2 m from link0's origin incl. the hand).
  const double reach = scene_->checker().reachRadius();
  EXPECT_GT(reach, 0.9);
  EXPECT_LT(reach, 2.0);
}

TEST(OccupancyMap, BeamsAreClippedToTheBounds) {
  mps::OccupancyMapOptions o = mps::panda::mapOptions();
  o.bounds = Eigen::AlignedBox3d(Eigen::Vector3d(-1, -1, -1), Eigen::Vector3d(1, 1, 1));
  std::string error;
  auto map = mps::OccupancyMap::create(o, &error);
  ASSERT_TRUE(map) << error;
  // From outside the box: free cells only inside it, the hit inside it, a hit outside ignored.
  const Eigen::Vector3d origin(2.0, 0.0, 0.0);
  mps::MapUpdate u;
  map->computeUpdate({{0.0, 0.0, 0.0}, {1.5, 0.5, 0.0}}, {}, origin, &u);
  map->apply(u);
  EXPECT_TRUE(map->occupied({0.0, 0.0, 0.0}));
  EXPECT_FALSE(map->occupied({1.5, 0.5, 0.0}));
  EXPECT_TRUE(map->observed({0.5, 0.0, 0.0}));   // seen free inside
  EXPECT_FALSE(map->observed({1.5, 0.0, 0.0}));  // outside: never touched
  EXPECT_EQ(u.stats.hit_cells, 1u);
}

/// The update rule written out plainly with octomap's own calls (every crossed cell updated, as octomap_server does):
/// the map must hold the same value in every cell, cloud after cloud, although it skips unchanged cells.
TEST(OccupancyMap, SkippingUnchangedCellsKeepsOctomapsValues) {
  auto map = makeMap();
  octomap::OcTree ref(0.02);
  const mps::OccupancyMapOptions& o = map->options();
  ref.setProbHit(o.prob_hit);
  ref.setProbMiss(o.prob_miss);
  ref.setClampingThresMin(o.clamp_min);
  ref.setClampingThresMax(o.clamp_max);
  ref.setOccupancyThres(o.occupancy_threshold);
  // Not on a cell boundary: there octomap's float keys and the map's double ones may name neighbouring cells.
  const Eigen::Vector3d origin(-0.309, 0.213, 1.187);
  octomap::KeySet touched;
  for (int cloud = 0; cloud < 12; ++cloud) {
    // A floor and a box that slides along x by 4 cm per cloud (its old cells are seen free again).
    auto pts = plane(-1.0, 1.0, -1.0, 1.0, -0.5, 0.03);
    const double x = -0.4 + 0.04 * cloud;
    const auto top = plane(x, x + 0.3, -0.2, 0.2, 0.1, 0.01);
    pts.insert(pts.end(), top.begin(), top.end());
    integrate(map.get(), pts, origin);
    // Reference: one beam per end cell, to the centroid of the points that end there; misses minus hits; every cell
    // updated with updateNode.
    octomap::KeySet hits, misses;
    struct Sum {
      Eigen::Vector3d points = Eigen::Vector3d::Zero();
      int count = 0;
    };
    std::unordered_map<octomap::OcTreeKey, Sum, octomap::OcTreeKey::KeyHash> ends;  // a cell's points
    for (const auto& p : pts) {
      Sum& e = ends[ref.coordToKey(octomap::point3d(p.x(), p.y(), p.z()))];  // float points
      e.points += p;
      ++e.count;
    }
    octomap::KeyRay ray;
    for (const auto& [key, e] : ends) {
      hits.insert(key);
      const Eigen::Vector3d c = e.points / e.count;
      ASSERT_TRUE(ref.computeRayKeys(octomap::point3d(origin.x(), origin.y(), origin.z()),
                                     octomap::point3d(c.x(), c.y(), c.z()), ray));
      misses.insert(ray.begin(), ray.end());
    }
    for (const auto& k : hits) ref.updateNode(k, true);
    for (const auto& k : misses) {
      if (hits.count(k) == 0) ref.updateNode(k, false);
    }
    touched.insert(hits.begin(), hits.end());
    touched.insert(misses.begin(), misses.end());
    // The map casts beams in double arithmetic, octomap in float: a beam that grazes a cell corner may cross the
    // neighbouring cell instead (0.3 % of the cells here). Skipping unchanged cells must add nothing to that. Every
    // cell octomap updated so far is compared (octomap's tree also holds cells it made when it expanded a pruned
    // node: they are not the rule's).
    std::size_t compared = 0, unknown = 0, differ = 0;
    for (const auto& k : touched) {
      const octomap::point3d c = ref.keyToCoord(k);
      const float v = map->logOdds(Eigen::Vector3d(c.x(), c.y(), c.z()));
      ++compared;
      if (std::isnan(v)) {
        ++unknown;
      } else if (v != ref.search(k)->getLogOdds()) {
        ++differ;
      }
    }
    EXPECT_GT(compared, 100000u);
    EXPECT_LT(unknown, compared / 200) << "cloud " << cloud;
    EXPECT_LT(differ, compared / 1000) << "cloud " << cloud;
    if (cloud == 11) {
      std::printf("[ octomap ] last cloud: %zu cells compared, %zu unknown in the map, %zu with other values\n",
                  compared, unknown, differ);
    }
  }
  EXPECT_TRUE(map->occupied({0.1, 0.0, 0.1}));    // the box now (x 0.04 .. 0.34)
  EXPECT_FALSE(map->occupied({-0.3, 0.0, 0.1}));  // where it was first
}

TEST_F(PandaOctomap, SensedTableBlocksTheRobot) {
  auto map = makeMap();
  // The table top as a camera above it sees it, minus what lies on the robot.
  const auto top = plane(-0.4, 1.1, -0.4, 0.4, 0.0, 0.005);
  std::vector<std::uint8_t> mask;
  scene_->checker().robotPointMask(kHome.data(), top, 0.03, &mask);
  std::size_t masked = 0;
  for (auto m : mask) masked += m;
  EXPECT_GT(masked, 0u) << "the base stands on the table: points around it belong to the robot";
  EXPECT_LT(masked, top.size() / 10);
  const auto t0 = Clock::now();
  integrate(map.get(), top, kCamera, mask);
  const double integrate_s = std::chrono::duration<double>(Clock::now() - t0).count();
  scene_->checker().setOccupancy(map.get());
  ASSERT_TRUE(scene_->checker().hasOccupancy());

  mps::StateCheck sc;
  scene_->checkState(kHome, &sc);
  EXPECT_EQ(sc.outcome, mps::CheckOutcome::kValid) << sc.message;
  scene_->checkState(kIntoTable, &sc);
  ASSERT_EQ(sc.outcome, mps::CheckOutcome::kWorldCollision) << sc.message;
  ASSERT_FALSE(sc.pairs.empty());
  EXPECT_EQ(sc.pairs[0].b, "octomap");

  mps::MotionCheck mc;
  scene_->validateMotion(kHome, kIntoTable, /*plan=*/false, &mc);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kPoseCollision) << mc.message;
  // The planner's and last_safe's quick check (no pairs) sees the map too.
  EXPECT_FALSE(scene_->checker().isStateValid(kIntoTable.data()));
  EXPECT_TRUE(scene_->checker().isStateValid(kHome.data()));

  // Speed of checks against the octree (printed, not asserted).
  const int n = 200;
  auto t1 = Clock::now();
  for (int k = 0; k < n; ++k) scene_->checkState(kHome, &sc);
  const double state_ms = 1e3 * std::chrono::duration<double>(Clock::now() - t1).count() / n;
  std::vector<double> goal = kHome;
  goal[0] = 0.5;
  mps::PathCheck pc;
  t1 = Clock::now();
  for (int k = 0; k < 20; ++k) scene_->checkPath(kHome, goal, &pc);
  const double path_ms = 1e3 * std::chrono::duration<double>(Clock::now() - t1).count() / 20;
  EXPECT_EQ(pc.outcome, mps::CheckOutcome::kValid) << pc.message;
  std::printf(
      "[ octomap ] %zu points integrated in %.1f ms (%zu occupied leaves); state check %.3f ms, "
      "path check (%zu states) %.3f ms\n",
      top.size(), 1e3 * integrate_s, map->occupiedLeafCount(), state_ms, pc.checked_states, path_ms);
  scene_->checker().setOccupancy(nullptr);
  scene_->checkState(kIntoTable, &sc);
  EXPECT_EQ(sc.outcome, mps::CheckOutcome::kValid) << "octree removed: " << sc.message;
}

/// The predictive margin: a sensed wall 6 cm beyond the hand's reach at the goal. The goal is free without a margin,
/// collides once the margin covers the gap; the start's own margin decides START_IN_COLLISION apart from the goal's.
TEST_F(PandaOctomap, SensedMarginInflatesTheRobotAgainstTheMap) {
  auto map = makeMap();
  // A wall x = 0.75 (y -0.4 .. 0.4, z 0 .. 0.8) seen from behind the robot.
  std::vector<Eigen::Vector3d> wall;
  for (double y = -0.4; y <= 0.4; y += 0.01) {
    for (double z = 0.0; z <= 0.8; z += 0.01) wall.emplace_back(0.75, y, z);
  }
  integrate(map.get(), wall, Eigen::Vector3d(-0.5, 0.0, 0.6));
  scene_->checker().setOccupancy(map.get());
  std::vector<double> goal = kHome;
  goal[1] = 0.2;  // leans towards the wall
  mps::StateCheck sc;
  // The smallest margin at which the goal collides, in steps of kMarginStep.
  double hit_at = -1.0;
  for (double m = 0.0; m <= 0.5 + 1e-9; m += mps::FclCollisionChecker::kMarginStep) {
    ASSERT_TRUE(scene_->checker().setOctreeMargin(m));
    scene_->checkState(goal, &sc);
    if (sc.outcome == mps::CheckOutcome::kWorldCollision) {
      hit_at = m;
      break;
    }
  }
  ASSERT_GT(hit_at, 0.02) << "the goal must be free without a margin";
  EXPECT_FALSE(scene_->checker().setOctreeMargin(-0.01));
  EXPECT_FALSE(scene_->checker().setOctreeMargin(mps::FclCollisionChecker::kMaxMargin + 0.01));
  ASSERT_TRUE(scene_->checker().setOctreeMargin(0.004));  // rounded up to one step
  EXPECT_DOUBLE_EQ(scene_->checker().octreeMargin(), mps::FclCollisionChecker::kMarginStep);
  ASSERT_TRUE(scene_->checker().setOctreeMargin(0.0));

  mps::MotionCheck mc;
  mps::SensedMargins sm;
  sm.start = sm.end = sm.plan = hit_at - mps::FclCollisionChecker::kMarginStep;
  scene_->validateMotion(kHome, goal, false, &mc, false, 0.0, 0.05, &sm);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kValid) << mc.message;
  sm.end = hit_at;  // where the robot will be by the end of the move, the wall may have come
  scene_->validateMotion(kHome, goal, false, &mc, false, 0.0, 0.05, &sm);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kPoseCollision) << mc.message;
  sm.start = 0.0;
  sm.end = hit_at - mps::FclCollisionChecker::kMarginStep;
  // Resting at the goal: the start's margin alone decides whether the robot may leave.
  scene_->validateMotion(goal, kHome, false, &mc, false, 0.0, 0.05, &sm);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kValid) << mc.message;
  sm.start = hit_at;
  scene_->validateMotion(goal, kHome, false, &mc, false, 0.0, 0.05, &sm);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kStartInCollision) << mc.message;
  EXPECT_DOUBLE_EQ(scene_->checker().octreeMargin(), 0.0) << "validateMotion leaves no margin behind";
  scene_->checker().setOccupancy(nullptr);
}

/// Out of a person's way (strategy retreat): the hand rests near a sensed wall, within the margin of the move's end (a
/// hold would not be covered). A refused move is answered with a move that backs away: every state of its path at
/// least as clear of the wall as the start, its goal clearer, free of the world and of self collisions. A commanded
/// move that backs away is accepted; a robot that cannot move (no reach) is boxed in; a covered hold asks for nothing.
TEST_F(PandaOctomap, ARobotRestingWithinTheMarginBacksAway) {
  auto map = makeMap();
  std::vector<Eigen::Vector3d> wall;
  for (double y = -0.4; y <= 0.4; y += 0.01) {
    for (double z = 0.0; z <= 0.8; z += 0.01) wall.emplace_back(0.75, y, z);
  }
  integrate(map.get(), wall, Eigen::Vector3d(-0.5, 0.0, 0.6));
  auto& checker = scene_->checker();
  checker.setOccupancy(map.get());
  constexpr double kFar = 1.0;
  std::vector<double> lean = kHome;
  lean[1] = 0.3;
  lean[3] = -1.8;  // reaches towards the wall: 5-6 cm from it
  const double lean_clear = checker.occupancyDistance(lean.data(), 0.0, kFar);
  ASSERT_GT(lean_clear, 0.02);
  ASSERT_LT(lean_clear, 0.12) << "the wall is a few cm from the arm";
  // The distance agrees with collision checks of the padded links inflated by the margin (the octree's levels).
  const double padding = checker.options().padding;
  ASSERT_TRUE(checker.setOctreeMargin(lean_clear - padding - 0.015));
  EXPECT_TRUE(checker.occupancyFree(lean.data()));
  ASSERT_TRUE(checker.setOctreeMargin(lean_clear - padding + 0.01));
  EXPECT_FALSE(checker.occupancyFree(lean.data()));
  ASSERT_TRUE(checker.setOctreeMargin(0.0));
  // Towards the wall (refused) and away from it: one joint moved by 0.15 rad, whichever way loses (gains) most.
  std::vector<double> closer = lean, back = lean;
  double closer_clear = lean_clear, back_clear = lean_clear;
  for (std::size_t i = 0; i < 7; ++i) {
    for (double d : {-0.15, 0.15}) {
      std::vector<double> q = lean;
      q[i] += d;
      const double c = checker.occupancyDistance(q.data(), 0.0, kFar);
      if (c < closer_clear) closer_clear = c, closer = q;
      if (c > back_clear) back_clear = c, back = q;
    }
  }
  ASSERT_LT(closer_clear, lean_clear - 0.01);
  ASSERT_GT(back_clear, lean_clear + 0.01);
  mps::SensedMargins sm;
  sm.end = sm.plan = lean_clear + 0.02;  // within the end margin, free of the start margin (0)
  mps::MotionRequest req;
  req.start = lean;
  req.goal = closer;
  req.plan_on_path_collision = true;
  req.duration = 0.05;
  mps::MotionCheck mc;
  scene_->validateMotion(req, &mc, &sm);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kPoseCollision) << mc.message;
  EXPECT_FALSE(mc.threatened) << "no retreat asked for: nothing computed";
  EXPECT_TRUE(mc.retreat_state.empty());

  req.retreat_reach.assign(7, 0.1);
  scene_->validateMotion(req, &mc, &sm);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kPoseCollision) << mc.message;
  EXPECT_TRUE(mc.threatened) << mc.message;
  EXPECT_NEAR(mc.clearance, lean_clear, 1e-9);
  ASSERT_EQ(mc.retreat_state.size(), 7u) << mc.message;
  EXPECT_GE(mc.retreat_clearance, mc.clearance + mps::PlanningScene::kRetreatGain);
  EXPECT_NE(mc.message.find("backs away"), std::string::npos) << mc.message;
  // Checked independently, finely: no state of the path comes closer than the start by more than half the retreat
  // resolution; the goal is as clear as reported; the world and self collisions are checked like every move.
  const std::vector<double> away = mc.retreat_state;
  for (std::size_t i = 0; i < 7; ++i) EXPECT_LE(std::fabs(away[i] - lean[i]), 0.1 + 1e-12);
  std::vector<double> q(7);
  for (int k = 0; k <= 200; ++k) {
    for (std::size_t i = 0; i < 7; ++i) q[i] = lean[i] + k / 200.0 * (away[i] - lean[i]);
    EXPECT_GE(checker.occupancyDistance(q.data(), 0.0, kFar), lean_clear - mps::PlanningScene::kRetreatResolution / 2)
        << "at " << k / 2.0 << " %";
  }
  EXPECT_NEAR(checker.occupancyDistance(away.data(), 0.0, kFar), mc.retreat_clearance, 1e-9);
  checker.setOccupancy(nullptr);
  mps::PathCheck pc;
  scene_->checkPath(lean, away, &pc);
  EXPECT_EQ(pc.outcome, mps::CheckOutcome::kValid) << pc.message;
  checker.setOccupancy(map.get());

  // Within the start's own margin every commanded move was refused (START_IN_COLLISION): one that backs away is
  // accepted now, one that does not is answered with a retreat.
  sm.start = sm.end;
  req.goal = back;
  req.retreat_reach.clear();
  scene_->validateMotion(req, &mc, &sm);
  EXPECT_NE(mc.outcome, mps::MotionOutcome::kValid) << mc.message;
  req.retreat_reach.assign(7, 0.1);
  scene_->validateMotion(req, &mc, &sm);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kValid) << mc.message;
  EXPECT_TRUE(mc.threatened);
  EXPECT_TRUE(mc.retreat_state.empty());
  EXPECT_NEAR(mc.retreat_clearance, back_clear, 1e-9);
  req.goal = closer;
  scene_->validateMotion(req, &mc, &sm);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kPoseCollision) << mc.message;  // the goal is checked first
  EXPECT_EQ(mc.retreat_state.size(), 7u) << mc.message;
  // safety:=ssm (SensedMargins::hold_when_threatened): threatened, the robot holds still. The move that backs away
  // is refused (a person may touch a robot at rest, not one moving), and no retreat is proposed.
  {
    mps::SensedMargins ssm = sm;
    ssm.hold_when_threatened = true;
    mps::MotionRequest held = req;
    held.goal = back;
    scene_->validateMotion(held, &mc, &ssm);
    EXPECT_NE(mc.outcome, mps::MotionOutcome::kValid) << mc.message;
    EXPECT_TRUE(mc.threatened) << mc.message;
    EXPECT_TRUE(mc.retreat_state.empty());
    EXPECT_NE(mc.message.find("held still"), std::string::npos) << mc.message;
    held.goal = closer;
    scene_->validateMotion(held, &mc, &ssm);
    EXPECT_EQ(mc.outcome, mps::MotionOutcome::kPoseCollision) << mc.message;
    EXPECT_TRUE(mc.retreat_state.empty()) << mc.message;
  }
  // What a retreat costs (printed, not asserted).
  const auto t0 = Clock::now();
  for (int k = 0; k < 20; ++k) scene_->validateMotion(req, &mc, &sm);
  const double search_ms = 1e3 * std::chrono::duration<double>(Clock::now() - t0).count() / 20;
  const auto t1 = Clock::now();
  for (int k = 0; k < 20; ++k) checker.occupancyDistance(lean.data(), 0.0, lean_clear + 0.1);
  std::printf("[ retreat ] refused move + retreat search: %.2f ms; one clearance: %.3f ms\n", search_ms,
              1e3 * std::chrono::duration<double>(Clock::now() - t1).count() / 20);

  // Boxed in: no reach, no retreat; the robot holds (and says why).
  req.retreat_reach.assign(7, 0.0);
  scene_->validateMotion(req, &mc, &sm);
  EXPECT_TRUE(mc.threatened);
  EXPECT_TRUE(mc.retreat_state.empty());
  EXPECT_NE(mc.message.find("boxed in"), std::string::npos) << mc.message;
  // A bad reach is an invalid request.
  req.retreat_reach.assign(6, 0.1);
  scene_->validateMotion(req, &mc, &sm);
  EXPECT_EQ(mc.outcome, mps::MotionOutcome::kInvalidRequest) << mc.message;

  // A hold the margin covers: nothing to back away from.
  sm.start = 0.0;
  sm.end = sm.plan = 0.0;
  req.retreat_reach.assign(7, 0.1);
  scene_->validateMotion(req, &mc, &sm);
  EXPECT_FALSE(mc.threatened) << mc.message;
  EXPECT_TRUE(mc.retreat_state.empty());
  EXPECT_DOUBLE_EQ(checker.octreeMargin(), 0.0) << "validateMotion leaves no margin behind";
  checker.setOccupancy(nullptr);
}

/// Unknown is occupied: the rule is octomap's update from a prior just above the threshold; one view clears what it
/// sees, space no camera sees stays occupied, known-free cells (inside the robot) are turned free, and switching the
/// rule off forgets only the prior.
/// checkPath leaves out, for a whole segment, the shapes that no occupied cell comes within their motion over half of
/// it at its midpoint (and so do state checks of a prepared segment's ends): the same answers as checking every shape
/// at every state. Random segments short and long around a wall and a person-sized column, at several margins; the
/// margin changes between the ends' checks (as validateMotion's start margin does: a culling made at one margin must
/// not answer at another), the column moves between a segment's preparation and its checks, and space no camera has
/// seen turns occupied (unknown_occupied) or free again between the ends' checks and the path's (a culling must not
/// outlive the map it was made for). Each of those two rules left out fails this test, and so does a culling that
/// leaves out the shapes' motion.
TEST_F(PandaOctomap, CullingAgainstTheMapChangesNoAnswer) {
  mps::OccupancyMapOptions mo = mps::panda::mapOptions();
  mo.bounds = Eigen::AlignedBox3d(Eigen::Vector3d(-1.2, -1.2, -0.4), Eigen::Vector3d(1.2, 1.2, 1.4));  // the reach
  std::string error;
  auto map = mps::OccupancyMap::create(mo, &error);
  ASSERT_NE(map, nullptr) << error;
  mps::FclCheckerOptions options = scene_->checker().options();
  options.cull_path_pairs = true;
  auto culled = mps::FclCollisionChecker::create(scene_->model(), options, &error);
  ASSERT_NE(culled, nullptr) << error;
  options.cull_path_pairs = false;
  auto every = mps::FclCollisionChecker::create(scene_->model(), options, &error);
  ASSERT_NE(every, nullptr) << error;
  const Eigen::Vector3d eye(1.6, 0.0, 1.2);
  std::vector<Eigen::Vector3d> wall;
  for (double y = -0.6; y <= 0.6; y += 0.01) {
    for (double z = 0.0; z <= 0.9; z += 0.01) wall.emplace_back(-0.55, y, z);
  }
  integrate(map.get(), wall, eye);
  // The column: a 0.2 m square of points from the floor to 1.1 m, at (x, y); moved between clouds.
  auto column = [&](double x, double y) {
    std::vector<Eigen::Vector3d> pts;
    for (double z = 0.0; z <= 1.1; z += 0.01) {
      for (double d = -0.1; d <= 0.1; d += 0.01) {
        pts.emplace_back(x - 0.1, y + d, z);
        pts.emplace_back(x + d, y - 0.1, z);
      }
    }
    integrate(map.get(), pts, eye);
  };
  column(0.65, 0.3);
  culled->setOccupancy(map.get());
  every->setOccupancy(map.get());
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  const auto& model = scene_->model();
  const std::size_t dof = model.dof();
  std::size_t counts[3] = {0, 0, 0}, states = 0, map_changes = 0, unseen_trials = 0;
  for (int trial = 0; trial < 1000; ++trial) {
    std::vector<double> q0(dof), q1(dof);
    const double reach = std::array<double, 4>{0.02, 0.08, 0.2, 0.5}[trial % 4];  // rad per joint, at most
    for (std::size_t i = 0; i < dof; ++i) {
      const double lo = model.lowerLimits()[i], hi = model.upperLimits()[i];
      q0[i] = std::min(std::max(kHome[i] + 0.6 * unit(rng), lo), hi);
      q1[i] = std::min(std::max(q0[i] + reach * unit(rng), lo), hi);
    }
    const double end_margin = std::array<double, 3>{0.0, 0.03, 0.1}[trial % 3];
    const double start_margin = trial % 5 == 0 ? 0.15 : end_margin;
    mps::PathCheckRequest request;
    request.find_first = trial % 2 == 0;
    request.state.max_pairs = std::array<std::size_t, 3>{0, 1, 100}[trial % 3];
    for (auto* c : {culled.get(), every.get()}) ASSERT_TRUE(c->setOctreeMargin(end_margin));
    culled->prepareSegment(q0.data(), q1.data());
    if (trial % 7 == 3) {  // the column moves after the segment was prepared
      column(0.6 + 0.15 * unit(rng), 0.3 * unit(rng));
      ++map_changes;
    }
    for (const std::vector<double>* q : {&q1, &q0}) {
      const double margin = q == &q1 ? end_margin : start_margin;
      for (auto* c : {culled.get(), every.get()}) ASSERT_TRUE(c->setOctreeMargin(margin));
      mps::CollisionResult sa, sb;
      culled->checkState(q->data(), request.state, &sa);
      every->checkState(q->data(), request.state, &sb);
      ASSERT_EQ(sa.status, sb.status) << "trial " << trial;
      ASSERT_EQ(sa.pairs.size(), sb.pairs.size()) << "trial " << trial;
    }
    if (trial % 7 == 5) {  // after the ends were checked (the segment's culling made), unseen space turns occupied
      map->setUnknownOccupied(!map->unknownOccupied());  // (or free again)
      ++map_changes;
    }
    for (auto* c : {culled.get(), every.get()}) ASSERT_TRUE(c->setOctreeMargin(end_margin));
    mps::PathCheckResult a, b;
    culled->checkPath(q0.data(), q1.data(), request, &a);
    every->checkPath(q0.data(), q1.data(), request, &b);
    ASSERT_EQ(a.status, b.status) << "trial " << trial;
    ASSERT_EQ(a.checked_states, b.checked_states) << "trial " << trial;
    ASSERT_EQ(a.collision_fraction, b.collision_fraction) << "trial " << trial;
    ASSERT_EQ(a.last_valid_fraction, b.last_valid_fraction) << "trial " << trial;
    ASSERT_EQ(a.pairs.size(), b.pairs.size()) << "trial " << trial;
    for (std::size_t k = 0; k < a.pairs.size(); ++k) {
      EXPECT_EQ(a.pairs[k].a, b.pairs[k].a) << "trial " << trial;
      EXPECT_EQ(a.pairs[k].b, b.pairs[k].b) << "trial " << trial;
    }
    ++counts[static_cast<int>(a.status)];
    states += a.checked_states;
    unseen_trials += map->unknownOccupied() ? 1 : 0;
  }
  // Paths free and paths that meet the map (self collisions as they come), long enough to cull on.
  EXPECT_GT(counts[0], 120u) << "free";
  EXPECT_GT(counts[2], 300u) << "world";
  EXPECT_GT(states, 1000u * 6);
  EXPECT_GT(map_changes, 250u);
  EXPECT_GT(unseen_trials, 300u);
}

/// Retreat with unseen space around the robot (unknown_occupied): only cells a camera saw occupied make the robot
/// back away (space no camera has seen, e.g. its own shadow, does not come closer); a retreat ends clearer of every
/// occupied cell and never brings any link closer to any of them, seen or unseen, than the robot stands (nothing can
/// reach it sooner than if it held); and the search ends, holding, when the caller's time budget runs out.
TEST_F(PandaOctomap, RetreatBacksAwayFromSeenCellsNeverCloserToAnyCell) {
  mps::OccupancyMapOptions o = mps::panda::mapOptions();
  const double reach = scene_->checker().reachRadius() + 0.3;
  o.bounds = Eigen::AlignedBox3d(Eigen::Vector3d::Constant(-reach), Eigen::Vector3d::Constant(reach));
  o.unknown_occupied = true;
  std::string error;
  auto map = mps::OccupancyMap::create(o, &error);
  ASSERT_TRUE(map) << error;
  auto& checker = scene_->checker();
  std::vector<double> lean = kHome;
  lean[1] = 0.3;
  lean[3] = -1.8;  // reaches towards x = 0.75
  // A camera behind the robot sees a wall at x = 0.75 (its rays clear the space before it); space the rays do not
  // reach stays unseen. The cells within kShell of its links at `lean` are known free.
  std::vector<Eigen::Vector3d> wall;
  for (double y = -0.4; y <= 0.4; y += 0.01) {
    for (double z = 0.0; z <= 0.8; z += 0.01) wall.emplace_back(0.75, y, z);
  }
  mps::MapUpdate u;
  map->computeUpdate(wall, {}, Eigen::Vector3d(-0.5, 0.0, 0.6), &u);
  std::vector<Eigen::AlignedBox3d> boxes;
  constexpr double kShell = 0.08;  // the known-free shell: the unseen space begins 8 cm from the links (the wall: 5-6)
  checker.robotBoundingBoxes(lean.data(), kShell, &boxes);
  std::vector<Eigen::Vector3d> centers;
  std::vector<std::uint64_t> keys, free_keys;
  std::vector<std::uint8_t> mask;
  for (const auto& box : boxes) {
    map->unobservedCells(box, &centers, &keys);
    checker.robotPointMask(lean.data(), centers, kShell, &mask);
    for (std::size_t k = 0; k < keys.size(); ++k) {
      if (mask[k] != 0) free_keys.push_back(keys[k]);
    }
  }
  map->addKnownFree(free_keys, &u);
  map->apply(u);
  checker.setOccupancy(map.get());
  constexpr double kFar = 1.0;
  const double seen0 = checker.occupancyDistance(lean.data(), 0.0, kFar, mps::CellClass::kSeen);
  const double unseen0 = checker.occupancyDistance(lean.data(), 0.0, kFar, mps::CellClass::kUnseen);
  ASSERT_GT(seen0, 0.02);
  ASSERT_LT(seen0, 0.12) << "the wall is a few cm from the arm";
  ASSERT_GT(unseen0, seen0) << "the wall is the nearest";
  ASSERT_LT(unseen0, 0.12) << "unseen space lies close to the robot (beyond its known-free shell)";
  EXPECT_DOUBLE_EQ(checker.occupancyDistance(lean.data(), 0.0, kFar), std::min(seen0, unseen0));

  std::vector<double> closer = lean;
  closer[1] += 0.15;  // towards the wall: refused
  mps::SensedMargins sm;
  sm.end = sm.plan = seen0 + 0.02;  // the wall within the end margin
  mps::MotionRequest req;
  req.start = lean;
  req.goal = closer;
  req.duration = 0.05;
  req.retreat_reach.assign(7, 0.1);
  mps::MotionCheck mc;
  scene_->validateMotion(req, &mc, &sm);
  EXPECT_NE(mc.outcome, mps::MotionOutcome::kValid) << mc.message;
  EXPECT_TRUE(mc.threatened) << mc.message;
  EXPECT_NEAR(mc.clearance, std::min(seen0, unseen0), 1e-9) << "the clearance from every occupied cell";
  ASSERT_EQ(mc.retreat_state.size(), 7u) << mc.message;
  EXPECT_GE(mc.retreat_clearance, mc.clearance + mps::PlanningScene::kRetreatGain);
  // Checked independently, finely: no state comes closer to any occupied cell than the start (within half the retreat
  // resolution); the goal is clearer.
  const double clear0 = std::min(seen0, unseen0);
  std::vector<double> q(7);
  for (int k = 0; k <= 200; ++k) {
    for (std::size_t i = 0; i < 7; ++i) q[i] = lean[i] + k / 200.0 * (mc.retreat_state[i] - lean[i]);
    EXPECT_GE(checker.occupancyDistance(q.data(), 0.0, kFar), clear0 - mps::PlanningScene::kRetreatResolution / 2)
        << "at " << k / 2.0 << " %";
  }
  EXPECT_NEAR(checker.occupancyDistance(mc.retreat_state.data(), 0.0, kFar), mc.retreat_clearance, 1e-9);

  // Out of time: the search stops and the robot holds, saying why.
  req.time_budget = 1e-9;
  scene_->validateMotion(req, &mc, &sm);
  EXPECT_TRUE(mc.threatened) << mc.message;
  EXPECT_TRUE(mc.retreat_state.empty());
  EXPECT_NE(mc.message.find("time the caller waits"), std::string::npos) << mc.message;
  req.time_budget = 0.0;

  // Unseen space alone within the margin (the same map without the wall): not a threat, nothing searched.
  auto blind = mps::OccupancyMap::create(o, &error);
  ASSERT_TRUE(blind) << error;
  mps::MapUpdate none;
  blind->computeUpdate({}, {}, Eigen::Vector3d(-0.5, 0.0, 0.6), &none);
  blind->addKnownFree(free_keys, &none);
  blind->apply(none);
  checker.setOccupancy(blind.get());
  ASSERT_TRUE(checker.setOctreeMargin(sm.end));
  ASSERT_FALSE(checker.occupancyFree(lean.data())) << "the unseen space lies within the margin";
  ASSERT_TRUE(checker.setOctreeMargin(0.0));
  scene_->validateMotion(req, &mc, &sm);
  EXPECT_FALSE(mc.threatened) << mc.message;
  EXPECT_TRUE(mc.retreat_state.empty());
  checker.setOccupancy(nullptr);
}

TEST(OccupancyMap, UnknownOccupiedRule) {
  mps::OccupancyMapOptions o = mps::panda::mapOptions();
  o.bounds = Eigen::AlignedBox3d(Eigen::Vector3d(-1.0, -1.0, -0.2), Eigen::Vector3d(1.0, 1.0, 1.0));
  o.unknown_occupied = true;
  std::string error;
  auto map = mps::OccupancyMap::create(o, &error);
  ASSERT_TRUE(map) << error;
  const std::size_t cells = map->unobservedCount();
  EXPECT_GE(cells, 100u * 100u * 60u);          // the whole box (one more cell per axis where a bound falls on an edge)
  EXPECT_TRUE(map->occupied({0.4, 0.0, 0.4}));  // never seen
  EXPECT_TRUE(map->occupied({-0.9, 0.9, 0.9}));
  EXPECT_FALSE(map->occupied({1.5, 0.0, 0.4}));  // outside the mapped box: never occupied
  EXPECT_EQ(map->occupiedLeafCount(), 0u);       // nothing seen occupied yet (rviz markers show only what was seen)
  // One view from above of a floor at z = 0 with a box top at z = 0.4 on it.
  const Eigen::Vector3d origin(0.4, 0.0, 0.99);
  auto pts = plane(0.0, 0.8, -0.4, 0.4, 0.0, 0.01);
  for (auto& p : pts) {
    if (std::fabs(p.x() - 0.4) <= 0.1 && std::fabs(p.y()) <= 0.1) p.z() = 0.4;
  }
  mps::MapUpdate u;
  map->computeUpdate(pts, {}, origin, &u);
  // Cells the robot's links would fill (here: a box the camera cannot see, under the box top), given as known free.
  std::vector<Eigen::Vector3d> centers;
  std::vector<std::uint64_t> keys;
  map->unobservedCells(Eigen::AlignedBox3d(Eigen::Vector3d(0.36, -0.04, 0.1), Eigen::Vector3d(0.46, 0.06, 0.3)),
                       &centers, &keys);
  EXPECT_EQ(keys.size(), 5u * 5u * 10u);
  for (const auto& c : centers) EXPECT_TRUE(map->occupied(c));
  map->addKnownFree(keys, &u);
  EXPECT_EQ(u.stats.known_free, keys.size());
  map->apply(u);
  EXPECT_FALSE(map->occupied({0.4, 0.0, 0.6}));     // seen free in one view (prior + one miss)
  EXPECT_FALSE(map->occupied({0.1, 0.3, 0.2}));     // seen free, beside the box
  EXPECT_TRUE(map->occupied({0.4, 0.0, 0.4}));      // hit: the box top
  EXPECT_TRUE(map->occupied({0.41, 0.03, 0.05}));   // under the box top, outside the known-free box: unseen
  EXPECT_FALSE(map->occupied({0.41, 0.01, 0.21}));  // known free
  EXPECT_TRUE(map->occupied({0.4, 0.0, -0.1}));     // under the floor: unseen
  EXPECT_TRUE(map->occupied({0.4, 0.0, 0.0}));      // the floor: hit
  EXPECT_LT(map->unobservedCount(), cells);
  map->unobservedCells(Eigen::AlignedBox3d(Eigen::Vector3d(0.36, -0.04, 0.1), Eigen::Vector3d(0.46, 0.06, 0.3)),
                       &centers, &keys);
  EXPECT_TRUE(keys.empty()) << "known-free cells count as observed";
  // The classes of occupied cells (CellClass): seen (the box top, the floor) and unseen (the prior), apart.
  auto any = [&](const Eigen::Vector3d& p, mps::CellClass which) {
    const Eigen::AlignedBox3d around(p.array() - 0.005, p.array() + 0.005);
    return map->anyOccupied(around, [](const Eigen::AlignedBox3d&) { return true; }, which);
  };
  // (cell centres: the query boxes stay inside one cell)
  const Eigen::Vector3d top(0.41, 0.01, 0.41), under(0.41, 0.03, 0.05), above(0.41, 0.01, 0.61);
  EXPECT_TRUE(any(top, mps::CellClass::kSeen) && any(top, mps::CellClass::kAll));
  EXPECT_FALSE(any(top, mps::CellClass::kUnseen));
  EXPECT_TRUE(any(under, mps::CellClass::kUnseen) && any(under, mps::CellClass::kAll));
  EXPECT_FALSE(any(under, mps::CellClass::kSeen));
  for (auto which : {mps::CellClass::kAll, mps::CellClass::kSeen, mps::CellClass::kUnseen}) {
    EXPECT_FALSE(any(above, which));  // seen free
  }
  // A whole region: the seen class visits exactly the cells seen occupied, the unseen one the unobserved cells.
  std::size_t seen_visited = 0, unseen_visited = 0;
  const double cell = o.resolution;
  auto count = [&](std::size_t* n) {
    return [n, cell](const Eigen::AlignedBox3d& b) {
      *n += static_cast<std::size_t>(std::llround(b.volume() / (cell * cell * cell)));
      return false;
    };
  };
  auto all = [](const Eigen::AlignedBox3d&) { return true; };
  map->visitOccupied(o.bounds, all, count(&seen_visited), mps::CellClass::kSeen);
  map->visitOccupied(o.bounds, all, count(&unseen_visited), mps::CellClass::kUnseen);
  EXPECT_EQ(seen_visited, map->occupiedLeafCount());
  EXPECT_EQ(unseen_visited, map->unobservedCount());
  // One hit turns a cell seen free occupied again, as without the rule.
  integrate(map.get(), {{0.1, 0.3, 0.2}}, origin);
  EXPECT_TRUE(map->occupied({0.1, 0.3, 0.2}));
  EXPECT_TRUE(any({0.1, 0.3, 0.2}, mps::CellClass::kSeen));
  // Off: the unobserved cells are unknown (free) again, what was observed stays.
  map->setUnknownOccupied(false);
  EXPECT_EQ(map->unobservedCount(), 0u);
  EXPECT_FALSE(map->occupied({0.41, 0.03, 0.05}));
  EXPECT_FALSE(map->observed({0.4, 0.0, -0.1}));
  EXPECT_TRUE(map->occupied({0.4, 0.0, 0.4}));
  EXPECT_FALSE(map->occupied({0.4, 0.0, 0.6}));
  map->unobservedCells(o.bounds, &centers, &keys);
  EXPECT_TRUE(keys.empty());
  // On again, then clear: every cell unobserved.
  map->setUnknownOccupied(true);
  EXPECT_TRUE(map->occupied({0.41, 0.03, 0.05}));
  EXPECT_FALSE(map->occupied({0.4, 0.0, 0.6}));
  EXPECT_TRUE(any(top, mps::CellClass::kSeen));
  EXPECT_TRUE(any(under, mps::CellClass::kUnseen));
  map->clear();
  EXPECT_EQ(map->unobservedCount(), cells);
  EXPECT_TRUE(map->occupied({0.4, 0.0, 0.6}));
  EXPECT_FALSE(any(top, mps::CellClass::kSeen)) << "nothing seen after a clear";
  EXPECT_TRUE(any(top, mps::CellClass::kUnseen));
  EXPECT_EQ(map->occupiedLeafCount(), 0u);
}

/// The robot in a map where nothing has been seen: the cells inside its links (self-filter padding) are known free,
/// so it is free at no margin; the unseen space around it blocks it once the sensed margin reaches past them.
TEST(OccupancyMap, UnobservedCellsAreEveryCellInTheBoxNoCloudObserved) {
  // Every cell whose centre lies in the box and that no cloud observed, in the grid's order, against a cell by cell
  // walk (unobservedCells reads the observed bits a word at a time: rows that start and end anywhere in a word).
  // The bounds are no multiple of the cell: rows of cells start anywhere in a word.
  mps::OccupancyMapOptions o = mps::panda::mapOptions();
  o.resolution = 0.02;
  o.max_range = 3.0;
  o.unknown_occupied = true;
  o.bounds = Eigen::AlignedBox3d(Eigen::Vector3d(-0.61, -0.5, -0.3), Eigen::Vector3d(0.7, 0.43, 0.95));
  std::string error;
  auto map = mps::OccupancyMap::create(o, &error);
  ASSERT_TRUE(map) << error;
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> x(-0.58, 0.67), y(-0.47, 0.4), z(-0.27, 0.92);  // a cell inside the bounds
  for (int view = 0; view < 6; ++view) {  // scattered points from scattered origins: observed cells in every pattern
    std::vector<Eigen::Vector3d> pts;
    for (int k = 0; k < 400; ++k) pts.emplace_back(x(rng), y(rng), z(rng));
    integrate(map.get(), pts, Eigen::Vector3d(x(rng), y(rng), z(rng)));
  }
  const double r = o.resolution;
  std::vector<Eigen::Vector3d> centers;
  std::vector<std::uint64_t> keys;
  std::size_t unobserved = 0;
  for (int trial = 0; trial < 60; ++trial) {
    const Eigen::Vector3d a(x(rng), y(rng), z(rng)), b(x(rng), y(rng), z(rng));
    const Eigen::AlignedBox3d box(a.cwiseMin(b), a.cwiseMax(b));
    map->unobservedCells(box, &centers, &keys);
    ASSERT_EQ(centers.size(), keys.size());
    std::vector<Eigen::Vector3d> expected;
    // Cell centres (i + 0.5) r, in the grid's order (x, then y, then z), that lie in the box and in the map.
    for (double cx = (std::floor(box.min().x() / r) + 0.5) * r; cx <= box.max().x(); cx += r) {
      for (double cy = (std::floor(box.min().y() / r) + 0.5) * r; cy <= box.max().y(); cy += r) {
        for (double cz = (std::floor(box.min().z() / r) + 0.5) * r; cz <= box.max().z(); cz += r) {
          const Eigen::Vector3d c(cx, cy, cz);
          if (!box.contains(c) || map->observed(c)) continue;
          expected.push_back(c);
        }
      }
    }
    ASSERT_EQ(centers.size(), expected.size()) << "trial " << trial;
    for (std::size_t k = 0; k < centers.size(); ++k) {
      ASSERT_LT((centers[k] - expected[k]).norm(), 1e-9) << "trial " << trial << ", cell " << k;
      EXPECT_TRUE(map->occupied(centers[k]));
    }
    unobserved += keys.size();
  }
  EXPECT_GT(unobserved, 1000u);
  // Beyond the map on every side: the whole grid.
  map->unobservedCells(Eigen::AlignedBox3d(o.bounds.min().array() - 0.1, o.bounds.max().array() + 0.1), &centers,
                       &keys);
  EXPECT_EQ(keys.size(), map->unobservedCount());
}

TEST_F(PandaOctomap, UnknownOccupiedAroundTheRobot) {
  mps::OccupancyMapOptions o = mps::panda::mapOptions();
  const double reach = scene_->checker().reachRadius() + 0.05;
  o.bounds = Eigen::AlignedBox3d(Eigen::Vector3d::Constant(-reach), Eigen::Vector3d::Constant(reach));
  o.unknown_occupied = true;
  std::string error;
  auto map = mps::OccupancyMap::create(o, &error);
  ASSERT_TRUE(map) << error;
  scene_->checker().setOccupancy(map.get());
  mps::StateCheck sc;
  scene_->checkState(kHome, &sc);
  EXPECT_EQ(sc.outcome, mps::CheckOutcome::kWorldCollision) << "inside unseen space";
  const double pad = 0.03;
  std::vector<Eigen::AlignedBox3d> boxes;
  scene_->checker().robotBoundingBoxes(kHome.data(), pad, &boxes);
  ASSERT_FALSE(boxes.empty());
  mps::MapUpdate u;
  map->computeUpdate({}, {}, Eigen::Vector3d::Zero(), &u);
  std::vector<Eigen::Vector3d> centers;
  std::vector<std::uint64_t> keys, free_keys;
  std::vector<std::uint8_t> mask;
  for (const auto& box : boxes) {
    map->unobservedCells(box, &centers, &keys);
    scene_->checker().robotPointMask(kHome.data(), centers, pad, &mask);
    for (std::size_t k = 0; k < keys.size(); ++k) {
      if (mask[k] != 0) free_keys.push_back(keys[k]);
    }
  }
  map->addKnownFree(free_keys, &u);
  EXPECT_GT(u.stats.known_free, 1000u);
  map->apply(u);
  scene_->checkState(kHome, &sc);
  EXPECT_EQ(sc.outcome, mps::CheckOutcome::kValid) << sc.message;
  ASSERT_TRUE(scene_->checker().setOctreeMargin(0.02));  // past the known-free shell: the unseen space is hit
  scene_->checkState(kHome, &sc);
  EXPECT_EQ(sc.outcome, mps::CheckOutcome::kWorldCollision) << sc.message;
  ASSERT_TRUE(scene_->checker().setOctreeMargin(0.0));
  std::vector<double> moved = kHome;
  moved[0] += 0.3;  // into space nobody has seen
  scene_->checkState(moved, &sc);
  EXPECT_EQ(sc.outcome, mps::CheckOutcome::kWorldCollision) << sc.message;
  scene_->checker().setOccupancy(nullptr);
}

/// Lockstep's one-step lag (octomap/lockstep_lag): a check reads the clouds up to the previous check's state, except
/// for the first check, another check of the same state, and the first after a reset, which read what the cameras saw
/// since it; and except when the lag would cost more margin than octomap/lockstep_lag_max_margin allows.
TEST(SensedMargin, LockstepMapCutoff) {
  const double none = std::numeric_limits<double>::quiet_NaN();
  auto cutoff = [](double previous, double stamp, double epoch) {
    return mps::lockstepMapCutoff(previous, stamp, epoch, 0.16, 0.01);  // the human world: 8 mm a 0.05 s step
  };
  EXPECT_EQ(cutoff(none, 5.0, 0.0), 5.0);   // the first check: every cloud
  EXPECT_EQ(cutoff(4.95, 5.0, 0.0), 4.95);  // a step later: the clouds up to the previous state
  EXPECT_EQ(cutoff(5.0, 5.0, 0.0), 5.0);    // the same state again: every cloud
  EXPECT_EQ(cutoff(5.0, 4.0, 0.0), 4.0);    // a clock that went back: every cloud up to the state
  EXPECT_EQ(cutoff(4.95, 5.0, 2.0), 4.95);  // a reset long before: as any step
  // A reset after the previous check: the views at the reset are in (within the epoch's slack), later ones wait (a
  // slower world: the 0.2 s since the reset cost 8 mm); at 0.16 m/s that lag costs 3 cm: every cloud.
  EXPECT_DOUBLE_EQ(mps::lockstepMapCutoff(4.95, 5.2, 5.0, 0.04, 0.01), 5.0 + mps::kEpochSlack);
  EXPECT_EQ(cutoff(4.95, 5.2, 5.0), 5.2);
  EXPECT_EQ(cutoff(4.95, 5.0, 5.0), 5.0);  // the reset's own state: every cloud
  // A lag that would cost more margin than allowed: every cloud. 0.16 m/s over a long step (1 s: 16 cm); ISO's
  // 1.6 m/s over one 0.05 s step (8 cm); within the budget, exactly at it (0.2 m/s x 0.05 s) and without a bound.
  EXPECT_EQ(cutoff(4.0, 5.0, 0.0), 5.0);
  EXPECT_EQ(mps::lockstepMapCutoff(4.95, 5.0, 0.0, 1.6, 0.01), 5.0);
  EXPECT_EQ(mps::lockstepMapCutoff(4.9375, 5.0, 0.0, 0.16, 0.01), 4.9375);  // 1 cm: 0.0625 s at 0.16 m/s
  EXPECT_EQ(mps::lockstepMapCutoff(4.9, 5.0, 0.0, 1.6, 0.0), 5.0);
  EXPECT_EQ(mps::lockstepMapCutoff(4.0, 5.0, 0.0, 0.0, 0.0), 4.0);   // nothing moves: the lag costs nothing
  EXPECT_EQ(mps::lockstepMapCutoff(4.0, 5.0, 0.0, -1.0, 0.0), 4.0);  // (no bound given: none)
}

/// The margin's arithmetic (README, "A person seen only by cameras"): 1.6 m/s and 0.1 s of map age cost 16 cm.
TEST(SensedMargin, AgeAndRule) {
  const double inf = std::numeric_limits<double>::infinity();
  EXPECT_EQ(mps::sensedMapAge(std::vector<double>{}, 5.0, 0.0), inf);      // nothing seen
  EXPECT_DOUBLE_EQ(mps::sensedMapAge({4.5, 4.9}, 5.0, 0.0), 0.5);          // the oldest camera decides
  EXPECT_DOUBLE_EQ(mps::sensedMapAge({5.2, 5.1}, 5.0, 0.0), 0.0);          // clouds newer than the state
  EXPECT_EQ(mps::sensedMapAge({4.5, 4.9}, 5.0, 4.7), inf);                 // one camera seen only before the reset
  EXPECT_NEAR(mps::sensedMapAge({4.6995, 4.9}, 5.0, 4.7), 0.3005, 1e-12);  // within the epoch's 1 ms slack
  // Issue 23: every camera the world lists counts; one never heard from leaves the map blind, and is named.
  std::string deciding;
  EXPECT_EQ(mps::sensedMapAge({{"left", 4.9}, {"right", -inf}}, 5.0, 0.0, &deciding), inf);
  EXPECT_EQ(deciding, "right");
  EXPECT_NEAR(mps::sensedMapAge({{"left", 4.9}, {"right", 4.6}}, 5.0, 0.0, &deciding), 0.4, 1e-12);
  EXPECT_EQ(deciding, "right");
  EXPECT_EQ(mps::sensedMapAge(std::vector<mps::CameraSeen>{}, 5.0, 0.0, &deciding), inf);
  EXPECT_EQ(deciding, "");
  mps::SensedMarginRule rule;
  rule.speed_bound = 1.6;
  rule.latency = 0.03;
  rule.plan_horizon = 1.0;
  rule.max_age = 1.0;
  rule.max_margin = 1.0;
  mps::SensedMargins m;
  std::string why;
  ASSERT_TRUE(rule.compute(0.1, 0.05, &m, &why)) << why;
  EXPECT_FALSE(m.hold_when_threatened);  // separation: a threatened robot may back away
  EXPECT_NEAR(m.start, 1.6 * 0.13, 1e-12);
  EXPECT_NEAR(m.end, 1.6 * 0.18, 1e-12);
  EXPECT_EQ(m.plan, inf);  // 1.6 x 1.13 = 1.81 m > max_margin: no plan can be checked, straight moves can
  EXPECT_FALSE(rule.compute(0.6, 0.05, &m, &why));  // 1.6 x 0.68 = 1.09 m: not even a straight move
  EXPECT_NE(why.find("margin"), std::string::npos) << why;
  rule.speed_bound = 0.16;
  ASSERT_TRUE(rule.compute(0.1, inf, &m, &why)) << why;
  EXPECT_NEAR(m.end, 0.16 * 1.13, 1e-12);  // a plan: the end at plan_horizon
  EXPECT_DOUBLE_EQ(m.plan_horizon, 1.0);
  EXPECT_FALSE(rule.compute(1.01, 0.05, &m, &why));  // older than max_age: fail closed
  EXPECT_NE(why.find("max_age"), std::string::npos) << why;
  rule.max_age = inf;  // no age limit, but blind is blind, also with no speed bound
  rule.speed_bound = 0.0;
  EXPECT_FALSE(rule.compute(inf, 0.05, &m, &why));
  ASSERT_TRUE(rule.compute(50.0, 0.05, &m, &why)) << why;
  EXPECT_EQ(m.end, 0.0);
}

TEST(SensedMargin, TheMapReachesTheLargestMarginAnyCheckUses) {
  // The sensed map covers the robot's padded reach plus largestMargin: the margin of a check whose map is as old as
  // max_age allows, for a plan as long as plan_horizon (the widest any check asks for), fits within it.
  const double inf = std::numeric_limits<double>::infinity(), res = 0.02;
  mps::SensedMarginRule rule;
  rule.speed_bound = 0.16;  // worlds/human.yaml's
  rule.latency = 0.03;
  rule.plan_horizon = 1.0;
  rule.max_age = 1.0;
  EXPECT_NEAR(rule.largestMargin(res), 0.16 * 2.03 + 2 * res, 1e-12);
  rule.max_margin = rule.largestMargin(res);
  mps::SensedMargins m;
  std::string why;
  ASSERT_TRUE(rule.compute(rule.max_age, inf, &m, &why)) << why;  // the oldest map, a plan
  EXPECT_LE(m.plan, rule.max_margin);
  EXPECT_LE(m.end, rule.max_margin);
  EXPECT_GT(m.plan + 2 * res, rule.max_margin - 1e-12);  // and no wider than that (two cells)
  rule.speed_bound = 0.0;                                // no speed bound: two cells
  EXPECT_DOUBLE_EQ(rule.largestMargin(res), 2 * res);
  rule.speed_bound = 1.6;  // 1.6 x 2.03 m: the checker's largest margin
  EXPECT_DOUBLE_EQ(rule.largestMargin(res), mps::FclCollisionChecker::kMaxMargin + 2 * res);
  const Eigen::AlignedBox3d box = mps::sensedMapBounds(1.2, 0.3648);
  EXPECT_TRUE(box.min().isApprox(Eigen::Vector3d::Constant(-1.5648)));
  EXPECT_TRUE(box.max().isApprox(Eigen::Vector3d::Constant(1.5648)));
}

TEST(SensedMargin, SsmUsesIso13855WhateverTheSpeedBound) {
  // safety ssm: the margin is ISO 13855's K t + C plus Z_d, K = 2.0 m/s up to 0.5 m, then 1.6 m/s (at least 0.5 m);
  // the world's speed bound (0.16 m/s, worlds/human.yaml's) plays no part, and hidden space grows at the hand's speed.
  const double inf = std::numeric_limits<double>::infinity();
  mps::SensedMarginRule rule;
  rule.safety = mps::Safety::kSsm;
  rule.speed_bound = 0.16;
  rule.iso.intrusion = 0.048;
  rule.uncertainty = 0.01;
  rule.latency = 0.03;
  rule.plan_horizon = 1.0;
  rule.max_age = 1.0;
  rule.max_margin = 1.0;
  EXPECT_DOUBLE_EQ(rule.speed(), 2.0);
  mps::SensedMargins m;
  std::string why;
  ASSERT_TRUE(rule.compute(0.033, 0.05, &m, &why)) << why;
  EXPECT_TRUE(m.hold_when_threatened);  // ssm: a threatened robot holds still
  EXPECT_NEAR(m.start, 2.0 * 0.063 + 0.048 + 0.01, 1e-12);
  EXPECT_NEAR(m.end, 2.0 * 0.113 + 0.048 + 0.01, 1e-12);  // 0.284 m: within reach, the hand's speed
  EXPECT_EQ(m.plan, inf);                                 // 1.6 x 1.063 + C: beyond max_margin, no plan
  ASSERT_TRUE(rule.compute(0.2, 0.05, &m, &why)) << why;  // 2.0 x 0.28 + C = 0.608 > 0.5: the body's speed,
  EXPECT_NEAR(m.end, 0.5 + 0.01, 1e-12);                  // 1.6 x 0.28 + C = 0.496: at least 0.5
  ASSERT_TRUE(rule.compute(0.3, 0.05, &m, &why)) << why;
  EXPECT_NEAR(m.end, 1.6 * 0.38 + 0.048 + 0.01, 1e-12);
  EXPECT_FALSE(rule.compute(0.6, 0.05, &m, &why));  // 1.6 x 0.68 + C > 1 m
  EXPECT_NE(why.find("ISO 13855"), std::string::npos) << why;
  // Margins never shrink with time (the path is checked at the end's margin: a monotone rule suffices).
  double last = 0.0;
  for (double t = 0.0; t < 0.6; t += 0.001) {
    EXPECT_GE(rule.reach(t), last - 1e-12) << t;
    last = rule.reach(t);
  }
  // The map reaches as far as the widest check: the checker's largest margin (a plan at the oldest map).
  EXPECT_DOUBLE_EQ(rule.largestMargin(0.02), mps::FclCollisionChecker::kMaxMargin + 0.04);
  rule.max_age = inf;
  EXPECT_DOUBLE_EQ(rule.largestMargin(0.02), mps::FclCollisionChecker::kMaxMargin + 0.04);
  EXPECT_EQ(rule.problem(), "");
  rule.uncertainty = -0.01;
  EXPECT_NE(rule.problem(), "");
  rule.safety = mps::Safety::kSeparation;  // (the ssm terms do not matter then)
  EXPECT_EQ(rule.problem(), "");
  EXPECT_DOUBLE_EQ(rule.speed(), 0.16);
  mps::Safety safety = mps::Safety::kSeparation;
  EXPECT_TRUE(mps::parseSafety("ssm", &safety));
  EXPECT_EQ(safety, mps::Safety::kSsm);
  EXPECT_FALSE(mps::parseSafety("SSM", &safety));
  EXPECT_EQ(mps::safetyNames(), "separation, ssm");
}

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}

TEST(OccupancyMap, MissesToClampFreeCountsTheViewsThatFillTheMap) {
  // A cell seen free in view after view: at clamp_min after missesToClampFree() views, and not one view earlier (each
  // of those views still changes it). From unknown_occupied's prior, and from unknown.
  for (bool unknown_occupied : {true, false}) {
    mps::OccupancyMapOptions o = mps::panda::mapOptions();
    o.bounds = Eigen::AlignedBox3d(Eigen::Vector3d(-1.0, -1.0, -0.2), Eigen::Vector3d(1.0, 1.0, 1.0));
    o.unknown_occupied = unknown_occupied;
    std::string error;
    auto map = mps::OccupancyMap::create(o, &error);
    ASSERT_TRUE(map) << error;
    const int views = map->missesToClampFree();
    ASSERT_GE(views, 2) << "the shipped log-odds take more than one miss to clamp_min";
    const float clamp_min = static_cast<float>(std::log(o.clamp_min / (1.0 - o.clamp_min)));
    const Eigen::Vector3d origin(0.4, 0.0, 0.99), free_cell(0.41, 0.01, 0.51);  // on the beams to the floor
    const auto floor = plane(0.0, 0.8, -0.4, 0.4, 0.0, 0.01);
    for (int k = 1; k <= views; ++k) {
      integrate(map.get(), floor, origin);
      const float v = map->logOdds(free_cell);
      if (k < views) {
        EXPECT_GT(v, clamp_min) << "view " << k << " of " << views << ", unknown_occupied " << unknown_occupied;
      } else {
        EXPECT_FLOAT_EQ(v, clamp_min) << "unknown_occupied " << unknown_occupied;
      }
    }
  }
}
