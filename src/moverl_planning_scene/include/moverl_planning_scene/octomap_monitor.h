/**
 * \file octomap_monitor.h
 * \brief Sensed obstacles, the ROS side: depth-camera point clouds (sensor_msgs/PointCloud2, any frame known to TF)
 *        are self-filtered with the configurations the robot may have been in (JointStateHistory) and integrated into
 *        the scene's OccupancyMap; ~octomap_status, ~octomap_markers and ~clear_octomap.
 *
 * Clouds and joint states are received on queues and threads of their own: a cloud takes tens of ms to integrate, and
 * the scene's services keep answering meanwhile (they only wait for the short tree update, under the scene's mutex).
 */
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <moverl_msgs/OctomapStatus.h>
#include <moverl_msgs/SensedCensus.h>
#include <ros/callback_queue.h>
#include <ros/ros.h>
#include <sensor_msgs/JointState.h>
#include <sensor_msgs/PointCloud2.h>
#include <std_srvs/Empty.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include "moverl_planning_scene/cloud_integrator.h"
#include "moverl_planning_scene/held_updates.h"
#include "moverl_planning_scene/joint_state_history.h"
#include "moverl_planning_scene/occupancy_map.h"
#include "moverl_planning_scene/planning_scene.h"
#include "moverl_planning_scene/sensed_margin.h"

namespace moverl_planning_scene {

/// \brief Why a cloud cannot be read as float32 x, y, z points ("" when it can): the fields exist as single float32
///        values inside each point, and the data holds every point the header claims.
std::string cloudLayoutError(const sensor_msgs::PointCloud2& cloud);

class OctomapMonitor {
 public:
  /// \param scene the scene whose checker gets the map; scene_mutex the mutex every reader of the scene holds
  /// \param filter_static points on the scene's static objects mark nothing (they are known exactly: obstacles sensed)
  OctomapMonitor(ros::NodeHandle nh, ros::NodeHandle pnh, PlanningScene* scene, std::mutex* scene_mutex,
                 bool filter_static = false);
  ~OctomapMonitor();

  /// \brief Read the octomap/ parameters, create the map, subscribe, and wait until the cameras' first views are in
  ///        the map (fail closed: an empty map calls everything free). False with *error.
  bool init(std::string* error);

  /// \brief The predictive margins (m) of one check whose move starts at `stamp` and lasts `duration` s (infinite:
  ///        unknown), from the map's age at `stamp`: under unknown_occupied, stamp minus the checks' map's time (its
  ///        last batch of views: OccupancyMap::mapTime; what the cameras missed since is in it as possibly occupied),
  ///        else stamp minus the oldest of the cameras' last integrated clouds. Either way the map is too old (fail
  ///        closed) when the oldest camera's last cloud is older than octomap/max_age.
  ///        In lockstep (octomap/lockstep) it first waits for the clouds received to be integrated; then,
  ///        while that age exceeds octomap/max_age, for newer clouds: both within stale_wait (wall) s in all (in
  ///        lockstep simulated time stands still meanwhile). False with *why when the map stays too old or a margin
  ///        exceeds the largest the checker has: nothing is known to be free (fail closed).
  ///        With octomap/lockstep_lag, the map the checks read holds the clouds up to the previous check's state
  ///        (lockstepMapCutoff), and it waits for those only; every cloud when the map would be older than max_age
  ///        without the others.
  ///        Must not be called with the scene's mutex held (integration needs it).
  /// \param epoch when the world's motions last restarted (a simulator reset moves every moving object back to its
  ///        start): a camera's clouds from before it tell nothing about where moving things are now, and the camera
  ///        counts as unseen until its next cloud. Zero: none.
  /// \param max_wait wall s the caller can spare for waiting (the shield's budget for the answer): the wait for clouds
  ///        lasts at most this, if it is shorter than octomap/stale_wait. Negative: stale_wait.
  bool margins(const ros::Time& stamp, double duration, SensedMargins* out, std::string* why,
               const ros::Time& epoch = ros::Time(), double max_wait = -1.0);
  /// \brief In lockstep (octomap/lockstep), wait until the clouds received are integrated, within octomap/stale_wait
  ///        (or max_wait, when >= 0 and shorter); at once in real time. margins() does it first; a query that reads
  ///        newestStamp() for its margin calls it before.
  void awaitIntegration(double max_wait = -1.0);
  /// \brief The newest integrated cloud's stamp (zero before the first).
  ros::Time newestStamp();
  /// \brief The world's sensing section (World.msg): its speed bound (m/s) replaces octomap/speed_bound (negative:
  ///        keep it); unknown_occupied switches OccupancyMapOptions::unknown_occupied; camera_frames are the frames of
  ///        the cameras it lists, each of which must be heard from (one never heard from leaves the map blind). Before
  ///        or after init.
  void setWorldSensing(double speed_bound, bool unknown_occupied, const std::vector<std::string>& camera_frames);
  /// \brief The world's cameras not heard from since start-up or the last clear.
  std::vector<std::string> unheardCameras();

