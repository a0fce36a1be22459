/**
 * \file planning_scene_node.cpp
 * \brief Thin ROS wrapper around moverl_planning_scene::PlanningScene: params, world mirroring, services.
 */
#include <ros/package.h>
#include <ros/ros.h>
#include <std_msgs/Bool.h>

#include <moverl_msgs/CheckPath.h>
#include <moverl_msgs/CheckState.h>
#include <moverl_msgs/GetFK.h>
#include <moverl_msgs/GetWorld.h>
#include <moverl_msgs/PlanPath.h>
#include <moverl_msgs/ValidateMotion.h>
#include <moverl_msgs/World.h>
#include <shape_msgs/SolidPrimitive.h>

#include <cstdlib>
#include <exception>
#include <mutex>

#include "moverl_planning_scene/planning_scene.h"

namespace mps = moverl_planning_scene;

namespace {

constexpr double kQuaternionEpsilon = 1e-9;

/// ROS world message -> core world objects. False with *error on unsupported shapes.
bool toWorld(const moverl_msgs::World& msg, std::vector<mps::WorldObject>* out, std::string* error) {
  out->clear();
  for (const auto& o : msg.objects) {
    mps::WorldObject w;
    w.id = o.id;
    switch (o.shape.type) {
      case shape_msgs::SolidPrimitive::BOX:
        w.type = mps::ShapeType::kBox;
        break;
      case shape_msgs::SolidPrimitive::SPHERE:
        w.type = mps::ShapeType::kSphere;
        break;
      case shape_msgs::SolidPrimitive::CYLINDER:
        w.type = mps::ShapeType::kCylinder;
        break;
      case shape_msgs::SolidPrimitive::CONE:
        w.type = mps::ShapeType::kCone;
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
    if (o.motion.type == moverl_msgs::ObstacleMotion::OSCILLATE) {
      w.motion.type = mps::ObstacleMotion::Type::kOscillate;
      w.motion.axis = Eigen::Vector3d(o.motion.axis[0], o.motion.axis[1], o.motion.axis[2]);
      w.motion.amplitude = o.motion.amplitude;
      w.motion.period = o.motion.period;
      w.motion.phase = o.motion.phase;
    } else if (o.motion.type != moverl_msgs::ObstacleMotion::NONE) {
      *error = "world object '" + o.id + "': unknown motion type " + std::to_string(o.motion.type);
      return false;
    }
    out->push_back(std::move(w));
  }
  return true;
}

void toPairs(const std::vector<mps::ContactPair>& in, std::vector<moverl_msgs::CollisionPair>* out) {
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

class PlanningSceneNode {
 public:
  PlanningSceneNode() : pnh_("~") {}

  /// Reads params, builds the scene, fetches the world, advertises. Returns false after ROS_FATAL.
  bool init() {
    std::string urdf;
    if (!nh_.getParam("robot_description", urdf) || urdf.empty()) {
      ROS_FATAL("planning_scene: parameter %s is not set (URDF text expected)", nh_.resolveName("robot_description").c_str());
      return false;
    }
    mps::PlanningSceneOptions o;
    if (!nh_.getParam("robot/joints", o.robot.joint_names) || o.robot.joint_names.empty()) {
      ROS_FATAL("planning_scene: parameter %s (list of controlled joint names) is not set",
                nh_.resolveName("robot/joints").c_str());
      return false;
    }
    nh_.param<std::string>("robot/base_link", o.robot.base_link, "");  // "": URDF root
    nh_.param<std::string>("robot/ee_link", o.robot.ee_link, "");      // "": child of the last joint
    if (nh_.hasParam("robot/fixed_joint_positions") &&
        !nh_.getParam("robot/fixed_joint_positions", o.robot.fixed_joint_positions)) {
      ROS_FATAL("planning_scene: /robot/fixed_joint_positions must be a dict {joint: position}");
      return false;
    }
    // Folder that package://<rest> mesh names are relative to (pybullet_data style URDFs).
    pnh_.param<std::string>("urdf_dir", o.robot.mesh_base_dir, "");
    o.robot.package_resolver = resolvePackage;

    pnh_.param("padding", o.checker.padding, 0.01);                  // obstacle inflation (m)
    pnh_.param("self_padding", o.checker.self_padding, 0.004);       // link inflation for self checks (m)
    pnh_.param("path_resolution", o.checker.path_resolution, 0.01);  // max point motion between checks (m)
    pnh_.param("acm_samples", o.checker.acm_samples, 20000);         // random configs for the ACM
    int acm_seed = 1;
    pnh_.param("acm_seed", acm_seed, 1);  // RNG seed of the ACM sampling
    o.checker.acm_seed = static_cast<unsigned>(acm_seed);
    std::string mesh_mode;
    pnh_.param<std::string>("mesh_mode", mesh_mode, "convex_hull");  // convex_hull | triangles
    if (mesh_mode == "convex_hull") {
      o.checker.mesh_mode = mps::MeshMode::kConvexHull;
    } else if (mesh_mode == "triangles") {
      o.checker.mesh_mode = mps::MeshMode::kTriangles;
    } else {
      ROS_FATAL("planning_scene: ~mesh_mode must be convex_hull or triangles, not '%s'", mesh_mode.c_str());
      return false;
    }
    bool acm_cache = false;
    pnh_.param("acm_cache", acm_cache, false);  // cache the ACM in $ROS_HOME/moverl_cache (it takes ~0.5 s)
    if (acm_cache) o.checker.acm_cache_dir = cacheDir();
    pnh_.param<std::string>("planner", o.planner.planner, "RRT");  // default OMPL planner
    pnh_.param("planning_time", o.planner.planning_time, 0.1);     // default time limit per call (s)
    pnh_.param("planner_range", o.planner.range, 0.0);             // tree planners' range (rad), 0: OMPL default
    pnh_.param("simplify", o.planner.simplify, true);              // shortcut solutions
    int planner_seed = 1;
    pnh_.param("planner_seed", planner_seed, 1);  // OMPL RNG seed, 0: not seeded
    o.planner.seed = static_cast<unsigned>(planner_seed);
    std::string world_service, world_topic;
    double world_timeout = 30.0;
    pnh_.param<std::string>("world_service", world_service, "/sim/get_world");  // moverl_msgs/GetWorld
    pnh_.param<std::string>("world_topic", world_topic, "/sim/world");          // moverl_msgs/World (latched)
    pnh_.param("world_timeout", world_timeout, 30.0);                            // s to wait for world_service

    std::string error;
    const ros::WallTime t0 = ros::WallTime::now();
    scene_ = mps::PlanningScene::create(urdf, o, &error);
    if (!scene_) {
      ROS_FATAL("planning_scene: cannot build the scene: %s", error.c_str());
      return false;
    }
    const mps::AcmStats& acm = scene_->checker().acmStats();
    ROS_INFO("planning_scene: %zu joints, ACM %s in %.2f s (adjacent %d, rigid %d, always %d, never %d, checked %d)%s%s",
             scene_->model().dof(), acm.from_cache ? "loaded" : "computed", acm.seconds, acm.adjacent, acm.rigid,
             acm.always, acm.never, acm.enabled, acm.cache_file.empty() ? "" : ", cache ",
             acm.cache_file.c_str());
    ROS_INFO("planning_scene: scene built in %.2f s", (ros::WallTime::now() - t0).toSec());

    // World: synchronous fetch, then mirror the latched topic.
    if (!ros::service::waitForService(world_service, ros::Duration(world_timeout))) {
      ROS_FATAL("planning_scene: world service %s not available after %.1f s (is the simulator running?)",
                world_service.c_str(), world_timeout);
      return false;
    }
    moverl_msgs::GetWorld get_world;
    if (!ros::service::call(world_service, get_world)) {
      ROS_FATAL("planning_scene: call to %s failed", world_service.c_str());
      return false;
    }
    if (!applyWorld(get_world.response.world, &error)) {
      ROS_FATAL("planning_scene: invalid world from %s: %s", world_service.c_str(), error.c_str());
      return false;
    }
    world_sub_ = nh_.subscribe(world_topic, 1, &PlanningSceneNode::onWorld, this);

    services_.push_back(pnh_.advertiseService("check_state", &PlanningSceneNode::checkState, this));
    services_.push_back(pnh_.advertiseService("check_path", &PlanningSceneNode::checkPath, this));
    services_.push_back(pnh_.advertiseService("plan", &PlanningSceneNode::plan, this));
    services_.push_back(pnh_.advertiseService("fk", &PlanningSceneNode::fk, this));
    services_.push_back(pnh_.advertiseService("validate_motion", &PlanningSceneNode::validateMotion, this));
    pnh_.setParam("joint_names", scene_->model().jointNames());
    ready_pub_ = pnh_.advertise<std_msgs::Bool>("ready", 1, /*latch=*/true);
    std_msgs::Bool ready;
    ready.data = true;
    ready_pub_.publish(ready);
    ROS_INFO("planning_scene: ready (%zu world objects)", scene_->checker().worldSize());
    return true;
  }

 private:
  bool applyWorld(const moverl_msgs::World& msg, std::string* error) {
    std::vector<mps::WorldObject> objects;
    if (!toWorld(msg, &objects, error)) return false;
    std::lock_guard<std::mutex> lock(mutex_);
    return scene_->setWorld(objects, error);
  }

  void onWorld(const moverl_msgs::World::ConstPtr& msg) {
    std::string error;
    if (!applyWorld(*msg, &error)) {
      ROS_ERROR("planning_scene: world update '%s' rejected, previous world kept: %s", msg->name.c_str(),
                error.c_str());
    } else {
      ROS_DEBUG("planning_scene: world '%s' with %zu objects", msg->name.c_str(), msg->objects.size());
    }
  }

  bool checkState(moverl_msgs::CheckState::Request& req, moverl_msgs::CheckState::Response& res) {
    try {
      std::lock_guard<std::mutex> lock(mutex_);
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

  bool checkPath(moverl_msgs::CheckPath::Request& req, moverl_msgs::CheckPath::Response& res) {
    try {
      std::lock_guard<std::mutex> lock(mutex_);
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

  bool plan(moverl_msgs::PlanPath::Request& req, moverl_msgs::PlanPath::Response& res) {
    try {
      std::lock_guard<std::mutex> lock(mutex_);
      scene_->plan(req.start, req.goal, req.planner, req.time_limit, &plan_);
      res.outcome = static_cast<uint8_t>(plan_.status);
      toTrajectory(plan_.waypoints, scene_->model().jointNames(), &res.path);
      res.planning_time = plan_.planning_time;
      res.path_length = plan_.path_length;
      res.message = plan_.message;
    } catch (const std::exception& e) {
      res.outcome = moverl_msgs::PlanPath::Response::INVALID_REQUEST;
      res.message = std::string("internal error: ") + e.what();
    }
    return true;
  }

  bool fk(moverl_msgs::GetFK::Request& req, moverl_msgs::GetFK::Response& res) {
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

  bool validateMotion(moverl_msgs::ValidateMotion::Request& req, moverl_msgs::ValidateMotion::Response& res) {
    try {
      std::lock_guard<std::mutex> lock(mutex_);
      scene_->validateMotion(req.start, req.goal, req.plan_on_path_collision, &motion_, req.find_last_free,
                             req.start_time, req.duration);
      res.moving_obstacles = motion_.moving_obstacles;
      res.outcome = static_cast<uint8_t>(motion_.outcome);
      res.replanned = motion_.replanned;
      if (motion_.replanned) toTrajectory(motion_.path, scene_->model().jointNames(), &res.path);
      toPairs(motion_.pairs, &res.pairs);
      res.message = motion_.message;
      res.state_check_time = motion_.state_check_time;
      res.path_check_time = motion_.path_check_time;
      res.planning_time = motion_.planning_time;
      res.last_free_fraction = motion_.last_free_fraction;
      res.last_free_state = motion_.last_free_state;
    } catch (const std::exception& e) {
      res.outcome = moverl_msgs::ValidateMotion::Response::INVALID_REQUEST;
      res.message = std::string("internal error: ") + e.what();
      res.last_free_fraction = -1.0;
      res.last_free_state.clear();
    }
    return true;
  }

  ros::NodeHandle nh_, pnh_;
  std::unique_ptr<mps::PlanningScene> scene_;
  std::mutex mutex_;  // serializes world updates and queries (the scene keeps scratch buffers)
  ros::Subscriber world_sub_;
  std::vector<ros::ServiceServer> services_;
  ros::Publisher ready_pub_;
  mps::StateCheck state_;
  mps::PathCheck path_;
  mps::PlanResult plan_;
  mps::MotionCheck motion_;
};

}  // namespace

int main(int argc, char** argv) {
  ros::init(argc, argv, "planning_scene");
  PlanningSceneNode node;
  if (!node.init()) return EXIT_FAILURE;
  ros::spin();
  return EXIT_SUCCESS;
}
