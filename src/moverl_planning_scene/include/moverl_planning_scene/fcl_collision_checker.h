/**
 * \file fcl_collision_checker.h
 * \brief FCL 0.7 implementation of CollisionChecker, with the allowed-collision matrix (ACM). ROS-free.
 */
#pragma once

#include <cstdint>
#include <limits>
#include <memory>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "moverl_planning_scene/collision_checker.h"
#include "moverl_planning_scene/occupancy_map.h"
#include "moverl_planning_scene/robot_model.h"
#include "moverl_planning_scene/tracked_parts.h"
#include "moverl_planning_scene/unset.h"

namespace fcl {
template <typename S>
class CollisionGeometry;
}  // namespace fcl

namespace moverl_planning_scene {

/// \brief How robot link meshes are represented.
enum class MeshMode { kConvexHull, kTriangles };

/// \brief Why a pair of links is not checked (kEnabled: it is checked).
enum class AcmReason : std::uint8_t { kEnabled = 0, kAdjacent, kRigid, kAlways, kNever, kStatic, kNoGeometry };

/// \brief Tunables of the FCL checker. Their values live in config/planning_scene.yaml (tunables.h reads them); unset
///        ones (NaN, -1) are rejected by create().
struct FclCheckerOptions {
  double padding = kUnset;  ///< world obstacles inflated by this (m)
  /// Each robot link is inflated by at least this (m) in self-collision checks (a pair: 2x); covers the physics
  /// engine's collision margins (PyBullet: 1 mm per convex hull) and motion between path samples (path_resolution / 2).
  double self_padding = kUnset;
  double path_resolution = kUnset;  ///< max motion of any robot point between checked states (m)
  MeshMode mesh_mode = MeshMode::kConvexHull;
  int acm_samples = -1;  ///< random configurations for the always/never-in-collision test (0: skip)
  unsigned acm_seed = 0;
  /// Folder where computed ACMs are cached (file name = hash of the inputs). Empty: no cache.
  std::string acm_cache_dir;
  /// checkPath leaves out, for a whole segment, the shape pairs a plane at its midpoint separates by more than their
  /// motion over half the segment can close (they meet at none of its states): the same answers with fewer GJK calls.
  /// Against the occupancy map likewise, the shapes that no occupied cell comes near enough at the midpoint.
  /// Not a tunable (the answers do not depend on it): false checks every pair at every state, for the tests that
  /// compare the two.
  bool cull_path_pairs = true;
};

/// \brief One collision geometry of a link as the checker holds it (diagnostics, tests, the parity tool).
struct LinkGeometry {
  ShapeType type = ShapeType::kBox;
  std::string piece;                                         ///< mesh piece (OBJ object/group name), "" otherwise
  Eigen::Isometry3d origin = Eigen::Isometry3d::Identity();  ///< shape frame in the link frame
  Eigen::Vector3d dims = Eigen::Vector3d::Zero();            ///< primitives, as CollisionShapeSpec::dims
  /// Meshes: the points (shape frame) whose convex hull is the shape in convex_hull mode (the mesh's vertices in
  /// triangles mode).
  std::vector<Eigen::Vector3d> vertices;
};

/// \brief Statistics of the ACM computation (for logs and tests).
struct AcmStats {
  bool from_cache = false;
  double seconds = 0.0;  ///< time spent computing or loading
  int adjacent = 0, rigid = 0, always = 0, never = 0, enabled = 0;
  /// "Never" pairs: the random samples found them apart, a search for their closest approach (from the samples where
  /// they came closest) too: the smallest distance (m) it found between two such pairs' padded shapes (not computed
  /// when loaded from the cache: infinity), and how many pairs it found touching (so checked after all).
  double never_min_distance = std::numeric_limits<double>::infinity();
  int never_refuted = 0;
  std::string cache_file;
};

/// \brief FCL-based checker: convex hulls (GJK) or OBBRSS triangle BVHs for robot meshes, primitives for the world.
class FclCollisionChecker : public CollisionChecker {
 public:
  /// \brief Loads the collision geometry and computes (or loads) the ACM. Returns nullptr with *error on failure.
  static std::unique_ptr<FclCollisionChecker> create(const RobotModel& model, const FclCheckerOptions& options,
                                                     std::string* error);
  ~FclCollisionChecker() override;

