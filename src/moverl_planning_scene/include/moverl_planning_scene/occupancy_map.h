/**
 * \file occupancy_map.h
 * \brief Sensed obstacles: an occupancy grid (OctoMap's sensor model) updated from depth-camera point clouds. ROS-free.
 *
 * Update rule (octomap_server's sensor model, discretized insertion): every beam from the sensor origin to a point
 * marks the cells it crosses as free (a miss) and the cell of its end point as occupied (a hit). Beams longer than
 * max_range mark free space up to max_range only (no-return readings at a camera's far plane clear space this way).
 * Points that belong to the robot itself (a mask computed by the caller, see FclCollisionChecker::robotPointMask) clear
 * the cells before them but mark nothing occupied; points on a static world object the scene knows exactly clear
 * their end cell too (the beam saw the space down to the object's surface). Within one cloud a cell hit by any beam
 * stays occupied even when other beams cross it. Points are grouped by the cell they end in (one beam per end cell, to
 * the centroid of its points, not to its centre as octomap does: a camera that sees a static scene hits the same cells
 * every view, and a cell that no centre's beam crosses would stay occupied for ever once a person left it, although a
 * point's line of sight crosses it; a cell where any obstacle point ends is hit, whatever else ends there). Beams are
 * clipped to `bounds` (the robot's reach and margin). Clearing: when an obstacle moves away, beams now pass through its
 * old cells and turn them free.
 *
 * Projective update (computeUpdateProjective, for an organized cloud that fits a pinhole camera): the same hits, and
 * instead of walking beams, each cell not yet clamped free (superblocks and blocks first, against min and max depth
 * pyramids of the image) is seen free when some pixel's ray passes through it (not merely touching a face, an edge or a
 * corner) and sees past all of it, and every pixel whose ray may meet it (the bounding rectangle of its corners'
 * projections), robot pixels aside, sees past all of it too.
 * It never sees free a cell where a pixel that may cross it saw a surface short of the cell's far side; ray casting's
 * beams to the end cells' centroids can graze such cells. A fixed camera sees mostly the same image view after view:
 * a block whose inputs did not change since the camera's last view (the depths over the tiles its rectangle reads, the
 * cloud's end cells in it, none of its cells newly not clamped free) is not evaluated again: it sees free the cells
 * that view saw free, less those clamped free since (skip_unchanged_blocks; the cells that stay unknown behind
 * surfaces are most of them, and they are seen free in none). The updates are the
 * same as when every block is evaluated (gtest Projective.SkippingUnchangedBlocksGivesTheSameUpdates,
 * `map_benchmark --identity`).
 *
 * Unknown space: by default cells never observed are unknown and count as free for collision checking (as in
 * MoveIt). With unknown_occupied they count as occupied (a person may stand where no camera looks): every cell of the
 * mapped box starts at a prior log-odds just above the occupancy threshold, which one miss turns free and one hit
 * keeps occupied, so the update rule is unchanged. Space no camera can see but that holds no obstacle (inside the
 * robot's links, inside static world objects) is turned free by the caller with addKnownFree.
 *
 * Hidden space (hidden_space, under unknown_occupied with a speed bound > 0): a cell seen free stays free only while
 * nothing that moves at up to speed_bound could have reached it since a camera last saw it free. The views of one
 * instant (clouds stamped alike: beginView) form a batch; when the batch closes (closeBatch), every free cell that no
 * view of the batch saw free, and that something possibly occupied when the batch before closed could have reached by
 * now, turns possibly occupied again (the unknown_occupied prior: one miss of a later view frees it, one hit keeps it).
 * Each such cell keeps a lower bound on the time something could first be in it: the previous batch's stamp plus its
 * distance (a lower bound: Chebyshev cells less one, times the resolution) to the nearest possibly-occupied cell over
 * the speed bound, kept as the largest of those bounds while it stays hidden, so that something in a hidden region
 * advances at the speed bound, not a cell per batch. That is the exact reachable set of anything moving at the bound
 * and never seen where the views looked, at the grid's resolution: see docs/sensing.md, "Space no camera sees". A
 * batch's misses of possibly-occupied cells wait for its close (a cell that one view saw free may be what another view
 * of the same instant shows something moving into). Only the free cells near possibly-occupied ones can turn (within
 * speed_bound x watch_time, by blocks: the watched blocks), and the update looks at those cells in every view even
 * when clamped free, as it looks at cells not yet clamped (the skipped unchanged blocks included).
 *
 * Representation: a dense grid over `bounds` holds each cell's log-odds (octomap's sensor model and its keys: the cell
 * of coordinate x is floor(x / resolution)), a bit per cell for "occupied" (log-odds at or above the threshold, the
 * unknown_occupied prior included) and, for the collision checks, how many cells are occupied in every block of 4^3
 * cells and every superblock of 16^3 (anyOccupied: empty blocks are skipped whole, full ones tested as one box). The
 * update deduplicates the cells that a cloud's beams cross without sorting, and it tells which of them it changes: a
 * cell already clamped at clamp_min stays where it is when seen free again. Besides the cells, the map keeps what the
 * projective update remembers of each camera's last view (skip_unchanged_blocks: about 72 bytes per block, 1 per
 * cell, and 12 bytes per cell of the blocks its later views evaluated, each cell's projection (its nearest pixel and
 * its footprint rectangle, which depend on the pose and intrinsics alone), for each of up to 8 cameras; a camera that
 * moves takes a new record at each pose, the least recently seen one making way). An update costs its beams
 * (projective: the blocks whose inputs changed) and the cells it changes
 * (`rosrun moverl_planning_scene map_benchmark`).
 */
