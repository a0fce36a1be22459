/**
 * \file scene_server.cpp
 * \brief SceneServer: the planning scene's parameters, world, services and sensed-obstacle monitor (see the header).
 */
#include "moverl_planning_scene/scene_server.h"

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <exception>

#include <ros/package.h>
#include <shape_msgs/SolidPrimitive.h>
#include <std_msgs/Bool.h>

#include "moverl_planning_scene/octomap_monitor.h"
#include "moverl_planning_scene/ros_param.h"

namespace moverl_planning_scene {
namespace {

const char* const kYaml = "load config/planning_scene.yaml";

// The core's outcome codes are the services' codes: checked here, where both are visible, at compile time.
template <class E>
constexpr std::uint8_t code(E e) {
  return static_cast<std::uint8_t>(e);
}
using CheckRes = moverl_msgs::CheckState::Response;
using PathRes = moverl_msgs::CheckPath::Response;
using PlanRes = moverl_msgs::PlanPath::Response;
using MotionRes = moverl_msgs::ValidateMotion::Response;
static_assert(code(CheckOutcome::kValid) == CheckRes::VALID &&
                  code(CheckOutcome::kSelfCollision) == CheckRes::SELF_COLLISION &&
                  code(CheckOutcome::kWorldCollision) == CheckRes::WORLD_COLLISION &&
                  code(CheckOutcome::kInvalidRequest) == CheckRes::INVALID_REQUEST &&
                  code(CheckOutcome::kMapStale) == CheckRes::MAP_STALE,
              "CheckOutcome differs from moverl_msgs/CheckState");
static_assert(code(CheckOutcome::kValid) == PathRes::VALID &&
                  code(CheckOutcome::kSelfCollision) == PathRes::SELF_COLLISION &&
                  code(CheckOutcome::kWorldCollision) == PathRes::WORLD_COLLISION &&
                  code(CheckOutcome::kInvalidRequest) == PathRes::INVALID_REQUEST &&
                  code(CheckOutcome::kMapStale) == PathRes::MAP_STALE,
              "CheckOutcome differs from moverl_msgs/CheckPath");
static_assert(code(PlanStatus::kSuccess) == PlanRes::SUCCESS &&
                  code(PlanStatus::kStartInvalid) == PlanRes::START_INVALID &&
                  code(PlanStatus::kGoalInvalid) == PlanRes::GOAL_INVALID &&
                  code(PlanStatus::kNoSolution) == PlanRes::NO_SOLUTION &&
                  code(PlanStatus::kInvalidRequest) == PlanRes::INVALID_REQUEST &&
                  code(PlanStatus::kMapStale) == PlanRes::MAP_STALE,
              "PlanStatus differs from moverl_msgs/PlanPath");
static_assert(code(MotionOutcome::kValid) == MotionRes::VALID &&
                  code(MotionOutcome::kSelfCollision) == MotionRes::SELF_COLLISION &&
                  code(MotionOutcome::kPoseCollision) == MotionRes::POSE_COLLISION &&
                  code(MotionOutcome::kPathCollision) == MotionRes::PATH_COLLISION &&
                  code(MotionOutcome::kStartInCollision) == MotionRes::START_IN_COLLISION &&
                  code(MotionOutcome::kInvalidRequest) == MotionRes::INVALID_REQUEST &&
                  code(MotionOutcome::kMapStale) == MotionRes::MAP_STALE,
              "MotionOutcome differs from moverl_msgs/ValidateMotion");

constexpr double kQuaternionEpsilon = 1e-9;

/// ROS world message -> core world objects. False with *error on unsupported shapes.
bool toWorld(const moverl_msgs::World& msg, std::vector<WorldObject>* out, std::string* error) {
  out->clear();
  for (const auto& o : msg.objects) {
    WorldObject w;
    w.id = o.id;
    switch (o.shape.type) {
      case shape_msgs::SolidPrimitive::BOX:
        w.type = ShapeType::kBox;
        break;
      case shape_msgs::SolidPrimitive::SPHERE:
        w.type = ShapeType::kSphere;
        break;
      case shape_msgs::SolidPrimitive::CYLINDER:
        w.type = ShapeType::kCylinder;
        break;
      case shape_msgs::SolidPrimitive::CONE:
        w.type = ShapeType::kCone;
        break;
      default:
        *error = "world object '" + o.id + "': unsupported shape type " + std::to_string(o.shape.type);
        return false;
    }
    w.dimensions.assign(o.shape.dimensions.begin(), o.shape.dimensions.end());
    const auto& q = o.pose.orientation;
    Eigen::Quaterniond rot(q.w, q.x, q.y, q.z);
    // An all-zero quaternion (unset field) means identity.
    rot = rot.norm() < kQuaternionEpsilon ? Eigen::Quaterniond::Identity() : rot.normalized();
    w.pose = Eigen::Isometry3d::Identity();
    w.pose.linear() = rot.toRotationMatrix();
    w.pose.translation() = Eigen::Vector3d(o.pose.position.x, o.pose.position.y, o.pose.position.z);
    if (o.motion.type == moverl_msgs::ObstacleMotion::OSCILLATE ||
        o.motion.type == moverl_msgs::ObstacleMotion::REACH) {
      w.motion.type = o.motion.type == moverl_msgs::ObstacleMotion::REACH ? ObstacleMotion::Type::kReach
                                                                          : ObstacleMotion::Type::kOscillate;
      w.motion.axis = Eigen::Vector3d(o.motion.axis[0], o.motion.axis[1], o.motion.axis[2]);
      w.motion.amplitude = o.motion.amplitude;
      w.motion.period = o.motion.period;
      w.motion.phase = o.motion.phase;
      w.motion.move = o.motion.move;
      w.motion.hold = o.motion.hold;
      w.motion.chance = o.motion.chance;
      w.motion.seed = o.motion.seed;
    } else if (o.motion.type != moverl_msgs::ObstacleMotion::NONE) {
      *error = "world object '" + o.id + "': unknown motion type " + std::to_string(o.motion.type);
      return false;
    }
    out->push_back(std::move(w));
  }
  return true;
}

void toPairs(const std::vector<ContactPair>& in, std::vector<moverl_msgs::CollisionPair>* out) {
  out->resize(in.size());
  for (std::size_t i = 0; i < in.size(); ++i) {
    (*out)[i].a = in[i].a;
    (*out)[i].b = in[i].b;
    (*out)[i].depth = in[i].depth;
  }
}

void toTrajectory(const std::vector<std::vector<double>>& waypoints, const std::vector<std::string>& joints,
                  trajectory_msgs::JointTrajectory* out) {
  out->joint_names = joints;
  out->points.resize(waypoints.size());
  for (std::size_t k = 0; k < waypoints.size(); ++k) out->points[k].positions = waypoints[k];
}

std::string cacheDir() {
  const char* ros_home = std::getenv("ROS_HOME");
  if (ros_home != nullptr && ros_home[0] != '\0') return std::string(ros_home) + "/moverl_cache";
  const char* home = std::getenv("HOME");
  return std::string(home != nullptr ? home : "/tmp") + "/.ros/moverl_cache";
}

/// package://pkg/rest -> <path of ROS package pkg>/rest, "" when unknown.
std::string resolvePackage(const std::string& url) {
  const std::string rest = url.substr(std::string("package://").size());
  const std::size_t slash = rest.find('/');
  if (slash == std::string::npos) return "";
  const std::string pkg_path = ros::package::getPath(rest.substr(0, slash));
  return pkg_path.empty() ? "" : pkg_path + rest.substr(slash);
}

}  // namespace

RobotModelOptions robotOptions(const ros::NodeHandle& nh, std::string* urdf) {
  const std::string robot_yaml = "load config/robots/<robot>.yaml (launch/robot.launch)";
  *urdf = requiredParam<std::string>(nh, "robot_description", robot_yaml);
  RobotModelOptions o;
  o.joint_names = requiredParam<std::vector<std::string>>(nh, "robot/joints", robot_yaml);
  o.base_link = requiredParam<std::string>(nh, "robot/base_link", robot_yaml);
  o.ee_link = requiredParam<std::string>(nh, "robot/ee_link", robot_yaml);
  if (nh.hasParam("robot/fixed_joint_positions") &&  // optional: robots without uncontrolled joints leave it out
      !nh.getParam("robot/fixed_joint_positions", o.fixed_joint_positions)) {
    throw std::runtime_error("parameter " + nh.resolveName("robot/fixed_joint_positions") +
                             " must be a dict {joint: position}");
  }
  o.package_resolver = resolvePackage;
  return o;
}

SceneServer::SceneServer(ros::NodeHandle nh, ros::NodeHandle pnh) : nh_(nh), pnh_(pnh) {}

SceneServer::~SceneServer() = default;

bool SceneServer::init(std::string* error) {
  PlanningSceneOptions o;
  std::string urdf, world_service, world_topic;
  double world_timeout = 0.0;
  try {
    o.robot = robotOptions(nh_, &urdf);
    o.robot.mesh_base_dir = requiredParam<std::string>(pnh_, "urdf_dir", kYaml);
    readSceneTunables(RosTunables(pnh_, kYaml), &o);
    if (requiredParam<bool>(pnh_, "acm_cache", kYaml)) o.checker.acm_cache_dir = cacheDir();
    world_timeout = requiredParam<double>(pnh_, "world_timeout", kYaml);
    const std::string launch = "set by launch/planning_scene.launch";
    obstacles_ = requiredParam<std::string>(pnh_, "obstacles", launch);
    world_service = requiredParam<std::string>(pnh_, "world_service", launch);
    world_topic = requiredParam<std::string>(pnh_, "world_topic", launch);
  } catch (const std::exception& e) {
    *error = e.what();
    return false;
  }
  if (obstacles_ != "objects" && obstacles_ != "octomap" && obstacles_ != "both" && obstacles_ != "sensed") {
    *error = pnh_.resolveName("obstacles") + " must be objects, octomap, both or sensed, not '" + obstacles_ + "'";
    return false;
  }
  planning_time_ = o.planner.planning_time;

  const ros::WallTime t0 = ros::WallTime::now();
  scene_ = PlanningScene::create(urdf, o, error);
  if (!scene_) {
    *error = "cannot build the scene: " + *error;
    return false;
  }
  const AcmStats& acm = scene_->checker().acmStats();
  ROS_INFO(
      "planning_scene: %zu joints, ACM %s in %.2f s (adjacent %d, rigid %d, always %d, never %d, checked %d; never "
      "pairs: closest approach found by search %.1f mm, %d found touching and checked)%s%s",
      scene_->model().dof(), acm.from_cache ? "loaded" : "computed", acm.seconds, acm.adjacent, acm.rigid, acm.always,
      acm.never, acm.enabled, acm.never_min_distance * 1e3, acm.never_refuted, acm.cache_file.empty() ? "" : ", cache ",
      acm.cache_file.c_str());
  ROS_INFO("planning_scene: scene built in %.2f s", (ros::WallTime::now() - t0).toSec());

  // World: synchronous fetch, then mirror the latched topic.
  if (!ros::service::waitForService(world_service, ros::Duration(world_timeout))) {
    *error = "world service " + world_service + " not available after " + std::to_string(world_timeout) +
             " s (is the simulator or the world server running?)";
    return false;
  }
  moverl_msgs::GetWorld get_world;
  if (!ros::service::call(world_service, get_world)) {
    *error = "call to " + world_service + " failed";
    return false;
  }
  if (!applyWorld(get_world.response.world, error)) {
    *error = "invalid world from " + world_service + ": " + *error;
    return false;
  }
  if (obstacles_ != "objects") {
    monitor_ = std::make_unique<OctomapMonitor>(nh_, pnh_, scene_.get(), &mutex_, obstacles_ == "sensed");
    monitor_->setWorldSensing(get_world.response.world.sensed_speed_bound,
                              get_world.response.world.sensed_unknown_occupied, get_world.response.world.camera_frames);
    if (!monitor_->init(error)) return false;
  }
  world_sub_ = nh_.subscribe(world_topic, 1, &SceneServer::onWorld, this);

  services_.push_back(pnh_.advertiseService("check_state", &SceneServer::checkState, this));
  services_.push_back(pnh_.advertiseService("check_path", &SceneServer::checkPath, this));
  services_.push_back(pnh_.advertiseService("plan", &SceneServer::servePlan, this));
  services_.push_back(pnh_.advertiseService("fk", &SceneServer::fk, this));
  services_.push_back(pnh_.advertiseService("validate_motion", &SceneServer::serveValidateMotion, this));
  services_.push_back(pnh_.advertiseService("get_world", &SceneServer::getWorld, this));
  // Facts for other processes (a shield that reaches the scene through its services, tools).
  pnh_.setParam("joint_names", scene_->model().jointNames());
  pnh_.setParam("joint_radius_bounds", jointRadiusBounds());
  ready_pub_ = pnh_.advertise<std_msgs::Bool>("ready", 1, /*latch=*/true);
  std_msgs::Bool ready;
  ready.data = true;
  ready_pub_.publish(ready);
  ROS_INFO("planning_scene: ready in %s (obstacles: %s, %zu world objects)", pnh_.getNamespace().c_str(),
           obstacles_.c_str(), scene_->checker().worldSize());
  return true;
}

std::vector<double> SceneServer::jointRadiusBounds() const {
  std::vector<double> radius(scene_->model().dof());
  for (std::size_t i = 0; i < radius.size(); ++i) radius[i] = scene_->checker().jointRadiusBound(i);
  return radius;
}

moverl_msgs::World SceneServer::world() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return world_msg_;
}

