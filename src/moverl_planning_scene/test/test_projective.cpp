/**
 * \file test_projective.cpp
 * \brief The pinhole fit of organized clouds and the map's projective integration (octomap/integration: projective),
 *        without a roscore: what it sees free, what it does not, and where it falls back to ray casting.
 */
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <set>
#include <stdexcept>

#include "moverl_planning_scene/cloud_integrator.h"
#include "moverl_planning_scene/occupancy_map.h"
#include "moverl_planning_scene/pinhole_camera.h"
#include "moverl_planning_scene/worker_pool.h"
#include "panda_support.h"

namespace mps = moverl_planning_scene;

namespace {

const mps::PinholeCamera kCamera{80, 60, 50.0, 52.0, 39.5, 29.5};

/// An optical frame at `origin` looking along +x of the map (optical z = map x, optical x = map -y, y = map -z).
Eigen::Isometry3d lookingAlongX(const Eigen::Vector3d& origin) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear().col(0) = -Eigen::Vector3d::UnitY();
  pose.linear().col(1) = -Eigen::Vector3d::UnitZ();
  pose.linear().col(2) = Eigen::Vector3d::UnitX();
  pose.translation() = origin;
  return pose;
}

/// An organized cloud (optical frame, x y z per pixel) whose pixel (u, v) sees depth depth(u, v).
template <class Depth>
std::vector<float> image(const mps::PinholeCamera& c, Depth depth) {
  std::vector<float> xyz;
  for (int v = 0; v < c.height; ++v) {
    for (int u = 0; u < c.width; ++u) {
      const double z = depth(u, v);
      xyz.push_back(static_cast<float>((u - c.cx) / c.fx * z));
      xyz.push_back(static_cast<float>((v - c.cy) / c.fy * z));
      xyz.push_back(static_cast<float>(z));
    }
  }
  return xyz;
}

/// Depth of the ray of pixel (u, v) to a sphere (optical frame) or to a far wall at depth `wall`.
double sphereOrWall(const mps::PinholeCamera& c, int u, int v, const Eigen::Vector3d& centre, double radius,
                    double wall) {
  const Eigen::Vector3d d((u - c.cx) / c.fx, (v - c.cy) / c.fy, 1.0);
  const double a = d.squaredNorm(), b = -2.0 * d.dot(centre), k = centre.squaredNorm() - radius * radius;
  const double disc = b * b - 4 * a * k;
  if (disc < 0) return wall;
  const double s = (-b - std::sqrt(disc)) / (2 * a);  // the depth (d has z = 1)
  return s > 0 && s < wall ? s : wall;
}

std::unique_ptr<mps::OccupancyMap> makeMap(bool unknown_occupied = false, bool skip_unchanged_blocks = true) {
  mps::OccupancyMapOptions o = mps::panda::mapOptions();
  o.resolution = 0.02;
  o.max_range = 3.0;
  o.bounds = Eigen::AlignedBox3d(Eigen::Vector3d(-0.5, -1.0, -1.0), Eigen::Vector3d(2.5, 1.0, 1.0));
  o.unknown_occupied = unknown_occupied;
  o.skip_unchanged_blocks = skip_unchanged_blocks;
  std::string error;
  auto m = mps::OccupancyMap::create(o, &error);
  EXPECT_TRUE(m) << error;
  return m;
}

/// The map-frame points of an organized optical-frame cloud (the ones with a return).
std::vector<Eigen::Vector3d> mapPoints(const std::vector<float>& xyz, const Eigen::Isometry3d& pose) {
  std::vector<Eigen::Vector3d> pts;
  for (std::size_t k = 0; k + 2 < xyz.size(); k += 3) {
    if (std::isfinite(xyz[k]) && std::isfinite(xyz[k + 1]) && std::isfinite(xyz[k + 2])) {
      pts.push_back(pose * Eigen::Vector3d(xyz[k], xyz[k + 1], xyz[k + 2]));
    }
  }
  return pts;
}

std::vector<float> depths(const std::vector<float>& xyz) {
  std::vector<float> z;
  for (std::size_t k = 2; k < xyz.size(); k += 3) z.push_back(xyz[k]);
  return z;
}

}  // namespace

TEST(Pinhole, FitsAnOrganizedCloudAndItsHoles) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> z(0.3, 3.0);
  auto xyz = image(kCamera, [&](int, int) { return z(rng); });
  for (std::size_t k = 0; k < xyz.size(); k += 21) xyz[k] = std::numeric_limits<float>::quiet_NaN();  // no returns
  for (std::size_t k = 10; k < xyz.size(); k += 37) xyz[k] = std::numeric_limits<float>::infinity();  // nor these
  mps::PinholeCamera fit;
  double residual = 0.0;
  std::string why;
  ASSERT_TRUE(mps::fitPinhole(xyz.data(), kCamera.width, kCamera.height, 1, 0.05, &fit, &residual, &why)) << why;
  EXPECT_NEAR(fit.fx, kCamera.fx, 1e-3);
  EXPECT_NEAR(fit.fy, kCamera.fy, 1e-3);
  EXPECT_NEAR(fit.cx, kCamera.cx, 1e-3);
  EXPECT_NEAR(fit.cy, kCamera.cy, 1e-3);
  EXPECT_LT(residual, 1e-3);
  EXPECT_TRUE(mps::fitPinhole(xyz.data(), kCamera.width, kCamera.height, 3, 0.05, &fit, &residual, &why)) << why;
}

TEST(Pinhole, RefusesWhatIsNotAPinholeImage) {
  mps::PinholeCamera fit;
  double residual = 0.0;
  std::string why;
  // Radial distortion of 0.3 px at the corners: not rectified.
  auto distorted = image(kCamera, [](int, int) { return 1.0; });
  for (std::size_t k = 0; k < distorted.size(); k += 3) {
    const double r2 = (distorted[k] * distorted[k] + distorted[k + 1] * distorted[k + 1]);
    distorted[k] *= static_cast<float>(1.0 + 0.02 * r2);
    distorted[k + 1] *= static_cast<float>(1.0 + 0.02 * r2);
  }
  EXPECT_FALSE(mps::fitPinhole(distorted.data(), kCamera.width, kCamera.height, 1, 0.05, &fit, &residual, &why));
  EXPECT_NE(why.find("px"), std::string::npos) << why;
  // A cloud in a frame whose z is not the view direction (a camera_link frame, x forward).
  auto turned = image(kCamera, [](int, int) { return 1.0; });
  for (std::size_t k = 0; k < turned.size(); k += 3) std::swap(turned[k], turned[k + 2]);
  EXPECT_FALSE(mps::fitPinhole(turned.data(), kCamera.width, kCamera.height, 1, 0.05, &fit, &residual, &why));
  // An unorganized cloud, and one without returns.
  EXPECT_FALSE(mps::fitPinhole(turned.data(), 4800, 1, 1, 0.05, &fit, &residual, &why));
  std::vector<float> none(3 * 80 * 60, std::numeric_limits<float>::quiet_NaN());
  EXPECT_FALSE(mps::fitPinhole(none.data(), 80, 60, 1, 0.05, &fit, &residual, &why));
  EXPECT_NE(why.find("too few"), std::string::npos) << why;
  // An image wider than the projective update keeps pixel rectangles for (a pinhole image otherwise).
  const mps::PinholeCamera wide{mps::kMaxPinholeSide + 1, 2, 1000.0, 1000.0, mps::kMaxPinholeSide / 2.0, 0.5};
  EXPECT_FALSE(mps::fitPinhole(image(wide, [](int, int) { return 1.0; }).data(), wide.width, wide.height, 1, 0.05, &fit,
                               &residual, &why));
  EXPECT_NE(why.find(std::to_string(mps::kMaxPinholeSide)), std::string::npos) << why;
}