#pragma once

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "moverl_planning_scene/grid_reach.h"
#include "moverl_planning_scene/pinhole_camera.h"
#include "moverl_planning_scene/unset.h"

namespace moverl_planning_scene {

class WorkerPool;

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
  /// m: how far from a static object's surface its points may lie (octomap/static_filter_padding: the points the
  /// caller masks kPointOnFixture). A fixture point's beam ends this much before it, toward the sensor: a cell resting
  /// on the surface (a table top's first layer) is then one where its points end, seen down to the surface and free,
  /// whichever side of the cell boundary the camera's depth put them. Else such a cell, once something lay there, is
  /// never seen free again (projection needs every depth beyond a cell). 0: the points' own cells.
  double fixture_pullback = 0.0;
  /// Only this box (map frame) is mapped: beams are clipped to it, hits outside it are ignored. Required (the dense
  /// grid covers it). The node sets it to the robot's padded reach plus the largest predictive margin a check may use
  /// (nothing outside can touch the robot within the margin's time).
  Eigen::AlignedBox3d bounds;
  /// Cells never observed count as occupied (see the file comment). Set by the scenario (a world file's `sensing:
  /// unknown_occupied:`), not by config/planning_scene.yaml; setUnknownOccupied switches it later.
  bool unknown_occupied = false;
  /// computeUpdateProjective leaves a block of cells as a camera's last view left it when nothing it depends on changed
  /// since (the same camera, the same depths over the block's pixels, the same cloud points in it, none of its cells
  /// newly not clamped free) and that view saw none of its cells free: the same updates with fewer cells projected
  /// (the cloud points are compared by a 64-bit hash sum per block: a collision, about 2^-64, could only leave cells
  /// as they were, never see one free). A cloud from within 1e-4 px and 1e-9 of a remembered camera's intrinsics and
  /// pose is that camera's, whose values are used, with this on or off (fitPinhole's fits of a fixed camera differ by
  /// about 1e-7 px; its tolerance is kPinholeTolerancePx, 0.05 px).
  /// The cells' projections into a remembered camera's image are kept between its views too (this on only).
  /// Not a tunable (the updates do not depend on it): false evaluates every block and projects every cell afresh, for
  /// the tests that compare the two.
  bool skip_unchanged_blocks = true;
  /// Free space no camera sees in a batch turns possibly occupied once something moving at speed_bound may have come
  /// there (see the file comment; setSpeedBound). Set by the scenario (the scene node: under unknown_occupied); needs
  /// beginView before every view and closeBatch after a batch's last. Off: every cell seen free stays free until a
  /// camera sees something there (a static scene).
  bool hidden_space = false;
  /// hidden_space: this map integrates clouds (computeUpdate*, closeBatch). false: it only applies the updates another
  /// map computed (octomap/lockstep_lag's checks' map), and keeps no watch.
  bool integrates = true;
  /// m/s: how fast anything the cameras may miss moves (hidden_space; the world's sensing: speed_bound).
  double speed_bound = 0.0;
  /// s: the longest a batch may come after the one before (octomap/watch_time): a batch later than that finds every
  /// free cell possibly occupied (the views stopped: nothing is known to be free). The views look at every free cell
  /// within speed_bound x (the longest of the last batches' intervals, a quarter more) of a possibly-occupied one, at
  /// most watch_time's; a batch later than the watch covers counts the cells they did not look at as hidden.
  double watch_time = kUnset;
};

/// \brief What a point of a cloud is, as computeUpdate's mask says.
constexpr std::uint8_t kPointObstacle = 0;   ///< anything else: its end cell is hit
constexpr std::uint8_t kPointOnRobot = 1;    ///< on the robot (self filter): clears the cells before it only
constexpr std::uint8_t kPointOnFixture = 2;  ///< on a static world object the scene knows exactly (obstacles: sensed):
                                             ///< clears the cells before it and its end cell

/// \brief Which occupied cells a query looks at.
enum class CellClass {
  kAll,     ///< every occupied cell: seen occupied, or never observed under unknown_occupied (the collision checks)
  kSeen,    ///< cells a camera saw occupied (a person, an object)
  kUnseen,  ///< cells occupied only because no camera has seen them (unknown_occupied's prior)
};

/// \brief What one integration did (logs, tests, the status topic).
struct MapUpdateStats {
  std::size_t points = 0;         ///< points in the cloud
  std::size_t invalid = 0;        ///< non-finite points (skipped)
  std::size_t robot = 0;          ///< points on the robot (free space before them only)
  std::size_t fixture = 0;        ///< points on static world objects (free space up to them)
  std::size_t beyond_range = 0;   ///< points beyond max_range (free space only)
  std::size_t hit_cells = 0;      ///< distinct cells marked occupied
  std::size_t free_cells = 0;     ///< distinct cells marked free (projective: those not yet clamped free only)
  std::size_t changed_cells = 0;  ///< of the hit and free cells, those whose value the update changes
  std::size_t known_free = 0;     ///< unobserved cells turned free by addKnownFree (inside the robot, static objects)
  /// projective: dirty blocks not evaluated, their cells seen free as the camera's last view saw them
  /// (skip_unchanged_blocks; with a superblock left whole, its blocks hidden from the camera too)
  std::size_t reused_blocks = 0;
};

