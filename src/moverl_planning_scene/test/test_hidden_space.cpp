/**
 * \file test_hidden_space.cpp
 * \brief The occupancy map's hidden space (OccupancyMapOptions::hidden_space, issue 52), without a roscore: free
 *        space that no camera sees stops counting as free once something moving at the speed bound could have come
 *        there from a possibly-occupied cell, and not before; a cell seen again is free at once; a hidden region far
 *        from everything stays free; a second map fed the same updates later is the same map.
 *
 * The scene: a camera at the origin looking along +x at a wall at x = 1.5 (hit: possibly occupied, with the unknown
 * space behind it). Its first views see the space before the wall free. Then the robot stands at x = 0.5 in front of
 * the camera's centre (robot pixels: they see nothing free and hide nothing beside them): the cone behind it, down to
 * the wall, is hidden. Only the wall can send anything into the cone (its sides are seen free every view), so a cell
 * of the cone (L - 1) cells from the wall turns possibly occupied once speed_bound x (time since it was last seen) has
 * passed (L - 1) x resolution.
 */
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "moverl_planning_scene/occupancy_map.h"
#include "moverl_planning_scene/pinhole_camera.h"
#include "panda_support.h"

namespace mps = moverl_planning_scene;

namespace {

// Dense enough that every cell before the wall is crossed by some pixel's ray (1.5 cm apart at the wall).
const mps::PinholeCamera kCamera{160, 120, 100.0, 104.0, 79.5, 59.5};
constexpr double kRes = 0.02, kWall = 1.5, kRobotDepth = 0.5, kSpeed = 0.1, kPeriod = 0.1;

Eigen::Isometry3d lookingAlongX() {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear().col(0) = -Eigen::Vector3d::UnitY();
  pose.linear().col(1) = -Eigen::Vector3d::UnitZ();
  pose.linear().col(2) = Eigen::Vector3d::UnitX();
  return pose;
}

/// The robot's pixels: a square in the image's centre (about 0.1 x 0.1 m at x = 0.5).
bool robotPixel(int u, int v) { return u >= 70 && u <= 89 && v >= 50 && v <= 69; }

std::unique_ptr<mps::OccupancyMap> makeMap(double speed = kSpeed, bool skip_unchanged_blocks = true,
                                           double watch_time = 1.0, bool integrates = true) {
  mps::OccupancyMapOptions o = mps::panda::mapOptions();
  o.resolution = kRes;
  o.max_range = 3.0;
  o.bounds = Eigen::AlignedBox3d(Eigen::Vector3d(-0.5, -1.0, -1.0), Eigen::Vector3d(2.5, 1.0, 1.0));
  o.unknown_occupied = true;
  o.skip_unchanged_blocks = skip_unchanged_blocks;
  o.hidden_space = true;
  o.speed_bound = speed;
  o.watch_time = watch_time;
  o.integrates = integrates;
  std::string error;
  auto m = mps::OccupancyMap::create(o, &error);
  EXPECT_TRUE(m) << error;
  return m;
}

/// One camera's view of the wall, with the robot in front of it or not: the update, computed on `map`.
void view(mps::OccupancyMap* map, bool robot, mps::MapUpdate* u) {
  const Eigen::Isometry3d pose = lookingAlongX();
  std::vector<Eigen::Vector3d> points;
  std::vector<std::uint8_t> mask;
  std::vector<float> depth;
  std::vector<std::uint8_t> pixel_mask;
  for (int v = 0; v < kCamera.height; ++v) {
    for (int uu = 0; uu < kCamera.width; ++uu) {
      const bool on_robot = robot && robotPixel(uu, v);
      const double z = on_robot ? kRobotDepth : kWall;
      points.push_back(pose *
                       Eigen::Vector3d((uu - kCamera.cx) / kCamera.fx * z, (v - kCamera.cy) / kCamera.fy * z, z));
      mask.push_back(on_robot ? mps::kPointOnRobot : mps::kPointObstacle);
      depth.push_back(static_cast<float>(z));
      pixel_mask.push_back(on_robot ? mps::kPointOnRobot : mps::kPointObstacle);
    }
  }
  map->computeUpdateProjective(points, mask, depth, pixel_mask, kCamera, pose, u);
}

/// A batch of one view stamped `stamp` on `map`, every update also handed to `log` (for a second map).
void batch(mps::OccupancyMap* map, double stamp, bool robot, std::vector<mps::MapUpdate>* log = nullptr,
           mps::BatchStats* stats = nullptr) {
  mps::MapUpdate close;
  if (map->beginView(stamp, &close)) {
    map->apply(close);
    if (log != nullptr) log->push_back(close);
  }
  mps::MapUpdate u;
  view(map, robot, &u);
  map->apply(u);
  if (log != nullptr) log->push_back(u);
  ASSERT_TRUE(map->closeBatch(&close, stats));
  map->apply(close);
  if (log != nullptr) log->push_back(close);
}

/// A point on the camera's axis, in the cone the robot hides, `cells` cells in front of the wall's first cell.
Eigen::Vector3d axis(int cells) { return {(std::floor(kWall / kRes) - cells + 0.5) * kRes, 0.01, 0.01}; }

}  // namespace