TEST(Projective, SeesFreeWhatLiesBeforeAWallAndNothingBehindIt) {
  auto map = makeMap();
  const Eigen::Isometry3d pose = lookingAlongX(Eigen::Vector3d(0.0, 0.0, 0.0));
  const auto xyz = image(kCamera, [](int, int) { return 1.5; });  // a wall at x = 1.5
  mps::MapUpdate u;
  map->computeUpdateProjective(mapPoints(xyz, pose), {}, depths(xyz), {}, kCamera, pose, &u);
  map->apply(u);
  EXPECT_GT(u.stats.hit_cells, 0u);
  EXPECT_TRUE(map->occupied(Eigen::Vector3d(1.51, 0.0, 0.0)));  // the wall's cell
  for (double x : {0.3, 0.7, 1.1, 1.45}) {
    EXPECT_TRUE(map->observed(Eigen::Vector3d(x, 0.01, 0.01))) << x;
    EXPECT_FALSE(map->occupied(Eigen::Vector3d(x, 0.01, 0.01))) << x;
  }
  EXPECT_FALSE(map->observed(Eigen::Vector3d(1.7, 0.01, 0.01)));  // behind the wall: unknown
  EXPECT_FALSE(map->observed(Eigen::Vector3d(0.5, 0.9, 0.01)));   // outside the view (half angle ~38 deg)
}

TEST(Projective, TheLayerRestingOnAFixtureIsSeenFreeAgainOnceWhatLayThereLeft) {
  // A fixture's top (a table at z = -0.2, a cell boundary) seen obliquely, its points 0.1 mm inside it (the camera's
  // depth error): they end in the fixture's own cells, none in the layer resting on it (z -0.2 to -0.18), and
  // projection never sees that layer free (the pixels just below a cell's see the fixture in front of its far
  // corner). A hand lay in the layer (hit); then only the fixture is seen. With fixture_pullback (the scene sets it
  // to octomap/static_filter_padding) the fixture's points end 3 mm before themselves toward the camera, in the layer:
  // seen down to the surface, free again. Without it the layer stays occupied for good.
  const double top = -0.2001, far = 3.5;
  auto table = [&](int, int v) {
    const double z = v > kCamera.cy ? -top * kCamera.fy / (v - kCamera.cy) : far;
    return z < 2.9 ? z : far;
  };
  const auto xyz = image(kCamera, table);
  const Eigen::Isometry3d pose = lookingAlongX(Eigen::Vector3d(0.0, 0.0, 0.0));
  const std::vector<Eigen::Vector3d> points = mapPoints(xyz, pose);
  const std::vector<std::uint8_t> fixture(points.size(), mps::kPointOnFixture);
  const Eigen::Vector3d layer(0.99, 0.01, -0.19);  // (pixel 39, 40 sees the table at x 0.991, y 0.0099)
  for (double pullback : {0.0, 0.003}) {
    SCOPED_TRACE(pullback);
    mps::OccupancyMapOptions o = mps::panda::mapOptions();
    o.resolution = 0.02;
    o.max_range = 3.0;
    o.bounds = Eigen::AlignedBox3d(Eigen::Vector3d(-0.5, -1.0, -1.0), Eigen::Vector3d(2.5, 1.0, 1.0));
    o.fixture_pullback = pullback;
    std::string error;
    auto map = mps::OccupancyMap::create(o, &error);
    ASSERT_TRUE(map) << error;
    {  // the hand in the layer
      std::vector<Eigen::Vector3d> with_hand = points;
      std::vector<std::uint8_t> mask = fixture;
      with_hand.push_back(layer);
      mask.push_back(mps::kPointObstacle);
      mps::MapUpdate u;
      map->computeUpdateProjective(with_hand, mask, depths(xyz), {}, kCamera, pose, &u);
      map->apply(u);
      ASSERT_TRUE(map->occupied(layer));
    }
    for (int k = 0; k < 6; ++k) {  // then the table alone
      mps::MapUpdate u;
      map->computeUpdateProjective(points, fixture, depths(xyz), {}, kCamera, pose, &u);
      map->apply(u);
    }
    EXPECT_EQ(map->occupied(layer), pullback == 0.0);
    EXPECT_FALSE(map->occupied(layer + Eigen::Vector3d(0.0, 0.0, 0.06)));  // above it: seen free either way
  }
  mps::OccupancyMapOptions o = mps::panda::mapOptions();
  o.resolution = 0.02;
  o.max_range = 3.0;
  o.bounds = Eigen::AlignedBox3d(Eigen::Vector3d(-0.5, -1.0, -1.0), Eigen::Vector3d(2.5, 1.0, 1.0));
  o.fixture_pullback = 0.02;
  std::string error;
  EXPECT_FALSE(mps::OccupancyMap::create(o, &error));  // a pullback of a cell or more is refused
  EXPECT_NE(error.find("fixture_pullback"), std::string::npos) << error;
}