/// \brief The cell updates computed from one cloud, applied later under the caller's lock.
struct MapUpdate {
  std::vector<std::uint64_t> hits;    ///< cell ids of the hit cells the update changes
  std::vector<std::uint64_t> misses;  ///< cell ids of the free cells it changes (hits removed)
  /// Cells free for good (inside the static objects: addKnownFree's fixed ones), among misses: never possibly
  /// occupied again (hidden_space).
  std::vector<std::uint64_t> fixed;
  /// hidden_space, a batch's close (closeBatch): the free cells that turn possibly occupied, then the misses of the
  /// batch's possibly-occupied cells (held until now) go in. The map's time (mapTime) is then `stamp`.
  bool close = false;
  /// close: every free cell not fixed turns possibly occupied (the batch came more than watch_time after the one
  /// before: the views stopped).
  bool forget = false;
  /// A late view (hidden_space: stamped before the open batch or the last closed one): it may add hits, but its misses
  /// of possibly-occupied cells are dropped (what it saw free may have been entered since).
  bool late = false;
  double stamp = std::numeric_limits<double>::quiet_NaN();  ///< s: the batch's (close) or the view's
  std::vector<std::uint64_t> stale;                         ///< close: free cells that turn possibly occupied
  MapUpdateStats stats;
};

/// \brief What the map holds within a ball (OccupancyMap::census).
struct MapCensus {
  std::size_t cells = 0;          ///< cells whose centre lies in the ball
  std::size_t free = 0;           ///< seen free (or known free)
  std::size_t seen_occupied = 0;  ///< seen occupied
  std::size_t stale = 0;          ///< seen free once, possibly occupied since (hidden_space)
  std::size_t unseen = 0;         ///< never observed
  /// Per octant around the ball's centre (index (x >= cx) + 2 (y >= cy) + 4 (z >= cz)): its cells, and of those the
  /// unseen and stale ones.
  std::size_t cells_by_octant[8] = {0, 0, 0, 0, 0, 0, 0, 0};
  std::size_t hidden_by_octant[8] = {0, 0, 0, 0, 0, 0, 0, 0};
};

/// \brief What a batch's close found (closeBatch, hidden_space).
struct BatchStats {
  std::size_t watched_blocks = 0;  ///< blocks whose free cells the views looked at
  std::size_t hidden = 0;          ///< watched free cells no view of the batch saw
  std::size_t stale = 0;           ///< of those, the ones that turned possibly occupied
  bool forget = false;             ///< every free cell turned possibly occupied (the batch came too late)
  /// The batch came later than its views' watch covered (they did not look at every cell something may have reached):
  /// its close counted every free cell within reach that they did not look at as hidden. Sound, but it turns cells
  /// the cameras saw free possibly occupied; beginView widens the watch first, so only a close computed before its
  /// predecessor's close was applied does this.
  bool beyond_watch = false;
};

/// \brief Occupancy grid in the robot base frame.
///        computeUpdate, addKnownFree and unobservedCells read the map and may run concurrently with collision checks
///        (anyOccupied), but not with apply, clear or setUnknownOccupied; those modify the map and must be serialized
///        with every reader by the caller. One thread integrates clouds (computeUpdate uses the map's scratch space;
///        computeUpdateProjective may share its cells out to a WorkerPool's threads within the call, and keeps each
///        camera's last view between calls; apply, clear and setUnknownOccupied write the counters it reads them with).
class OccupancyMap {
 public:
  /// \brief A block is 2^kBlockBits cells along each axis (4^3 cells), a superblock 2^kSuperBits (16^3).
  static constexpr int kBlockBits = 2, kSuperBits = 4;
  /// \brief nullptr with *error for bad options (resolution <= 0, probabilities outside (0, 1), ...).
  static std::unique_ptr<OccupancyMap> create(const OccupancyMapOptions& options, std::string* error);
  ~OccupancyMap();

