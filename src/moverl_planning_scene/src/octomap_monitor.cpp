/**
 * \file octomap_monitor.cpp
 * \brief OctomapMonitor: point clouds -> self filter (JointStateHistory) -> OccupancyMap (see the header).
 */
#include "moverl_planning_scene/octomap_monitor.h"

#include <hri_msgs/IdsList.h>

#include <pthread.h>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>

#include <sensor_msgs/point_cloud2_iterator.h>
#include <visualization_msgs/Marker.h>

#include "moverl_planning_scene/pending_clouds.h"
#include "moverl_planning_scene/ros_param.h"
#include "moverl_planning_scene/sensed_margin.h"

namespace moverl_planning_scene {

namespace {
const char* const kYaml = "load config/planning_scene.yaml";
/// The cloud subscriber's transport queue: this many times octomap/queue_size (room for as many cameras' views).
constexpr int kCloudTransportQueue = 16;
}  // namespace

// PointCloud2ConstIterator checks none of this.
std::string cloudLayoutError(const sensor_msgs::PointCloud2& c) {
  if (c.is_bigendian) return "big-endian data";
  if (c.point_step == 0) return "point_step 0";
  for (const char* name : {"x", "y", "z"}) {
    const sensor_msgs::PointField* field = nullptr;
    for (const auto& f : c.fields) {
      if (f.name == name) field = &f;
    }
    if (field == nullptr) return std::string("no field ") + name;
    if (field->datatype != sensor_msgs::PointField::FLOAT32 || field->count != 1) {
      return std::string("field ") + name + " is not one float32";
    }
    if (static_cast<std::uint64_t>(field->offset) + 4 > c.point_step) {
      return std::string("field ") + name + " lies beyond point_step";
    }
  }
  const std::uint64_t row = static_cast<std::uint64_t>(c.width) * c.point_step;
  if (c.row_step < row) return "row_step shorter than width * point_step";
  if (static_cast<std::uint64_t>(c.row_step) * c.height > c.data.size()) {
    return "data holds " + std::to_string(c.data.size()) + " bytes, the header claims " +
           std::to_string(static_cast<std::uint64_t>(c.row_step) * c.height);
  }
  return "";
}

OctomapMonitor::OctomapMonitor(ros::NodeHandle nh, ros::NodeHandle pnh, PlanningScene* scene, std::mutex* scene_mutex,
                               bool filter_static)
    : nh_(nh), pnh_(pnh), scene_(scene), scene_mutex_(scene_mutex), filter_static_(filter_static) {
  speed_bound_ = -1.0;  // until init or the world sets it
}

void OctomapMonitor::setWorldSensing(double speed_bound, bool unknown_occupied,
                                     const std::vector<std::string>& camera_frames) {
  const bool bound_given = speed_bound >= 0.0 && std::isfinite(speed_bound);
  const double bound = bound_given ? speed_bound : speed_bound_.load();
  bool cameras_changed = false;
  {
    std::lock_guard<std::mutex> lock(stamps_mutex_);
    cameras_changed = cameras_ != camera_frames;
    cameras_ = camera_frames;
  }
  static_known_free_ = true;  // the static objects may have changed (the integrator's next cloud)
  const bool bound_changed = bound_given != world_speed_bound_.exchange(bound_given) || bound != speed_bound_.load();
  speed_bound_ = bound;
  const bool switched = unknown_occupied_.exchange(unknown_occupied) != unknown_occupied;
  // Nothing the maps hold changed (a world whose objects moved, the start-up world latched again): done, without
  // waiting for the sensor thread, which in real time with every camera at 30 Hz may hold its lock for seconds on end
  // (the caller is the queue that answers the env's calls).
  if (!map_ || (!switched && !bound_changed && !cameras_changed)) return;
  std::lock_guard<std::mutex> sensor_lock(sensor_mutex_);
  if (lag_) publishHeld(nullptr);  // the updates computed before the change, first (as map_ had them)
  {
    std::lock_guard<std::mutex> lock(*scene_mutex_);
    for (OccupancyMap* m : {map_.get(), checked_map_.get()}) {
      if (m == nullptr) continue;
      if (switched) m->setUnknownOccupied(unknown_occupied);
      m->setSpeedBound(marginRule().speed());  // how fast what the cameras miss may come (hidden space)
    }
  }
  publishStatus(last_cloud_stamp_, last_cloud_frame_);  // the unobserved count changed
}

OctomapMonitor::~OctomapMonitor() {
  // Stop the threads before the members they use go.
  if (sensor_spinner_) sensor_spinner_->stop();
  {
    std::lock_guard<std::mutex> lock(pending_mutex_);
    stop_ = true;
  }
  pending_cv_.notify_all();
  idle_cv_.notify_all();  // a check waiting for integration returns now
  if (integrator_.joinable()) integrator_.join();
  if (joint_spinner_) joint_spinner_->stop();
}

bool OctomapMonitor::init(std::string* error) {
  OctomapMonitorOptions o;
  if (!readOctomapMonitorOptions(RosTunables(pnh_, kYaml), &o, error)) return false;
  OccupancyMapOptions mo = o.map;
  const std::string& cloud_topic = o.cloud_topic;
  const std::string& joint_topic = o.joint_states_topic;
  const int queue = o.queue_size;
  const double startup_timeout = o.startup_timeout;
  self_filter_padding_ = o.self_filter_padding;
  static_filter_padding_ = o.static_filter_padding;
  future_tolerance_ = o.future_tolerance;
  camera_wait_ = o.camera_wait;
  batch_wait_ = o.batch_wait;
  transform_timeout_ = o.transform_timeout;
  joint_state_wait_ = o.joint_state_wait;
  queue_depth_ = static_cast<std::size_t>(std::max(1, queue));
  rule_ = o.margin;
  max_age_ = o.margin.max_age;
  track_people_ = o.track_people;
  tracking_ = o.tracking;
  part_radii_ = o.part_radii;
  stale_wait_ = o.stale_wait;
  lockstep_ = o.lockstep;
  lag_ = o.lockstep && o.lockstep_lag;
  lag_max_margin_ = o.lockstep_lag_max_margin;
  integration_ = o.integration;
  if (speed_bound_ < 0.0) speed_bound_ = rule_.speed_bound;  // the world did not give one
  // Map only what the robot can reach (padded), plus the largest predictive margin a query may use: something
  // farther away cannot touch the robot within the margin's time. Beams are clipped there, which keeps integration
  // fast. A margin beyond this slack is refused (margins()): the map cannot see that far.
  max_margin_ = marginRule().largestMargin(mo.resolution);
  mo.bounds = sensedMapBounds(scene_->checker().reachRadius() + scene_->checker().options().padding, max_margin_);
  const double reach = mo.bounds.max().x();
  mo.unknown_occupied = unknown_occupied_;
  // Free space no camera sees turns possibly occupied once something at the speed bound may have come there (under
  // unknown_occupied; the clouds of one instant are one batch: intoMaps).
  mo.hidden_space = true;
  mo.speed_bound = marginRule().speed();
  map_ = OccupancyMap::create(mo, error);
  if (!map_) return false;
  if (lag_) {
    OccupancyMapOptions checked = mo;
    checked.integrates = false;  // it gets map_'s updates: no watch of its own
    checked_map_ = OccupancyMap::create(checked, error);
    if (!checked_map_) return false;
  }
  CloudIntegratorOptions io;
  io.self_filter_padding = self_filter_padding_;
  io.static_filter_padding = static_filter_padding_;
  io.filter_static = filter_static_;
  io.integration = integration_;
  io.threads = o.integration_threads;
  cloud_integrator_ = std::make_unique<CloudIntegrator>(map_.get(), &scene_->checker(), scene_mutex_, io);
  {
    std::lock_guard<std::mutex> lock(*scene_mutex_);
    scene_->checker().setOccupancy(lag_ ? checked_map_.get() : map_.get());
  }
  joints_ = scene_->model().jointNames();
  tf_buffer_ = std::make_unique<tf2_ros::Buffer>(ros::Duration(30.0));
  tf_listener_ = std::make_unique<tf2_ros::TransformListener>(*tf_buffer_, nh_);
  // One status per integrated cloud, and a listener may count them (step_cost.py sums every cloud's integration
  // time): clouds integrated back to back (lockstep's queue, two threads) must not replace each other's status in the
  // outgoing queue, as a queue of 1 let them.
  status_pub_ = pnh_.advertise<moverl_msgs::OctomapStatus>("octomap_status", 64, /*latch=*/true);
  marker_pub_ = pnh_.advertise<visualization_msgs::Marker>("octomap_markers", 1, /*latch=*/true);
  clear_srv_ = pnh_.advertiseService("clear_octomap", &OctomapMonitor::clear, this);
  census_srv_ = pnh_.advertiseService("sensed_census", &OctomapMonitor::census, this);
  ros::SubscribeOptions js = ros::SubscribeOptions::create<sensor_msgs::JointState>(
      joint_topic, 50, [this](const sensor_msgs::JointState::ConstPtr& m) { onJointState(m); }, ros::VoidPtr(),
      &joint_queue_);
  // The transport's queue holds the clouds until onCloud takes them (at once: it only queues them per camera, where
  // octomap/queue_size applies). roscpp drops the oldest silently when it is full: deep enough for a burst of every
  // camera's views (a lockstep step at 30 Hz publishes them a millisecond apart while both cores integrate).
  ros::SubscribeOptions pc = ros::SubscribeOptions::create<sensor_msgs::PointCloud2>(
      cloud_topic, static_cast<uint32_t>(kCloudTransportQueue * std::max(1, queue)),
      [this](const sensor_msgs::PointCloud2::ConstPtr& m) { onCloud(m); }, ros::VoidPtr(), &sensor_queue_);
  joint_sub_ = nh_.subscribe(js);
  cloud_sub_ = nh_.subscribe(pc);
  if (track_people_) {
    ros::SubscribeOptions bodies = ros::SubscribeOptions::create<hri_msgs::IdsList>(
        "/humans/bodies/tracked", 10,
        [this](const hri_msgs::IdsList::ConstPtr& m) {
          std::lock_guard<std::mutex> lock(bodies_mutex_);
          bodies_ = m->ids;
        },
        ros::VoidPtr(), &sensor_queue_);
    bodies_sub_ = nh_.subscribe(bodies);
  }
  integrator_ = std::thread([this] { integrateLoop(); });
  sensor_spinner_ = std::make_unique<ros::AsyncSpinner>(1, &sensor_queue_);
  sensor_spinner_->start();
  joint_spinner_ = std::make_unique<ros::AsyncSpinner>(1, &joint_queue_);
  joint_spinner_->start();
  publishStatus(ros::Time(0), "");
  std::string cameras;
  {
    std::lock_guard<std::mutex> lock(stamps_mutex_);
    for (const auto& c : cameras_) cameras += (cameras.empty() ? "" : ", ") + c;
  }
  char approach[256];
  if (rule_.safety == Safety::kSsm) {
    std::snprintf(approach, sizeof(approach),
                  "safety ssm: ISO 13855's %.1f m/s within %.2f m, %.1f m/s beyond, intrusion %.3f m, sensor "
                  "uncertainty %.3f m; the speed bound %.2f m/s is not used",
                  rule_.iso.hand_speed, rule_.iso.reach_distance, rule_.iso.body_speed, rule_.iso.intrusion,
                  rule_.uncertainty, speed_bound_.load());
  } else {
    std::snprintf(approach, sizeof(approach), "safety separation: speed bound %.2f m/s (%s)", speed_bound_.load(),
                  world_speed_bound_ ? "the world file's sensing: speed_bound"
                                     : "octomap/speed_bound of config/planning_scene.yaml: the world file gives none");
  }
  ROS_INFO(
      "planning_scene: sensing obstacles from %s (cameras %s; resolution %.3f m, max range %.2f m, self filter %.3f m, "
      "static filter %.3f m, mapped within +-%.2f m of the base; %s; max age %.2f s; unknown cells count as %s)",
      cloud_sub_.getTopic().c_str(), cameras.empty() ? "(none listed by the world)" : cameras.c_str(), mo.resolution,
      mo.max_range, self_filter_padding_, static_filter_padding_, reach, approach, max_age_,
      mo.unknown_occupied ? "occupied" : "free");
  // Fail closed: no query is answered before the map has seen the world (an empty map calls everything free). A cloud
  // of every camera the world lists (as many as it lists: one in a cell with one camera), or one cloud when it lists
  // none; once one is in, the others get camera_wait more.
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(startup_timeout);
  std::vector<std::string> unheard = unheardCameras();
  bool listed = false;
  {
    std::lock_guard<std::mutex> lock(stamps_mutex_);
    listed = !cameras_.empty();
  }
  ros::WallTime camera_deadline;
  // (The others' wait counts from the first cloud: set in the condition, so that a first cloud that came during the
  // sleep below does not end the wait before it began.)
  auto others_waited = [&] {
    if (camera_deadline.isZero()) camera_deadline = ros::WallTime::now() + ros::WallDuration(camera_wait_);
    return ros::WallTime::now() >= camera_deadline;
  };
  while (clouds_ == 0 || (!unheard.empty() && !others_waited())) {
    if (!ros::ok()) {
      *error = "shut down while waiting for the first point clouds";
      return false;
    }
    if (clouds_ == 0 && ros::WallTime::now() > deadline) {
      std::string why;
      {
        std::lock_guard<std::mutex> lock(stamps_mutex_);
        for (const auto& d : last_drop_) why += "; " + d.first + ": " + d.second;
      }
      *error = "no point cloud integrated from " + cloud_sub_.getTopic() + " after " + std::to_string(startup_timeout) +
               " s (" +
               (listed ? "the world's cameras " +
                             [&] {
                               std::string s;
                               for (const auto& u : unheard) s += (s.empty() ? "" : ", ") + u;
                               return s;
                             }() +
                             " sent none"
                       : "the world lists no camera") +
               ", dropped " + std::to_string(dropped_.load()) + why +
               "): is a depth camera publishing there, with TF for its frame and joint states on " +
               joint_sub_.getTopic() + "?";
      return false;
    }
    ros::WallDuration(0.01).sleep();
    unheard = unheardCameras();
  }
  // One still unheard leaves the map blind (every check fails closed, naming it) until it is heard.
  for (const auto& cam : unheard) {
    std::string why;
    {
      std::lock_guard<std::mutex> lock(stamps_mutex_);
      const auto it = last_drop_.find(cam);
      if (it != last_drop_.end()) why = " (its clouds were dropped: " + it->second + ")";
    }
    ROS_WARN(
        "planning_scene: camera %s (in the world's cameras:) sent no cloud within %.1f s of the first%s: the sensed "
        "map is blind (every check fails closed) until it does",
        cam.c_str(), camera_wait_, why.c_str());
  }
  ROS_INFO("planning_scene: %u clouds integrated at start-up, %zu occupied cells", clouds_.load(),
           map_->occupiedLeafCount());
  publishStatus(last_cloud_stamp_, last_cloud_frame_);
  return true;
}

std::vector<std::string> OctomapMonitor::unheardCameras() {
  std::lock_guard<std::mutex> lock(stamps_mutex_);
  std::vector<std::string> out;
  for (const auto& c : cameras_) {
    if (frame_stamps_.find(c) == frame_stamps_.end()) out.push_back(c);
  }
  return out;
}

void OctomapMonitor::onJointState(const sensor_msgs::JointState::ConstPtr& msg) {
  std::vector<double> q(joints_.size(), std::numeric_limits<double>::quiet_NaN());
  std::size_t found = 0;
  for (std::size_t k = 0; k < msg->name.size() && k < msg->position.size(); ++k) {
    const auto it = std::find(joints_.begin(), joints_.end(), msg->name[k]);
    if (it == joints_.end()) continue;  // not ours
    double& slot = q[static_cast<std::size_t>(it - joints_.begin())];
    if (!std::isnan(slot)) continue;  // listed twice
    slot = msg->position[k];
    ++found;
  }
  if (found != q.size()) return;  // another robot's or a partial message
  for (double v : q) {
    if (!std::isfinite(v)) return;  // a broken driver's message: never a configuration to filter with
  }
  history_.add(static_cast<std::int64_t>(msg->header.stamp.toNSec()), std::move(q));
}

void OctomapMonitor::onCloud(const sensor_msgs::PointCloud2::ConstPtr& msg) {
  {
    std::lock_guard<std::mutex> lock(pending_mutex_);
    // What a camera keeps waiting: pending_clouds.h (lockstep: every view up to queue_size; real time: the newest, and
    // a cloud of the batch being integrated).
    const double batch = open_batch_.isZero() ? std::numeric_limits<double>::quiet_NaN() : open_batch_.toSec();
    const double flight = integrating_ ? in_flight_.toSec() : std::numeric_limits<double>::quiet_NaN();
    const std::size_t dropped = admitCloud(
        &pending_[msg->header.frame_id], msg,
        [](const sensor_msgs::PointCloud2::ConstPtr& m) { return m->header.stamp.toSec(); }, lockstep_, queue_depth_,
        batch, flight);
    if (dropped > 0 && lockstep_) {
      ROS_WARN_THROTTLE(5.0,
                        "planning_scene: lockstep: more than octomap/queue_size (%zu) views of '%s' waiting: "
                        "the oldest is skipped (a long move's backlog; the map keeps the newest)",
                        queue_depth_, msg->header.frame_id.c_str());
    }
    outstanding_ += 1 - static_cast<int>(dropped);  // the dropped ones' places go to msg
  }
  pending_cv_.notify_one();
}

void OctomapMonitor::integrateLoop() {
  // Named for the tools that split a process's CPU by thread (step_cost.py), as its pool's workers are
  // (worker_pool.cpp).
  pthread_setname_np(pthread_self(), "mps_integrate");
  while (true) {
    sensor_msgs::PointCloud2::ConstPtr msg;
    {
      std::unique_lock<std::mutex> lock(pending_mutex_);
      pending_cv_.wait(lock, [&] { return stop_ || !pending_.empty(); });
      if (stop_) return;
      // The oldest cloud first (the clouds of one instant are one batch of the map: they go in together), among
      // equals the camera whose last integrated cloud is oldest (never integrated: first), so that no camera starves.
      auto pick_oldest = [&] {
        auto pick = pending_.begin();
        auto last = [&](const std::string& frame) {
          const auto it = integrated_.find(frame);
          return it == integrated_.end() ? ros::Time() : it->second;
        };
        for (auto it = pending_.begin(); it != pending_.end(); ++it) {
          const ros::Time a = it->second.front()->header.stamp, b = pick->second.front()->header.stamp;
          if (a < b || (a == b && last(it->first) < last(pick->first))) pick = it;
        }
        return pick;
      };
      // A later instant's cloud while a camera heard lately has not sent its cloud of the open batch yet, and has none
      // waiting: wait for it up to octomap/batch_wait (in lockstep it was rendered with the others and is on its way).
      auto missing = [&](const ros::Time& stamp) {
        if (open_batch_.isZero() || !(stamp > open_batch_)) return false;
        std::lock_guard<std::mutex> stamps(stamps_mutex_);
        for (const auto& cam : cameras_) {
          const auto it = integrated_.find(cam);
          if (it == integrated_.end() || it->second >= open_batch_) continue;  // never heard, or in the batch
          if ((open_batch_ - it->second).toSec() > max_age_) continue;         // not heard lately
          if (pending_.count(cam) != 0) continue;  // its next cloud is waiting: it skipped this instant
          return true;
        }
        return false;
      };
      auto pick = pick_oldest();
      if (!lockstep_ && open_batch_.isZero()) {
        // Real time, between batches: the newest instant every camera sending has a cloud of, whole; the older clouds
        // go (pending_clouds.h). None (unsynchronised cameras, one still on its way): the oldest cloud, as below.
        const auto stamp_of = [](const sensor_msgs::PointCloud2::ConstPtr& m) { return m->header.stamp.toSec(); };
        const double at = newestWholeInstant(pending_, sendingCameras(), stamp_of);
        if (!std::isnan(at)) {
          outstanding_ -= static_cast<int>(dropOlderThan(&pending_, at, stamp_of));
          pick = pick_oldest();
        }
      }
      if (missing(pick->second.front()->header.stamp)) {
        const auto until =
            std::chrono::steady_clock::now() +
            std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(batch_wait_));
        pending_cv_.wait_until(lock, until,
                               [&] { return stop_ || !missing(pick_oldest()->second.front()->header.stamp); });
        if (stop_) return;
        pick = pick_oldest();
      }
      msg = pick->second.front();
      pick->second.pop_front();
      if (pick->second.empty()) pending_.erase(pick);
      integrating_ = true;
      in_flight_ = msg->header.stamp;
    }
    integrate(msg);
    {
      std::lock_guard<std::mutex> lock(pending_mutex_);
      --outstanding_;  // integrated or dropped: either way no longer on its way into the map
      integrating_ = false;
    }
    idle_cv_.notify_all();
  }
}

