#include "moverl_planning_scene/tunables.h"

#include <cmath>
#include <map>
#include <sstream>
#include <stdexcept>
#include <vector>

#include <yaml-cpp/yaml.h>

namespace moverl_planning_scene {

struct YamlTunables::Impl {
  std::string path;
  YAML::Node root;

  /// The node at "a/b/c", or an invalid node.
  YAML::Node find(const std::string& key) const {
    YAML::Node node = YAML::Clone(root);
    std::stringstream parts(key);
    std::string part;
    while (std::getline(parts, part, '/')) {
      if (!node.IsMap() || !node[part]) return YAML::Node(YAML::NodeType::Undefined);
      node = node[part];
    }
    return node.IsScalar() ? node : YAML::Node(YAML::NodeType::Undefined);
  }

  template <class T>
  bool as(const std::string& key, T* value) const {
    const YAML::Node node = find(key);
    if (!node.IsDefined()) return false;
    try {
      *value = node.as<T>();
      return true;
    } catch (const YAML::Exception&) {
      return false;
    }
  }
};

YamlTunables::YamlTunables(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
YamlTunables::~YamlTunables() = default;

std::unique_ptr<YamlTunables> YamlTunables::fromFile(const std::string& path, std::string* error) {
  auto impl = std::make_unique<Impl>();
  impl->path = path;
  try {
    impl->root = YAML::LoadFile(path);
  } catch (const YAML::Exception& e) {
    if (error != nullptr) *error = path + ": " + e.what();
    return nullptr;
  }
  if (!impl->root.IsMap()) {
    if (error != nullptr) *error = path + ": not a map of tunables";
    return nullptr;
  }
  return std::unique_ptr<YamlTunables>(new YamlTunables(std::move(impl)));
}

bool YamlTunables::get(const std::string& key, double* value) const { return impl_->as(key, value); }
bool YamlTunables::get(const std::string& key, int* value) const { return impl_->as(key, value); }
bool YamlTunables::get(const std::string& key, bool* value) const { return impl_->as(key, value); }
bool YamlTunables::get(const std::string& key, std::string* value) const { return impl_->as(key, value); }
std::string YamlTunables::describe(const std::string& key) const { return impl_->path + ": key " + key; }

void readSceneTunables(const Tunables& t, PlanningSceneOptions* o) {
  o->checker.padding = t.require<double>("padding");
  o->checker.self_padding = t.require<double>("self_padding");
  o->checker.path_resolution = t.require<double>("path_resolution");
  o->checker.acm_samples = t.require<int>("acm_samples");
  o->checker.acm_seed = static_cast<unsigned>(t.require<int>("acm_seed"));
  const std::string mesh_mode = t.require<std::string>("mesh_mode");
  if (mesh_mode == "convex_hull") {
    o->checker.mesh_mode = MeshMode::kConvexHull;
  } else if (mesh_mode == "triangles") {
    o->checker.mesh_mode = MeshMode::kTriangles;
  } else {
    throw std::runtime_error(t.describe("mesh_mode") + " must be convex_hull or triangles, not '" + mesh_mode + "'");
  }
  o->planner.planner = t.require<std::string>("planner");
  o->planner.planning_time = t.require<double>("planning_time");
  o->planner.range = t.require<double>("planner_range");
  o->planner.simplify = t.require<bool>("simplify");
  o->planner.seed = static_cast<unsigned>(t.require<int>("planner_seed"));
}

bool loadRobotConfig(const std::string& path, RobotModelOptions* o, std::string* urdf_uri, std::string* error) {
  try {
    const YAML::Node robot = YAML::LoadFile(path)["robot"];
    if (!robot || !robot.IsMap()) throw std::runtime_error("no robot: map");
    o->joint_names = robot["joints"].as<std::vector<std::string>>();
    o->base_link = robot["base_link"].as<std::string>();
    o->ee_link = robot["ee_link"].as<std::string>();
    o->fixed_joint_positions.clear();
    if (robot["fixed_joint_positions"]) {
      o->fixed_joint_positions = robot["fixed_joint_positions"].as<std::map<std::string, double>>();
    }
    *urdf_uri = robot["urdf"].as<std::string>();
  } catch (const std::exception& e) {
    if (error != nullptr) *error = path + ": " + e.what();
    return false;
  }
  return true;
}

bool loadWorldBox(const std::string& path, const std::string& id, WorldObject* box, std::string* error) {
  try {
    const YAML::Node objects = YAML::LoadFile(path)["objects"];
    if (!objects || !objects.IsSequence()) throw std::runtime_error("no objects: list");
    std::string ids;
    for (const auto& o : objects) {
      const auto oid = o["id"].as<std::string>();
      if (oid != id) {
        ids += (ids.empty() ? "" : ", ") + oid;
        continue;
      }
      if (o["shape"].as<std::string>() != "box") throw std::runtime_error("object " + id + " is not a box");
      const auto size = o["size"].as<std::vector<double>>();
      const auto xyz = o["xyz"].as<std::vector<double>>();
      const auto rpy = o["rpy"] ? o["rpy"].as<std::vector<double>>() : std::vector<double>(3, 0.0);
      if (size.size() != 3 || xyz.size() != 3 || rpy.size() != 3) {
        throw std::runtime_error("object " + id + ": size, xyz and rpy take 3 numbers each");
      }
      box->id = id;
      box->type = ShapeType::kBox;
      box->dimensions = size;
      box->pose = Eigen::Translation3d(xyz[0], xyz[1], xyz[2]) * Eigen::AngleAxisd(rpy[2], Eigen::Vector3d::UnitZ()) *
                  Eigen::AngleAxisd(rpy[1], Eigen::Vector3d::UnitY()) *
                  Eigen::AngleAxisd(rpy[0], Eigen::Vector3d::UnitX());
      box->motion = ObstacleMotion();
      return true;
    }
    throw std::runtime_error("no object " + id + " (objects: " + ids + ")");
  } catch (const std::exception& e) {
    if (error != nullptr) *error = path + ": " + e.what();
    return false;
  }
}

void readOccupancyMapTunables(const Tunables& t, OccupancyMapOptions* o) {
  o->resolution = t.require<double>("octomap/resolution");
  o->max_range = t.require<double>("octomap/max_range");
  o->prob_hit = t.require<double>("octomap/prob_hit");
  o->prob_miss = t.require<double>("octomap/prob_miss");
  o->clamp_min = t.require<double>("octomap/clamp_min");
  o->clamp_max = t.require<double>("octomap/clamp_max");
  o->occupancy_threshold = t.require<double>("octomap/occupancy_threshold");
  o->watch_time = t.require<double>("octomap/watch_time");
  o->fixture_pullback = t.require<double>("octomap/static_filter_padding");  // (the fixture points' distance)
}

void readSensedMarginTunables(const Tunables& t, SensedMarginRule* rule) {
  const std::string safety = t.require<std::string>("octomap/safety");
  if (!parseSafety(safety, &rule->safety)) {
    throw std::runtime_error("octomap/safety: unknown safety definition '" + safety + "' (valid: " + safetyNames() +
                             ")");
  }
  rule->speed_bound = t.require<double>("octomap/speed_bound");
  rule->latency = t.require<double>("octomap/latency");
  rule->plan_horizon = t.require<double>("octomap/plan_horizon");
  rule->max_age = t.require<double>("octomap/max_age");
  rule->iso.intrusion = t.require<double>("octomap/ssm/intrusion");  // read (and checked) under either safety
  rule->uncertainty = t.require<double>("octomap/ssm/sensor_uncertainty");
  for (const auto& p :
       {std::make_pair("speed_bound", rule->speed_bound), std::make_pair("latency", rule->latency),
        std::make_pair("plan_horizon", rule->plan_horizon), std::make_pair("ssm/intrusion", rule->iso.intrusion),
        std::make_pair("ssm/sensor_uncertainty", rule->uncertainty)}) {
    if (!(p.second >= 0.0) || !std::isfinite(p.second)) {
      throw std::runtime_error(std::string("octomap/") + p.first + " must be finite and >= 0");
    }
  }
  if (!(rule->max_age > 0.0)) throw std::runtime_error("octomap/max_age must be > 0 (.inf: no limit)");
  const std::string bad = rule->problem();
  if (!bad.empty()) throw std::runtime_error(bad);
}

bool readOctomapMonitorOptions(const Tunables& t, OctomapMonitorOptions* o, std::string* error) {
  std::string integration;
  try {
    readOccupancyMapTunables(t, &o->map);
    o->self_filter_padding = t.require<double>("octomap/self_filter_padding");
    o->static_filter_padding = t.require<double>("octomap/static_filter_padding");
    o->future_tolerance = t.require<double>("octomap/future_tolerance");
    o->camera_wait = t.require<double>("octomap/camera_wait");
    o->batch_wait = t.require<double>("octomap/batch_wait");
    o->transform_timeout = t.require<double>("octomap/transform_timeout");
    o->joint_state_wait = t.require<double>("octomap/joint_state_wait");
    o->cloud_topic = t.require<std::string>("octomap/cloud_topic");
    o->joint_states_topic = t.require<std::string>("octomap/joint_states_topic");
    o->queue_size = t.require<int>("octomap/queue_size");
    o->startup_timeout = t.require<double>("octomap/startup_timeout");
    readSensedMarginTunables(t, &o->margin);
    o->stale_wait = t.require<double>("octomap/stale_wait");
    o->lockstep = t.require<bool>("octomap/lockstep");
    o->lockstep_lag = o->lockstep && t.require<bool>("octomap/lockstep_lag");
    o->lockstep_lag_max_margin = t.require<double>("octomap/lockstep_lag_max_margin");
    o->track_people = t.require<bool>("octomap/ssm/tracking/use");
    o->tracking.motion.max_speed = t.require<double>("octomap/ssm/tracking/max_speed");
    o->tracking.position_error = t.require<double>("octomap/ssm/tracking/position_error");
    o->tracking.max_age = t.require<double>("octomap/ssm/tracking/max_age");
    const std::string bad = o->tracking.problem();
    if (!bad.empty()) throw std::runtime_error("octomap/ssm/tracking: " + bad);
    std::string parts_error;
    if (!parsePartRadii(t.require<std::string>("octomap/ssm/tracking/parts"), &o->part_radii, &parts_error)) {
      throw std::runtime_error("octomap/ssm/tracking/parts: " + parts_error);
    }
    if (o->track_people && o->margin.safety != Safety::kSsm) {
      throw std::runtime_error("octomap/ssm/tracking/use: the tracked people are ssm's (octomap/safety is " +
                               safetyName(o->margin.safety) + ")");
    }
    integration = t.require<std::string>("octomap/integration");
    o->integration_threads = t.require<int>("octomap/integration_threads");
  } catch (const std::exception& e) {
    if (error != nullptr) *error = e.what();
    return false;
  }
  for (const auto& p :
       {std::make_pair("stale_wait", o->stale_wait), std::make_pair("self_filter_padding", o->self_filter_padding),
        std::make_pair("static_filter_padding", o->static_filter_padding),
        std::make_pair("future_tolerance", o->future_tolerance), std::make_pair("camera_wait", o->camera_wait),
        std::make_pair("batch_wait", o->batch_wait),
        std::make_pair("lockstep_lag_max_margin", o->lockstep_lag_max_margin)}) {
    if (!(p.second >= 0.0) || !std::isfinite(p.second)) {
      if (error != nullptr) *error = std::string("octomap/") + p.first + " must be finite and >= 0";
      return false;
    }
  }
  if (!parseIntegration(integration, &o->integration, error)) return false;
  if (o->integration_threads < 1) {
    if (error != nullptr) {
      *error = "octomap/integration_threads must be >= 1, not " + std::to_string(o->integration_threads);
    }
    return false;
  }
  return true;
}

}  // namespace moverl_planning_scene