TEST(Projective, AHitCellOrAFixturesEndCellIsNotSeenFreeByTheProjectionToo) {
  // A wall at x = 1.5 in every pixel; besides its points, an obstacle's point and a fixture's point in front of it,
  // on rays that see past them (the depths say free there). The obstacle's cell is hit and stays so (occupied wins);
  // the fixture's cell is seen free once, as where only a fixture's points end; no cell is in the update twice.
  auto map = makeMap();
  const Eigen::Isometry3d pose = lookingAlongX(Eigen::Vector3d(0.0, 0.0, 0.0));
  const auto xyz = image(kCamera, [](int, int) { return 1.5; });
  std::vector<Eigen::Vector3d> points = mapPoints(xyz, pose);
  std::vector<std::uint8_t> mask(points.size(), mps::kPointObstacle);
  const Eigen::Vector3d obstacle(0.71, 0.01, 0.01), fixture(0.91, 0.01, 0.01);
  points.push_back(obstacle);
  mask.push_back(mps::kPointObstacle);
  points.push_back(fixture);
  mask.push_back(mps::kPointOnFixture);
  mps::MapUpdate u;
  map->computeUpdateProjective(points, mask, depths(xyz), {}, kCamera, pose, &u);
  auto cells_at = [&](const std::vector<std::uint64_t>& keys, const Eigen::Vector3d& p) {
    return std::count_if(keys.begin(), keys.end(), [&](std::uint64_t key) {
      return (map->cellCentre(key) - p).cwiseAbs().maxCoeff() < 0.01;  // p's cell (resolution 0.02)
    });
  };
  EXPECT_EQ(cells_at(u.hits, obstacle), 1);
  EXPECT_EQ(cells_at(u.misses, obstacle), 0);
  EXPECT_EQ(cells_at(u.hits, fixture), 0);
  EXPECT_EQ(cells_at(u.misses, fixture), 1);
  EXPECT_GT(cells_at(u.misses, Eigen::Vector3d(0.81, 0.01, 0.01)), 0);  // between them: seen free
  std::set<std::uint64_t> once(u.hits.begin(), u.hits.end());
  once.insert(u.misses.begin(), u.misses.end());
  EXPECT_EQ(once.size(), u.hits.size() + u.misses.size());
  EXPECT_EQ(u.stats.free_cells, u.misses.size());  // a fresh map: every cell seen free changes
}

TEST(Projective, ACellClampedFreeIsNotLookedAtAgain) {
  // The same wall, view after view: the cells before it clamp free, and from then on an update sees none of them
  // (stats.free_cells counts the cells not yet clamped free only), with the camera's last view repeated or without.
  for (bool skip : {false, true}) {
    auto map = makeMap(false, skip);
    const Eigen::Isometry3d pose = lookingAlongX(Eigen::Vector3d(0.0, 0.0, 0.0));
    const auto xyz = image(kCamera, [](int, int) { return 1.5; });
    mps::MapUpdate u;
    for (int view = 0; view < 12; ++view) {
      map->computeUpdateProjective(mapPoints(xyz, pose), {}, depths(xyz), {}, kCamera, pose, &u);
      if (view == 0) EXPECT_GT(u.stats.free_cells, 1000u);
      map->apply(u);
    }
    EXPECT_EQ(u.stats.free_cells, 0u) << "skip_unchanged_blocks " << skip;
    EXPECT_TRUE(u.misses.empty()) << "skip_unchanged_blocks " << skip;
    EXPECT_FALSE(map->occupied(Eigen::Vector3d(1.1, 0.01, 0.01)));
  }
}

TEST(Projective, PixelsWithoutAReturnSeeNothingFree) {
  auto map = makeMap();
  const Eigen::Isometry3d pose = lookingAlongX(Eigen::Vector3d(0.0, 0.0, 0.0));
  // The left half of the image has no return (NaN): nothing along it is known.
  auto xyz = image(kCamera, [](int u, int) { return u < 40 ? std::numeric_limits<double>::quiet_NaN() : 1.5; });
  mps::MapUpdate u;
  map->computeUpdateProjective(mapPoints(xyz, pose), {}, depths(xyz), {}, kCamera, pose, &u);
  map->apply(u);
  EXPECT_FALSE(map->observed(Eigen::Vector3d(1.0, 0.3, 0.01)));  // optical x < 0: map +y, the NaN half
  EXPECT_TRUE(map->observed(Eigen::Vector3d(1.0, -0.3, 0.01)));
}

TEST(Projective, BeamsBeyondMaxRangeClearUpToIt) {
  auto map = makeMap();
  const mps::PinholeCamera narrow{160, 120, 400.0, 400.0, 79.5, 59.5};  // 0.25 cm per pixel at 1 m
  const Eigen::Isometry3d pose = lookingAlongX(Eigen::Vector3d(-1.0, 0.0, 0.0));
  const auto xyz = image(narrow, [](int, int) { return 10.0; });  // a far plane beyond max_range (3 m)
  mps::MapUpdate u;
  map->computeUpdateProjective(mapPoints(xyz, pose), {}, depths(xyz), {}, narrow, pose, &u);
  map->apply(u);
  EXPECT_EQ(u.stats.hit_cells, 0u);
  EXPECT_TRUE(map->observed(Eigen::Vector3d(1.7, 0.01, 0.01)));   // 2.7 m away
  EXPECT_FALSE(map->observed(Eigen::Vector3d(2.1, 0.01, 0.01)));  // 3.1 m away: beyond max_range
}

/// Cells whose centre lies inside the ball that one integration sees free, a ball in front of a wall seen from 15
/// places by `camera` (the count over all views).
std::size_t freedInsideBall(const mps::PinholeCamera& camera, bool projective) {
  auto map = makeMap();
  const Eigen::Vector3d ball(1.2, 0.05, -0.03);
  const double radius = 0.15;
  std::size_t freed_inside = 0, free_cells = 0;
  for (double y : {-0.4, -0.2, 0.0, 0.2, 0.4}) {
    for (double z : {-0.3, 0.0, 0.3}) {
      const Eigen::Isometry3d pose = lookingAlongX(Eigen::Vector3d(0.0, y, z));
      const Eigen::Vector3d c = pose.inverse() * ball;
      const auto xyz = image(camera, [&](int u, int v) { return sphereOrWall(camera, u, v, c, radius, 2.2); });
      mps::MapUpdate u;
      if (projective) {
        map->computeUpdateProjective(mapPoints(xyz, pose), {}, depths(xyz), {}, camera, pose, &u);
      } else {
        map->computeUpdate(mapPoints(xyz, pose), {}, pose.translation(), &u);
      }
      for (std::uint64_t key : u.misses) freed_inside += (map->cellCentre(key) - ball).norm() < radius ? 1 : 0;
      free_cells += u.stats.free_cells;
      map->apply(u);
    }
  }
  EXPECT_GT(free_cells, 10000u);
  EXPECT_TRUE(map->occupied(ball + Eigen::Vector3d(-radius + 0.005, 0.0, 0.0)));  // the front of the ball
  return freed_inside;
}

TEST(Projective, SeesFreeLessOfAnObstacleThanRayCasting) {
  // A cell is seen free when the rays that cross it pass it; with pixels as wide as cells a ray may cross a cell's
  // corner beside the ball whose centre lies inside it (neither method can tell; ray casting's beams to the end
  // cells' centroids also graze cells no pixel's ray crosses). With pixels a quarter of a cell wide at the ball,
  // the projective rule sees none of the ball free; at any size it sees less of it free than ray casting.
  const mps::PinholeCamera coarse = kCamera;                            // 2.4 cm per pixel at the ball
  const mps::PinholeCamera fine{320, 240, 240.0, 240.0, 159.5, 119.5};  // 0.5 cm per pixel at the ball
  const std::size_t coarse_projective = freedInsideBall(coarse, true), coarse_rays = freedInsideBall(coarse, false);
  EXPECT_LT(coarse_projective, coarse_rays);
  EXPECT_EQ(freedInsideBall(fine, true), 0u);
  EXPECT_GT(freedInsideBall(fine, false), 0u);
}