std::vector<std::string> OctomapMonitor::sendingCameras() {
  // (pending_mutex_ held.) The cameras with clouds waiting, and the world's cameras integrated within max_age of the
  // newest waiting cloud: heard lately, their cloud of that instant may still be on its way.
  std::vector<std::string> out;
  double newest = -std::numeric_limits<double>::infinity();
  for (const auto& [frame, queue] : pending_) {
    out.push_back(frame);
    newest = std::max(newest, queue.back()->header.stamp.toSec());
  }
  for (const auto& cam : cameras_) {
    const auto it = integrated_.find(cam);
    if (pending_.count(cam) != 0 || it == integrated_.end()) continue;
    if (newest - it->second.toSec() <= max_age_) out.push_back(cam);
  }
  return out;
}

void OctomapMonitor::integrate(const sensor_msgs::PointCloud2::ConstPtr& msg) {
  std::lock_guard<std::mutex> sensor_lock(sensor_mutex_);
  const ros::WallTime t0 = ros::WallTime::now();
  geometry_msgs::TransformStamped tf;
  const std::string& base = scene_->model().baseLink();
  try {
    tf = tf_buffer_->lookupTransform(base, msg->header.frame_id, msg->header.stamp, ros::Duration(transform_timeout_));
  } catch (const tf2::TransformException& e) {
    drop("cloud from '" + msg->header.frame_id + "' dropped: " + e.what(), msg->header.frame_id);
    return;
  }
  const std::string bad = cloudLayoutError(*msg);  // before waiting for a joint state: a malformed cloud goes at once
  if (!bad.empty()) {
    drop("malformed cloud from '" + msg->header.frame_id + "' dropped: " + bad, msg->header.frame_id);
    return;
  }
  // A cloud stamped in the future (a camera's clock ahead of this one) would make the map look younger than it is.
  const double ahead = msg->header.stamp.toSec() - ros::Time::now().toSec();
  if (ahead > future_tolerance_) {
    drop("cloud from '" + msg->header.frame_id + "' dropped: stamped " + std::to_string(ahead) +
             " s ahead of this node's clock (octomap/future_tolerance " + std::to_string(future_tolerance_) +
             " s): synchronise the camera's clock with the robot's",
         msg->header.frame_id);
    return;
  }
  if (!history_.around(static_cast<std::int64_t>(msg->header.stamp.toNSec()), joint_state_wait_, &configurations_)) {
    drop("cloud from '" + msg->header.frame_id + "' dropped: no joint state stamped at or after it within " +
             std::to_string(joint_state_wait_) + " s on " + joint_sub_.getTopic() +
             " (cannot filter the robot's points)",
         msg->header.frame_id);
    return;
  }
  const auto& t = tf.transform;
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = Eigen::Quaterniond(t.rotation.w, t.rotation.x, t.rotation.y, t.rotation.z).toRotationMatrix();
  pose.translation() = Eigen::Vector3d(t.translation.x, t.translation.y, t.translation.z);
  CloudView view;  // cloudLayoutError accepted the layout: float32 x, y, z within each point, rows within the data
  view.data = msg->data.data();
  view.width = static_cast<int>(msg->width);
  view.height = static_cast<int>(msg->height);
  view.point_step = msg->point_step;
  view.row_step = msg->row_step;
  for (const auto& f : msg->fields) {
    if (f.name == "x") view.x = f.offset;
    if (f.name == "y") view.y = f.offset;
    if (f.name == "z") view.z = f.offset;
  }
  std::string why;
  if (static_known_free_.exchange(false)) cloud_integrator_->staticObjectsChanged();
  // The world's motions restarted (a reset teleported what moves): nothing hidden is known to be free any more.
  if (forget_pending_.exchange(false)) map_->forgetAtNextClose();
  // The clouds of one instant are one batch of the map's hidden space: a cloud stamped later closes the open one.
  // (A batch closed here, by the next instant's first cloud, reports what it found as one closed by its last.)
  if (cloud_integrator_->beginView(msg->header.stamp.toSec(), &close_update_, &batch_stats_)) {
    intoMaps(close_update_, ros::Time(close_update_.stamp), "");
  }
  const Integration used = cloud_integrator_->compute(view, pose, configurations_, &update_, nullptr, &why);
  // Say when a camera's clouds fall back to ray casting (and why), and when they are projected again.
  const bool fell_back = used != integration_;
  auto seen = fell_back_.find(msg->header.frame_id);
  if (seen == fell_back_.end() ? fell_back : seen->second != fell_back) {
    if (fell_back) {
      ROS_WARN(
          "%s: a cloud from '%s' is integrated by ray casting: octomap/integration %s needs an organized cloud "
          "in the camera's optical frame that fits a pinhole camera (%s)",
          pnh_.getNamespace().c_str(), msg->header.frame_id.c_str(), integrationName(integration_), why.c_str());
    } else if (seen != fell_back_.end()) {
      ROS_INFO("%s: clouds from '%s' are projected again", pnh_.getNamespace().c_str(), msg->header.frame_id.c_str());
    }
    fell_back_[msg->header.frame_id] = fell_back;
  }
  {
    std::lock_guard<std::mutex> lock(pending_mutex_);
    integrated_[msg->header.frame_id] = std::max(integrated_[msg->header.frame_id], msg->header.stamp);
    const double open = map_->batchStamp();
    open_batch_ = std::isnan(open) ? ros::Time() : ros::Time(open);
  }
  intoMaps(update_, msg->header.stamp, msg->header.frame_id);
  ++clouds_;
  // The batch's last camera: close it (what no view of it saw may turn possibly occupied).
  if (!update_.late && batchComplete(msg->header.stamp) &&
      cloud_integrator_->closeBatch(&close_update_, &batch_stats_)) {
    intoMaps(close_update_, msg->header.stamp, "");
    std::lock_guard<std::mutex> lock(pending_mutex_);
    open_batch_ = ros::Time();
  }
  last_integration_ = (ros::WallTime::now() - t0).toSec();
  last_cloud_stamp_ = msg->header.stamp;
  last_cloud_frame_ = msg->header.frame_id;
  publishStatus(msg->header.stamp, msg->header.frame_id);
  publishMarkers();
}