bool SceneServer::applyWorld(const moverl_msgs::World& msg, std::string* error) {
  std::vector<WorldObject> objects;
  if (!toWorld(msg, &objects, error)) return false;
  if (obstacles_ == "octomap") objects.clear();  // sensed only: the scene must not know the objects
  if (obstacles_ == "sensed") {                  // the static ones only (the cell's fixtures); what moves is sensed
    objects.erase(
        std::remove_if(objects.begin(), objects.end(), [](const WorldObject& o) { return o.motion.moving(); }),
        objects.end());
  }
  std::lock_guard<std::mutex> lock(mutex_);
  if (!scene_->setWorld(objects, error)) return false;
  world_msg_ = msg;
  return true;
}

/// The world as the world source describes it (its objects too in octomap mode, where the scene ignores them), with its
/// motion epoch: what the env observes and the shield times moving obstacles with.
bool SceneServer::getWorld(moverl_msgs::GetWorld::Request&, moverl_msgs::GetWorld::Response& res) {
  res.world = world();
  return true;
}

void SceneServer::onWorld(const moverl_msgs::World::ConstPtr& msg) {
  if (*msg == world()) return;  // the world init fetched, latched on the topic: applied already
  std::string error;
  if (!applyWorld(*msg, &error)) {
    ROS_ERROR("planning_scene: world update '%s' rejected, previous world kept: %s", msg->name.c_str(), error.c_str());
  } else {
    if (monitor_) monitor_->setWorldSensing(msg->sensed_speed_bound, msg->sensed_unknown_occupied, msg->camera_frames);
    ROS_DEBUG("planning_scene: world '%s' with %zu objects", msg->name.c_str(), msg->objects.size());
  }
}