  /// \brief Beams from origin to every point (all in the map frame). robot_mask: empty, or one value per point
  ///        (kPointObstacle, kPointOnRobot, kPointOnFixture).
  void computeUpdate(const std::vector<Eigen::Vector3d>& points, const std::vector<std::uint8_t>& robot_mask,
                     const Eigen::Vector3d& origin, MapUpdate* out);
  /// \brief As computeUpdate, for an organized cloud that fits a pinhole camera (fitPinhole): the hits as
  ///        computeUpdate's (points and robot_mask alike: map frame, any of the image's points), free space by
  ///        projection instead of ray casting (see the file comment). depth: camera.width * camera.height z-depths in
  ///        the optical frame, row-major (non-finite or <= 0: no return); pixel_mask: empty, or what each pixel's point
  ///        is (robot_mask's values per pixel: a robot pixel hides nothing beside it); sensor_pose: the optical frame
  ///        in the map frame. Costs the cells that are not yet clamped free in view, not the beams: a grid cell is
  ///        projected into the image instead of every pixel's beam being walked through the grid. pool: the threads
  ///        that project the cells (superblocks as tasks); nullptr: the calling thread alone. The update is the same,
  ///        in the same order, whatever the pool (gtest Projective.AnyNumberOfWorkersGivesTheSameUpdates).
  void computeUpdateProjective(const std::vector<Eigen::Vector3d>& points, const std::vector<std::uint8_t>& robot_mask,
                               const std::vector<float>& depth, const std::vector<std::uint8_t>& pixel_mask,
                               const PinholeCamera& camera, const Eigen::Isometry3d& sensor_pose, MapUpdate* out,
                               WorkerPool* pool = nullptr);
  /// \brief Unobserved cells (never hit nor seen free) known to hold no obstacle, given as cell ids from
  ///        unobservedCells: added to `out` as seen free, unless this cloud hits them. Call after computeUpdate with
  ///        the same update, before apply (it uses computeUpdate's marks of this cloud).
  void addKnownFree(const std::vector<std::uint64_t>& keys, MapUpdate* out) { addKnownFree(keys, false, out); }
  /// \brief As addKnownFree, for keys from knownFreeCells. fixed: free for good (inside the static objects), never
  ///        possibly occupied again. hidden_space: every key counts as seen free by this view's batch (the robot's
  ///        padding band at the cloud's configuration, the static objects' insides: nobody stands there).
  void addKnownFree(const std::vector<std::uint64_t>& keys, bool fixed, MapUpdate* out);
  /// \brief The cells whose centre lies in `box` that a region known to hold no obstacle frees or vouches for: as
  ///        unobservedCells, and, with hidden_space, also the cells possibly occupied since last seen free, and the
  ///        cells not seen occupied that are not yet fixed (fixed). A free cell of the robot's band is vouched for at
  ///        the batch's close instead (closeBatch's known_free), where it would turn possibly occupied.
  void knownFreeCells(const Eigen::AlignedBox3d& box, bool fixed, std::vector<Eigen::Vector3d>* centers,
                      std::vector<std::uint64_t>* keys) const;
  /// \brief Apply an update to the map (hits, then misses).
  void apply(const MapUpdate& update);
  /// \brief Forget everything (all cells unknown: occupied under unknown_occupied).
  void clear();
  /// \brief Switch the unknown-is-occupied rule. On: every unobserved cell gets the prior (occupied); off: they turn
  ///        unknown (free) again. Modifies the map: serialize with readers as apply.
  void setUnknownOccupied(bool on);
  bool unknownOccupied() const { return options_.unknown_occupied; }
  /// \brief Centres and ids of the cells whose centre lies in `box` and that were never observed. Empty unless
  ///        unknown_occupied.
  void unobservedCells(const Eigen::AlignedBox3d& box, std::vector<Eigen::Vector3d>* centers,
                       std::vector<std::uint64_t>* keys) const;
  /// \brief How many cells count as occupied only because no camera has seen them (0 unless unknown_occupied).
  std::size_t unobservedCount() const;

  /// \brief True when the cell containing p (map frame) is occupied (seen so, or unobserved under unknown_occupied).
  bool occupied(const Eigen::Vector3d& p) const;
  /// \brief True when the cell containing p has been hit or seen free since the last clear.
  bool observed(const Eigen::Vector3d& p) const;
  /// \brief Log-odds of the cell containing p (NaN: unknown, or outside the map).
  float logOdds(const Eigen::Vector3d& p) const;
  /// \brief Centre and edge length of every cell seen occupied. Cells occupied only because no camera has seen them
  ///        (unknown_occupied) are left out: unobservedCount.
  void occupiedLeaves(std::vector<Eigen::Vector3d>* centers, std::vector<double>* sizes) const;
  /// \brief How many cells a camera saw occupied (kept up to date by apply).
  std::size_t occupiedLeafCount() const;
  /// \brief Changes whenever the cells may have (apply, clear, setUnknownOccupied), to a value no map of this process
  ///        has had: what a reader remembers of the cells holds while it stays the same (checkPath's culling).
  std::uint64_t revision() const { return revision_; }