void OctomapMonitor::intoMaps(const MapUpdate& update, const ros::Time& stamp, const std::string& frame) {
  {
    std::lock_guard<std::mutex> lock(*scene_mutex_);
    map_->apply(update);
  }
  if (lag_) {
    bool at_once = false;
    {
      std::lock_guard<std::mutex> lock(pending_mutex_);
      held_.push(static_cast<std::int64_t>(stamp.toNSec()), frame, update);
      at_once = std::isnan(previous_check_) || publish_at_once_ || held_.full();
    }
    // Before the first check (start-up), or while a check waits for every cloud: at once, as that check would. And
    // when no check comes for long (the shield off): the checks' map gets newer, never older, than the rule says.
    if (at_once) publishHeld(nullptr);
  } else if (!frame.empty()) {
    markSeen(frame, stamp);
  }
}

bool OctomapMonitor::batchComplete(const ros::Time& stamp) {
  std::lock_guard<std::mutex> pending(pending_mutex_);
  std::lock_guard<std::mutex> lock(stamps_mutex_);
  for (const auto& c : cameras_) {
    const auto it = integrated_.find(c);
    if (it == integrated_.end() || it->second < stamp) return false;
  }
  return true;
}

void OctomapMonitor::markSeen(const std::string& frame, const ros::Time& stamp) {
  if (frame.empty()) return;  // a batch's close
  {
    std::lock_guard<std::mutex> lock(stamps_mutex_);
    ros::Time& last = frame_stamps_[frame];
    last = std::max(last, stamp);  // clouds of one camera may arrive out of order
  }
  stamps_cv_.notify_all();
}