TEST(Projective, AVacatedCellClearsWithinAsManyViewsAsRayCasting) {
  const Eigen::Isometry3d pose = lookingAlongX(Eigen::Vector3d(0.0, 0.0, 0.0));
  const mps::PinholeCamera fine{320, 240, 240.0, 240.0, 159.5, 119.5};
  const Eigen::Vector3d ball(1.0, 0.0, 0.0);
  const Eigen::Vector3d c = pose.inverse() * ball;
  const auto with = image(fine, [&](int u, int v) { return sphereOrWall(fine, u, v, c, 0.1, 2.0); });
  const auto without = image(fine, [](int, int) { return 2.0; });
  const Eigen::Vector3d front = ball - Eigen::Vector3d(0.095, 0.0, 0.0);
  auto views = [&](bool projective) {
    auto map = makeMap();
    mps::MapUpdate u;
    map->computeUpdateProjective(mapPoints(with, pose), {}, depths(with), {}, fine, pose, &u);
    map->apply(u);
    EXPECT_TRUE(map->occupied(front));
    for (int n = 1; n <= 20; ++n) {
      if (projective) {
        map->computeUpdateProjective(mapPoints(without, pose), {}, depths(without), {}, fine, pose, &u);
      } else {
        map->computeUpdate(mapPoints(without, pose), {}, pose.translation(), &u);
      }
      map->apply(u);
      if (!map->occupied(front)) return n;
    }
    return 1000;
  };
  const int projective = views(true), rays = views(false);
  EXPECT_LT(rays, 20);
  EXPECT_LE(projective, rays);
}

TEST(Projective, RobotPixelsHideNothingBesideThemAndSeeNothingFree) {
  // A link (robot pixels, the self filter's) 0.999 m in front of the camera covers the image's left part, up to the
  // pixel column 166; a wall 2 m away behind. The cell 1.00-1.02 m deep whose image reaches past the link's
  // silhouette (columns 165-169) is crossed by rays that see the wall: seen free, as ray casting's beams beside a
  // link see it; were those pixels an obstacle, it would not be. A cell straight behind the link is never seen free.
  const mps::PinholeCamera fine{320, 240, 240.0, 240.0, 159.5, 119.5};
  const Eigen::Isometry3d pose = lookingAlongX(Eigen::Vector3d(0.0, 0.0, 0.0));
  const int edge = 167;  // the first column past the link
  const auto xyz = image(fine, [&](int u, int) { return u < edge ? 0.999 : 2.0; });
  std::vector<std::uint8_t> robot_pixels, robot_points;
  for (int v = 0; v < fine.height; ++v) {
    for (int u = 0; u < fine.width; ++u) robot_pixels.push_back(u < edge ? mps::kPointOnRobot : mps::kPointObstacle);
  }
  robot_points = robot_pixels;  // every pixel has a return: points and pixels in the same order
  const Eigen::Vector3d beside(1.01, -0.03, 0.01), behind(1.01, 0.05, 0.01), link(0.995, 0.05, 0.01);
  for (bool on_robot : {true, false}) {
    auto map = makeMap();
    mps::MapUpdate u;
    const std::vector<std::uint8_t> none;
    map->computeUpdateProjective(mapPoints(xyz, pose), on_robot ? robot_points : none, depths(xyz),
                                 on_robot ? robot_pixels : none, fine, pose, &u);
    map->apply(u);
    EXPECT_EQ(map->observed(beside), on_robot) << on_robot;
    EXPECT_FALSE(map->observed(behind)) << on_robot;
    EXPECT_EQ(map->occupied(link), !on_robot) << on_robot;  // the link's own cells: hit as an obstacle only
  }
}

TEST(Projective, CellsJustInFrontOfTheCameraAreSeenAndNoneBesideIt) {
  // The blocks across the camera's plane have no rectangle in the image; the ones wholly beyond a side of the image
  // hold nothing to see, the others are looked into cell by cell. A camera inside the map, a wall 2 m ahead: a cell
  // 2-4 cm in front of the lens (in a block across its plane) is seen free; cells beside it, out of the image, and
  // behind the camera are not. Two cameras: one centred, one whose principal point and focal lengths differ by axis.
  for (const mps::PinholeCamera& camera : {kCamera, mps::PinholeCamera{80, 60, 35.0, 70.0, 20.0, 45.0}}) {
    auto map = makeMap();
    const Eigen::Isometry3d pose = lookingAlongX(Eigen::Vector3d(0.0, 0.0, 0.0));
    const auto wall = image(camera, [](int, int) { return 2.0; });
    mps::MapUpdate u;
    map->computeUpdateProjective(mapPoints(wall, pose), {}, depths(wall), {}, camera, pose, &u);
    map->apply(u);
    EXPECT_TRUE(map->observed(Eigen::Vector3d(0.03, 0.0, 0.0)));
    EXPECT_TRUE(map->observed(Eigen::Vector3d(0.05, -0.01, 0.0)));
    EXPECT_FALSE(map->observed(Eigen::Vector3d(0.03, 0.5, 0.0)));   // beside: out of the image
    EXPECT_FALSE(map->observed(Eigen::Vector3d(0.03, 0.0, -0.5)));  // below
    EXPECT_FALSE(map->observed(Eigen::Vector3d(-0.03, 0.0, 0.0)));  // behind
    // Every cell near the camera's plane: one whose corners all project into the image (a pixel inside) is seen free
    // (every ray there sees the wall), one whose corners all lie beyond the same side of the image is not.
    std::size_t inside = 0, beyond = 0;
    for (double x = 0.01; x < 0.2; x += 0.02) {
      for (double y = -0.29; y < 0.3; y += 0.02) {
        for (double z = -0.29; z < 0.3; z += 0.02) {
          int in = 0, side[4] = {0, 0, 0, 0};
          for (int c = 0; c < 8; ++c) {
            const Eigen::Vector3d q =
                pose.inverse() * Eigen::Vector3d(x + ((c & 1) ? 0.01 : -0.01), y + ((c & 2) ? 0.01 : -0.01),
                                                 z + ((c & 4) ? 0.01 : -0.01));
            const double uu = camera.fx * q.x() / q.z() + camera.cx, vv = camera.fy * q.y() / q.z() + camera.cy;
            in += uu > 1 && uu < camera.width - 2 && vv > 1 && vv < camera.height - 2 ? 1 : 0;
            side[0] += uu < -1 ? 1 : 0;
            side[1] += uu > camera.width ? 1 : 0;
            side[2] += vv < -1 ? 1 : 0;
            side[3] += vv > camera.height ? 1 : 0;
          }
          const Eigen::Vector3d centre(x, y, z);
          if (in == 8) {
            ++inside;
            EXPECT_TRUE(map->observed(centre)) << centre.transpose();
          } else if (*std::max_element(side, side + 4) == 8) {
            ++beyond;
            EXPECT_FALSE(map->observed(centre)) << centre.transpose();
          }
        }
      }
    }
    EXPECT_GT(inside, 100u);
    EXPECT_GT(beyond, 100u);
  }
}