  bool setWorld(const std::vector<WorldObject>& objects, std::string* error) override;
  void setMotionWindow(double t0, double t1) override;
  bool hasMovingObstacles() const override { return !moving_.empty(); }
  /// Also answers from the culling of the last segment prepared (prepareSegment, or checkPath's) when q is one of its
  /// ends and the world has not changed since: the same answers.
  void checkState(const double* q, const CollisionRequest& request, CollisionResult* result) override;
  /// \brief Culls the shape pairs for the segment q0 -> q1 (as checkPath does, see cull_path_pairs) ahead of checks
  ///        of its ends and of the segment itself, which then reuse it while the world (setWorld, setMotionWindow)
  ///        stays as it is. Nothing without cull_path_pairs.
  void prepareSegment(const double* q0, const double* q1);
  void checkPath(const double* q0, const double* q1, const PathCheckRequest& request, PathCheckResult* result) override;
  std::size_t interiorStateCount(const double* q0, const double* q1) const override;

  /// \brief Sensed obstacles: an occupancy map in the base frame (its occupied cells are obstacles). Robot links are
  ///        inflated by `padding` against it (its cells cannot be). nullptr removes it. The map is read by every check:
  ///        callers must not modify it while a check runs; it must outlive its use here.
  void setOccupancy(const OccupancyMap* map) { occupancy_ = map; }
  bool hasOccupancy() const { return occupancy_ != nullptr; }
  /// \brief safety:=ssm with a tracker (tracked_parts.h): in the checks that follow, a seen cell a part explains
  ///        stops a link only when the link, padded, also meets the part's keep_out ball (the part lies in both where
  ///        the map saw it, grown by the margin, and where its newer track puts it). Cells not seen occupied, and seen
  ///        ones no part explains, keep the map's check. nullptr or empty: none.
  ///        Only the state and path checks use them (occupancyFree and occupancyDistance do not: the retreat's
  ///        questions stay ISO's). The parts must outlive their use here.
  void setTrackedParts(const std::vector<ExplainedPart>* parts) { parts_ = parts; }
  /// \brief The sensed obstacles' predictive margin (m, >= 0): robot links are inflated by padding + margin against
  ///        the occupancy map in the checks that follow (where a sensed obstacle may have moved since it was seen).
  ///        Rounded up to a multiple of kMarginStep; each link's inflated shapes are built the first time a level is
  ///        used. False (margin unchanged) when the margin is not finite, negative or above kMaxMargin.
  bool setOctreeMargin(double margin);
  /// \brief The margin (m) the occupancy checks now use (the requested one rounded up).
  double octreeMargin() const { return octo_level_ * kMarginStep; }
  /// \brief True when no moving link's shape, padded and inflated by the current margin, meets an occupied cell of
  ///        class `which` in q.
  bool occupancyFree(const double* q, CellClass which = CellClass::kAll);
  /// \brief The distance (m) in q between the moving links' raw collision shapes and the nearest occupied cell of
  ///        class `which` (GJK), exact when it lies in [below, above]: as soon as one below `below` is found it is
  ///        returned (early exit), and `above` when every such cell is at least that far. 0 when a link meets a cell.
  ///        No map: infinity.
  double occupancyDistance(const double* q, double below, double above, CellClass which = CellClass::kAll);
  static constexpr double kMarginStep = 0.01;  ///< m between the sensed margin's levels
  static constexpr double kMaxMargin = 1.0;    ///< m: the largest margin (100 levels)
  /// \brief mask[k] = 1 when points[k] (base frame) lies within `padding` of any robot link's collision shape in
  ///        configuration q (static links included). Reads only constant data: safe to call while checks run.
  /// \param skip (optional, one per point) points already known to be on the robot (nonzero): not tested, mask 0
  ///        (the self filter of several configurations ORs their masks: each tests what the ones before left).
  /// \param pool (optional) parts of the points tested on its threads at once (the same mask).
  void robotPointMask(const double* q, const std::vector<Eigen::Vector3d>& points, double padding,
                      std::vector<std::uint8_t>* mask, const std::vector<std::uint8_t>* skip = nullptr,
                      WorkerPool* pool = nullptr) const;
  /// \brief mask[k] = 1 when points[k] (base frame) lies within `padding` of a static world object (no motion; cones
  ///        as their bounding cylinder). Reads the world: callers serialize it with setWorld.
  /// \param pool (optional) parts of the points tested on its threads at once (the same mask).
  void staticObjectPointMask(const std::vector<Eigen::Vector3d>& points, double padding,
                             std::vector<std::uint8_t>* mask, WorkerPool* pool = nullptr) const;
  /// \brief mask[k] = 1 when points[k] (base frame) lies inside a static world object's shape exactly (boxes, spheres
  ///        and cylinders; never inside a cone). Nothing can be there. Reads the world: callers serialize it with
  ///        setWorld.
  void staticObjectSolidMask(const std::vector<Eigen::Vector3d>& points, std::vector<std::uint8_t>* mask) const;
  /// \brief Axis-aligned boxes (base frame) around the bounding sphere of each robot collision shape in configuration
  ///        q, grown by `padding`: where robotPointMask can return 1.
  void robotBoundingBoxes(const double* q, double padding, std::vector<Eigen::AlignedBox3d>* boxes) const;
  /// \brief Axis-aligned boxes (base frame) around each static world object, grown by `padding`: where
  ///        staticObjectPointMask can return 1. Reads the world: callers serialize it with setWorld.
  void staticObjectBoxes(double padding, std::vector<Eigen::AlignedBox3d>* boxes) const;
  /// \brief As robotPointMask, for the collision shapes of one link only (link index; -1: every link).
  void linkPointMask(const double* q, int link, const std::vector<Eigen::Vector3d>& points, double padding,
                     std::vector<std::uint8_t>* mask, const std::vector<std::uint8_t>* skip = nullptr) const;
  /// \brief As linkPointMask, by FCL's sphere test for every shape (linkPointMask answers convex hulls from their
  ///        faces): the oracle its tests compare it with, slower.
  void linkPointMaskFcl(const double* q, int link, const std::vector<Eigen::Vector3d>& points, double padding,
                        std::vector<std::uint8_t>* mask) const;
  /// \brief The collision geometries of a link (index in RobotModel::linkNames()): one per primitive, one per mesh
  ///        piece (mesh_loader.h).
  std::vector<LinkGeometry> linkGeometry(int link) const;
  /// \brief Mesh pieces whose convex hull came out degenerate (flat, tiny, or unverifiable): they are checked as the
  ///        hull of all their points, padded by icosahedra around every point (correct, slower).
  std::size_t degenerateHulls() const { return degenerate_hulls_; }
  /// \brief Bound (m) on the distance of any robot collision point from the base origin over all configurations.
  double reachRadius() const { return reach_radius_; }
  /// Name reported for the octree in colliding pairs.
  static constexpr const char* kOctomapId = "octomap";