  /// \brief Which of the cells (centres, map frame) a caller knows hold nothing at the batch's instant (the robot's
  ///        padding band in its configurations then): *known gets one value per centre, non-zero for those.
  using KnownFree = std::function<void(const std::vector<Eigen::Vector3d>& centres, std::vector<std::uint8_t>* known)>;
  /// \brief hidden_space: the next view (computeUpdate*) is stamped `stamp` (s). When a batch of views stamped
  ///        before it is open, that batch is closed first into *close (closeBatch, with known_free) and true is
  ///        returned: apply it, to every map, before this view's update. A view stamped before the open batch, or at
  ///        or before the last closed one, is late (its update says so: MapUpdate::late). Off (not hidden_space):
  ///        false, nothing to do. stats: what the close found (optional, as closeBatch's).
  bool beginView(double stamp, MapUpdate* close, const KnownFree* known_free = nullptr, BatchStats* stats = nullptr);
  /// \brief hidden_space: close the open batch into *close (apply it to every map): the free cells no view of the
  ///        batch saw, that known_free (optional) does not vouch for, and that something possibly occupied may have
  ///        reached by the batch's stamp turn possibly occupied, then the batch's held misses go in. False (nothing to
  ///        close) when no batch is open or hidden_space is off. Reads the map like computeUpdate (not concurrently
  ///        with apply).
  bool closeBatch(MapUpdate* close, BatchStats* stats = nullptr, const KnownFree* known_free = nullptr);
  /// \brief hidden_space: the next batch's close finds every free cell possibly occupied (MapUpdate::forget), as after
  ///        a gap longer than watch_time: the world's motions restarted (things moved faster than any bound).
  void forgetAtNextClose() { forget_next_ = true; }
  /// \brief The stamp of the open batch (NaN: none).
  double batchStamp() const { return batch_stamp_; }
  /// \brief hidden_space: the cells (ids) that lie wholly inside a static object (nothing can pass through them: the
  ///        reach into hidden space goes around them). Replaces the ones given before.
  void setSolid(const std::vector<std::uint64_t>& keys);
  /// \brief Centres and ids of every cell whose centre lies in `box`.
  void cellsIn(const Eigen::AlignedBox3d& box, std::vector<Eigen::Vector3d>* centers,
               std::vector<std::uint64_t>* keys) const;
  /// \brief hidden_space: the stamp of the last closed batch applied (-infinity before the first): what the map knows
  ///        is possibly occupied is as of then (a check's age counts from it).
  double mapTime() const { return map_time_; }
  /// \brief hidden_space: the world's speed bound (m/s; <= 0: nothing moves, hidden space stays free).
  void setSpeedBound(double speed_bound);
  /// \brief Cells possibly occupied because something may have come there since a camera last saw them free.
  std::size_t staleCount() const { return stale_cells_; }
  /// hidden_space: how far (cells, Chebyshev) from a possibly-occupied cell the views look at free cells (-1: off).
  int watchCells() const { return watch_cells_; }
  /// hidden_space: how many batches came later than the watch covered and had it widened before their views.
  std::size_t watchesAhead() const { return watches_ahead_; }
  /// \brief True when the cell containing p is such a cell.
  bool stale(const Eigen::Vector3d& p) const;
  /// \brief What the cells whose centre lies within `radius` of `at` (map frame) hold: free, seen occupied,
  ///        stale, never observed, and where the latter two lie. Reads the map like the checks.
  void census(const Eigen::Vector3d& at, double radius, MapCensus* out) const;

  /// \brief What anyOccupied asks of a box (map frame) that holds occupied cells: does the box meet the caller's shape?
  using BoxTest = std::function<bool(const Eigen::AlignedBox3d& box)>;
  /// \brief How much of a box a query leaves out (visitOccupied's `exclude`: the cells a tracked part explains).
  enum class Excluded : std::uint8_t { kNone, kPartly, kWholly };
  using ExcludeTest = std::function<Excluded(const Eigen::AlignedBox3d& box)>;
  /// \brief True when the caller's shape meets an occupied cell within `region` (map frame): superblocks and blocks
  ///        without occupied cells are skipped, a full one that meets the shape answers at once (one of its cells
  ///        meets it), a partial one is looked into, down to the occupied cells themselves. `meets` is asked about
  ///        boxes that hold occupied cells only; it must be exact for cell boxes (the answer is as exact as it is).
  ///        `which`: the occupied cells of that class only.
  bool anyOccupied(const Eigen::AlignedBox3d& region, const BoxTest& meets, CellClass which = CellClass::kAll) const;
  /// \brief The traversal behind anyOccupied: within `region`, every box that holds occupied cells of class `which`
  ///        (a superblock, a block, a cell) is offered to `near`; one it refuses is skipped, one it accepts is looked
  ///        into, or, when all its cells are occupied cells of that class (a full superblock or block, a cell), handed
  ///        to `visit`. True as soon as `visit` returns true (stop), false when the traversal ends. `whole_blocks`: a
  ///        block (4^3 cells) `near` accepts is handed to `visit` whole, full or not (a coarser traversal, for callers
  ///        that may answer for a block as for any of its cells).
  ///        `exclude` (optional): a box it says is wholly excluded is skipped, one it says is partly excluded is looked
  ///        into even when full (a cell partly excluded counts).
  bool visitOccupied(const Eigen::AlignedBox3d& region, const BoxTest& near, const BoxTest& visit,
                     CellClass which = CellClass::kAll, bool whole_blocks = false,
                     const ExcludeTest* exclude = nullptr) const;
  /// \brief The centre of the cell with id `key` (MapUpdate's ids), map frame.
  Eigen::Vector3d cellCentre(std::uint64_t key) const {
    std::int64_t at[3];
    unravel(static_cast<std::int64_t>(key), size_, at);
    return centre(at[0], at[1], at[2]);
  }
  /// \brief A bound (m) on how far the centre of a cell lies from any point of it: half its diagonal.
  double cellHalfDiagonal() const { return 0.5 * std::sqrt(3.0) * options_.resolution; }
  const OccupancyMapOptions& options() const { return options_; }
  /// \brief How many misses take an unobserved cell (at unknown_occupied's prior, or unknown) to clamp_min: until a
  ///        camera has seen its free space that often, each view changes every cell it sees free (the map's fill).
  int missesToClampFree() const {
    const float from = options_.unknown_occupied ? prior_ : 0.0f;
    return std::max(1, static_cast<int>(std::ceil((clamp_min_ - from) / log_miss_)));
  }

 private:
  /// What computeUpdateProjective keeps of one camera's last view (skip_unchanged_blocks); defined in the .cpp.
  struct View;
  /// computeUpdateProjective's per-worker scratch (its misses, counts, a footprint); defined in the .cpp.
  struct Scratch;
  /// Where a task's (a superblock's) misses are: that worker's scratch, [begin, end).
  struct TaskMisses {
    int worker = 0;
    std::size_t begin = 0, end = 0;
  };