/// View n of a changing scene: two fixed cameras that overlap (intrinsics jittered as fitPinhole's are), one that
/// moves now and then, one that moves every view (more cameras than the map remembers: the least recently seen make
/// way, and their records are reused), a ball that walks, a static one, robot pixels that move, a patch without
/// returns that comes and goes, and now and then a cloud to integrate by ray casting (ray_cast).
struct SceneView {
  mps::PinholeCamera camera;
  Eigen::Isometry3d pose;
  std::vector<Eigen::Vector3d> points;
  std::vector<std::uint8_t> point_mask, pixel_mask;
  std::vector<float> depth;
  bool ray_cast = false;
};

SceneView sceneView(int n, int scale = 1) {
  const Eigen::Vector3d fixed_ball(1.5, -0.3, 0.2);
  SceneView s;
  const int which = n % 4;
  s.pose = lookingAlongX(which == 0   ? Eigen::Vector3d(0.0, 0.0, 0.0)
                         : which == 1 ? Eigen::Vector3d(0.0, 0.4, 0.2)
                         : which == 2 ? Eigen::Vector3d(0.0, -0.3 + 0.02 * (n / 15), 0.0)
                                      : Eigen::Vector3d(0.0, -0.5 + 0.01 * n, 0.1));
  s.camera = kCamera;  // scale times as many pixels each way, the same field of view
  s.camera.width *= scale;
  s.camera.height *= scale;
  s.camera.fx = s.camera.fx * scale + 1e-9 * (n % 5);  // a fixed camera's fits differ in the last digits
  s.camera.fy *= scale;
  s.camera.cx = (s.camera.cx + 0.5) * scale - 0.5;
  s.camera.cy = (s.camera.cy + 0.5) * scale - 0.5;
  const double t = 0.15 * n;
  const Eigen::Vector3d walking(1.1, 0.35 * std::sin(t), 0.0);
  const Eigen::Vector3d a = s.pose.inverse() * walking, b = s.pose.inverse() * fixed_ball;
  const bool robot_here = which == 0;
  const int robot_u0 = 10 + (n / 6) % 20;  // robot pixels (a link in front) that move every other view of A
  auto robot = [&](int u, int v) {
    u /= scale;
    v /= scale;
    return robot_here && u >= robot_u0 && u < robot_u0 + 12 && v > 35;
  };
  auto depth = [&](int u, int v) {
    if (robot(u, v)) return 0.7;
    if (which == 1 && (n / 9) % 2 == 1 && u / scale > 60 && v / scale < 15) {
      return std::numeric_limits<double>::quiet_NaN();
    }
    return std::min(sphereOrWall(s.camera, u, v, a, 0.12, 2.0), sphereOrWall(s.camera, u, v, b, 0.1, 2.0));
  };
  const auto xyz = image(s.camera, depth);
  for (int v = 0; v < s.camera.height; ++v) {
    for (int u = 0; u < s.camera.width; ++u) {
      s.pixel_mask.push_back(robot(u, v) ? mps::kPointOnRobot : mps::kPointObstacle);
      if (std::isfinite(xyz[3 * (v * s.camera.width + u) + 2])) s.point_mask.push_back(s.pixel_mask.back());
    }
  }
  s.points = mapPoints(xyz, s.pose);
  s.depth = depths(xyz);
  s.ray_cast = n % 17 == 16;
  return s;
}

/// Integrate view s into map (by ray casting or projection, as s says) on `pool` (nullptr: the calling thread).
void integrate(mps::OccupancyMap* map, const SceneView& s, mps::MapUpdate* u, mps::WorkerPool* pool = nullptr) {
  if (s.ray_cast) {
    map->computeUpdate(s.points, s.point_mask, s.pose.translation(), u);
  } else {
    map->computeUpdateProjective(s.points, s.point_mask, s.depth, s.pixel_mask, s.camera, s.pose, u, pool);
  }
}

TEST(Projective, ARayThatOnlyTouchesACellDoesNotSeeIt) {
  // A camera on a cell boundary whose middle column of pixels looks along the boundary plane (cx on a pixel centre,
  // the optical centre at y = 0 of the map, a plane between two columns of cells): those rays run along the cells'
  // faces without entering them. Beyond fx * resolution (1 m) the next columns' rays pass outside the two cells beside
  // the plane, so nothing enters them: they are between the rays of a sparse image, and must stay unseen (a thin
  // thing inside them, off the plane, would not be seen). Nearer, the next columns' rays cross them.
  const mps::PinholeCamera camera{81, 61, 50.0, 52.0, 40.0, 30.0};
  const Eigen::Isometry3d pose = lookingAlongX(Eigen::Vector3d(0.0, 0.0, 0.0));
  const auto wall = image(camera, [](int, int) { return 2.0; });
  for (bool skip : {true, false}) {
    auto map = makeMap(false, skip);
    mps::MapUpdate u;
    map->computeUpdateProjective(mapPoints(wall, pose), {}, depths(wall), {}, camera, pose, &u);
    std::size_t beside_far = 0, beside_near = 0;
    for (std::uint64_t key : u.misses) {
      const Eigen::Vector3d c = map->cellCentre(key);
      if (std::fabs(std::fabs(c.y()) - 0.01) > 1e-9) continue;  // the two columns of cells beside y = 0
      if (c.x() > 1.05 && c.x() < 1.9) ++beside_far;
      if (c.x() > 0.3 && c.x() < 0.9) ++beside_near;
    }
    EXPECT_EQ(beside_far, 0u) << "skip " << skip;
    EXPECT_GT(beside_near, 100u) << "skip " << skip;  // crossed by the next columns' rays
  }
}

TEST(Projective, SkippingUnchangedBlocksGivesTheSameUpdates) {
  // skip_unchanged_blocks leaves a block as its camera's last view left it when nothing it depends on changed. Two
  // maps, one with it and one evaluating every block, take the same views (sceneView: cameras fixed and moving, more
  // than the map remembers, a ball walking, robot pixels, dropouts, ray casting now and then), and the
  // unknown-is-occupied rule switched and the map cleared once. Every update is the same (hits and misses as sets, and
  // the count of cells seen free).
  std::size_t reused = 0;
  for (bool unknown_occupied : {false, true}) {
    auto skipping = makeMap(unknown_occupied, true), every = makeMap(unknown_occupied, false);
    ASSERT_TRUE(skipping && every);
    for (int n = 0; n < 120; ++n) {
      const SceneView s = sceneView(n);
      mps::MapUpdate us, ue;
      integrate(skipping.get(), s, &us);
      integrate(every.get(), s, &ue);
      reused += us.stats.reused_blocks;
      EXPECT_EQ(ue.stats.reused_blocks, 0u);
      for (auto* cells : {&us.hits, &us.misses, &ue.hits, &ue.misses}) std::sort(cells->begin(), cells->end());
      ASSERT_EQ(us.hits, ue.hits) << "view " << n << " unknown_occupied " << unknown_occupied;
      ASSERT_EQ(us.misses, ue.misses) << "view " << n << " unknown_occupied " << unknown_occupied;
      EXPECT_EQ(us.stats.free_cells, ue.stats.free_cells) << "view " << n << " unknown_occupied " << unknown_occupied;
      skipping->apply(us);
      every->apply(ue);
      if (n == 60) {
        skipping->setUnknownOccupied(!unknown_occupied);
        every->setUnknownOccupied(!unknown_occupied);
      }
      if (n == 90) {
        skipping->clear();
        every->clear();
      }
    }
  }
  EXPECT_GT(reused, 1000u);  // it did skip
}