 private:
  void onJointState(const sensor_msgs::JointState::ConstPtr& msg);
  /// Receives a cloud: it replaces its camera's pending one (the integration thread takes them camera by camera).
  void onCloud(const sensor_msgs::PointCloud2::ConstPtr& msg);
  /// The integration thread: integrates the pending cloud of the camera whose last integrated cloud is oldest, so
  /// that no camera starves when integration falls behind (a shared queue dropped whichever cloud was oldest).
  void integrateLoop();
  /// Lockstep: wait until the clouds received stamped up to *cutoff (nullptr: all of them) are integrated into map_.
  void awaitPending(const ros::Time* cutoff, std::chrono::steady_clock::time_point deadline);
  /// octomap/lockstep_lag: apply the held updates to the checks' map, in their order, up to the first stamped after
  /// *cutoff (nullptr: all); their cameras count as seen from then on.
  void publishHeld(const ros::Time* cutoff);
  /// The cloud stamped `stamp` from `frame` is in the map the checks read (its age counts it).
  void markSeen(const std::string& frame, const ros::Time& stamp);
  void integrate(const sensor_msgs::PointCloud2::ConstPtr& msg);
  /// Real time, pending_mutex_ held: the cameras a whole batch needs (with clouds waiting, or heard lately).
  std::vector<std::string> sendingCameras();
  /// An update of map_ (a cloud's, or a batch's close: frame ""): into map_ now, and into the checks' map now or, with
  /// octomap/lockstep_lag, held for it. The integration thread only.
  void intoMaps(const MapUpdate& update, const ros::Time& stamp, const std::string& frame);
  /// Every camera the world lists has a cloud stamped `stamp` or later in map_ (none listed: true).
  bool batchComplete(const ros::Time& stamp);
  bool clear(std_srvs::Empty::Request&, std_srvs::Empty::Response&);
  /// ~sensed_census: what the checks' map holds within the robot's reach (SensedCensus.srv).
  bool census(moverl_msgs::SensedCensus::Request& req, moverl_msgs::SensedCensus::Response& res);
  void drop(const std::string& why, const std::string& frame = "");
  void publishStatus(const ros::Time& stamp, const std::string& sensor_frame);
  void publishMarkers();