  OccupancyMap() = default;
  /// The cell of a coordinate (octomap's key convention), or -1 outside the map.
  std::int64_t cellOf(const Eigen::Vector3d& p) const {
    const std::int64_t i = indexOf(p.x(), 0), j = indexOf(p.y(), 1), k = indexOf(p.z(), 2);
    if (i < 0 || j < 0 || k < 0 || i >= size_[0] || j >= size_[1] || k >= size_[2]) return -1;
    return cellId(i, j, k);
  }
  /// The id of the cell at grid indices (i, j, k) (MapUpdate's keys; value_'s index): x-major, z fastest.
  std::int64_t cellId(std::int64_t i, std::int64_t j, std::int64_t k) const {
    return (i * size_[1] + j) * size_[2] + k;
  }
  /// The index of the superblock at superblock coordinates (x, y, z), in the same order.
  std::int64_t superIndex(std::int64_t x, std::int64_t y, std::int64_t z) const {
    return (x * supers_[1] + y) * supers_[2] + z;
  }
  /// The indices (at) of index c of a grid of dims, as cellId and superIndex order them.
  static void unravel(std::int64_t c, const std::int64_t* dims, std::int64_t* at) {
    at[2] = c % dims[2];
    at[1] = (c / dims[2]) % dims[1];
    at[0] = c / (dims[1] * dims[2]);
  }
  /// Grid index of a coordinate along axis i (may lie outside [0, size); a coordinate beyond +-1e15 cells, or NaN,
  /// lies outside). floor without libm's call (the baseline x86-64 build has no rounding instruction; every point of
  /// every cloud comes here).
  std::int64_t indexOf(double x, int i) const {
    const double s = x * inv_resolution_;
    constexpr std::int64_t kFar = std::int64_t{1} << 52;
    if (!(s > -1e15 && s < 1e15)) return s > 0.0 ? kFar : -kFar;
    const auto t = static_cast<std::int64_t>(s);
    return t - (static_cast<double>(t) > s ? 1 : 0) - offset_[i];
  }
  /// Centre of grid cell (i, j, k).
  Eigen::Vector3d centre(std::int64_t i, std::int64_t j, std::int64_t k) const {
    return Eigen::Vector3d((i + offset_[0] + 0.5) * options_.resolution, (j + offset_[1] + 0.5) * options_.resolution,
                           (k + offset_[2] + 0.5) * options_.resolution);
  }
  /// The log-odds a hit (update > 0) or a miss leaves in a cell that holds v (NaN: never observed).
  float updated(float v, float update) const;
  /// computeUpdate's and computeUpdateProjective's steps 1-2: the cloud's end cells (order_, order_flags_) and its
  ///        hits (hit_, out->hits); clears the seen_ marks and out. With beams (ray casting: a beam to each end cell),
  ///        the sums and counts of each cell's points for its centroid (order_end_, order_count_), and the cells where
  ///        the beams of points beyond max_range are cut; without (projection, which sees free space from the
  ///        depths), those points' cells are left out (they carry no flag). The points' cells are found in parts on
  ///        the pool (optional; the same result).
  void collectEndCells(const std::vector<Eigen::Vector3d>& points, const std::vector<std::uint8_t>& robot_mask,
                       const Eigen::Vector3d& origin, MapUpdate* out, bool beams, WorkerPool* pool);
  /// collectEndCells' table: the slot of cell c (where it is, or the empty one where it goes), and a table twice as
  ///        large (the cells of order_ kept).
  std::size_t slot(std::int64_t c) const;
  void growSlots();
  /// The index of block (x, y, z) (block grid coordinates) in the per-block arrays: superblock-major (a superblock's
  /// blocks side by side, in x, y, z order), so that the blocks the projective update visits together share cache
  /// lines.
  std::int64_t blockIndex(std::int64_t x, std::int64_t y, std::int64_t z) const {
    constexpr int sub_shift = kSuperBits - kBlockBits;
    constexpr std::int64_t sub = (1 << sub_shift) - 1;
    const std::int64_t super = superIndex(x >> sub_shift, y >> sub_shift, z >> sub_shift);
    return (super << (3 * sub_shift)) | (((x & sub) << (2 * sub_shift)) | ((y & sub) << sub_shift) | (z & sub));
  }
  /// The block and the superblock that hold cell c, and (bit: optional) c's bit in the block's words (block_clamped_).
  void boxesOf(std::int64_t c, std::int64_t* block, std::int64_t* super, std::uint64_t* bit = nullptr) const;
  /// Set cell c's value, keeping the occupied bit and the block counts.
  void setValue(std::int64_t c, float v);
  /// One hit (or miss) into cell c, as apply does it (observed, the seen counts, hidden space's marks).
  void applyOne(std::int64_t c, bool hit);
  /// Every unobserved cell at the prior (on) or unknown (off).
  void fillUnobserved(bool on);
  /// Count cell c in (delta 1) or out of (-1) the seen-occupied block counts.
  void countSeen(std::int64_t c, int delta);