TEST(Projective, AnyNumberOfWorkersGivesTheSameUpdates) {
  // The projective update's superblocks shared out between a pool's threads: the same hits and misses in the same
  // order, the same counts, as on the calling thread alone, view after view (the views' records too: a block a worker
  // left wrongly would show in a later view), with skipping on and off. On images large enough (scale 4: 320 x 240),
  // the points' end cells and the pixels' depths are worked out in parts on the pool too.
  mps::WorkerPool two(2), three(3);
  std::size_t misses = 0, known_free = 0;
  for (const auto& [skip, scale] : {std::make_pair(true, 1), std::make_pair(false, 1), std::make_pair(true, 4)}) {
    auto alone = makeMap(true, skip), on_two = makeMap(true, skip), on_three = makeMap(true, skip);
    ASSERT_TRUE(alone && on_two && on_three);
    for (int n = 0; n < (scale == 1 ? 80 : 24); ++n) {
      const SceneView s = sceneView(n, scale);
      ASSERT_EQ(s.points.size() >= 2 * mps::WorkerPool::kCheapPart, scale > 1);
      mps::MapUpdate ua, u2, u3;
      integrate(alone.get(), s, &ua);
      integrate(on_two.get(), s, &u2, &two);
      integrate(on_three.get(), s, &u3, &three);
      // The cells the update marked seen (the workers set their bits in shared words) are what addKnownFree leaves
      // out: the unobserved cells around the walking ball, offered to it, come out the same.
      const Eigen::AlignedBox3d around(Eigen::Vector3d(0.8, -0.5, -0.3), Eigen::Vector3d(1.4, 0.5, 0.3));
      std::vector<Eigen::Vector3d> centres;
      std::vector<std::uint64_t> keys;
      for (const auto& [map, u] :
           {std::make_pair(alone.get(), &ua), std::make_pair(on_two.get(), &u2), std::make_pair(on_three.get(), &u3)}) {
        map->unobservedCells(around, &centres, &keys);
        map->addKnownFree(keys, u);
      }
      for (const mps::MapUpdate* u : {&u2, &u3}) {
        EXPECT_EQ(u->stats.known_free, ua.stats.known_free);
        ASSERT_EQ(u->hits, ua.hits) << "view " << n;
        ASSERT_EQ(u->misses, ua.misses) << "view " << n;
        EXPECT_EQ(u->stats.free_cells, ua.stats.free_cells);
        EXPECT_EQ(u->stats.reused_blocks, ua.stats.reused_blocks);
        EXPECT_EQ(u->stats.changed_cells, ua.stats.changed_cells);
        EXPECT_EQ(u->stats.hit_cells, ua.stats.hit_cells);
        EXPECT_EQ(u->stats.robot, ua.stats.robot);
        EXPECT_EQ(u->stats.fixture, ua.stats.fixture);
        EXPECT_EQ(u->stats.beyond_range, ua.stats.beyond_range);
        EXPECT_EQ(u->stats.invalid, ua.stats.invalid);
      }
      misses += ua.misses.size();
      known_free += ua.stats.known_free;
      alone->apply(ua);
      on_two->apply(u2);
      on_three->apply(u3);
    }
  }
  EXPECT_GT(misses, 10000u);  // there was work to share
  EXPECT_GT(known_free, 1000u);
}

TEST(Projective, FindsTheEndCellsRayCastingFindsInTheSameOrderWhateverTheParts) {
  // Both integrations hit the cells where obstacle points end, in the order of their first points, and count the
  // points of each kind. The projective one folds each part's points into runs of one cell first, on the pool; a run
  // may go on across the parts' seam. A 320 x 240 cloud (several parts) with points of every kind mixed in rows:
  // non-finite ones, beyond max_range, on the robot, on a fixture, obstacles.
  mps::PinholeCamera camera = kCamera;
  camera.width *= 4;
  camera.height *= 4;
  camera.fx *= 4;
  camera.fy *= 4;
  camera.cx = (camera.cx + 0.5) * 4 - 0.5;
  camera.cy = (camera.cy + 0.5) * 4 - 0.5;
  const Eigen::Isometry3d pose = lookingAlongX(Eigen::Vector3d(0.0, 0.0, 0.0));
  const Eigen::Vector3d ball(0.1, 0.0, 1.2);
  auto kind = [&](int u, int v) -> std::uint8_t {
    if (v % 50 < 10 && u >= 160) return mps::kPointOnFixture;
    if (v % 50 < 10 && u % 3 != 0) return mps::kPointOnRobot;  // an obstacle point in every third: hands and links
    return mps::kPointObstacle;
  };
  // Far (beyond max_range, 3 m) in the top rows' right half; a ball before a wall elsewhere.
  const auto xyz = image(
      camera, [&](int u, int v) { return v < 30 && u > 200 ? 3.5 : sphereOrWall(camera, u, v, ball, 0.25, 2.2); });
  std::vector<Eigen::Vector3d> points;
  std::vector<std::uint8_t> mask, pixel_mask;
  for (int v = 0; v < camera.height; ++v) {
    for (int u = 0; u < camera.width; ++u) {
      const std::size_t k = 3 * (static_cast<std::size_t>(v) * camera.width + u);
      pixel_mask.push_back(kind(u, v));
      mask.push_back(kind(u, v));
      points.push_back((u + 3 * v) % 23 == 0 ? Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN())
                                             : Eigen::Vector3d(pose * Eigen::Vector3d(xyz[k], xyz[k + 1], xyz[k + 2])));
    }
  }
  ASSERT_GE(points.size(), 4 * mps::WorkerPool::kCheapPart);
  mps::WorkerPool three(3);
  auto cast = makeMap(), alone = makeMap(), shared = makeMap();
  mps::MapUpdate uc, ua, us;
  cast->computeUpdate(points, mask, pose.translation(), &uc);
  alone->computeUpdateProjective(points, mask, depths(xyz), pixel_mask, camera, pose, &ua);
  shared->computeUpdateProjective(points, mask, depths(xyz), pixel_mask, camera, pose, &us, &three);
  EXPECT_GT(uc.stats.invalid, 1000u);
  EXPECT_GT(uc.stats.beyond_range, 1000u);
  EXPECT_GT(uc.stats.robot, 1000u);
  EXPECT_GT(uc.stats.fixture, 1000u);
  EXPECT_GT(uc.hits.size(), 100u);
  for (const mps::MapUpdate* u : {&ua, &us}) {
    EXPECT_EQ(u->hits, uc.hits);
    EXPECT_EQ(u->stats.hit_cells, uc.stats.hit_cells);
    EXPECT_EQ(u->stats.invalid, uc.stats.invalid);
    EXPECT_EQ(u->stats.beyond_range, uc.stats.beyond_range);
    EXPECT_EQ(u->stats.robot, uc.stats.robot);
    EXPECT_EQ(u->stats.fixture, uc.stats.fixture);
  }
}