  /// \brief Reason why the pair of links (by name) is (not) checked; kNoGeometry for unknown names.
  AcmReason acmReason(const std::string& link_a, const std::string& link_b) const;
  /// \brief How the ACM was obtained.
  const AcmStats& acmStats() const { return acm_stats_; }
  /// \brief Bound r_i (m per rad, or 1 for prismatic) of controlled joint i used by the path check.
  double jointRadiusBound(std::size_t i) const { return joint_radius_[i]; }
  /// \brief checkPath's culling: a bound (m) on how far any point of link b's padded shapes moves relative to link a
  ///        (-1: to the base, where world obstacles are) on the segment q0 -> q1, and of a's relative to b. The joints
  ///        between the two in the tree count, each by |q1_i - q0_i| times its radius (jointRadiusBound's, per link);
  ///        a joint that moves both moves them as one rigid body.
  double segmentMotionBound(const double* q0, const double* q1, int a, int b) const;
  /// \brief Number of world objects.
  std::size_t worldSize() const;
  /// \brief Bounding-sphere radius and centre of world object i as currently checked (tests: the swept inflation).
  double obstacleRadius(std::size_t i) const;
  Eigen::Vector3d obstacleCenter(std::size_t i) const;
  /// \brief True when world object i (as currently checked, padded) contains point p (world frame).
  bool obstacleContains(std::size_t i, const Eigen::Vector3d& p) const;
  const FclCheckerOptions& options() const { return options_; }

  /// checkPath's culling remembers, per shape pair, what proposes its next separating plane: an upper bound on the
  /// pair's distance at the last culling's midpoint (GJK's, grown by their motion since) and the plane that separated
  /// them then (unit normal in the first shape's frame; zero: none).
  struct PairMemory {
    double upper = std::numeric_limits<double>::infinity();
    Eigen::Vector3d plane = Eigen::Vector3d::Zero();
  };