  // Hidden space (hidden_space.cpp).
  /// Block (x, y, z) grid coordinates of block index b (blockIndex's inverse).
  void blockCoords(std::int64_t b, std::int64_t* at) const;
  /// The cell ids of a block's cells (bit n: cell_offset_[n] from its first cell), first cell id and which bits lie
  /// inside the grid.
  std::int64_t blockFirstCell(const std::int64_t* block_at) const;
  /// The steps from the cells to the nearest possibly-occupied cell (occupied_) or the grid's outside, around the
  ///        solid cells (a person goes around a table, not through it): reach_, exact up to needed (kCellSearch at
  ///        most), and at least needed for the cells that far from every one (GridReach's far).
  void buildReach(int needed);
  /// The watched cells: the free cells within watch_cells_ (Chebyshev, in cells) of a possibly-occupied cell or of the
  /// grid's edge. full: recompute every block's (else only near the blocks whose cells changed since: grown_blocks_).
  void updateWatched(bool full);
  /// The blocks within m (Chebyshev, in blocks) of one holding a possibly-occupied cell or of the grid's edge: *out
  /// per block index, 1 for those.
  void dilateBlocks(int m, std::vector<std::uint8_t>* out) const;
  /// How many blocks away something at the speed bound may come within `seconds` (blocks - 1 edges < that far).
  int blocksWithin(double seconds) const;
  void setWatched(std::int64_t b, std::uint64_t mask);
  /// Every block's watched cells for a watch of L cells, at once (bit operations over the whole grid).
  void watchAll(int L);
  /// The watched cells of the block at block coordinates block_at for a watch of L cells (its bits).
  std::uint64_t watchMask(const std::int64_t* block_at, int L) const;
  /// How many cells away (Chebyshev) something at the speed bound may come within `seconds`.
  int cellsWithin(double seconds) const;
  /// A block's watched cells, as its bits.
  std::uint64_t watchedBits(std::int64_t b) const { return block_watched_.empty() ? 0 : block_watched_[b]; }
  /// A cell turned possibly occupied because something may have come there since it was seen free.
  void makeStale(std::int64_t c);
  /// block_free_'s bit of cell c, from its observed and occupied bits (hidden_space).
  void refreshFree(std::int64_t c);
  /// The apply() part of a batch's close.
  void applyClose(const MapUpdate& update);
  /// Widen watch_cells_ to what the open batch's interval since the map's time lets something come (true if it did:
  /// then updateWatched(true)), so that the batch's views look at every cell its close asks about.
  bool watchAhead();
  /// hidden_space with a bound: the rule applies (unknown_occupied, speed bound > 0).
  bool hiddenSpaceActive() const {
    return options_.hidden_space && options_.unknown_occupied && options_.speed_bound > 0.0;
  }