void OctomapMonitor::publishHeld(const ros::Time* cutoff) {
  std::lock_guard<std::mutex> publishing(publish_mutex_);
  std::vector<HeldUpdates::Held> out;
  {
    std::lock_guard<std::mutex> lock(pending_mutex_);
    out = cutoff == nullptr ? held_.takeAll() : held_.takeUpTo(static_cast<std::int64_t>(cutoff->toNSec()));
  }
  if (out.empty()) return;
  {
    std::lock_guard<std::mutex> lock(*scene_mutex_);
    for (const auto& h : out) checked_map_->apply(h.update);
  }
  for (const auto& h : out) markSeen(h.frame, ros::Time().fromNSec(static_cast<std::uint64_t>(h.stamp_ns)));
}

void OctomapMonitor::awaitPending(const ros::Time* cutoff, std::chrono::steady_clock::time_point deadline) {
  // Lockstep: simulated time stands still between steps, so the clouds rendered up to this state are all in, or on
  // their way. Integrating them first makes the map as old as the cameras make it, not as old as this machine's
  // integration lags (which would widen the margin and discard more moves on a faster simulator: the answers would
  // depend on the machine).
  if (!lockstep_) return;
  std::unique_lock<std::mutex> pending(pending_mutex_);
  idle_cv_.wait_until(pending, deadline, [&] {
    if (stop_) return true;
    if (cutoff == nullptr) return outstanding_ == 0;
    if (integrating_ && in_flight_ <= *cutoff) return false;
    for (const auto& p : pending_) {
      for (const auto& m : p.second) {
        if (m->header.stamp <= *cutoff) return false;
      }
    }
    return true;
  });
}