TEST(Projective, ACloudsUpdateDoesNotDependOnTheMarksOfTheCloudBefore) {
  // An update marks the cells it hits and sees free (a cell counts once a cloud); the next cloud starts with none
  // marked. A map that computed the first cloud (its marks left) and one that only applied its update (the same
  // values, no marks) give the next cloud the same update, whichever integration computes either. The next cloud,
  // from another pose: a wall of fixture points (the cells where they end are seen free) where the first saw a ball,
  // and free space before it.
  const Eigen::Isometry3d pose = lookingAlongX(Eigen::Vector3d(0.0, 0.0, 0.0));
  const Eigen::Isometry3d moved = lookingAlongX(Eigen::Vector3d(0.0, 0.1, 0.05));
  const mps::PinholeCamera small{40, 30, 25.0, 26.0, 19.5, 14.5};  // kCamera's view, coarser
  const auto ball =
      image(small, [&](int u, int v) { return sphereOrWall(small, u, v, Eigen::Vector3d(0.1, 0.0, 1.2), 0.25, 2.2); });
  const auto wall = image(kCamera, [](int, int) { return 1.3; });
  const auto wall_points = mapPoints(wall, moved);
  const std::vector<std::uint8_t> fixture(wall_points.size(), mps::kPointOnFixture);
  for (bool first_projective : {true, false}) {
    for (bool next_projective : {true, false}) {
      auto computed = makeMap(true);
      auto applied = makeMap(true);
      mps::MapUpdate u;
      if (first_projective) {
        computed->computeUpdateProjective(mapPoints(ball, pose), {}, depths(ball), {}, small, pose, &u);
      } else {
        computed->computeUpdate(mapPoints(ball, pose), {}, pose.translation(), &u);
      }
      ASSERT_GT(u.misses.size(), 1000u);
      ASSERT_GT(u.hits.size(), 30u);
      computed->apply(u);
      applied->apply(u);
      mps::MapUpdate a, b;
      for (auto* m : {computed.get(), applied.get()}) {
        mps::MapUpdate* out = m == computed.get() ? &a : &b;
        if (next_projective) {
          m->computeUpdateProjective(wall_points, fixture, depths(wall), {}, kCamera, moved, out);
        } else {
          m->computeUpdate(wall_points, fixture, moved.translation(), out);
        }
      }
      EXPECT_GT(a.misses.size(), 1000u);
      EXPECT_EQ(a.misses, b.misses) << first_projective << next_projective;
      EXPECT_EQ(a.hits, b.hits) << first_projective << next_projective;
      EXPECT_EQ(a.stats.free_cells, b.stats.free_cells) << first_projective << next_projective;
    }
  }
}

TEST(Projective, ACellThePointsStopHittingIsLookedAtAgainThoughTheDepthsStay) {
  // The hits come from the cloud's points, the free space from its depths. A point off every pixel's ray (a cloud
  // within fitPinhole's tolerance, not on it) hits its cell in every view, so the cell never turns clamped free; when
  // the point is gone and the depths are the same, that cell's block must be looked at again (the end cells in each
  // block are part of what a view remembers), and the cell is seen free as with every block evaluated.
  const Eigen::Isometry3d pose = lookingAlongX(Eigen::Vector3d(0.0, 0.0, 0.0));
  const mps::PinholeCamera fine{320, 240, 240.0, 240.0, 159.5, 119.5};
  const auto wall = image(fine, [](int, int) { return 2.0; });
  const Eigen::Vector3d stray(1.0, 0.013, 0.007);
  auto views = [&](bool skip) {  // views until the cell is free again once the point is gone
    auto map = makeMap(false, skip);
    mps::MapUpdate u;
    for (int n = 0; n < 8; ++n) {
      auto points = mapPoints(wall, pose);
      points.push_back(stray);
      map->computeUpdateProjective(points, {}, depths(wall), {}, fine, pose, &u);
      map->apply(u);
    }
    EXPECT_EQ(u.stats.reused_blocks > 0, skip);  // the settled blocks are left alone
    EXPECT_TRUE(map->occupied(stray));
    for (int n = 1; n <= 20; ++n) {
      map->computeUpdateProjective(mapPoints(wall, pose), {}, depths(wall), {}, fine, pose, &u);
      map->apply(u);
      if (!map->occupied(stray)) return n;
    }
    return 1000;
  };
  const int every = views(false);
  EXPECT_LT(every, 20);
  EXPECT_EQ(views(true), every);
}

/// The Panda's scene, a map and a projective CloudIntegrator's options on two threads; a camera looking along x.
class Integrating : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::string urdf = MOVERL_PANDA_URDF;
    std::string error;
    scene = mps::PlanningScene::create(mps::panda::readFile(urdf), mps::panda::options(urdf), &error);
    ASSERT_TRUE(scene) << error;
    map = makeMap();
    io.integration = mps::Integration::kProjective;
    io.self_filter_padding = 0.01;
    io.static_filter_padding = 0.003;
    io.threads = 2;
  }
  std::unique_ptr<mps::PlanningScene> scene;
  std::unique_ptr<mps::OccupancyMap> map;
  mps::CloudIntegratorOptions io;
  const Eigen::Isometry3d pose = lookingAlongX(Eigen::Vector3d(-0.4, 0.0, 0.5));
  const std::vector<std::vector<double>> home = {{0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785}};
};