  OccupancyMapOptions options_;
  double inv_resolution_ = 0.0;
  double max_range2_ = 0.0;             ///< options_.max_range squared
  std::int64_t offset_[3] = {0, 0, 0};  ///< floor(x / resolution) of the grid's cell 0, per axis
  std::int64_t size_[3] = {0, 0, 0};
  std::vector<float> value_;                ///< log-odds of each cell; NaN: never observed
  std::vector<std::uint64_t> seen_, hit_;   ///< computeUpdate's scratch: a bit per cell (seen free, hit this cloud)
  std::vector<std::int64_t> order_;         ///< computeUpdate's scratch: the end cells, in the order of their points
  std::vector<std::uint8_t> order_flags_;   ///< computeUpdate's scratch: the flags of the points ending in each
  std::vector<Eigen::Vector3d> order_end_;  ///< computeUpdate's scratch: the sum of each end cell's points
  std::vector<std::uint32_t> order_count_;  ///< computeUpdate's scratch: how many points end in each end cell
  /// collectEndCells' scratch: each point's end cell (-1: outside) and its flags; without beams each part's runs of
  /// points that end in one cell, at the part's first elements
  std::vector<std::int32_t> point_cell_;
  std::vector<std::uint8_t> point_flags_;
  /// computeUpdate's scratch: the end cells' index in order_, an open-addressing table keyed by cell id (-1: empty),
  /// a power of two twice as large as the most end cells a cloud had (small: the grid's cells are many). Key and index
  /// side by side in 8 bytes (the map has fewer than 2^31 cells): a look-up touches one cache line, and a 160x120
  /// cloud's table stays within a core's L2 cache (its new end cells are random look-ups).
  struct Slot {
    std::int32_t key = -1;
    std::uint32_t index = 0;
  };
  std::vector<Slot> slots_;
  std::vector<std::size_t> order_slot_;  ///< where each end cell of order_ is in that table
  int slot_bits_ = 0;
  std::vector<std::uint64_t> observed_;  ///< a bit per cell: hit or seen free at least once since the last clear
  std::size_t observed_cells_ = 0;       ///< how many bits of observed_ are set
  std::vector<std::uint64_t> occupied_;  ///< a bit per cell: log-odds >= the threshold
  std::vector<std::uint64_t> clamped_;   ///< a bit per cell: log-odds at clamp_min (a miss changes nothing)
  // Occupied cells per block of 4^3 cells (blockIndex) and per superblock of 16^3, and the blocks' grid sizes.
  std::vector<std::uint8_t> block_count_;
  /// Per block, a bit per cell (in the block's x, y, z order): at clamp_min (clamped_'s bits, gathered per block), or
  /// past the grid's end. A block with every bit set has no dirty cell: a miss changes none of its cells.
  std::vector<std::uint64_t> block_clamped_;
  /// computeUpdateProjective's scratch, per block: a bit per cell hit or seen free before its blocks are evaluated
  /// (hit_ and seen_'s bits of the cloud's end cells; zero again after the update)
  std::vector<std::uint64_t> block_ended_;
  /// Each cell of a block (its bit in those words) as an offset of its id from the block's first cell's.
  std::int64_t cell_offset_[8 * sizeof(std::uint64_t)] = {};
  std::vector<std::uint16_t> super_dirty_;  ///< per superblock: its cells not at clamp_min (unknown ones included)
  /// computeUpdateProjective's scratch: pyramids of each pixel's free depth (max_depth_, level 0: the free depths) and
  /// of the same with robot pixels at their reach (min_depth_: they hide nothing beside)
  std::vector<std::vector<float>> min_depth_, max_depth_;
  std::vector<std::uint16_t> super_count_;
  // The same counts for the cells seen occupied only (observed and at or above the threshold: CellClass::kSeen).
  std::vector<std::uint8_t> seen_block_count_;
  std::vector<std::uint16_t> seen_super_count_;
  std::int64_t blocks_[3] = {0, 0, 0}, supers_[3] = {0, 0, 0};
  float log_hit_ = 0.0f, log_miss_ = 0.0f, clamp_min_ = 0.0f, clamp_max_ = 0.0f;
  float prior_ = 0.0f;              ///< log-odds of an unobserved cell under unknown_occupied
  float threshold_ = 0.0f;          ///< log-odds of occupancy_threshold
  std::int64_t seen_occupied_ = 0;  ///< observed cells at or above the threshold
  // skip_unchanged_blocks: a counter of the map's updates (computeUpdate*, apply, clear, setUnknownOccupied) and, per
  // block and
  // superblock, its value when a cell in it last turned not clamped free (a view before then is out of date); the
  // cameras' last views; per block and superblock, a sum of hashes of the cloud's end cells in it (and the ones
  // holding any).
  std::uint64_t epoch_ = 0;
  std::uint64_t revision_ = 0;  ///< revision(): set from a counter shared by every map (nextRevision)
  std::vector<std::uint64_t> block_dirtied_, super_dirtied_;
  std::vector<std::unique_ptr<View>> views_;
  std::vector<std::uint64_t> end_hash_, super_end_hash_;
  // Hidden space. Per block (blockIndex): the cells the open batch's views saw free or knew free (a bit each, the
  // block's x, y, z order), and whether its cells are watched (every cell looked at by every view); per superblock how
  // many of its blocks are watched. Per cell: stale (possibly occupied since last seen free), fixed (free for good),
  // and for a watched cell hidden from the views, a lower bound on when something could first be in it (NaN: seen by
  // the last batch, or not watched). The misses of possibly-occupied cells held until the batch's close.
  std::vector<std::uint64_t> batch_seen_, block_watched_;
  std::vector<std::uint64_t>
      block_free_;  ///< per block, its free cells (observed, not occupied): the close's candidates
  std::vector<std::uint16_t> super_watched_;
  std::vector<std::uint64_t> stale_, fixed_, solid_;
  std::vector<float> free_until_;
  std::vector<std::uint64_t> held_misses_;
  std::vector<Eigen::Vector3d> vouch_centres_;  ///< closeBatch's scratch: the would-be stale cells for known_free
  std::vector<std::uint8_t> vouch_known_;
  std::vector<std::int64_t>
      grown_blocks_;                      ///< blocks with a cell that turned possibly occupied or free since the watch
  std::vector<std::uint8_t> grown_mark_;  ///< per block: listed in grown_blocks_ (1), or in updateWatched's list (2)
  int watch_cells_ = 0;                   ///< cells (Chebyshev) around a possibly-occupied one that are watched
  double watch_made_at_ = -std::numeric_limits<double>::infinity();  ///< the map's time when the watch was last made
  int watch_made_cells_ = 0;                                         ///< and its watch_cells_ then
  std::vector<std::uint64_t> turned_free_;  ///< per block, its cells that turned free since the watch was made
  std::vector<std::uint64_t> watch_scratch_a_, watch_scratch_b_;  ///< watchAll's bit sets
  static constexpr int kIntervals = 8;                            ///< the batches whose intervals size the watch
  double intervals_[kIntervals] = {};                             ///< s: the last batches' intervals (0: none yet)
  std::size_t watches_ahead_ = 0;                                 ///< watchAhead's widenings so far
  GridReach reach_;                          ///< closeBatch's steps to the possibly-occupied cells (buildReach)
  std::vector<std::uint8_t> reach_scratch_;  ///< closeBatch's blocks, when a batch came later than the watch covers
  int closes_since_full_watch_ = 0;
  double batch_stamp_ = std::numeric_limits<double>::quiet_NaN();
  double map_time_ = -std::numeric_limits<double>::infinity();
  bool recording_ = false;    ///< this view records what it sees free for the open batch (not late)
  bool forget_next_ = false;  ///< forgetAtNextClose
  std::size_t stale_cells_ = 0;
  std::vector<std::int64_t> end_blocks_, end_supers_;
  /// per pixel: 1 where the depths differ from the camera's last view (level 0), and its max pyramid
  std::vector<std::vector<float>> changed_max_;
  // computeUpdateProjective's tasks (the superblocks not all clamped free), its workers' scratch, each task's misses.
  std::vector<double> ray_x_, ray_y_;  ///< its camera's ray direction per pixel column and row (z = 1)
  std::vector<std::int64_t> tasks_;
  std::vector<Scratch> scratch_;
  std::vector<TaskMisses> task_misses_;
};

}  // namespace moverl_planning_scene