void OctomapMonitor::awaitIntegration(double max_wait) {
  const double wait = max_wait >= 0.0 ? std::min(stale_wait_, max_wait) : stale_wait_;
  awaitPending(nullptr,
               std::chrono::steady_clock::now() + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                                                      std::chrono::duration<double>(std::max(0.0, wait))));
  if (lag_) publishHeld(nullptr);
}

bool OctomapMonitor::margins(const ros::Time& stamp, double duration, SensedMargins* out, std::string* why,
                             const ros::Time& epoch, double max_wait) {
  // Every camera the world lists counts, heard from or not (one never heard from leaves the map blind), and so does
  // any other camera whose clouds came in.
  std::string deciding;
  auto age = [&] {
    std::vector<CameraSeen> cameras;
    for (const auto& c : cameras_) {
      const auto it = frame_stamps_.find(c);
      cameras.push_back({c, it == frame_stamps_.end() ? -std::numeric_limits<double>::infinity() : it->second.toSec()});
    }
    for (const auto& f : frame_stamps_) {
      if (std::find(cameras_.begin(), cameras_.end(), f.first) == cameras_.end()) {
        cameras.push_back({f.first, f.second.toSec()});
      }
    }
    return sensedMapAge(cameras, stamp.toSec(), epoch.toSec(), &deciding);
  };
  // (A check's epoch is computed from doubles, stamp - start_time: it jitters by far less than kEpochSlack.)
  if (epoch.toSec() > motion_epoch_.load() + kEpochSlack) {
    motion_epoch_ = epoch.toSec();
    forget_pending_ = true;
  }
  const double wait = max_wait >= 0.0 ? std::min(stale_wait_, max_wait) : stale_wait_;
  const auto deadline =
      std::chrono::steady_clock::now() + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                                             std::chrono::duration<double>(std::max(0.0, wait)));
  // octomap/lockstep_lag: the clouds up to the previous check's state (the later ones are integrated meanwhile).
  ros::Time cutoff = stamp;
  if (lag_) {
    std::lock_guard<std::mutex> lock(pending_mutex_);
    cutoff = ros::Time(
        lockstepMapCutoff(previous_check_, stamp.toSec(), epoch.toSec(), marginRule().speed(), lag_max_margin_));
    previous_check_ = std::isnan(previous_check_) ? stamp.toSec() : std::max(previous_check_, stamp.toSec());
  }
  awaitPending(lag_ ? &cutoff : nullptr, deadline);
  if (lag_) publishHeld(&cutoff);
  std::unique_lock<std::mutex> lock(stamps_mutex_);
  double map_age = age();
  bool at_once = false;
  if (map_age > max_age_ && lag_) {
    // Too old as of the previous check: every cloud, and those that come while this check waits (as in one map).
    lock.unlock();
    {
      std::lock_guard<std::mutex> pending(pending_mutex_);
      publish_at_once_ = at_once = true;
    }
    awaitPending(nullptr, deadline);
    publishHeld(nullptr);
    lock.lock();
    map_age = age();
  }
  if (map_age > max_age_ && wait > 0.0) {
    stamps_cv_.wait_until(lock, deadline, [&] { return age() <= max_age_; });
    map_age = age();
  }
  const bool none = cameras_.empty() && frame_stamps_.empty();
  lock.unlock();
  if (at_once) {
    std::lock_guard<std::mutex> pending(pending_mutex_);
    publish_at_once_ = false;
  }
  // Under unknown_occupied, what the cameras missed since the checks' map's last batch is in it as possibly occupied
  // (hidden space): the margin counts from that batch. The oldest camera still fails the check closed when too old.
  double margin_age = map_age;
  if (std::isfinite(map_age) && map_age <= max_age_ && unknown_occupied_ && marginRule().speed() > 0.0) {
    double map_time = 0.0;
    {
      std::lock_guard<std::mutex> scene_lock(*scene_mutex_);
      map_time = (checked_map_ ? checked_map_ : map_)->mapTime();
    }
    margin_age = std::max(0.0, stamp.toSec() - map_time);
  }
  if (marginRule().compute(margin_age, duration, out, why)) {
    out->parts.clear();
    if (track_people_ && std::isfinite(duration)) {
      const double now = stamp.toSec();
      const std::vector<TrackedPart> parts = trackedParts();
      out->parts = explainParts(parts, tracking_, now, now - margin_age, now + duration + rule_.latency, out->end,
                                rule_.uncertainty);
      ROS_INFO_THROTTLE(10.0, "planning_scene: tracked people: %zu of %zu parts in TF used (map age %.3f s)",
                        out->parts.size(), parts.size(), margin_age);
    }
    return true;
  }
  if (!std::isfinite(map_age)) {
    *why = none ? "no camera has been heard from: nothing is known to be free"
                : "camera " + deciding +
                      " has not been heard from since start-up or the world's motions restarted: "
                      "nothing is known to be free where only it looks";
  } else if (map_age > max_age_) {
    *why += " (the oldest view: camera " + deciding + ")";
  }
  return false;
}

