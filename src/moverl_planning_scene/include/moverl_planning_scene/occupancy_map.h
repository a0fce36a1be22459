/**
 * \file occupancy_map.h
 * \brief Sensed obstacles: an OctoMap occupancy octree updated from depth-camera point clouds. ROS-free.
 *
 * Update rule (octomap_server's sensor model, discretized insertion): every beam from the sensor origin to a point
 * marks the cells it crosses as free (a miss) and the cell of its end point as occupied (a hit). Beams longer than
 * max_range mark free space up to max_range only (no-return readings at a camera's far plane clear space this way).
 * Points that belong to the robot itself (a mask computed by the caller, see FclCollisionChecker::robotPointMask) clear
 * the cells before them but mark nothing occupied; points on a static world object the scene knows exactly clear
 * their end cell too (the beam saw the space down to the object's surface). Within one cloud a cell hit by any beam
 * stays occupied even when other beams cross it. Points are grouped by the cell they end in (one beam per end cell, to
 * its centre; a cell where any obstacle point ends is hit, whatever else ends there). Beams are clipped to `bounds`
 * (the robot's reach and margin). Clearing: when an obstacle moves away, beams now pass through its old cells and turn
 * them free.
 *
 * Unknown space: by default cells never observed are unknown and count as free for collision checking (as in
 * MoveIt). With unknown_occupied they count as occupied (a person may stand where no camera looks): every cell of the
 * mapped box starts at a prior log-odds just above the occupancy threshold, which one miss turns free and one hit
 * keeps occupied, so the update rule is unchanged. Space no camera can see but that holds no obstacle (inside the
 * robot's links, inside static world objects) is turned free by the caller with addKnownFree.
 *
 * Cost: a dense grid over `bounds` mirrors the tree's leaves (one log-odds value per cell). It deduplicates the cells
 * that a cloud's beams cross without sorting, and it tells which of them the update would change: a cell already
 * clamped at clamp_min stays where it is when seen free again, so the tree only receives the cells that change. Once
 * the static scene has been seen, a cloud changes the few thousand cells around what moved instead of the ~800,000
 * cells its beams cross (`rosrun moverl_planning_scene map_benchmark`).
 */
#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "moverl_planning_scene/unset.h"

namespace octomap {
class OcTree;
class OcTreeNode;
}  // namespace octomap

namespace moverl_planning_scene {

/// \brief Tunables of the occupancy map. Their values live in config/planning_scene.yaml's octomap: section (tunables.h
///        reads them); unset ones (NaN) are rejected by create().
struct OccupancyMapOptions {
  double resolution = kUnset;  ///< leaf size (m)
  double max_range = kUnset;   ///< beams are integrated up to this range (m); longer ones clear space only
  double prob_hit = kUnset;    ///< occupancy probability of a hit
  double prob_miss = kUnset;   ///< occupancy probability of a miss
  double clamp_min = kUnset;   ///< clamping of cell probabilities (lets cells change state quickly)
  double clamp_max = kUnset;
  double occupancy_threshold = kUnset;  ///< a cell above this probability is an obstacle
  /// Only this box (map frame) is mapped: beams are clipped to it, hits outside it are ignored. Required (the dense
  /// grid covers it). The node sets it to the robot's padded reach plus the largest predictive margin a check may use
  /// (nothing outside can touch the robot within the margin's time).
  Eigen::AlignedBox3d bounds;
  /// Cells never observed count as occupied (see the file comment). Set by the scenario (a world file's `sensing:
  /// unknown_occupied:`), not by config/planning_scene.yaml; setUnknownOccupied switches it later.
  bool unknown_occupied = false;
};

/// \brief What a point of a cloud is, as computeUpdate's mask says.
constexpr std::uint8_t kPointObstacle = 0;   ///< anything else: its end cell is hit
constexpr std::uint8_t kPointOnRobot = 1;    ///< on the robot (self filter): clears the cells before it only
constexpr std::uint8_t kPointOnFixture = 2;  ///< on a static world object the scene knows exactly (obstacles: sensed):
                                             ///< clears the cells before it and its end cell

/// \brief What one integration did (logs, tests, the status topic).
struct MapUpdateStats {
  std::size_t points = 0;         ///< points in the cloud
  std::size_t invalid = 0;        ///< non-finite points (skipped)
  std::size_t robot = 0;          ///< points on the robot (free space before them only)
  std::size_t fixture = 0;        ///< points on static world objects (free space up to them)
  std::size_t beyond_range = 0;   ///< points beyond max_range (free space only)
  std::size_t hit_cells = 0;      ///< distinct cells marked occupied
  std::size_t free_cells = 0;     ///< distinct cells marked free
  std::size_t changed_cells = 0;  ///< of the hit and free cells, those whose value the update changes
  std::size_t known_free = 0;     ///< unobserved cells turned free by addKnownFree (inside the robot, static objects)
};

/// \brief The cell updates computed from one cloud, applied later under the caller's lock.
struct MapUpdate {
  std::vector<std::uint64_t> hits;    ///< packed octomap keys of the hit cells the update changes
  std::vector<std::uint64_t> misses;  ///< packed octomap keys of the free cells it changes (hits removed)
  MapUpdateStats stats;
};

/// \brief Occupancy octree in the robot base frame.
///        computeUpdate, addKnownFree and unobservedCells read the map (not the tree) and may run concurrently with
///        collision checks that read tree(), but not with apply, clear or setUnknownOccupied; those modify the tree
///        and the map and must be serialized with every reader by the caller. One thread integrates clouds
///        (computeUpdate uses the map's scratch space).
class OccupancyMap {
 public:
  /// \brief nullptr with *error for bad options (resolution <= 0, probabilities outside (0, 1), ...).
  static std::unique_ptr<OccupancyMap> create(const OccupancyMapOptions& options, std::string* error);
  ~OccupancyMap();

