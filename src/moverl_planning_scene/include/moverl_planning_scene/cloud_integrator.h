/**
 * \file cloud_integrator.h
 * \brief One depth-camera cloud into the occupancy map, as the scene node does it, ROS-free (the node and
 *        map_benchmark share it): the points into the map frame, the robot's points marked (self filter, every
 *        configuration the robot may have been in), the static objects' points marked (obstacles: sensed), the
 *        map's update, by projection when the cloud is a pinhole image, else by ray casting, and, under
 *        unknown_occupied, the unobserved cells no camera can see but that hold no obstacle turned free (inside the
 *        robot in those configurations, within the padding it keeps; once per world, inside the static objects).
 */
#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "moverl_planning_scene/fcl_collision_checker.h"
#include "moverl_planning_scene/occupancy_map.h"
#include "moverl_planning_scene/pinhole_camera.h"
#include "moverl_planning_scene/unset.h"
#include "moverl_planning_scene/worker_pool.h"

namespace moverl_planning_scene {

/// \brief How free space is found (config/planning_scene.yaml octomap/integration).
enum class Integration {
  kProjective,  ///< an organized cloud that fits a pinhole camera: grid cells projected into the image
  kRayCasting,  ///< every end cell's beam walked through the grid (any cloud)
};
/// \brief "projective" / "ray_casting" -> the enum. False with *error naming the valid choices.
bool parseIntegration(const std::string& name, Integration* out, std::string* error);
const char* integrationName(Integration integration);

/// \brief Pixels a cloud's points may stray from a pinhole image's rays and still be projected (fitPinhole's
///        tolerance). A driver's organized cloud from a rectified depth image lies on them up to float rounding.
constexpr double kPinholeTolerancePx = 0.05;

/// \brief A cloud's points as a PointCloud2 lays them out: float32 x, y, z at byte offsets within each point,
///        points `point_step` bytes apart, rows `row_step` bytes apart (the caller checked that they fit in the data).
struct CloudView {
  const std::uint8_t* data = nullptr;
  int width = 0, height = 0;
  std::size_t point_step = 12, row_step = 0;
  std::size_t x = 0, y = 4, z = 8;  ///< byte offsets of the fields
};

struct CloudIntegratorOptions {
  double self_filter_padding = kUnset;                 ///< octomap/self_filter_padding
  double static_filter_padding = kUnset;               ///< octomap/static_filter_padding
  bool filter_static = false;                          ///< mark the static objects' points (obstacles: sensed)
  Integration integration = Integration::kRayCasting;  ///< the node sets octomap/integration's
  int threads = 0;  ///< octomap/integration_threads: threads that integrate a cloud, the caller's included (>= 1)
};

/// \brief Where one cloud's time went (s, wall clock of the calling thread).
struct CloudTiming {
  double points = 0.0;         ///< into the map frame (projective: with the pinhole fit and its check)
  double self_filter = 0.0;    ///< robotPointMask over the configurations
  double static_filter = 0.0;  ///< staticObjectPointMask
  double update = 0.0;         ///< the map's update (computeUpdate or computeUpdateProjective)
  double known_free = 0.0;     ///< unknown_occupied: the unobserved cells inside the robot and static objects freed
  double total() const { return points + self_filter + static_filter + update + known_free; }
};

class CloudIntegrator {
 public:
  /// \param world_mutex held while reading the checker's world (static filter); nullptr: none needed
  /// Throws std::invalid_argument when options.threads < 1.
  CloudIntegrator(OccupancyMap* map, const FclCollisionChecker* checker, std::mutex* world_mutex,
                  const CloudIntegratorOptions& options);

  /// \brief The update of one cloud (apply it to the map under the readers' lock). cloud: width * height points in
  ///        the sensor frame (non-finite: no return). sensor_pose: the sensor frame in the map frame. configurations:
  ///        where the robot may have been when the cloud was taken (at least one). Returns the integration used:
  ///        projective falls back to ray casting when the cloud is not a pinhole image (*why, if given, says why; ""
  ///        otherwise).
  Integration compute(const CloudView& cloud, const Eigen::Isometry3d& sensor_pose,
                      const std::vector<std::vector<double>>& configurations, MapUpdate* update,
                      CloudTiming* timing = nullptr, std::string* why = nullptr);
  /// \brief The static objects changed (a new world, a cleared map): the next cloud turns their unobserved cells
  ///        free again (unknown_occupied). Call from the thread that calls compute.
  void staticObjectsChanged() { static_known_free_ = true; }
  /// \brief The map's hidden space (OccupancyMapOptions::hidden_space): the next cloud is stamped `stamp` (s);
  ///        OccupancyMap::beginView, the batch it closes vouched for as closeBatch below. True with *close to apply
  ///        (and *stats, optional, what the close found).
  bool beginView(double stamp, MapUpdate* close, BatchStats* stats = nullptr);
  /// \brief OccupancyMap::closeBatch, the robot's padding band in the configurations of the batch's clouds known free
  ///        (as compute's addKnownFree: nobody stands there).
  bool closeBatch(MapUpdate* close, BatchStats* stats = nullptr);
  /// \brief The threads that integrate a cloud (options.threads).
  int threads() const { return pool_->threads(); }
  /// \brief The intrinsics the last projective update used.
  const PinholeCamera& camera() const { return camera_; }

 private:
  OccupancyMap* map_;
  const FclCollisionChecker* checker_;
  std::mutex* world_mutex_;
  CloudIntegratorOptions options_;
  std::unique_ptr<WorkerPool> pool_;  ///< options_.threads: the points, their filters and the projective update
  PinholeCamera camera_;
  std::vector<float> sensor_xyz_, depth_;
  std::vector<Eigen::Vector3d> points_;
  std::vector<std::uint32_t> pixel_of_;   ///< the pixel of each of points_
  std::vector<std::uint8_t> has_return_;  ///< per pixel: 1 where its point is finite
  std::vector<std::size_t> row_first_;    ///< per row: the index in points_ of its first point (and the count last)
  std::vector<PinholeFit> row_fit_;       ///< projective: per row, its points' sums for the pinhole fit
  std::vector<double> row_worst_;         ///< projective: per row, pinholeRowResidual of its points
  std::vector<std::uint8_t> mask_, mask_more_, pixel_mask_;
  /// Unknown-is-occupied: turns free in *update the unobserved cells that reach into the robot's padding (in the
  /// cloud's configurations: no camera sees them, the robot stands there; left occupied they would block it where it
  /// stands) and, once per world, into a static object's filter zone. docs/sensing.md states the blind zone this
  /// leaves.
  void addKnownFree(const std::vector<std::vector<double>>& configurations, MapUpdate* update);
  bool static_known_free_ = true;  ///< the static objects' cells are to be turned free (next cloud)
  std::vector<std::vector<double>> batch_configurations_;  ///< the configurations of the open batch's clouds
  OccupancyMap::KnownFree batch_known_free_;               ///< the robot's band in them (closeBatch's known_free)
  std::vector<std::uint8_t> band_mask_;
  std::vector<Eigen::AlignedBox3d> boxes_;  ///< addKnownFree's scratch
  std::vector<Eigen::Vector3d> cell_centers_, box_centers_;
  std::vector<std::uint64_t> cell_keys_, box_keys_, free_keys_, solid_keys_;
  std::vector<Eigen::Vector3d> corners_;
};

}  // namespace moverl_planning_scene