std::vector<TrackedPart> OctomapMonitor::trackedParts() {
  std::vector<std::string> bodies;
  {
    std::lock_guard<std::mutex> lock(bodies_mutex_);
    bodies = bodies_;
  }
  std::vector<TrackedPart> parts;
  const std::string& base = scene_->model().baseLink();
  for (const std::string& body : bodies) {
    for (const auto& [frame, radius] : part_radii_) {
      TrackedPart p;
      p.id = frame + "_" + body;
      try {
        const geometry_msgs::TransformStamped tf = tf_buffer_->lookupTransform(base, p.id, ros::Time(0));
        p.position =
            Eigen::Vector3d(tf.transform.translation.x, tf.transform.translation.y, tf.transform.translation.z);
        p.stamp = tf.header.stamp.toSec();
      } catch (const tf2::TransformException&) {
        continue;  // not (yet) there: its cells are unexplained
      }
      p.speed = tracking_.motion.max_speed;  // REP 155 reports no velocity
      p.radius = radius;
      parts.push_back(p);
    }
  }
  return parts;
}

SensedMarginRule OctomapMonitor::marginRule() const {
  SensedMarginRule rule = rule_;
  rule.speed_bound = speed_bound_;
  rule.max_margin = std::min(FclCollisionChecker::kMaxMargin, max_margin_);
  return rule;
}