  /// \brief Beams from origin to every point (all in the map frame). robot_mask: empty, or one value per point
  ///        (kPointObstacle, kPointOnRobot, kPointOnFixture).
  void computeUpdate(const std::vector<Eigen::Vector3d>& points, const std::vector<std::uint8_t>& robot_mask,
                     const Eigen::Vector3d& origin, MapUpdate* out);
  /// \brief Unobserved cells (never hit nor seen free) known to hold no obstacle, given as packed keys from
  ///        unobservedCells: added to `out` as seen free, unless this cloud hits them. Call after computeUpdate with
  ///        the same update, before apply (it uses computeUpdate's marks of this cloud).
  void addKnownFree(const std::vector<std::uint64_t>& keys, MapUpdate* out);
  /// \brief Apply an update to the tree (hits, then misses).
  void apply(const MapUpdate& update);
  /// \brief Forget everything (all cells unknown: occupied under unknown_occupied).
  void clear();
  /// \brief Switch the unknown-is-occupied rule. On: every unobserved cell gets the prior (occupied); off: they turn
  ///        unknown (free) again. Modifies the tree: serialize with readers as apply.
  void setUnknownOccupied(bool on);
  bool unknownOccupied() const { return options_.unknown_occupied; }
  /// \brief Centres and packed keys of the cells whose centre lies in `box` and that were never observed. Empty
  ///        unless unknown_occupied.
  void unobservedCells(const Eigen::AlignedBox3d& box, std::vector<Eigen::Vector3d>* centers,
                       std::vector<std::uint64_t>* keys) const;
  /// \brief How many cells count as occupied only because no camera has seen them (0 unless unknown_occupied).
  std::size_t unobservedCount() const;

  /// \brief The tree (for FCL). Stays the same object for the map's lifetime.
  std::shared_ptr<const octomap::OcTree> tree() const;
  /// \brief True when the cell containing p (map frame) is occupied.
  bool occupied(const Eigen::Vector3d& p) const;
  /// \brief Centre and edge length of every leaf seen occupied (pruned leaves may be larger than the resolution).
  ///        Leaves occupied only because no camera has seen them (unknown_occupied) are left out: unobservedCount.
  void occupiedLeaves(std::vector<Eigen::Vector3d>* centers, std::vector<double>* sizes) const;
  /// \brief How many cells a camera saw occupied (kept up to date by apply: no walk of the tree).
  std::size_t occupiedLeafCount() const;
  const OccupancyMapOptions& options() const { return options_; }

 private:
  OccupancyMap() = default;
  /// Index of a packed key in the dense grid, or -1 outside it.
  std::int64_t cell(std::uint64_t packed) const;
  /// The packed key of grid cell (at[0], at[1], at[2]).
  std::uint64_t packAt(const std::int64_t* at) const;
  /// The log-odds a hit (update > 0) or a miss leaves in a cell that holds v (NaN: never observed).
  float updated(float v, float update) const;
  /// A leaf occupied by what a camera saw (not only by the unknown_occupied prior).
  bool seenOccupied(const octomap::OcTreeNode& node) const;
  /// Every unobserved cell at the prior (on) or unknown (off), in value_ and the tree.
  void fillUnobserved(bool on);

  OccupancyMapOptions options_;
  std::shared_ptr<octomap::OcTree> tree_;
  // Dense mirror of the tree's leaves inside bounds: cell (i, j, k) holds the key key_min_ + (i, j, k).
  std::uint16_t key_min_[3] = {0, 0, 0};
  std::int64_t size_[3] = {0, 0, 0};
  std::vector<float> value_;               ///< log-odds of each cell; NaN: never observed (no node in the tree)
  std::vector<std::uint64_t> seen_, hit_;  ///< computeUpdate's scratch: a bit per cell (seen free, hit this cloud)
  std::vector<std::uint64_t> observed_;    ///< a bit per cell: hit or seen free at least once since the last clear
  float log_hit_ = 0.0f, log_miss_ = 0.0f, clamp_min_ = 0.0f, clamp_max_ = 0.0f;
  float prior_ = 0.0f;              ///< log-odds of an unobserved cell under unknown_occupied
  float threshold_ = 0.0f;          ///< log-odds of occupancy_threshold
  std::int64_t seen_occupied_ = 0;  ///< observed cells at or above the threshold
  /// An observed cell's value counts as seen occupied.
  bool seenOccupiedValue(float v, bool observed) const { return observed && v >= threshold_; }
};

}  // namespace moverl_planning_scene