 private:
  struct Geom;
  struct Obstacle;
  explicit FclCollisionChecker(const RobotModel& model);
  bool loadGeometry(std::string* error);
  void computeAcm();
  bool geomPairCollides(const Geom& a, const Geom& b, bool compute_depth, double* depth, bool padded) const;
  bool linkPairCollides(int la, int lb, bool padded);
  /// linkPointMask's and robotPointMask's test (pool: parts of the points on its threads).
  void pointMask(const double* q, int link, const std::vector<Eigen::Vector3d>& points, double padding,
                 std::vector<std::uint8_t>* mask, const std::vector<std::uint8_t>* skip, WorkerPool* pool) const;
  /// Distance (m) between two links' padded shapes at the current transforms; 0 when they touch.
  double linkPairDistance(int la, int lb);
  /// Gap (m) between two links' padded bounding spheres at the current transforms (a lower bound of the distance).
  double sphereGap(int la, int lb) const;
  /// Keep q among the configurations of the smallest gaps (acm.cpp's kSearchStarts).
  void keepClosest(double gap, const std::vector<double>& q,
                   std::vector<std::pair<double, std::vector<double>>>* best) const;
  /// The smallest distance between two links' padded shapes a pattern search over the joints between them finds,
  /// from each start configuration (0: they touch).
  double searchNeverPair(int la, int lb, const std::vector<std::pair<double, std::vector<double>>>& starts);
  void updateTransforms(const double* q);
  /// checkState's work; with `culled`, the shape pairs cullPairs left out are skipped.
  void checkStateImpl(const double* q, const CollisionRequest& request, CollisionResult* result, bool culled);
  /// checkPath's culling: marks (self_active_, world_active_) the shape pairs that may meet on the segment q0 -> q1.
  void cullPairs(const double* q0, const double* q1);
  /// m per rad of joint i: how far a point of link b's padded shapes moves relative to link a (-1: the base), or of
  /// a's relative to b (the one joint i moves); 0 when it moves both or neither.
  double linkMotionRadius(int a, int b, std::size_t i) const;
  std::uint64_t acmKey() const;
  bool loadAcm(const std::string& file);
  void saveAcm(const std::string& file) const;
  void rebuildPairLists();