ros::Time OctomapMonitor::newestStamp() {
  std::lock_guard<std::mutex> lock(stamps_mutex_);
  ros::Time newest;
  for (const auto& f : frame_stamps_) newest = std::max(newest, f.second);
  return newest;
}

bool OctomapMonitor::clear(std_srvs::Empty::Request&, std_srvs::Empty::Response&) {
  std::lock_guard<std::mutex> sensor_lock(sensor_mutex_);
  std::lock_guard<std::mutex> publishing(publish_mutex_);  // no held update goes in after the clear
  {
    std::lock_guard<std::mutex> lock(*scene_mutex_);
    map_->clear();
    if (checked_map_) checked_map_->clear();
  }
  {
    std::lock_guard<std::mutex> lock(pending_mutex_);
    held_.clear();  // views from before the clear
  }
  static_known_free_ = true;
  {
    std::lock_guard<std::mutex> lock(stamps_mutex_);
    frame_stamps_.clear();  // nothing seen: blind until the cameras' next clouds
  }
  {
    std::lock_guard<std::mutex> lock(pending_mutex_);
    integrated_.clear();
    open_batch_ = ros::Time();
  }
  batch_stats_ = BatchStats();
  clouds_ = 0;
  update_.stats = MapUpdateStats();
  publishStatus(ros::Time(0), "");
  publishMarkers();
  return true;
}