TEST(HiddenSpace, AHiddenCellTurnsPossiblyOccupiedOnceSomethingCouldHaveComeAndNotBefore) {
  auto map = makeMap();
  double t = 0.0;
  for (int k = 0; k < 3; ++k, t += kPeriod) batch(map.get(), t, false);  // seen free, view after view
  const double last_seen = t - kPeriod;
  for (int cells : {1, 3, 8, 20}) {
    EXPECT_TRUE(map->observed(axis(cells)));
    EXPECT_FALSE(map->occupied(axis(cells))) << cells;
  }
  EXPECT_TRUE(map->occupied(Eigen::Vector3d(kWall + 0.01, 0.01, 0.01)));  // the wall
  // The robot steps in front of the camera: the cone behind it is hidden from now on.
  std::vector<double> turned(25, -1.0);
  for (; t < last_seen + 1.2 - 1e-9; t += kPeriod) {
    mps::BatchStats stats;
    batch(map.get(), t, true, nullptr, &stats);
    EXPECT_GT(stats.hidden, 0u);
    for (int cells = 1; cells < 25; ++cells) {
      if (turned[cells] < 0.0 && map->stale(axis(cells))) turned[cells] = t;
      EXPECT_EQ(map->stale(axis(cells)), map->occupied(axis(cells))) << cells << " at " << t;
    }
  }
  // A cell `cells` grid steps before the wall's first (Chebyshev L = cells) is (L - 1) x resolution from it at least:
  // something coming from the wall at kSpeed needs that long after the cell was last seen free. It turns at the first
  // batch after then, never before (the one next to the wall at once).
  for (int cells : {1, 2, 3, 5}) {
    const double may_come = last_seen + (cells - 1) * kRes / kSpeed;
    ASSERT_GE(turned[cells], 0.0) << "the cell " << cells << " cells from the wall never turned";
    EXPECT_GT(turned[cells], may_come - 1e-9) << cells;
    EXPECT_LE(turned[cells], may_come + kPeriod + 1e-9) << cells;
  }
  // The nearest to the wall went first; the ones near the robot are still free (nothing could have come so far).
  EXPECT_LE(turned[1], turned[3]);
  EXPECT_LE(turned[3], turned[5]);
  for (int cells : {20, 24}) {
    EXPECT_LT(turned[cells], 0.0) << cells;
    EXPECT_FALSE(map->occupied(axis(cells))) << cells;
  }
  EXPECT_GT(map->staleCount(), 0u);
  // The robot steps away: the camera sees the cone again, and every cell of it is free at once.
  batch(map.get(), t, false);
  for (int cells = 1; cells < 25; ++cells) {
    EXPECT_FALSE(map->stale(axis(cells))) << cells;
    EXPECT_FALSE(map->occupied(axis(cells))) << cells;
  }
}

TEST(HiddenSpace, WithoutASpeedBoundHiddenSpaceStaysFree) {
  auto map = makeMap(0.0);
  double t = 0.0;
  for (int k = 0; k < 3; ++k, t += kPeriod) batch(map.get(), t, false);
  for (int k = 0; k < 12; ++k, t += kPeriod) batch(map.get(), t, true);
  EXPECT_EQ(map->staleCount(), 0u);
  EXPECT_FALSE(map->occupied(axis(1)));
}

TEST(HiddenSpace, ABatchLaterThanTheWatchCoversForgetsEveryFreeCell) {
  auto map = makeMap(kSpeed, true, 0.5);
  batch(map.get(), 0.0, false);
  batch(map.get(), 0.1, false);
  EXPECT_FALSE(map->occupied(axis(20)));
  mps::BatchStats stats;
  batch(map.get(), 0.1 + 0.6, true, nullptr, &stats);  // the camera stopped for 0.6 s > watch_time
  EXPECT_TRUE(stats.forget);
  EXPECT_TRUE(map->occupied(axis(20)));  // hidden now, and not known free
  EXPECT_TRUE(map->stale(axis(20)));
  EXPECT_TRUE(map->stale(Eigen::Vector3d(0.6, 0.3, 0.01)));  // nothing is known free after the gap
  batch(map.get(), 0.8, true);                               // the next view sees it free again
  EXPECT_FALSE(map->occupied(Eigen::Vector3d(0.6, 0.3, 0.01)));
  EXPECT_TRUE(map->stale(axis(20)));  // what it does not see stays possibly occupied
}