/// Sensed obstacles, for the queries without a stamp (check_state, check_path, plan): the margin as of the newest
/// integrated cloud (the time of a state these queries do not know), for a state (duration 0) or a plan. False with
/// *why when the map is too old.
bool SceneServer::unstampedMargin(bool plan, double* margin, std::string* why) {
  *margin = 0.0;
  if (!monitor_) return true;
  SensedMargins m;
  monitor_->awaitIntegration();  // lockstep: the clouds received first, so that the newest stamp is the map's
  if (!monitor_->margins(monitor_->newestStamp(), plan ? std::numeric_limits<double>::infinity() : 0.0, &m, why)) {
    return false;
  }
  *margin = plan ? m.plan : m.start;
  if (!(*margin <= FclCollisionChecker::kMaxMargin)) {
    *why = "a plan's sensed margin is beyond the largest the checker builds (speed bound x plan horizon)";
    return false;
  }
  return true;
}

bool SceneServer::checkState(moverl_msgs::CheckState::Request& req, moverl_msgs::CheckState::Response& res) {
  try {
    std::string blind;
    if (!unstampedMargin(false, &res.sensed_margin, &blind)) {
      res.outcome = moverl_msgs::CheckState::Response::MAP_STALE;
      res.message = blind;
      return true;
    }
    std::lock_guard<std::mutex> lock(mutex_);
    const OctreeMarginScope margin(&scene_->checker(), res.sensed_margin);
    scene_->checkState(req.positions, &state_);  // depth 0: FCL MPR depths on vertex-only hulls are unreliable
    res.outcome = static_cast<uint8_t>(state_.outcome);
    toPairs(state_.pairs, &res.pairs);
    res.message = state_.message;
    res.check_time = state_.check_time;
  } catch (const std::exception& e) {
    res.outcome = moverl_msgs::CheckState::Response::INVALID_REQUEST;
    res.message = std::string("internal error: ") + e.what();
  }
  return true;
}

