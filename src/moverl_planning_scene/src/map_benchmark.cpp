/**
 * \file map_benchmark.cpp
 * \brief Cost of integrating one depth-camera cloud into the sensed map, the live pipeline without ROS: the scene
 *        node's CloudIntegrator (points into the map frame, self filter, static filter, the map's update), once with
 *        ray casting and once by projection (octomap/integration), on the same clouds, and how the two maps differ.
 *
 * Clouds: recorded by the simulator's cameras (`--recording DIR`, from src/moverl_gym/tools/record_clouds.py: the
 * images the sim node publishes, with the robot's configuration and the world's static objects), or synthetic: the
 * cameras of a world file render by ray casting the table top of worlds/table.yaml, the floor, and a standing person
 * as a vertical cylinder of radius 0.165 m from z 0.14 to 0.72 at x 0.8, walking along y as worlds/human.yaml's torso
 * does, the robot at home (its points are not drawn). Cells and bounds as the scene node sets them for the Panda
 * (the bounds with the largest margin the world's speed bound asks for), with its hidden space: the clouds of one
 * instant are one batch, closed after the last of them (the stage "hidden space (batch close)").
 *
 * Usage: map_benchmark [world.yaml] [clouds] [--size WxH] [--recording DIR] [--threads N] [--resolution M] [--check]
 *                      [--identity] [--projective-only]
 *   (synthetic: default worlds/human.yaml, 60 clouds, cameras in turn, --size overrides the cameras' images)
 *   --check: exit 1 when either integration sees free a cell whose centre lies inside the synthetic person (a cell
 *   holding part of an obstacle; the static table's cells are the fixture filter's to clear, and are not counted).
 *   --threads N: threads that integrate a cloud (default: config/planning_scene.yaml's octomap/integration_threads).
 *   --resolution M: the map's cell edge in metres (default: config/planning_scene.yaml's octomap/resolution): what
 *   a coarser or finer map costs on the same clouds.
 *   --projective-only: leave ray casting out (a profiler's or callgrind's run of the projective update alone).
 *   --identity: also integrate every cloud by projection with skip_unchanged_blocks off (every block evaluated, on one
 *   thread) into
 *   a third map; exit 1 when any of its updates differs from the projective run's (the hit and missed cells, as sets,
 *   and the cells a batch's close turns possibly occupied: the hidden space's).
 */
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <string>

#include "moverl_planning_scene/cloud_integrator.h"
#include "moverl_planning_scene/occupancy_map.h"
#include "moverl_planning_scene/planning_scene.h"
#include "moverl_planning_scene/sensed_margin.h"
#include "moverl_planning_scene/tunables.h"

namespace mps = moverl_planning_scene;
using Clock = std::chrono::steady_clock;

namespace {

struct Camera {
  std::string id;
  Eigen::Vector3d origin, target;
  int width = 0, height = 0;
  double fov = 0.0, far = 0.0, period = 0.0;
};

/// One cloud as a camera publishes it: organized, optical frame (z forward, x right, y down), and where from.
struct Cloud {
  std::string camera;
  int width = 0, height = 0;
  std::vector<float> xyz;
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();  ///< optical frame in the base frame
  std::vector<double> joints;
  double person_y = std::numeric_limits<double>::quiet_NaN();  ///< synthetic scene: where the person stood
  double stamp = 0.0;  ///< s: when it was taken (the clouds of one instant are one batch of the map's hidden space)
};

/// Synthetic scene: is p inside the person (the walking cylinder) standing at person_y?
bool insidePerson(const Eigen::Vector3d& p, double person_y) {
  return p.z() >= 0.14 && p.z() <= 0.72 && std::hypot(p.x() - 0.8, p.y() - person_y) < 0.165;
}

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
  // The torso's top (a closed solid: the cameras above must not see into it).
  if (std::fabs(d.z()) > 1e-12) {
    const double s = (0.72 - o.z()) / d.z();
    const Eigen::Vector3d p = o + s * d;
    if (s > 0.0 && s < best && std::hypot(p.x() - cx, p.y() - cy) <= r) best = s;
  }
  return best;
}