TEST(HiddenSpace, ABatchLaterThanItsWatchCoversStaysSoundAndWidensTheWatch) {
  // The watch is sized by the longest of the last batches' intervals (a quarter more). A batch later than that: the
  // views did not look at every cell something may have reached, so its close counts the free cells they did not look
  // at as hidden; then the watch covers the longer interval.
  constexpr double kFast = 1.0;  // m/s: 0.125 s lets something come 7 cells (6.25 + 1), 0.25 s 13
  auto map = makeMap(kFast);
  double t = 0.0;
  for (int k = 0; k < 10; ++k, t += kPeriod) batch(map.get(), t, false);  // (eight intervals of 0.1 s and more)
  EXPECT_EQ(map->watchCells(), 7);
  // The robot steps in front of the camera, and its view comes 0.2 s after the last one: something may have come 11
  // cells, farther than the views looked.
  const double last_seen = t - kPeriod, late = last_seen + 0.2;
  batch(map.get(), late, true);
  EXPECT_EQ(map->watchCells(), 13);
  // Where something from the wall could have come within 0.2 s has turned possibly occupied ((L - 1) x resolution <=
  // 0.2 m from the wall's first cell), and the cells it could not have reached stay free (0.6 and 0.8 m from the wall,
  // 0.4 m and more from the view's edges, where unseen space begins).
  for (int cells = 1; cells <= 10; ++cells) EXPECT_TRUE(map->stale(axis(cells))) << cells;
  for (int cells : {30, 40}) {
    EXPECT_FALSE(map->stale(axis(cells))) << cells;
    EXPECT_FALSE(map->occupied(axis(cells))) << cells;
  }
  for (t = late + kPeriod; t < last_seen + 0.45; t += kPeriod) batch(map.get(), t, true);
  EXPECT_TRUE(map->stale(axis(20)));  // (19 x 0.02 m within 0.4 s)
}

TEST(HiddenSpace, ABatchLaterThanTheWatchHasItWidenedBeforeItsViewsAndTurnsNothingTheySawStale) {
  // The integrator skips instants: a batch 0.2 s after the last, when the watch covers 0.125 s. Its views see the whole
  // cone free (no robot in front): with the watch widened before them (beginView), they look at every cell something
  // could have reached, and the close turns none of them stale. Were the watch not widened, the close would count the
  // free cells 8-11 cells from the view's edges (looked at by no view) as hidden.
  constexpr double kFast = 1.0;
  for (bool open_by_next_view : {false, true}) {
    SCOPED_TRACE(open_by_next_view ? "closed by the next instant's first view" : "closed by its last view");
    auto map = makeMap(kFast);
    double t = 0.0;
    for (int k = 0; k < 10; ++k, t += kPeriod) batch(map.get(), t, false);
    ASSERT_EQ(map->watchCells(), 7);
    const double late = t - kPeriod + 0.2;
    mps::BatchStats stats;
    if (!open_by_next_view) {
      batch(map.get(), late, false, nullptr, &stats);
    } else {
      // A view of the last instant opens a batch that the late batch's first view closes (path of the node).
      mps::MapUpdate close, u;
      ASSERT_FALSE(map->beginView(late - 0.2 + 1e-3, &close));  // (stamped after the map's time: a batch of its own)
      view(map.get(), false, &u);
      map->apply(u);
      ASSERT_TRUE(map->beginView(late + 1e-3, &close, nullptr, &stats));
      EXPECT_FALSE(stats.beyond_watch);
      map->apply(close);  // the watch widens here, before the late batch's view
      view(map.get(), false, &u);
      map->apply(u);
      ASSERT_TRUE(map->closeBatch(&close, &stats));
      map->apply(close);
    }
    EXPECT_EQ(map->watchesAhead(), 1u);
    EXPECT_FALSE(stats.beyond_watch);
    EXPECT_FALSE(stats.forget);
    EXPECT_EQ(stats.stale, 0u);
    EXPECT_EQ(map->staleCount(), 0u);
    EXPECT_EQ(map->watchCells(), 13);  // (then the history's 0.2 s x 1.25)
  }
}

TEST(HiddenSpace, ALateViewSeesNothingFreeThatWasPossiblyOccupied) {
  auto map = makeMap();
  batch(map.get(), 0.0, false);
  batch(map.get(), 0.1, false);
  for (double t = 0.2; t < 1.0; t += kPeriod) batch(map.get(), t, true);
  ASSERT_TRUE(map->stale(axis(1)));
  // A view stamped before the map's time (it came late) shows the cone free: it may have been entered since.
  mps::MapUpdate close, u;
  EXPECT_FALSE(map->beginView(0.5, &close));
  view(map.get(), false, &u);
  EXPECT_TRUE(u.late);
  map->apply(u);
  EXPECT_TRUE(map->stale(axis(1)));
  EXPECT_TRUE(map->occupied(axis(1)));
}