  ros::NodeHandle nh_, pnh_;
  PlanningScene* scene_;
  std::mutex* scene_mutex_;
  bool filter_static_ = false;
  std::unique_ptr<OccupancyMap> map_;  // the clouds integrated; without octomap/lockstep_lag also the checks' map
  // octomap/lockstep_lag (lockstep only): the map the checks read. It gets map_'s updates later, in the same order
  // (an update is computed against map_ as it was: applied to the same state, it gives the same map).
  bool lag_ = false;
  double lag_max_margin_ = 0.0;  // octomap/lockstep_lag_max_margin (m)
  std::unique_ptr<OccupancyMap> checked_map_;
  HeldUpdates held_;          // map_'s updates not yet in checked_map_ (guarded by pending_mutex_)
  std::mutex publish_mutex_;  // serializes publishHeld (the updates go in in their order)
  double previous_check_ = std::numeric_limits<double>::quiet_NaN();  // the latest check's stamp (pending_mutex_)
  bool publish_at_once_ = false;  // a check waits for every cloud: they go into its map as they come (pending_mutex_)
  bool integrating_ = false;      // the integration thread holds a cloud stamped in_flight_ (pending_mutex_)
  ros::Time in_flight_;
  std::mutex sensor_mutex_;  // serializes cloud integration with ~clear_octomap (never held by the queries)
  ros::CallbackQueue sensor_queue_, joint_queue_;
  std::unique_ptr<ros::AsyncSpinner> sensor_spinner_, joint_spinner_;
  std::unique_ptr<tf2_ros::Buffer> tf_buffer_;
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;
  ros::Subscriber joint_sub_, cloud_sub_, bodies_sub_;
  // octomap/ssm/tracking (safety ssm, use): the tracked bodies (REP 155's /humans/bodies/tracked) and what a check
  // trusts of their parts' TF frames.
  bool track_people_ = false;
  TrackingRule tracking_;
  std::vector<std::pair<std::string, double>> part_radii_;
  std::mutex bodies_mutex_;          // guards bodies_
  std::vector<std::string> bodies_;  // the last list's ids
  /// The parts of the tracked bodies as their TF frames give them now (base frame; a frame not there is skipped).
  std::vector<TrackedPart> trackedParts();
  ros::Publisher status_pub_, marker_pub_;
  ros::ServiceServer clear_srv_, census_srv_;
  std::vector<std::string> joints_;
  JointStateHistory history_{400};
  std::unique_ptr<CloudIntegrator> cloud_integrator_;
  Integration integration_ = Integration::kRayCasting;  // octomap/integration (init reads it)
  std::map<std::string, bool> fell_back_;               // per camera frame: its last cloud fell back to ray casting
  std::vector<std::vector<double>> configurations_;
  MapUpdate update_, close_update_;
  BatchStats batch_stats_;                        // the last batch's close (integration thread)
  std::atomic<double> motion_epoch_{0.0};         // the newest motion epoch a check named (margins)
  std::atomic<bool> forget_pending_{false};       // it is newer than the map: the next batch forgets what it knew free
  std::map<std::string, ros::Time> integrated_;   // per camera frame: its last cloud in map_ (pending_mutex_)
  ros::Time open_batch_;                          // the stamp of map_'s open batch (zero: none; pending_mutex_)
  double batch_wait_ = 0.0;                       // octomap/batch_wait (s, wall)
  std::map<std::string, std::string> last_drop_;  // per camera frame: why its last dropped cloud was (stamps_)
  double joint_state_wait_ = 0.0, self_filter_padding_ = 0.0, transform_timeout_ = 0.0, last_integration_ = 0.0;
  double static_filter_padding_ = 0.0, future_tolerance_ = 0.0, camera_wait_ = 0.0;
  std::atomic<bool> world_speed_bound_{false};  // the world file gave the speed bound (else octomap/speed_bound)
  std::atomic<uint32_t> clouds_{0}, dropped_{0};
  ros::Time last_cloud_stamp_;  // the last integrated cloud's stamp and frame (reported with drops too)
  std::string last_cloud_frame_;
  // The sensed margin: octomap/safety, speed_bound, latency, plan_horizon, max_age, ssm/ (config/planning_scene.yaml;
  // rule_.speed_bound is the YAML's) and stale_wait; speed_bound_ is the one in force (the world's, else the YAML's).
  SensedMarginRule rule_;
  std::atomic<double> speed_bound_{0.0};
  std::atomic<bool> unknown_occupied_{false};   // the world's sensing: unknown_occupied
  std::atomic<bool> static_known_free_{false};  // the static objects changed: tell the integrator (next cloud)
  double max_age_ = 0.0, stale_wait_ = 0.0;
  double max_margin_ = 0.0;  // the largest margin the mapped box covers (beyond the robot's padded reach)
  /// The margin rule of these tunables and speed bound (max_margin: max_margin_, within the checker's largest).
  SensedMarginRule marginRule() const;
  std::mutex stamps_mutex_;  // guards frame_stamps_; stamps_cv_ is notified after every integrated cloud
  std::condition_variable stamps_cv_;
  std::map<std::string, ros::Time> frame_stamps_;  // each camera frame's last integrated cloud stamp
  std::vector<std::string> cameras_;               // the frames of the cameras the world lists
  std::mutex pending_mutex_;                       // guards pending_ and stop_; pending_cv_ wakes the integrator
  std::condition_variable pending_cv_;
  // Per frame the clouds not yet integrated: in lockstep in order (the newest queue_size), in real time the newest.
  std::map<std::string, std::deque<sensor_msgs::PointCloud2::ConstPtr>> pending_;
  bool lockstep_ = false;        // octomap/lockstep (init reads it)
  std::size_t queue_depth_ = 1;  // octomap/queue_size: clouds kept per camera in lockstep
  int outstanding_ = 0;  // clouds pending or being integrated (guarded by pending_mutex_; idle_cv_ when it drops)
  std::condition_variable idle_cv_;
  bool stop_ = false;
  std::thread integrator_;
};

}  // namespace moverl_planning_scene