bool SceneServer::checkPath(moverl_msgs::CheckPath::Request& req, moverl_msgs::CheckPath::Response& res) {
  try {
    std::string blind;
    if (!unstampedMargin(false, &res.sensed_margin, &blind)) {
      res.outcome = moverl_msgs::CheckPath::Response::MAP_STALE;
      res.collision_fraction = -1.0;
      res.message = blind;
      return true;
    }
    std::lock_guard<std::mutex> lock(mutex_);
    const OctreeMarginScope margin(&scene_->checker(), res.sensed_margin);
    scene_->checkPath(req.start, req.goal, &path_);
    res.outcome = static_cast<uint8_t>(path_.outcome);
    toPairs(path_.pairs, &res.pairs);
    res.collision_fraction = path_.collision_fraction;
    res.checked_states = static_cast<uint32_t>(path_.checked_states);
    res.message = path_.message;
    res.check_time = path_.check_time;
  } catch (const std::exception& e) {
    res.outcome = moverl_msgs::CheckPath::Response::INVALID_REQUEST;
    res.message = std::string("internal error: ") + e.what();
  }
  return true;
}

void SceneServer::plan(const std::vector<double>& start, const std::vector<double>& goal, const std::string& planner,
                       double time_limit, PlanResult* out) {
  try {
    double sensed = 0.0;
    std::string blind;
    if (!unstampedMargin(true, &sensed, &blind)) {
      out->status = PlanStatus::kMapStale;
      out->waypoints.clear();
      out->message = "no plan: " + blind;
      return;
    }
    std::lock_guard<std::mutex> lock(mutex_);
    const OctreeMarginScope margin(&scene_->checker(), sensed);
    scene_->plan(start, goal, planner, time_limit, out);
  } catch (const std::exception& e) {
    out->status = PlanStatus::kInvalidRequest;
    out->waypoints.clear();
    out->message = std::string("internal error: ") + e.what();
  }
}