TEST(HiddenSpace, ASecondMapFedTheSameUpdatesLaterIsTheSameMap) {
  // octomap/lockstep_lag: the checks' map gets the integrated map's updates later, in their order.
  auto map = makeMap(), second = makeMap(kSpeed, true, 1.0, /*integrates=*/false);  // as the node makes it
  std::vector<mps::MapUpdate> log;
  double t = 0.0;
  for (int k = 0; k < 3; ++k, t += kPeriod) batch(map.get(), t, false, &log);
  for (int k = 0; k < 8; ++k, t += kPeriod) batch(map.get(), t, true, &log);
  batch(map.get(), t, false, &log);
  t += kPeriod;
  for (int k = 0; k < 4; ++k, t += kPeriod) batch(map.get(), t, true, &log);
  for (const auto& u : log) second->apply(u);
  ASSERT_GT(map->staleCount(), 0u);
  EXPECT_EQ(second->staleCount(), map->staleCount());
  EXPECT_EQ(second->occupiedLeafCount(), map->occupiedLeafCount());
  EXPECT_EQ(second->unobservedCount(), map->unobservedCount());
  EXPECT_EQ(second->mapTime(), map->mapTime());
  for (double x = -0.49; x < 2.5; x += kRes) {
    for (double y = -0.39; y < 0.4; y += 2 * kRes) {
      const Eigen::Vector3d p(x, y, 0.01);
      ASSERT_EQ(second->occupied(p), map->occupied(p)) << p.transpose();
      ASSERT_EQ(second->stale(p), map->stale(p)) << p.transpose();
    }
  }
}

TEST(HiddenSpace, SkippingUnchangedBlocksGivesTheSameMap) {
  // The watched cells are looked at in every view, by a block repeated from the camera's last view as by one
  // evaluated afresh: the same cells turn possibly occupied.
  auto skip = makeMap(kSpeed, true), every = makeMap(kSpeed, false);
  double t = 0.0;
  for (int k = 0; k < 14; ++k, t += kPeriod) {
    const bool robot = k >= 3 && k != 9;
    batch(skip.get(), t, robot);
    batch(every.get(), t, robot);
    ASSERT_EQ(skip->staleCount(), every->staleCount()) << "batch " << k;
    ASSERT_EQ(skip->occupiedLeafCount(), every->occupiedLeafCount()) << "batch " << k;
  }
  EXPECT_GT(skip->staleCount(), 0u);
}

TEST(HiddenSpace, NothingReachesHiddenSpaceThroughASolidObject) {
  // A slab wholly inside a static object (solid cells: a table top) stands between the wall and the hidden cone, two
  // to three cells before the wall and wide beyond the cone: something coming from the wall must go around it. The
  // cell behind the slab turns later than the same cell without it; the cells between the wall and the slab do not.
  auto turned_at = [](bool slab) {
    auto map = makeMap();
    if (slab) {
      std::vector<Eigen::Vector3d> centres;
      std::vector<std::uint64_t> keys;
      const double x0 = (std::floor(kWall / kRes) - 3) * kRes, x1 = (std::floor(kWall / kRes) - 1) * kRes;
      map->cellsIn(Eigen::AlignedBox3d(Eigen::Vector3d(x0, -0.4, -0.4), Eigen::Vector3d(x1, 0.4, 0.4)), &centres,
                   &keys);
      map->setSolid(keys);
    }
    double t = 0.0;
    for (int k = 0; k < 3; ++k, t += kPeriod) batch(map.get(), t, false);
    std::vector<double> turned(8, -1.0);
    for (; t < 2.0; t += kPeriod) {
      batch(map.get(), t, true);
      for (int cells = 1; cells < 8; ++cells) {
        if (turned[cells] < 0.0 && map->stale(axis(cells))) turned[cells] = t;
      }
    }
    return turned;
  };
  const std::vector<double> open = turned_at(false), blocked = turned_at(true);
  EXPECT_DOUBLE_EQ(blocked[1], open[1]);  // between the wall and the slab: as before
  EXPECT_LT(blocked[2], 0.0);             // the slab's cells: nothing can be in them, ever
  EXPECT_LT(blocked[3], 0.0);
  ASSERT_GE(open[4], 0.0);
  EXPECT_TRUE(blocked[4] < 0.0 || blocked[4] > open[4] + 1e-9) << open[4] << " " << blocked[4];  // behind it: later
}