bool OctomapMonitor::census(moverl_msgs::SensedCensus::Request& req, moverl_msgs::SensedCensus::Response& res) {
  const double reach = scene_->checker().reachRadius() + scene_->checker().options().padding;
  res.radius = req.radius > 0.0 && std::isfinite(req.radius) ? req.radius : reach;
  MapCensus m;
  {
    std::lock_guard<std::mutex> lock(*scene_mutex_);
    (checked_map_ ? checked_map_ : map_)
        ->census(Eigen::Vector3d(req.centre.x, req.centre.y, req.centre.z), res.radius, &m);
  }
  res.success = true;
  res.cells = static_cast<uint32_t>(m.cells);
  res.free_cells = static_cast<uint32_t>(m.free);
  res.seen_occupied = static_cast<uint32_t>(m.seen_occupied);
  res.stale_cells = static_cast<uint32_t>(m.stale);
  res.unseen_cells = static_cast<uint32_t>(m.unseen);
  res.unknown_occupied = unknown_occupied_;
  for (int k = 0; k < 8; ++k) {
    res.cells_by_octant[k] = static_cast<uint32_t>(m.cells_by_octant[k]);
    res.hidden_by_octant[k] = static_cast<uint32_t>(m.hidden_by_octant[k]);
  }
  return true;
}

/// A cloud that cannot be integrated: counted, logged (throttled) and reported in ~octomap_status.
void OctomapMonitor::drop(const std::string& why, const std::string& frame) {
  ++dropped_;
  if (!frame.empty()) {
    std::lock_guard<std::mutex> lock(stamps_mutex_);
    last_drop_[frame] = why;
  }
  ROS_WARN_THROTTLE(5.0, "planning_scene: %s", why.c_str());
  publishStatus(last_cloud_stamp_, last_cloud_frame_);
}

void OctomapMonitor::publishStatus(const ros::Time& stamp, const std::string& sensor_frame) {
  moverl_msgs::OctomapStatus s;
  s.header.stamp = stamp;
  s.header.frame_id = scene_->model().baseLink();
  s.resolution = map_->options().resolution;
  s.clouds = clouds_;
  {
    std::lock_guard<std::mutex> lock(*scene_mutex_);
    s.occupied_leaves = static_cast<uint32_t>(map_->occupiedLeafCount());
    s.stale_cells = static_cast<uint32_t>(map_->staleCount());
    const double t = (checked_map_ ? checked_map_ : map_)->mapTime();
    s.map_time = std::isfinite(t) ? t : 0.0;
  }
  s.hidden_cells = static_cast<uint32_t>(batch_stats_.hidden);
  s.turned_stale = static_cast<uint32_t>(batch_stats_.stale);
  s.beyond_watch = batch_stats_.beyond_watch;
  s.watches_ahead = static_cast<uint32_t>(map_->watchesAhead());
  s.sensor_frame = sensor_frame;
  const MapUpdateStats& u = update_.stats;
  s.points = static_cast<uint32_t>(u.points);
  s.robot_points = static_cast<uint32_t>(u.robot);
  s.beyond_range = static_cast<uint32_t>(u.beyond_range);
  s.hit_cells = static_cast<uint32_t>(u.hit_cells);
  s.free_cells = static_cast<uint32_t>(u.free_cells);
  s.integration_time = last_integration_;
  s.dropped = dropped_;
  {
    std::lock_guard<std::mutex> lock(*scene_mutex_);
    s.unobserved_cells = static_cast<uint32_t>(map_->unobservedCount());
  }
  s.known_free_cells = static_cast<uint32_t>(u.known_free);
  s.fixture_points = static_cast<uint32_t>(u.fixture);
  s.unheard_cameras = unheardCameras();
  status_pub_.publish(s);
}

/// Occupied cells as one CUBE_LIST (only when someone listens, e.g. rviz).
void OctomapMonitor::publishMarkers() {
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
    std::lock_guard<std::mutex> lock(*scene_mutex_);
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

}  // namespace moverl_planning_scene