bool SceneServer::servePlan(moverl_msgs::PlanPath::Request& req, moverl_msgs::PlanPath::Response& res) {
  PlanResult result;
  plan(req.start, req.goal, req.planner, req.time_limit, &result);
  res.outcome = static_cast<uint8_t>(result.status);
  toTrajectory(result.waypoints, scene_->model().jointNames(), &res.path);
  res.planning_time = result.planning_time;
  res.path_length = result.path_length;
  res.message = result.message;
  return true;
}

bool SceneServer::fk(moverl_msgs::GetFK::Request& req, moverl_msgs::GetFK::Response& res) {
  try {
    std::lock_guard<std::mutex> lock(mutex_);
    std::vector<Eigen::Isometry3d> poses;
    res.success = scene_->fk(req.positions, req.links, &poses, &res.message);
    res.poses.resize(poses.size());
    for (std::size_t i = 0; i < poses.size(); ++i) {
      const Eigen::Quaterniond q(poses[i].linear());
      res.poses[i].position.x = poses[i].translation().x();
      res.poses[i].position.y = poses[i].translation().y();
      res.poses[i].position.z = poses[i].translation().z();
      res.poses[i].orientation.x = q.x();
      res.poses[i].orientation.y = q.y();
      res.poses[i].orientation.z = q.z();
      res.poses[i].orientation.w = q.w();
    }
  } catch (const std::exception& e) {
    res.success = false;
    res.message = std::string("internal error: ") + e.what();
  }
  return true;
}

