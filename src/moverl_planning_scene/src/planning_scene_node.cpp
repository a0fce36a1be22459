/**
 * \file planning_scene_node.cpp
 * \brief Thin ROS wrapper around moverl_planning_scene::PlanningScene: params, world mirroring, services, and the
 *        sensed-obstacle map (point clouds -> OccupancyMap) when ~obstacles is octomap or both.
 */
#include <ros/callback_queue.h>
#include <ros/package.h>
#include <ros/ros.h>
#include <sensor_msgs/JointState.h>
#include <sensor_msgs/PointCloud2.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <std_msgs/Bool.h>
#include <std_srvs/Empty.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>
#include <visualization_msgs/Marker.h>

#include <moverl_msgs/CheckPath.h>
#include <moverl_msgs/CheckState.h>
#include <moverl_msgs/GetFK.h>
#include <moverl_msgs/GetWorld.h>
#include <moverl_msgs/OctomapStatus.h>
#include <moverl_msgs/PlanPath.h>
#include <moverl_msgs/ValidateMotion.h>
#include <moverl_msgs/World.h>
#include <shape_msgs/SolidPrimitive.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdlib>
#include <deque>
#include <exception>
#include <mutex>

#include "moverl_planning_scene/occupancy_map.h"
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
    pnh_.param<std::string>("obstacles", obstacles_, "objects");  // objects | octomap | both
    if (obstacles_ != "objects" && obstacles_ != "octomap" && obstacles_ != "both") {
      ROS_FATAL("planning_scene: ~obstacles must be objects, octomap or both, not '%s'", obstacles_.c_str());
      return false;
    }
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
    if (obstacles_ != "objects" && !initOctomap()) return false;
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
    ROS_INFO("planning_scene: ready (obstacles: %s, %zu world objects)", obstacles_.c_str(),
             scene_->checker().worldSize());
    return true;
  }

 private:
  /// Sensed obstacles: params, map, TF, subscriptions on their own callback queue and thread (a cloud takes tens of
  /// ms; the services keep answering meanwhile and only wait for the short tree update).
  bool initOctomap() {
    mps::OccupancyMapOptions mo;
    pnh_.param("octomap/resolution", mo.resolution, mo.resolution);
    pnh_.param("octomap/max_range", mo.max_range, mo.max_range);
    pnh_.param("octomap/prob_hit", mo.prob_hit, mo.prob_hit);
    pnh_.param("octomap/prob_miss", mo.prob_miss, mo.prob_miss);
    pnh_.param("octomap/clamp_min", mo.clamp_min, mo.clamp_min);
    pnh_.param("octomap/clamp_max", mo.clamp_max, mo.clamp_max);
    pnh_.param("octomap/occupancy_threshold", mo.occupancy_threshold, mo.occupancy_threshold);
    pnh_.param("octomap/self_filter_padding", self_filter_padding_, 0.03);
    pnh_.param("octomap/transform_timeout", transform_timeout_, 0.1);
    pnh_.param("octomap/joint_state_wait", joint_state_wait_, 0.5);
    std::string cloud_topic, joint_topic;
    int queue = 4;
    pnh_.param<std::string>("octomap/cloud_topic", cloud_topic, "/sim/points");
    pnh_.param<std::string>("octomap/joint_states_topic", joint_topic, "/joint_states");
    pnh_.param("octomap/queue_size", queue, 4);
    int startup_clouds = 2;
    double startup_timeout = 30.0;
    pnh_.param("octomap/startup_clouds", startup_clouds, 2);
    pnh_.param("octomap/startup_timeout", startup_timeout, 30.0);
    if (!(self_filter_padding_ >= 0.0) || !std::isfinite(self_filter_padding_)) {
      ROS_FATAL("planning_scene: ~octomap/self_filter_padding must be >= 0");
      return false;
    }
    // Map only what the robot can reach (padded): beams are clipped there, which keeps integration fast.
    const double reach = scene_->checker().reachRadius() + scene_->checker().options().padding + 2 * mo.resolution;
    mo.bounds = Eigen::AlignedBox3d(Eigen::Vector3d::Constant(-reach), Eigen::Vector3d::Constant(reach));
    std::string error;
    map_ = mps::OccupancyMap::create(mo, &error);
    if (!map_) {
      ROS_FATAL("planning_scene: %s", error.c_str());
      return false;
    }
    {
      std::lock_guard<std::mutex> lock(mutex_);
      scene_->checker().setOctree(map_->tree());
    }
    const auto& joints = scene_->model().jointNames();
    for (std::size_t i = 0; i < joints.size(); ++i) joint_index_[joints[i]] = i;
    tf_buffer_.reset(new tf2_ros::Buffer(ros::Duration(30.0)));
    tf_listener_.reset(new tf2_ros::TransformListener(*tf_buffer_, nh_));
    status_pub_ = pnh_.advertise<moverl_msgs::OctomapStatus>("octomap_status", 1, /*latch=*/true);
    marker_pub_ = pnh_.advertise<visualization_msgs::Marker>("octomap_markers", 1, /*latch=*/true);
    services_.push_back(pnh_.advertiseService("clear_octomap", &PlanningSceneNode::clearOctomap, this));
    ros::SubscribeOptions js = ros::SubscribeOptions::create<sensor_msgs::JointState>(
        joint_topic, 50, [this](const sensor_msgs::JointState::ConstPtr& m) { onJointState(m); }, ros::VoidPtr(),
        &joint_queue_);
    ros::SubscribeOptions pc = ros::SubscribeOptions::create<sensor_msgs::PointCloud2>(
        cloud_topic, static_cast<uint32_t>(std::max(1, queue)), [this](const sensor_msgs::PointCloud2::ConstPtr& m) { onCloud(m); },
        ros::VoidPtr(), &sensor_queue_);
    joint_sub_ = nh_.subscribe(js);
    cloud_sub_ = nh_.subscribe(pc);
    sensor_spinner_.reset(new ros::AsyncSpinner(1, &sensor_queue_));
    sensor_spinner_->start();
    joint_spinner_.reset(new ros::AsyncSpinner(1, &joint_queue_));
    joint_spinner_->start();
    publishStatus(ros::Time(0), "");
    ROS_INFO("planning_scene: sensing obstacles from %s (resolution %.3f m, max range %.2f m, self filter %.3f m, "
             "mapped within +-%.2f m of the base)", cloud_sub_.getTopic().c_str(), mo.resolution, mo.max_range,
             self_filter_padding_, reach);
    // Fail closed: no query is answered before the map has seen the world (an empty map calls everything free).
    const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(startup_timeout);
    while (clouds_ < static_cast<uint32_t>(std::max(0, startup_clouds))) {
      if (!ros::ok()) return false;
      if (ros::WallTime::now() > deadline) {
        ROS_FATAL("planning_scene: only %u of %d point clouds integrated from %s after %.1f s (dropped %u): is a depth "
                  "camera publishing there, with TF for its frame and joint states on %s?",
                  clouds_.load(), startup_clouds, cloud_sub_.getTopic().c_str(), startup_timeout, dropped_.load(),
                  joint_sub_.getTopic().c_str());
        return false;
      }
      ros::WallDuration(0.01).sleep();
    }
    ROS_INFO("planning_scene: %u clouds integrated at start-up, %zu occupied cells", clouds_.load(),
             map_->occupiedLeafCount());
    return true;
  }

  void onJointState(const sensor_msgs::JointState::ConstPtr& msg) {
    std::vector<double> q(joint_index_.size(), std::numeric_limits<double>::quiet_NaN());
    std::size_t found = 0;
    for (std::size_t k = 0; k < msg->name.size() && k < msg->position.size(); ++k) {
      const auto it = joint_index_.find(msg->name[k]);
      if (it == joint_index_.end()) continue;
      q[it->second] = msg->position[k];
      ++found;
    }
    if (found != q.size()) return;  // another robot's or a partial message
    {
      std::lock_guard<std::mutex> lock(joint_mutex_);
      joint_history_.emplace_back(msg->header.stamp, std::move(q));
      while (joint_history_.size() > kJointHistory) joint_history_.pop_front();
    }
    joint_cv_.notify_all();
  }

  /// The robot configurations the cloud may have been taken in: the last joint state stamped before it, every state
  /// stamped exactly at it (lockstep: a reset changes the configuration without advancing time, so several states
  /// can share the render's stamp) and the first one after it (the robot moved between two joint states). The self
  /// filter removes the points near any of them, so the robot never leaves itself behind as an obstacle.
  /// Waits (up to joint_state_wait) until a joint state stamped at or after the cloud has arrived: the driver may
  /// publish the state a render saw after the cloud. False when none came (the cloud is then dropped: filtering
  /// with an older configuration would leave the robot behind as an obstacle).
  bool jointStatesAround(const ros::Time& stamp, std::vector<std::vector<double>>* out) {
    out->clear();
    std::unique_lock<std::mutex> lock(joint_mutex_);
    const bool arrived = joint_cv_.wait_for(lock, std::chrono::duration<double>(joint_state_wait_), [&] {
      return !joint_history_.empty() && joint_history_.back().first >= stamp;
    });
    if (!arrived) return false;
    const std::vector<double>* before = nullptr;
    const std::vector<double>* after = nullptr;
    for (const auto& js : joint_history_) {
      if (js.first < stamp) {
        before = &js.second;
      } else if (js.first == stamp) {
        out->push_back(js.second);
      } else if (after == nullptr) {
        after = &js.second;
      }
    }
    if (before != nullptr) out->push_back(*before);
    if (after != nullptr) out->push_back(*after);
    return true;
  }

  void onCloud(const sensor_msgs::PointCloud2::ConstPtr& msg) {
    std::lock_guard<std::mutex> sensor_lock(sensor_mutex_);
    const ros::WallTime t0 = ros::WallTime::now();
    geometry_msgs::TransformStamped tf;
    const std::string& base = scene_->model().baseLink();
    try {
      tf = tf_buffer_->lookupTransform(base, msg->header.frame_id, msg->header.stamp,
                                       ros::Duration(transform_timeout_));
    } catch (const tf2::TransformException& e) {
      ++dropped_;
      ROS_WARN_THROTTLE(5.0, "planning_scene: cloud from '%s' dropped: %s", msg->header.frame_id.c_str(), e.what());
      return;
    }
    if (!jointStatesAround(msg->header.stamp, &configurations_)) {
      ++dropped_;
      ROS_WARN_THROTTLE(5.0, "planning_scene: cloud dropped: no joint state stamped at or after it within %.2f s "
                        "(cannot filter the robot's points)", joint_state_wait_);
      return;
    }
    const auto& t = tf.transform;
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.linear() = Eigen::Quaterniond(t.rotation.w, t.rotation.x, t.rotation.y, t.rotation.z).toRotationMatrix();
    pose.translation() = Eigen::Vector3d(t.translation.x, t.translation.y, t.translation.z);
    points_.clear();
    points_.reserve(static_cast<std::size_t>(msg->width) * msg->height);
    try {
      sensor_msgs::PointCloud2ConstIterator<float> x(*msg, "x"), y(*msg, "y"), z(*msg, "z");
      for (; x != x.end(); ++x, ++y, ++z) points_.push_back(pose * Eigen::Vector3d(*x, *y, *z));
    } catch (const std::exception& e) {
      ++dropped_;
      ROS_WARN_THROTTLE(5.0, "planning_scene: cloud without float32 x, y, z fields dropped: %s", e.what());
      return;
    }
    for (std::size_t c = 0; c < configurations_.size(); ++c) {
      scene_->checker().robotPointMask(configurations_[c].data(), points_, self_filter_padding_,
                                       c == 0 ? &mask_ : &mask_more_);
      if (c > 0) {
        for (std::size_t k = 0; k < mask_.size(); ++k) mask_[k] |= mask_more_[k];
      }
    }
    map_->computeUpdate(points_, mask_, pose.translation(), &update_);
    {
      std::lock_guard<std::mutex> lock(mutex_);
      map_->apply(update_);
    }
    ++clouds_;
    last_integration_ = (ros::WallTime::now() - t0).toSec();
    publishStatus(msg->header.stamp, msg->header.frame_id);
    publishMarkers();
  }

  bool clearOctomap(std_srvs::Empty::Request&, std_srvs::Empty::Response&) {
    std::lock_guard<std::mutex> sensor_lock(sensor_mutex_);
    {
      std::lock_guard<std::mutex> lock(mutex_);
      map_->clear();
    }
    clouds_ = 0;
    update_.stats = mps::MapUpdateStats();
    publishStatus(ros::Time(0), "");
    publishMarkers();
    return true;
  }

  void publishStatus(const ros::Time& stamp, const std::string& sensor_frame) {
    moverl_msgs::OctomapStatus s;
    s.header.stamp = stamp;
    s.header.frame_id = scene_->model().baseLink();
    s.resolution = map_->options().resolution;
    s.clouds = clouds_;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      s.occupied_leaves = static_cast<uint32_t>(map_->occupiedLeafCount());
    }
    s.sensor_frame = sensor_frame;
    const mps::MapUpdateStats& u = update_.stats;
    s.points = static_cast<uint32_t>(u.points);
    s.robot_points = static_cast<uint32_t>(u.robot);
    s.beyond_range = static_cast<uint32_t>(u.beyond_range);
    s.hit_cells = static_cast<uint32_t>(u.hit_cells);
    s.free_cells = static_cast<uint32_t>(u.free_cells);
    s.integration_time = last_integration_;
    s.dropped = dropped_;
    status_pub_.publish(s);
  }

  /// Occupied cells as one CUBE_LIST (only when someone listens, e.g. rviz).
  void publishMarkers() {
    if (marker_pub_.getNumSubscribers() == 0) return;
    visualization_msgs::Marker m;
    m.header.frame_id = scene_->model().baseLink();
    m.header.stamp = ros::Time(0);
    m.ns = "octomap";
    m.type = visualization_msgs::Marker::CUBE_LIST;
    m.action = visualization_msgs::Marker::ADD;
    m.pose.orientation.w = 1.0;
    m.scale.x = m.scale.y = m.scale.z = map_->options().resolution;
    m.color.r = 0.2f;
    m.color.g = 0.6f;
    m.color.b = 1.0f;
    m.color.a = 0.8f;
    std::vector<Eigen::Vector3d> centers;
    std::vector<double> sizes;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      map_->occupiedLeaves(&centers, &sizes);
    }
    const double r = map_->options().resolution;
    for (std::size_t k = 0; k < centers.size(); ++k) {
      // Pruned (larger) leaves: one cube per resolution cell inside them.
      const int n = std::max(1, static_cast<int>(std::lround(sizes[k] / r)));
      for (int i = 0; i < n; ++i) {
        for (int j = 0; j < n; ++j) {
          for (int l = 0; l < n; ++l) {
            geometry_msgs::Point p;
            p.x = centers[k].x() + (i - 0.5 * (n - 1)) * r;
            p.y = centers[k].y() + (j - 0.5 * (n - 1)) * r;
            p.z = centers[k].z() + (l - 0.5 * (n - 1)) * r;
            m.points.push_back(p);
          }
        }
      }
    }
    if (m.points.empty()) m.action = visualization_msgs::Marker::DELETE;
    marker_pub_.publish(m);
  }

  bool applyWorld(const moverl_msgs::World& msg, std::string* error) {
    std::vector<mps::WorldObject> objects;
    if (!toWorld(msg, &objects, error)) return false;
    if (obstacles_ == "octomap") objects.clear();  // sensed only: the scene must not know the objects
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

  static constexpr std::size_t kJointHistory = 400;  // joint states kept to match cloud stamps

  ros::NodeHandle nh_, pnh_;
  std::string obstacles_ = "objects";
  std::unique_ptr<mps::PlanningScene> scene_;
  // Sensed obstacles (obstacles: octomap | both). Everything below is used by the sensor thread only, except map_
  // (tree updates under mutex_) and the publishers.
  std::unique_ptr<mps::OccupancyMap> map_;
  std::mutex sensor_mutex_;  // serializes cloud integration with ~clear_octomap (never held by the queries)
  ros::CallbackQueue sensor_queue_;
  std::unique_ptr<ros::AsyncSpinner> sensor_spinner_;
  std::unique_ptr<tf2_ros::Buffer> tf_buffer_;
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;
  ros::Subscriber joint_sub_, cloud_sub_;
  ros::Publisher status_pub_, marker_pub_;
  std::map<std::string, std::size_t> joint_index_;
  std::deque<std::pair<ros::Time, std::vector<double>>> joint_history_;
  std::vector<Eigen::Vector3d> points_;
  std::vector<std::uint8_t> mask_, mask_more_;
  std::vector<std::vector<double>> configurations_;
  ros::CallbackQueue joint_queue_;
  std::unique_ptr<ros::AsyncSpinner> joint_spinner_;
  std::mutex joint_mutex_;  // joint_history_
  std::condition_variable joint_cv_;
  double joint_state_wait_ = 0.5;
  mps::MapUpdate update_;
  double self_filter_padding_ = 0.03, transform_timeout_ = 0.1, last_integration_ = 0.0;
  std::atomic<uint32_t> clouds_{0}, dropped_{0};
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