/// The optical frame of a camera at c.origin looking at c.target (x right, y down, z forward).
Eigen::Isometry3d opticalPose(const Camera& c) {
  const Eigen::Vector3d fwd = (c.target - c.origin).normalized();
  const Eigen::Vector3d right = fwd.cross(Eigen::Vector3d::UnitZ()).normalized(), down = fwd.cross(right);
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear().col(0) = right;
  pose.linear().col(1) = down;
  pose.linear().col(2) = fwd;
  pose.translation() = c.origin;
  return pose;
}

Cloud render(const Camera& c, double person_y, const std::vector<double>& joints) {
  Cloud out;
  out.camera = c.id;
  out.width = c.width;
  out.height = c.height;
  out.pose = opticalPose(c);
  out.joints = joints;
  out.person_y = person_y;
  const Eigen::Matrix3d r = out.pose.linear();
  const double f = 0.5 * c.height / std::tan(0.5 * c.fov * M_PI / 180.0);  // vertical field of view (PyBullet's)
  out.xyz.reserve(3 * static_cast<std::size_t>(c.width) * c.height);
  for (int v = 0; v < c.height; ++v) {
    for (int u = 0; u < c.width; ++u) {
      const Eigen::Vector3d ray((u + 0.5 - 0.5 * c.width) / f, (v + 0.5 - 0.5 * c.height) / f, 1.0);
      const Eigen::Vector3d d = (r * ray).normalized();
      // A depth camera reports depth along its axis: a far-plane pixel lies on the far plane, not on a sphere.
      const double s = castRay(c.origin, d, person_y, c.far * ray.norm());
      const Eigen::Vector3d p = ray * (s / ray.norm());
      for (int i = 0; i < 3; ++i) out.xyz.push_back(static_cast<float>(p[i]));
    }
  }
  return out;
}

Eigen::Vector3d vec3(const YAML::Node& n) {
  return Eigen::Vector3d(n[0].as<double>(), n[1].as<double>(), n[2].as<double>());
}
Eigen::Isometry3d pose(const YAML::Node& xyz, const YAML::Node& quat) {
  Eigen::Isometry3d p = Eigen::Isometry3d::Identity();
  p.linear() =
      Eigen::Quaterniond(quat[3].as<double>(), quat[0].as<double>(), quat[1].as<double>(), quat[2].as<double>())
          .normalized()
          .toRotationMatrix();
  p.translation() = vec3(xyz);
  return p;
}

/// A recording of record_clouds.py: its clouds and static objects. Throws with the file's name on a bad one.
std::vector<Cloud> loadRecording(const std::string& dir, std::vector<mps::WorldObject>* objects, std::string* world) {
  const YAML::Node root = YAML::LoadFile(dir + "/recording.yaml");
  *world = root["world"].as<std::string>();
  for (const auto& o : root["static_objects"]) {
    mps::WorldObject w;
    w.id = o["id"].as<std::string>();
    const std::string type = o["type"].as<std::string>();
    if (type == "box") {
      w.type = mps::ShapeType::kBox;
    } else if (type == "sphere") {
      w.type = mps::ShapeType::kSphere;
    } else if (type == "cylinder") {
      w.type = mps::ShapeType::kCylinder;
    } else if (type == "cone") {
      w.type = mps::ShapeType::kCone;
    } else {
      throw std::runtime_error("static object '" + w.id + "': type '" + type + "' (box, sphere, cylinder, cone)");
    }
    w.dimensions = o["dimensions"].as<std::vector<double>>();
    w.pose = pose(o["xyz"], o["quat"]);
    objects->push_back(w);
  }
  std::vector<Cloud> clouds;
  for (const auto& c : root["clouds"]) {
    Cloud cloud;
    cloud.camera = c["camera"].as<std::string>();
    cloud.width = c["width"].as<int>();
    cloud.height = c["height"].as<int>();
    cloud.pose = pose(c["xyz"], c["quat"]);
    cloud.joints = c["joints"].as<std::vector<double>>();
    cloud.stamp = c["t"].as<double>();
    const std::string file = dir + "/" + c["file"].as<std::string>();
    std::ifstream in(file, std::ios::binary);
    cloud.xyz.resize(3 * static_cast<std::size_t>(cloud.width) * cloud.height);
    in.read(reinterpret_cast<char*>(cloud.xyz.data()), static_cast<std::streamsize>(cloud.xyz.size() * 4));
    if (!in || in.peek() != EOF)
      throw std::runtime_error(file + ": not " + std::to_string(cloud.xyz.size()) + " floats");
    clouds.push_back(std::move(cloud));
  }
  if (clouds.empty()) throw std::runtime_error(dir + "/recording.yaml lists no clouds");
  return clouds;
}