  const RobotModel& model_;
  FclCheckerOptions options_;
  std::vector<Geom> geoms_;                      // all robot collision shapes
  mutable std::mutex grids_mutex_;               // guards the shapes' distance_grid, built when first needed
  std::vector<std::vector<int>> link_geoms_;     // per link
  std::vector<AcmReason> acm_;                   // n_links x n_links
  std::vector<std::pair<int, int>> self_pairs_;  // enabled link pairs
  std::vector<int> world_geoms_;                 // geoms of moving links
  std::vector<Obstacle> world_;
  const OccupancyMap* occupancy_ = nullptr;            // sensed obstacles (may be null)
  const std::vector<ExplainedPart>* parts_ = nullptr;  // tracked parts (may be null)
  int octo_level_ = 0;                                 // sensed margin: octoGeom's level (kMarginStep each)
  /// True when the shape at tf meets an occupied cell (of class `which`) of the occupancy map; with `grow` > 0, a cell
  /// grown by `grow` (m) on every side, or a block of cells grown so (true for any cell within `grow` of the shape,
  /// and for some a little farther: checkPath's culling).
  bool meetsOccupied(const std::shared_ptr<fcl::CollisionGeometry<double>>& shape, const Eigen::Isometry3d& tf,
                     CellClass which = CellClass::kAll, double grow = 0.0,
                     const OccupancyMap::ExcludeTest* exclude = nullptr) const;
  /// With tracked parts: g's shape `shape` (inflated by the current margin) meets an unseen cell, a seen cell no part
  /// explains, or a part's explained cell while g's padded shape meets that part's keep_out ball.
  bool meetsTracked(const std::shared_ptr<fcl::CollisionGeometry<double>>& shape, const Geom& g) const;
  /// How much of `box` lies within p.explains of p.centre.
  static OccupancyMap::Excluded within(const Eigen::AlignedBox3d& box, const ExplainedPart& p);
  /// g's padded shape (at the current transforms) meets p's keep_out ball.
  bool meetsBall(const Geom& g, const ExplainedPart& p) const;
  /// checkPath's culling against the occupancy map, for the states of the segment cullPairs last culled: makes
  /// occupancy_active_ hold, for this map (its revision) and margin, when it does not yet (at the segment's
  /// midpoint: world shapes' transforms are left there) and returns true; false when it was made at another margin,
  /// or the segment is too short to be worth it (every shape is then checked).
  bool occupancyCulled();
  /// The shape of g checked against the occupancy map at the current margin.
  const std::shared_ptr<fcl::CollisionGeometry<double>>& octoGeom(Geom& g);
  std::vector<std::size_t> moving_;  // indices into world_ of moving obstacles
  double window_t0_ = 0.0, window_t1_ = std::numeric_limits<double>::infinity();
  std::vector<double> joint_radius_;
  // checkPath's culling: per shape, per joint, how far a (padded) point of the shape moves per rad (0: not moved);
  // per enabled link pair, per joint, how far a point of one link moves relative to the other (joints that move both
  // move them as one: 0); per shape pair (self: in checkState's order; world: obstacle x world_geoms_), 1 when it may
  // meet on the segment being checked.
  std::vector<std::vector<double>> geom_joint_radius_;
  std::vector<std::vector<double>> pair_joint_radius_;
  std::vector<std::uint8_t> self_active_, world_active_;
  // Against the occupancy map, per world_geoms_ entry, 1 when the shape may meet an occupied cell on the segment: made
  // for the map's revision (unique to the map too), the margin level and the culling (cull_serial_ counts cullPairs)
  // recorded beside.
  std::vector<std::uint8_t> occupancy_active_;
  std::uint64_t occupancy_culled_revision_ = 0, occupancy_culled_serial_ = 0, cull_serial_ = 0;
  std::size_t cull_states_ = 0;  // the states of the segment cullPairs last culled, its ends included
  int occupancy_culled_level_ = 0;
  std::vector<double> half_dq_, drift_;
  // The memory per shape pair (self: as self_active_; world: as world_active_, for the world of memory_world_stamp_),
  // and the midpoint its bounds hold at.
  std::vector<PairMemory> self_memory_, world_memory_;
  std::vector<double> memory_mid_;
  std::uint64_t memory_world_stamp_ = 0;
  // The segment self_active_ and world_active_ were culled for, and the world then (world_stamp_ counts its changes).
  std::vector<double> culled_q0_, culled_q1_;
  std::uint64_t culled_stamp_ = 0, world_stamp_ = 1;
  /// True when the culling in self_active_ / world_active_ holds for the segment q0 -> q1 in the current world.
  bool culledFor(const double* q0, const double* q1) const;
  /// True when the segment q0 -> q1 may be culled: cull_path_pairs, and every prismatic joint within its limits at
  /// both ends (the motion bound counts its travel within them).
  bool cullable(const double* q0, const double* q1) const;
  double reach_radius_ = 0.0;
  std::vector<Eigen::Isometry3d> link_poses_;
  std::vector<std::pair<double, Eigen::AlignedBox3d>> near_boxes_;  // occupancyDistance's scratch
  std::vector<double> q_scratch_;
  CollisionResult state_scratch_;
  AcmStats acm_stats_;
  std::size_t degenerate_hulls_ = 0;
};

/// \brief Sets a checker's tracked parts for a scope and back to none at its end.
class TrackedPartsScope {
 public:
  TrackedPartsScope(FclCollisionChecker* checker, const std::vector<ExplainedPart>* parts) : checker_(checker) {
    checker_->setTrackedParts(parts);
  }
  ~TrackedPartsScope() { checker_->setTrackedParts(nullptr); }
  TrackedPartsScope(const TrackedPartsScope&) = delete;
  TrackedPartsScope& operator=(const TrackedPartsScope&) = delete;

 private:
  FclCollisionChecker* checker_;
};

/// \brief Sets a checker's sensed margin for a scope and back to none at its end (every query leaves none behind).
class OctreeMarginScope {
 public:
  OctreeMarginScope(FclCollisionChecker* checker, double margin) : checker_(checker) {
    checker_->setOctreeMargin(margin);
  }
  ~OctreeMarginScope() { checker_->setOctreeMargin(0.0); }
  OctreeMarginScope(const OctreeMarginScope&) = delete;
  OctreeMarginScope& operator=(const OctreeMarginScope&) = delete;

 private:
  FclCollisionChecker* checker_;
};

}  // namespace moverl_planning_scene