TEST_F(Integrating, FallsBackToRayCastingForAnUnorganizedCloud) {
  std::string error;
  io.threads = 0;
  EXPECT_THROW(mps::CloudIntegrator(map.get(), &scene->checker(), nullptr, io), std::invalid_argument);
  io.threads = 2;
  mps::CloudIntegrator integrator(map.get(), &scene->checker(), nullptr, io);
  const auto xyz = image(kCamera, [](int, int) { return 2.0; });
  mps::MapUpdate u;
  std::string why;
  mps::CloudView view;
  view.data = reinterpret_cast<const std::uint8_t*>(xyz.data());
  view.width = kCamera.width;
  view.height = kCamera.height;
  view.row_step = 12 * static_cast<std::size_t>(kCamera.width);
  EXPECT_EQ(integrator.compute(view, pose, home, &u, nullptr, &why), mps::Integration::kProjective);
  EXPECT_EQ(why, "");
  EXPECT_NEAR(integrator.camera().fx, kCamera.fx, 1e-3);
  const int n = kCamera.width * kCamera.height;
  view.width = n;
  view.height = 1;
  view.row_step = 12 * static_cast<std::size_t>(n);
  EXPECT_EQ(integrator.compute(view, pose, home, &u, nullptr, &why), mps::Integration::kRayCasting);
  EXPECT_NE(why.find("unorganized"), std::string::npos) << why;
  EXPECT_GT(u.stats.free_cells, 0u);
  mps::Integration parsed;
  EXPECT_FALSE(mps::parseIntegration("voxblox", &parsed, &error));
  EXPECT_NE(error.find("projective, ray_casting"), std::string::npos) << error;
}

TEST_F(Integrating, ReadsAPackedCloudInPlaceAsItCopiesAnyOtherLayout) {
  // Packed float32 x, y, z is read where it lies; any other layout (points of 16 bytes with the fields shuffled and
  // rows padded, or a packed cloud at an address a float may not be read from) is copied first. The same cloud gives
  // the same intrinsics and the same update, views after view, either way.
  const mps::PinholeCamera camera{120, 90, 100.0, 100.0, 59.5, 44.5};
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> z(0.5, 3.0);
  auto xyz = image(camera, [&](int, int) { return z(rng); });
  for (std::size_t k = 0; k < xyz.size(); k += 29) xyz[k] = std::numeric_limits<float>::quiet_NaN();  // no returns
  const std::size_t n = static_cast<std::size_t>(camera.width) * camera.height;
  // 16 bytes a point: z, a pad, x, y; 8 bytes of padding after each row.
  const std::size_t row_step = 16 * static_cast<std::size_t>(camera.width) + 8;
  std::vector<std::uint8_t> shuffled(row_step * camera.height, 0);
  for (std::size_t k = 0; k < n; ++k) {
    std::uint8_t* at = &shuffled[(k / camera.width) * row_step + (k % camera.width) * 16];
    std::memcpy(at, &xyz[3 * k + 2], 4);
    std::memcpy(at + 8, &xyz[3 * k], 4);
    std::memcpy(at + 12, &xyz[3 * k + 1], 4);
  }
  std::vector<std::uint8_t> unaligned(12 * n + 1);
  std::memcpy(unaligned.data() + 1, xyz.data(), 12 * n);
  mps::CloudView packed;
  packed.data = reinterpret_cast<const std::uint8_t*>(xyz.data());
  packed.width = camera.width;
  packed.height = camera.height;
  packed.row_step = 12 * static_cast<std::size_t>(camera.width);
  mps::CloudView other = packed;
  other.data = shuffled.data();
  other.point_step = 16;
  other.row_step = row_step;
  other.x = 8;
  other.y = 12;
  other.z = 0;
  mps::CloudView odd = packed;
  odd.data = unaligned.data() + 1;
  auto run = [&](const mps::CloudView& view) {
    auto m = makeMap();
    mps::CloudIntegrator integrator(m.get(), &scene->checker(), nullptr, io);
    std::vector<mps::MapUpdate> updates(3);
    std::string why;
    for (auto& u : updates) {
      EXPECT_EQ(integrator.compute(view, pose, home, &u, nullptr, &why), mps::Integration::kProjective) << why;
      m->apply(u);
    }
    return std::make_pair(integrator.camera(), updates);
  };
  const auto a = run(packed);
  EXPECT_GT(a.second[0].misses.size(), 1000u);
  EXPECT_GT(a.second[0].hits.size(), 100u);
  for (const auto& view : {other, odd}) {
    const auto b = run(view);
    EXPECT_EQ(b.first.fx, a.first.fx);
    EXPECT_EQ(b.first.cx, a.first.cx);
    EXPECT_EQ(b.first.fy, a.first.fy);
    EXPECT_EQ(b.first.cy, a.first.cy);
    for (std::size_t k = 0; k < a.second.size(); ++k) {
      EXPECT_EQ(b.second[k].hits, a.second[k].hits) << "view " << k;
      EXPECT_EQ(b.second[k].misses, a.second[k].misses) << "view " << k;
    }
  }
}

TEST_F(Integrating, FitsThePinholeAsFitPinholeAndChecksEveryPoint) {
  // The integrator fits the model in its passes over the points (a strided subset) and checks every point: the same
  // intrinsics as fitPinhole's, and a cloud whose odd columns stray from their rays (between a stride of 2) refused.
  mps::CloudIntegrator integrator(map.get(), &scene->checker(), nullptr, io);
  const mps::PinholeCamera camera{200, 150, 120.0, 125.0, 99.5, 74.5};  // 30,000 points: fitted on a stride
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> z(0.5, 3.0);
  auto xyz = image(camera, [&](int, int) { return z(rng); });
  for (std::size_t k = 0; k < xyz.size(); k += 33) xyz[k] = std::numeric_limits<float>::quiet_NaN();  // no returns
  mps::CloudView view;
  view.width = camera.width;
  view.height = camera.height;
  view.row_step = 12 * static_cast<std::size_t>(camera.width);
  mps::MapUpdate u;
  std::string why;
  view.data = reinterpret_cast<const std::uint8_t*>(xyz.data());
  ASSERT_EQ(integrator.compute(view, pose, home, &u, nullptr, &why), mps::Integration::kProjective) << why;
  mps::PinholeCamera fit;
  double residual = 0.0;
  ASSERT_TRUE(
      mps::fitPinhole(xyz.data(), camera.width, camera.height, 1, mps::kPinholeTolerancePx, &fit, &residual, &why));
  EXPECT_NEAR(integrator.camera().fx, fit.fx, 1e-6);
  EXPECT_NEAR(integrator.camera().fy, fit.fy, 1e-6);
  EXPECT_NEAR(integrator.camera().cx, fit.cx, 1e-6);
  EXPECT_NEAR(integrator.camera().cy, fit.cy, 1e-6);
  // The odd columns 0.2 px off their rays (x scaled about the principal point).
  auto off = xyz;
  for (int v = 0; v < camera.height; ++v) {
    for (int u = 1; u < camera.width; u += 2) {
      float* p = &off[3 * (static_cast<std::size_t>(v) * camera.width + u)];
      p[0] += static_cast<float>(0.2 / camera.fx * p[2]);
    }
  }
  view.data = reinterpret_cast<const std::uint8_t*>(off.data());
  EXPECT_EQ(integrator.compute(view, pose, home, &u, nullptr, &why), mps::Integration::kRayCasting);
  EXPECT_NE(why.find("px"), std::string::npos) << why;
  EXPECT_FALSE(
      mps::fitPinhole(off.data(), camera.width, camera.height, 2, mps::kPinholeTolerancePx, &fit, &residual, &why));
}