void report(const char* what, std::vector<double> t) {
  if (t.empty()) return;
  std::sort(t.begin(), t.end());
  double sum = 0.0;
  for (double v : t) sum += v;
  std::printf("  %-32s n=%4zu  mean %8.2f ms  p50 %8.2f ms  max %8.2f ms\n", what, t.size(), 1e3 * sum / t.size(),
              1e3 * t[t.size() / 2], 1e3 * t.back());
}

int usage(const char* why) {
  std::fprintf(stderr,
               "error: %s\nusage: map_benchmark [world.yaml with cameras:] [clouds > 0] [--size WxH] "
               "[--recording DIR] [--threads N] [--resolution M] [--check] [--identity] [--projective-only]\n",
               why);
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  std::string world = MOVERL_CONFIG_DIR "/../worlds/human.yaml", recording;
  int clouds_wanted = 60, width = 0, height = 0, threads = 0;
  double resolution = 0.0;
  bool check = false, identity = false, projective_only = false;
  std::vector<std::string> positional;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--check") {
      check = true;
    } else if (a == "--identity") {
      identity = true;
    } else if (a == "--projective-only") {
      projective_only = true;
    } else if (a == "--size" || a == "--recording" || a == "--threads" || a == "--resolution") {
      if (i + 1 >= argc) return usage((a + " needs a value").c_str());
      const std::string v = argv[++i];
      if (a == "--recording") {
        recording = v;
      } else if (a == "--threads") {
        threads = std::atoi(v.c_str());
        if (threads < 1) return usage("--threads takes a number >= 1");
      } else if (a == "--resolution") {
        char* end = nullptr;
        resolution = std::strtod(v.c_str(), &end);
        if (end == v.c_str() || *end != '\0' || !(resolution > 0.0) || !std::isfinite(resolution)) {
          return usage("--resolution takes a cell edge in metres > 0 (e.g. 0.03)");
        }
      } else if (std::sscanf(v.c_str(), "%dx%d", &width, &height) != 2 || width < 2 || height < 2) {
        return usage("--size takes WxH, both >= 2 (e.g. 640x480)");
      }
    } else if (a.rfind("--", 0) == 0) {
      return usage(("unknown option " + a +
                    " (--size, --recording, --threads, --resolution, --check, --identity, --projective-only)")
                       .c_str());
    } else {
      positional.push_back(a);
    }
  }
  if (positional.size() > 2) return usage("at most two positional arguments");
  if (check && !recording.empty())
    return usage("--check needs the synthetic scene (a recording has no person to check)");
  if (!positional.empty() && !positional[0].empty()) world = positional[0];
  if (positional.size() > 1) clouds_wanted = std::atoi(positional[1].c_str());
  if (clouds_wanted <= 0) return usage("clouds must be > 0");

  std::string error, uri;
  mps::PlanningSceneOptions o;
  const auto tunables = mps::YamlTunables::fromFile(MOVERL_CONFIG_DIR "/planning_scene.yaml", &error);
  if (!tunables || !mps::loadRobotConfig(MOVERL_CONFIG_DIR "/robots/panda.yaml", &o.robot, &uri, &error)) {
    std::fprintf(stderr, "error: %s\n", error.c_str());
    return 1;
  }
  std::vector<Cloud> clouds;
  std::vector<mps::WorldObject> objects;
  std::string source;
  try {
    mps::readSceneTunables(*tunables, &o);
    if (!recording.empty()) {
      clouds = loadRecording(recording, &objects, &world);
      source = "recording " + recording;
    } else {
      std::vector<Camera> cams;
      for (const auto& c : YAML::LoadFile(world)["cameras"]) {
        Camera cam;
        cam.id = c["id"].as<std::string>();
        cam.origin = vec3(c["xyz"]);
        cam.target = vec3(c["target"]);
        cam.width = width > 0 ? width : c["width"].as<int>();
        cam.height = height > 0 ? height : c["height"].as<int>();
        cam.fov = c["fov"].as<double>();
        cam.far = c["far"].as<double>();
        cam.period = 1.0 / c["rate"].as<double>();
        cams.push_back(cam);
      }
      if (cams.empty()) return usage((world + " lists no cameras").c_str());
      const std::vector<double> home = {0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785};
      double sim_time = 0.0;
      for (int k = 0; k < clouds_wanted; ++k) {
        const Camera& c = cams[static_cast<std::size_t>(k) % cams.size()];
        if (k % cams.size() == 0 && k > 0) sim_time += c.period;
        clouds.push_back(render(c, 0.15 * std::sin(2 * M_PI * sim_time / 6.0), home));
        clouds.back().stamp = sim_time;
      }
      mps::WorldObject table;  // the synthetic scene's table top, as worlds/human.yaml's
      table.id = "table";
      table.dimensions = {1.5, 0.8, 0.03};
      table.pose.translation() = Eigen::Vector3d(0.35, 0.0, -0.015);
      objects.push_back(table);
      source = "synthetic scene, cameras of " + world;
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
  const std::string urdf_file = MOVERL_PANDA_URDF;
  o.robot.mesh_base_dir = urdf_file.substr(0, urdf_file.rfind('/'));
  std::ifstream urdf_in(urdf_file);
  std::stringstream urdf;
  urdf << urdf_in.rdbuf();
  auto scene = mps::PlanningScene::create(urdf.str(), o, &error);
  if (!scene || !scene->setWorld(objects, &error)) {
    std::fprintf(stderr, "error: %s\n", error.c_str());
    return 1;
  }
  mps::OccupancyMapOptions mo;
  mps::CloudIntegratorOptions io;
  mps::SensedMarginRule rule;  // the margin's tunables (the box the node maps, below)
  try {
    mps::readOccupancyMapTunables(*tunables, &mo);
    io.self_filter_padding = tunables->require<double>("octomap/self_filter_padding");
    io.static_filter_padding = tunables->require<double>("octomap/static_filter_padding");
    io.threads = threads > 0 ? threads : tunables->require<int>("octomap/integration_threads");
    if (resolution > 0.0) mo.resolution = resolution;
    mps::readSensedMarginTunables(*tunables, &rule);
    mo.hidden_space = true;  // as the scene node: the clouds of one instant are one batch
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
  io.filter_static = true;  // obstacles: sensed (the world's static objects are known)
  // The world's sensing: its speed bound (replaces octomap/speed_bound) and unknown_occupied (default on), as
  // moverl_sim.world reads them and the scene node takes them.
  try {
    const YAML::Node sensing = YAML::LoadFile(world)["sensing"];
    mo.unknown_occupied = !(sensing && sensing["unknown_occupied"]) || sensing["unknown_occupied"].as<bool>();
    if (sensing && sensing["speed_bound"]) rule.speed_bound = sensing["speed_bound"].as<double>();
    mo.speed_bound = rule.speed();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s: %s\n", world.c_str(), e.what());
    return 1;
  }
  // The box the scene node maps (OctomapMonitor::init): the robot's padded reach and the largest margin a check uses.
  mo.bounds = mps::sensedMapBounds(scene->checker().reachRadius() + scene->checker().options().padding,
                                   rule.largestMargin(mo.resolution));
  struct Run {
    mps::Integration integration;
    std::unique_ptr<mps::OccupancyMap> map;
    std::unique_ptr<mps::CloudIntegrator> integrator;
    std::vector<double> t_points, t_self, t_static, t_update, t_known_free, t_apply, t_close, t_total;
    std::map<std::string, std::vector<double>> camera_update, camera_close;  ///< per camera id, after the fill
    std::size_t hidden = 0, stale = 0, batches = 0;
    std::vector<double> t_steady;  ///< total, the clouds after each camera's fill views
    std::size_t free_cells = 0, changed = 0, fallbacks = 0, freed_inside = 0, reused = 0;
  };
  Run runs[2];
  runs[0].integration = mps::Integration::kRayCasting;
  runs[1].integration = mps::Integration::kProjective;
  for (Run& r : runs) {
    r.map = mps::OccupancyMap::create(mo, &error);
    if (!r.map) {
      std::fprintf(stderr, "error: %s\n", error.c_str());
      return 1;
    }
    io.integration = r.integration;
    r.integrator = std::make_unique<mps::CloudIntegrator>(r.map.get(), &scene->checker(), nullptr, io);
  }
  // --identity: a third map, integrated by projection with every block evaluated.
  std::unique_ptr<mps::OccupancyMap> reference_map;
  std::unique_ptr<mps::CloudIntegrator> reference;
  std::size_t identity_failures = 0;
  std::vector<double> reference_total, reference_update;
  if (identity) {
    mps::OccupancyMapOptions every_block = mo;
    every_block.skip_unchanged_blocks = false;
    reference_map = mps::OccupancyMap::create(every_block, &error);
    io.integration = mps::Integration::kProjective;
    io.threads = 1;
    reference = std::make_unique<mps::CloudIntegrator>(reference_map.get(), &scene->checker(), nullptr, io);
  }
  std::printf(
      "%s: %zu clouds of %d x %d px; map resolution %.3f m within +-%.2f m (the robot's reach, and a margin for "
      "%.2f m/s); live filters (self, static%s); %d thread%s\n",
      source.c_str(), clouds.size(), clouds[0].width, clouds[0].height, mo.resolution, mo.bounds.max().x(),
      rule.speed_bound, mo.unknown_occupied ? ", known free: unknown_occupied" : "", runs[0].integrator->threads(),
      runs[0].integrator->threads() == 1 ? "" : "s");
  std::vector<std::string> first_seen;
  std::vector<int> views_of;  // per camera in first_seen, its clouds so far
  // A camera's views that fill the map from unknown: each sees free again every cell the ones before saw free, until
  // those cells reach clamp_min.
  const int fill_views = runs[1].map->missesToClampFree();
  std::size_t ray_only_person = 0, ray_only_max = 0, ray_only_clouds = 0, proj_only_sum = 0, proj_only_max = 0,
              compared = 0;
  mps::MapUpdate u, close;
  std::vector<Eigen::Vector3d> centers;
  // The hidden space's batches: a cloud stamped later than the one before closes the open batch first (as the scene
  // node's integration does), the last cloud closes its own. The close's cost counts against the cloud that closes.
  auto close_batch = [&](mps::CloudIntegrator* integrator, mps::OccupancyMap* map, bool begin_at, double stamp,
                         Run* r) {
    const auto t0 = Clock::now();
    mps::BatchStats bs;
    const bool closed = begin_at ? integrator->beginView(stamp, &close) : integrator->closeBatch(&close, &bs);
    if (closed) map->apply(close);
    const double s = std::chrono::duration<double>(Clock::now() - t0).count();
    if (r != nullptr && closed && !begin_at) {
      r->hidden += bs.hidden;
      r->stale += bs.stale;
      ++r->batches;
    }
    return closed ? s : 0.0;
  };
  for (std::size_t ci = 0; ci < clouds.size(); ++ci) {
    const Cloud& c = clouds[ci];
    const bool batch_ends = ci + 1 == clouds.size() || clouds[ci + 1].stamp != c.stamp;
    const auto camera =
        static_cast<std::size_t>(std::find(first_seen.begin(), first_seen.end(), c.camera) - first_seen.begin());
    if (camera == first_seen.size()) {
      first_seen.push_back(c.camera);
      views_of.push_back(0);
    }
    const int view_index = views_of[camera]++;
    const bool first = view_index == 0;
    // The two integrations take turns going first (the first warms the caches for the second's filters).
    for (int turn = 0; turn < 2; ++turn) {
      Run& r = runs[(turn + compared) % 2];
      if (projective_only && r.integration != mps::Integration::kProjective) continue;
      mps::CloudTiming t;
      std::string why;
      mps::CloudView view;
      view.data = reinterpret_cast<const std::uint8_t*>(c.xyz.data());
      view.width = c.width;
      view.height = c.height;
      view.row_step = 12 * static_cast<std::size_t>(c.width);
      double closing = close_batch(r.integrator.get(), r.map.get(), true, c.stamp, nullptr);
      const auto used = r.integrator->compute(view, c.pose, {c.joints}, &u, &t, &why);
      if (used != r.integration) {
        ++r.fallbacks;
        std::fprintf(stderr, "%s: cloud of %s fell back to ray casting: %s\n", mps::integrationName(r.integration),
                     c.camera.c_str(), why.c_str());
      }
      if (reference && r.integration == mps::Integration::kProjective) {
        // The same cloud with every block evaluated: the same hits and misses (as sets), or --identity fails.
        mps::MapUpdate full;
        mps::CloudTiming tr;
        close_batch(reference.get(), reference_map.get(), true, c.stamp, nullptr);
        reference->compute(view, c.pose, {c.joints}, &full, &tr, nullptr);
        const auto a0 = Clock::now();
        reference_map->apply(full);
        if (!first) {
          reference_total.push_back(tr.total() + std::chrono::duration<double>(Clock::now() - a0).count());
          reference_update.push_back(tr.update);
        }
        auto same = [](std::vector<std::uint64_t> a, std::vector<std::uint64_t> b) {
          std::sort(a.begin(), a.end());
          std::sort(b.begin(), b.end());
          return a == b;
        };
        mps::MapUpdate mine_close, full_close;
        if (batch_ends) {
          // The two maps' closes, compared below (their stale cells), applied after.
          r.map->apply(u);
          if (r.integrator->closeBatch(&mine_close)) r.map->apply(mine_close);
          if (reference->closeBatch(&full_close)) reference_map->apply(full_close);
        }
        if (!same(u.hits, full.hits) || !same(u.misses, full.misses) || !same(mine_close.stale, full_close.stale)) {
          ++identity_failures;
          std::fprintf(
              stderr, "identity: cloud %zu of %s: %zu hits, %zu misses with skip_unchanged_blocks, %zu, %zu without\n",
              compared, c.camera.c_str(), u.hits.size(), u.misses.size(), full.hits.size(), full.misses.size());
        }
      }
      // A cell whose centre lies inside the person holds part of the person: seeing it free is a miss of the map.
      if (!std::isnan(c.person_y)) {
        for (std::uint64_t key : u.misses) r.freed_inside += insidePerson(r.map->cellCentre(key), c.person_y) ? 1 : 0;
      }
      const auto t0 = Clock::now();
      const bool compared_closes = reference && r.integration == mps::Integration::kProjective && batch_ends;
      if (!compared_closes) r.map->apply(u);  // (else applied above, with the close)
      const double apply = std::chrono::duration<double>(Clock::now() - t0).count();
      if (batch_ends && !compared_closes) closing += close_batch(r.integrator.get(), r.map.get(), false, c.stamp, &r);
      if (first) continue;  // the first view of each camera fills the map from unknown: left out
      r.t_points.push_back(t.points);
      r.t_self.push_back(t.self_filter);
      r.t_static.push_back(t.static_filter);
      r.t_update.push_back(t.update);
      if (mo.unknown_occupied) r.t_known_free.push_back(t.known_free);
      r.t_apply.push_back(apply);
      r.t_close.push_back(closing);
      r.t_total.push_back(t.total() + apply + closing);
      if (view_index >= fill_views) {
        r.t_steady.push_back(t.total() + apply + closing);
        r.camera_update[c.camera].push_back(t.update);
        r.camera_close[c.camera].push_back(closing);
      }
      r.free_cells += u.stats.free_cells;
      r.changed += u.stats.changed_cells;
      r.reused += u.stats.reused_blocks;
    }

    // The occupied cells of the two maps: the ray-cast map's that the projective map lacks (cells it cleared, rightly
    // or not: inside the person, in the synthetic scene, is the wrong kind), and the
    // projective map's extra ones (cells it clears later, or not).
    std::size_t ray_only = 0, proj_only = 0;
    runs[0].map->occupiedLeaves(&centers, nullptr);
    for (const auto& p : centers) {
      if (runs[1].map->occupied(p)) continue;
      ++ray_only;
      if (!std::isnan(c.person_y) && insidePerson(p, c.person_y)) ++ray_only_person;
    }
    runs[1].map->occupiedLeaves(&centers, nullptr);
    for (const auto& p : centers) proj_only += runs[0].map->occupied(p) ? 0 : 1;
    ++compared;
    ray_only_max = std::max(ray_only_max, ray_only);
    ray_only_clouds += ray_only > 0 ? 1 : 0;
    proj_only_sum += proj_only;
    proj_only_max = std::max(proj_only_max, proj_only);
  }
  double points = 0.0;  // per later cloud, mean
  for (std::size_t k = 0; k < clouds.size(); ++k) points += static_cast<double>(clouds[k].xyz.size() / 3);
  points /= static_cast<double>(clouds.size());
  double mean_total[2] = {0.0, 0.0};
  for (int k = 0; k < 2; ++k) {
    Run& r = runs[k];
    std::printf("%s (later clouds; each camera's first view fills the map from unknown and is left out):\n",
                mps::integrationName(r.integration));
    const bool projective = r.integration == mps::Integration::kProjective;
    report(projective ? "points, the pinhole fit" : "points into the map frame", r.t_points);
    report("self filter", r.t_self);
    report("static filter", r.t_static);
    report(projective ? "update (projective)" : "update (ray casting)", r.t_update);
    report("known free (unknown_occupied)", r.t_known_free);
    report("apply", r.t_apply);
    report("hidden space (batch close)", r.t_close);
    report("total", r.t_total);
    if (r.integration == mps::Integration::kProjective) {
      report("total after the map's fill", r.t_steady);
      for (const auto& [camera, update] : r.camera_update) {
        report(("  " + camera + ": update").c_str(), update);
        report(("  " + camera + ": batch close").c_str(), r.camera_close[camera]);
      }
      std::printf(
          "    (the fill: each camera's first %d views, which see free again the cells the ones before saw free, "
          "until they reach clamp_min)\n",
          fill_views);
    }
    const std::size_t n = std::max<std::size_t>(1, r.t_total.size());
    for (double v : r.t_total) mean_total[k] += v / n;
    std::printf(
        "  per cloud: %zu cells seen free, %zu cells changed%s; %zu occupied cells at the end; %.2f million "
        "points/s; %zu fallbacks to ray casting\n",
        r.free_cells / n, r.changed / n,
        r.integration == mps::Integration::kProjective
            ? (", " + std::to_string(r.reused / n) + " blocks not evaluated (the camera's last view repeated)").c_str()
            : "",
        r.map->occupiedLeafCount(), mean_total[k] > 0 ? points / mean_total[k] / 1e6 : 0.0, r.fallbacks);
    if (r.batches > 0) {
      std::printf(
          "  hidden space: %zu batches; per batch %.0f watched free cells no view saw, %.1f of them turned stale; "
          "%zu stale cells at the end\n",
          r.batches, static_cast<double>(r.hidden) / r.batches, static_cast<double>(r.stale) / r.batches,
          r.map->staleCount());
    }
    if (recording.empty()) {
      std::printf("  cells seen free with their centre inside the person (all clouds): %zu\n", r.freed_inside);
    }
  }
  std::printf("projective / ray casting, mean total per cloud: %.3f (%.2f ms vs %.2f ms)\n",
              mean_total[1] / mean_total[0], 1e3 * mean_total[1], 1e3 * mean_total[0]);
  std::printf(
      "occupied cells after each of %zu clouds: ray-cast map's missing from the projective map: max %zu (in %zu "
      "clouds); projective map's extra: mean %.1f, max %zu\n",
      compared, ray_only_max, ray_only_clouds, static_cast<double>(proj_only_sum) / compared, proj_only_max);
  if (recording.empty()) {
    std::printf("  of the ray-cast map's missing cells, with their centre inside the person (all clouds): %zu\n",
                ray_only_person);
  }
  if (identity) {
    std::printf("projective, every block evaluated (skip_unchanged_blocks off, the same clouds):\n");
    report("update (projective)", reference_update);
    report("total", reference_total);
    std::printf("identity (skip_unchanged_blocks against every block evaluated): %zu of %zu updates differ\n",
                identity_failures, clouds.size());
    if (identity_failures > 0) return 1;
  }
  if (check && (runs[0].freed_inside > 0 || runs[1].freed_inside > 0)) {
    std::printf("CHECK FAILED: cells inside the person were seen free\n");
    return 1;
  }
  return 0;
}
