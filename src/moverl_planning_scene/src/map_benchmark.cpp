/**
 * \file map_benchmark.cpp
 * \brief Cost of integrating one depth-camera cloud into the sensed map (OccupancyMap), without ROS or a simulator:
 *        the cameras of a world file render a synthetic scene by ray casting (the table top of worlds/table.yaml,
 *        the floor, and a standing person as a vertical cylinder of radius 0.165 m from z 0.14 to 0.72 at x 0.8,
 *        walking along y as worlds/human.yaml's torso does). Cells and bounds as the scene node sets them for the
 * Panda. Usage: map_benchmark [world.yaml] [clouds]   (default: worlds/human.yaml, 60 clouds, cameras in turn)
 */
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <sstream>

#include "moverl_planning_scene/occupancy_map.h"
#include "moverl_planning_scene/planning_scene.h"
#include "moverl_planning_scene/tunables.h"

namespace mps = moverl_planning_scene;
using Clock = std::chrono::steady_clock;

namespace {

struct Camera {
  Eigen::Vector3d origin, target;
  int width = 0, height = 0;
  double fov = 0.0, far = 0.0, period = 0.0;
};

double seconds(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

/// Distance along the unit ray o + s d to the synthetic scene (far when nothing is hit).
double castRay(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double person_y, double far) {
  double best = far;
  auto plane = [&](double z, double x0, double x1, double y0, double y1) {
    if (std::fabs(d.z()) < 1e-12) return;
    const double s = (z - o.z()) / d.z();
    if (s <= 0.0 || s >= best) return;
    const Eigen::Vector3d p = o + s * d;
    if (p.x() >= x0 && p.x() <= x1 && p.y() >= y0 && p.y() <= y1) best = s;
  };
  plane(0.0, -0.4, 1.1, -0.4, 0.4);                 // table top
  plane(-0.75, -5.0, 5.0, -5.0, 5.0);               // floor
  const double cx = 0.8, cy = person_y, r = 0.165;  // torso
  const double a = d.x() * d.x() + d.y() * d.y();
  if (a > 1e-12) {
    const double bx = o.x() - cx, by = o.y() - cy;
    const double b = 2.0 * (d.x() * bx + d.y() * by), c = bx * bx + by * by - r * r, disc = b * b - 4 * a * c;
    if (disc >= 0.0) {
      const double s = (-b - std::sqrt(disc)) / (2 * a);
      const double z = o.z() + s * d.z();
      if (s > 0.0 && s < best && z >= 0.14 && z <= 0.72) best = s;
    }
  }
  return best;
}

std::vector<Eigen::Vector3d> render(const Camera& c, double person_y) {
  const Eigen::Vector3d fwd = (c.target - c.origin).normalized();
  const Eigen::Vector3d right = fwd.cross(Eigen::Vector3d::UnitZ()).normalized(), up = right.cross(fwd);
  const double f = 0.5 * c.height / std::tan(0.5 * c.fov * M_PI / 180.0);  // vertical field of view (PyBullet's)
  std::vector<Eigen::Vector3d> pts;
  pts.reserve(static_cast<std::size_t>(c.width) * c.height);
  for (int v = 0; v < c.height; ++v) {
    for (int u = 0; u < c.width; ++u) {
      const Eigen::Vector3d d =
          (fwd * f + right * (u + 0.5 - 0.5 * c.width) - up * (v + 0.5 - 0.5 * c.height)).normalized();
      // A depth camera reports depth along its axis: a far-plane pixel lies on the far plane, not on a sphere.
      const double s = castRay(c.origin, d, person_y, c.far / d.dot(fwd));
      pts.push_back(c.origin + s * d);
    }
  }
  return pts;
}

void report(const char* what, std::vector<double> t) {
  if (t.empty()) return;
  std::sort(t.begin(), t.end());
  double sum = 0.0;
  for (double v : t) sum += v;
  std::printf("%-34s n=%4zu  mean %8.2f ms  p50 %8.2f ms  max %8.2f ms\n", what, t.size(), 1e3 * sum / t.size(),
              1e3 * t[t.size() / 2], 1e3 * t.back());
}

}  // namespace

int main(int argc, char** argv) {
  const std::string world = argc > 1 && argv[1][0] != '\0' ? argv[1] : MOVERL_CONFIG_DIR "/../worlds/human.yaml";
  const int clouds = argc > 2 ? std::atoi(argv[2]) : 60;
  std::vector<Camera> cams;
  try {
    for (const auto& c : YAML::LoadFile(world)["cameras"]) {
      Camera cam;
      auto vec = [&](const char* k) {
        return Eigen::Vector3d(c[k][0].as<double>(), c[k][1].as<double>(), c[k][2].as<double>());
      };
      cam.origin = vec("xyz");
      cam.target = vec("target");
      cam.width = c["width"].as<int>();
      cam.height = c["height"].as<int>();
      cam.fov = c["fov"].as<double>();
      cam.far = c["far"].as<double>();
      cam.period = 1.0 / c["rate"].as<double>();
      cams.push_back(cam);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s: %s\n", world.c_str(), e.what());
    return 1;
  }
  if (cams.empty() || clouds <= 0) {
    std::fprintf(stderr, "usage: map_benchmark [world.yaml with cameras:] [clouds > 0]\n");
    return 1;
  }
  std::string error, uri;
  mps::PlanningSceneOptions o;
  const auto tunables = mps::YamlTunables::fromFile(MOVERL_CONFIG_DIR "/planning_scene.yaml", &error);
  if (!tunables || !mps::loadRobotConfig(MOVERL_CONFIG_DIR "/robots/panda.yaml", &o.robot, &uri, &error)) {
    std::fprintf(stderr, "error: %s\n", error.c_str());
    return 1;
  }
  mps::readSceneTunables(*tunables, &o);
  const std::string urdf_file = MOVERL_PANDA_URDF;
  o.robot.mesh_base_dir = urdf_file.substr(0, urdf_file.rfind('/'));
  std::ifstream urdf_in(urdf_file);
  std::stringstream urdf;
  urdf << urdf_in.rdbuf();
  auto scene = mps::PlanningScene::create(urdf.str(), o, &error);
  if (!scene) {
    std::fprintf(stderr, "error: %s\n", error.c_str());
    return 1;
  }
  mps::OccupancyMapOptions mo;
  mps::readOccupancyMapTunables(*tunables, &mo);
  // As OctomapMonitor::init sets them.
  const double reach = scene->checker().reachRadius() + scene->checker().options().padding + 2 * mo.resolution;
  mo.bounds = Eigen::AlignedBox3d(Eigen::Vector3d::Constant(-reach), Eigen::Vector3d::Constant(reach));
  auto map = mps::OccupancyMap::create(mo, &error);
  if (!map) {
    std::fprintf(stderr, "error: %s\n", error.c_str());
    return 1;
  }
  std::printf("%zu cameras of %s, %d x %d px; map resolution %.3f m within +-%.2f m\n", cams.size(), world.c_str(),
              cams[0].width, cams[0].height, mo.resolution, reach);
  const std::vector<double> home = {0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785};
  std::vector<double> t_mask, t_compute, t_apply, t_first;
  std::vector<std::uint8_t> mask;
  mps::MapUpdate u;
  std::size_t free_cells = 0, updated = 0;
  double sim_time = 0.0;
  for (int k = 0; k < clouds; ++k) {
    const Camera& c = cams[static_cast<std::size_t>(k) % cams.size()];
    if (k % cams.size() == 0 && k > 0) sim_time += c.period;
    const double person_y = 0.15 * std::sin(2 * M_PI * sim_time / 6.0);
    const auto pts = render(c, person_y);
    auto t = Clock::now();
    scene->checker().robotPointMask(home.data(), pts, 0.03, &mask);
    const double dm = seconds(t);
    t = Clock::now();
    map->computeUpdate(pts, mask, c.origin, &u);
    const double dc = seconds(t);
    t = Clock::now();
    map->apply(u);
    const double da = seconds(t);
    if (k < static_cast<int>(cams.size())) {
      t_first.push_back(dm + dc + da);
      continue;  // the first view of each camera fills the map from unknown: reported apart
    }
    t_mask.push_back(dm);
    t_compute.push_back(dc);
    t_apply.push_back(da);
    free_cells += u.stats.free_cells;
    updated += u.stats.changed_cells;
  }
  report("first view of each camera (total)", t_first);
  report("self filter (robot at home)", t_mask);
  report("computeUpdate (ray casting)", t_compute);
  report("apply (tree update)", t_apply);
  const std::size_t n = t_compute.empty() ? 1 : t_compute.size();
  std::printf("per later cloud: %zu cells seen free, %zu tree cells changed; %zu occupied leaves at the end\n",
              free_cells / n, updated / n, map->occupiedLeafCount());
  return 0;
}