void SceneServer::validate(const MotionRequest& req, MotionCheck* out) {
  // The caller's budget (MotionRequest::time_budget): the wait for clouds takes at most half of it, and the scene's
  // own work (the checks, a plan within planning_time, a retreat search) must end by 90 % of it; the rest carries the
  // answer back.
  const auto t0 = std::chrono::steady_clock::now();
  const double budget = req.time_budget > 0.0 ? req.time_budget : -1.0;
  try {
    // Sensed obstacles: the margins from the map's age at the state's stamp (may wait for clouds: before the lock,
    // which integration needs).
    SensedMargins sensed;
    std::string blind;
    // Without a stamp: as of the newest cloud (in lockstep the driver's clock is not this node's).
    // The motions' epoch (the last reset) is stamp - start_time.
    const double epoch = req.stamp - req.start_time;
    const bool stamped = req.stamp > 0.0;
    if (monitor_ && !monitor_->margins(stamped ? ros::Time(req.stamp) : monitor_->newestStamp(), req.duration, &sensed,
                                       &blind, !stamped || !(epoch > 0.0) ? ros::Time() : ros::Time(epoch),
                                       budget > 0.0 ? 0.5 * budget : -1.0)) {
      *out = MotionCheck();
      out->outcome = MotionOutcome::kMapStale;
      out->moving_obstacles = true;  // sensed obstacles may move: time passes while the robot holds
      out->message = blind + ": failing closed";
      out->map_age = sensed.map_age;
      out->last_free_fraction = -1.0;
      ROS_WARN_THROTTLE(5.0, "planning_scene: %s", out->message.c_str());
      return;
    }
    std::lock_guard<std::mutex> lock(mutex_);
    if (budget > 0.0) {
      MotionRequest within = req;  // what is left of the budget after the wait and the lock
      const double spent = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      within.time_budget = std::max(1e-3, 0.9 * budget - spent);
      scene_->validateMotion(within, out, monitor_ ? &sensed : nullptr);
    } else {
      scene_->validateMotion(req, out, monitor_ ? &sensed : nullptr);
    }
    out->moving_obstacles = out->moving_obstacles || monitor_ != nullptr;  // sensed obstacles may move
    out->map_age = sensed.map_age;
    out->sensed_margin = sensed.end;
    out->plan_horizon = sensed.plan_horizon;
  } catch (const std::exception& e) {
    *out = MotionCheck();
    out->outcome = MotionOutcome::kInvalidRequest;
    out->message = std::string("internal error: ") + e.what();
    out->last_free_fraction = -1.0;
  }
}

bool SceneServer::serveValidateMotion(moverl_msgs::ValidateMotion::Request& req,
                                      moverl_msgs::ValidateMotion::Response& res) {
  MotionRequest request;
  request.start = req.start;
  request.goal = req.goal;
  request.measured_start = req.measured_start;
  request.plan_on_path_collision = req.plan_on_path_collision;
  request.find_last_free = req.find_last_free;
  request.start_time = req.start_time;
  request.duration = req.duration;
  request.stamp = req.stamp.toSec();
  request.retreat_reach = req.retreat_reach;
  request.time_budget = req.time_budget;
  MotionCheck m;
  validate(request, &m);
  res.outcome = static_cast<uint8_t>(m.outcome);
  res.replanned = m.replanned;
  res.path = trajectory_msgs::JointTrajectory();
  if (m.replanned) toTrajectory(m.path, scene_->model().jointNames(), &res.path);
  toPairs(m.pairs, &res.pairs);
  res.message = m.message;
  res.state_check_time = m.state_check_time;
  res.path_check_time = m.path_check_time;
  res.planning_time = m.planning_time;
  res.last_free_fraction = m.last_free_fraction;
  res.last_free_state = m.last_free_state;
  res.moving_obstacles = m.moving_obstacles;
  res.map_age = m.map_age;
  res.sensed_margin = m.sensed_margin;
  res.plan_horizon = m.plan_horizon;
  res.threatened = m.threatened;
  res.clearance = m.clearance;
  res.retreat_state = m.retreat_state;
  res.retreat_clearance = m.retreat_clearance;
  return true;
}

ros::Time SceneServer::motionEpoch() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return world_msg_.motion_epoch;
}

}  // namespace moverl_planning_scene
