#include "moverl_planning_scene/occupancy_map.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <mutex>
#include <type_traits>

#include "moverl_planning_scene/worker_pool.h"

namespace moverl_planning_scene {
namespace {

bool probability(double p) { return std::isfinite(p) && p > 0.0 && p < 1.0; }
/// Log-odds as octomap computes them (float).
float logodds(double p) { return static_cast<float>(std::log(p / (1.0 - p))); }

/// The dense grid's largest size (cells): 4 bytes each, and a few bits.
constexpr std::int64_t kMaxCells = 64 * 1024 * 1024;
static_assert(kMaxCells < (std::int64_t{1} << 31), "collectEndCells' table keys cells by int32");
/// Cells per block (4^3) and superblock (16^3) edge, as shifts.
constexpr int kBlockShift = OccupancyMap::kBlockBits, kSuperShift = OccupancyMap::kSuperBits;
/// A superblock's blocks along each axis, and in all (kSubShift: their shift).
constexpr int kSubShift = kSuperShift - kBlockShift, kSuperBlocks = 1 << (3 * kSubShift);

/// Clips the segment a -> b to the box: the parameters [*t0, *t1] of the part inside. False when it misses the box.
bool clipToBox(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::AlignedBox3d& box, double* t0,
               double* t1) {
  *t0 = 0.0;
  *t1 = 1.0;
  const Eigen::Vector3d d = b - a;
  for (int i = 0; i < 3; ++i) {
    if (std::fabs(d[i]) < 1e-12) {
      if (a[i] < box.min()[i] || a[i] > box.max()[i]) return false;
      continue;
    }
    double u0 = (box.min()[i] - a[i]) / d[i], u1 = (box.max()[i] - a[i]) / d[i];
    if (u0 > u1) std::swap(u0, u1);
    *t0 = std::max(*t0, u0);
    *t1 = std::min(*t1, u1);
    if (*t0 > *t1) return false;
  }
  return true;
}

// The flags of the points that end in a cell (order_flags_).
constexpr std::uint8_t kHit = 1, kRobot = 2, kFixture = 4;
constexpr std::uint8_t kInvalidPoint = 0xff;  // collectEndCells' flags of a non-finite point (no cell)
// A cell where only fixture points end was seen down to the fixture's surface (anything above it would have stopped a
// beam): both integrations count it as seen free.
constexpr bool onlyFixtureEnds(std::uint8_t end) { return end == kFixture; }

/// std::floor and std::ceil of a moderate x (|x| < 2^52), exact, without libm's call (the baseline x86-64 build has no
/// rounding instruction, and these run for every cell projected).
inline double floorOf(double x) {
  const double t = static_cast<double>(static_cast<std::int64_t>(x));
  return t > x ? t - 1.0 : t;
}
inline double ceilOf(double x) {
  const double t = static_cast<double>(static_cast<std::int64_t>(x));
  return t < x ? t + 1.0 : t;
}

/// A ray sees a cell free only where it passes through it: inside the cell's slabs over more than this fraction of a
/// cell (a ray along a face, or through an edge or a corner, only touches the cell; with a camera on a cell boundary,
/// as in an axis-aligned set-up, whole columns of pixels do). And a pixel whose centre projects within kEdgePx of a
/// box's rectangle is in it (the corners' projections round either way).
constexpr double kInside = 1e-6, kEdgePx = 1e-6;

/// A box of the grid as a camera sees it: its z-depth range and the pixels whose rays may cross it (the bounding
/// rectangle of its corners' projections, clipped to the image). state: 0 in front of the camera with pixels, 1
/// nothing to see (behind the camera, or outside the image), 2 across the camera's plane (no projection).
/// The rectangle's bounds fit 16 bits (kMaxPinholeSide): a block's record, footprint included, is one cache line.
struct Footprint {
  double zmin = 0.0, zmax = 0.0;
  std::int16_t u0 = 0, u1 = -1, v0 = 0, v1 = -1;
  std::int8_t state = 1;
};
static_assert(kMaxPinholeSide <= std::numeric_limits<std::int16_t>::max(), "a footprint's pixels are 16-bit");

/// skip_unchanged_blocks: a cloud from a pose and intrinsics this close to a remembered view's is that camera's next
/// view (fitPinhole's intrinsics of a fixed camera differ from cloud to cloud by about 1e-7 px, the points' float
/// rounding); the view's own values are then used. At most kMaxViews cameras are remembered (the least recently seen
/// one makes way).
constexpr double kSameCameraPx = 1e-4, kSamePose = 1e-9;
constexpr std::size_t kMaxViews = 8;

/// A cell as a camera sees it, from its pose and intrinsics alone: what the projective update projects for a cell,
/// kept per block for a camera's next views (each filled the first time a view needs it). nearest: the pixel nearest
/// the projection of the cell's centre, as 2 * index + 1 when its ray passes within the cell's inscribed sphere (it
/// surely crosses the cell), 2 * index otherwise, -1 when the centre projects outside the image. u0, u1, v0, v1: the
/// cell's footprint rectangle (u0 > u1: nothing to see, the footprint's state 1 or 2).
struct CellProjection {
  static constexpr std::int32_t kNotYet = std::numeric_limits<std::int32_t>::min();
  static constexpr std::int16_t kNotYet16 = std::numeric_limits<std::int16_t>::min();
  std::int32_t nearest = kNotYet;
  std::int16_t u0 = kNotYet16, u1 = 0, v0 = 0, v1 = 0;
};
constexpr int kBlockCells = 1 << (3 * kBlockShift);
static_assert(kBlockCells <= 64, "a block's cells are the bits of one word");
/// A block's word with every bit set: each of its cells (and the bits past them) clamped free, or past the grid's end.
constexpr std::uint64_t kAllCells = ~std::uint64_t{0};

bool sameCamera(const PinholeCamera& a, const PinholeCamera& b) {
  if (a.width != b.width || a.height != b.height) return false;
  // The largest difference of the two models' pixel coordinates over the image's rays.
  const double ru = std::max(a.cx, a.width - 1.0 - a.cx) / a.fx, rv = std::max(a.cy, a.height - 1.0 - a.cy) / a.fy;
  return std::fabs(a.fx - b.fx) * ru + std::fabs(a.cx - b.cx) <= kSameCameraPx &&
         std::fabs(a.fy - b.fy) * rv + std::fabs(a.cy - b.cy) <= kSameCameraPx;
}

bool samePose(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return (a.matrix() - b.matrix()).cwiseAbs().maxCoeff() <= kSamePose;
}

/// splitmix64's finalizer: a cell's id and flags to a 64-bit hash (a block's end cells: the sum of theirs).
std::uint64_t mix(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

bool testBit(const std::vector<std::uint64_t>& bits, std::int64_t k) { return ((bits[k >> 6] >> (k & 63)) & 1u) != 0; }
void setBit(std::vector<std::uint64_t>* bits, std::int64_t k) { (*bits)[k >> 6] |= std::uint64_t{1} << (k & 63); }
void clearBit(std::vector<std::uint64_t>* bits, std::int64_t k) { (*bits)[k >> 6] &= ~(std::uint64_t{1} << (k & 63)); }
/// A revision no map of this process has had (OccupancyMap::revision).
std::uint64_t nextRevision() {
  static std::atomic<std::uint64_t> counter{0};
  return ++counter;
}

}  // namespace

std::unique_ptr<OccupancyMap> OccupancyMap::create(const OccupancyMapOptions& o, std::string* error) {
  auto bad = [&](const std::string& why) {
    if (error != nullptr) *error = "octomap: " + why;
    return nullptr;
  };
  if (!std::isfinite(o.resolution) || o.resolution <= 0.0) return bad("resolution must be > 0");
  if (!std::isfinite(o.max_range) || o.max_range <= 0.0) return bad("max_range must be > 0");
  if (!std::isfinite(o.fixture_pullback) || o.fixture_pullback < 0.0 || o.fixture_pullback >= o.resolution)
    return bad("fixture_pullback must be >= 0 and below the resolution");
  if (!probability(o.prob_hit) || o.prob_hit <= 0.5) return bad("prob_hit must be in (0.5, 1)");
  if (!probability(o.prob_miss) || o.prob_miss >= 0.5) return bad("prob_miss must be in (0, 0.5)");
  if (!probability(o.clamp_min) || !probability(o.clamp_max) || o.clamp_min >= o.clamp_max) {
    return bad("clamp_min < clamp_max, both in (0, 1), required");
  }
  if (!probability(o.occupancy_threshold) || o.occupancy_threshold <= o.clamp_min ||
      o.occupancy_threshold >= o.clamp_max) {
    return bad("occupancy_threshold must lie in (clamp_min, clamp_max)");
  }
  auto logit = [](double p) { return std::log(p / (1.0 - p)); };
  if (!(logit(o.prob_hit) + logit(o.clamp_min) > logit(o.occupancy_threshold))) {
    return bad(
        "one hit must make a cell clamped at clamp_min occupied: logit(prob_hit) + logit(clamp_min) > "
        "logit(occupancy_threshold) (an obstacle stepping into space seen free would show views later)");
  }
  if (o.bounds.isEmpty() || !o.bounds.min().allFinite() || !o.bounds.max().allFinite()) {
    return bad("bounds (the mapped box) must be set");
  }
  std::unique_ptr<OccupancyMap> m(new OccupancyMap());
  m->options_ = o;
  m->inv_resolution_ = 1.0 / o.resolution;
  m->max_range2_ = o.max_range * o.max_range;
  std::int64_t cells = 1;
  for (int i = 0; i < 3; ++i) {
    const double lo = std::floor(o.bounds.min()[i] * m->inv_resolution_);
    const double hi = std::floor(o.bounds.max()[i] * m->inv_resolution_);
    if (!(hi - lo < 1e6)) return bad("bounds hold too many cells at this resolution");
    m->offset_[i] = static_cast<std::int64_t>(lo);
    m->size_[i] = static_cast<std::int64_t>(hi - lo) + 1;
    cells *= m->size_[i];
    if (cells > kMaxCells) break;
  }
  if (cells > kMaxCells) {
    return bad("bounds hold " + std::to_string(cells) + " cells at this resolution (at most " +
               std::to_string(kMaxCells) + ")");
  }
  const std::size_t words = static_cast<std::size_t>((cells + 63) / 64);
  m->value_.assign(static_cast<std::size_t>(cells), std::numeric_limits<float>::quiet_NaN());
  m->seen_.assign(words, 0);
  m->hit_.assign(words, 0);
  m->observed_.assign(words, 0);
  m->occupied_.assign(words, 0);
  m->clamped_.assign(words, 0);
  std::int64_t supers = 1;
  for (int i = 0; i < 3; ++i) {
    m->blocks_[i] = ((m->size_[i] - 1) >> kBlockShift) + 1;
    m->supers_[i] = ((m->size_[i] - 1) >> kSuperShift) + 1;
    supers *= m->supers_[i];
  }
  const std::int64_t blocks = supers * kSuperBlocks;  // blockIndex's: every superblock's, those past the grid unused
  m->block_count_.assign(static_cast<std::size_t>(blocks), 0);
  m->block_clamped_.assign(static_cast<std::size_t>(blocks), 0);
  m->block_ended_.assign(static_cast<std::size_t>(blocks), 0);
  for (int n = 0; n < kBlockCells; ++n) {
    constexpr int mask = (1 << kBlockShift) - 1;
    m->cell_offset_[n] = m->cellId(n >> (2 * kBlockShift), (n >> kBlockShift) & mask, n & mask);
  }
  m->super_count_.assign(static_cast<std::size_t>(supers), 0);
  m->super_dirty_.assign(static_cast<std::size_t>(supers), 0);
  m->seen_block_count_.assign(static_cast<std::size_t>(blocks), 0);
  m->seen_super_count_.assign(static_cast<std::size_t>(supers), 0);
  m->block_dirtied_.assign(static_cast<std::size_t>(blocks), 0);
  m->super_dirtied_.assign(static_cast<std::size_t>(supers), 0);
  m->end_hash_.assign(static_cast<std::size_t>(blocks), 0);
  m->super_end_hash_.assign(static_cast<std::size_t>(supers), 0);
  if (o.hidden_space) {
    if (!std::isfinite(o.watch_time) || o.watch_time <= 0.0) return bad("watch_time must be > 0 (hidden_space)");
    if (!std::isfinite(o.speed_bound)) return bad("speed_bound must be finite (hidden_space)");
    m->batch_seen_.assign(static_cast<std::size_t>(blocks), 0);
    m->block_watched_.assign(static_cast<std::size_t>(blocks), 0);
    m->block_free_.assign(static_cast<std::size_t>(blocks), 0);
    m->turned_free_.assign(static_cast<std::size_t>(blocks), 0);
    m->super_watched_.assign(static_cast<std::size_t>(supers), 0);
    m->grown_mark_.assign(static_cast<std::size_t>(blocks), 0);
    m->stale_.assign(words, 0);
    m->fixed_.assign(words, 0);
    m->solid_.assign(words, 0);
    m->free_until_.assign(static_cast<std::size_t>(cells), std::numeric_limits<float>::quiet_NaN());
  }
  m->log_hit_ = logodds(o.prob_hit);
  m->log_miss_ = logodds(o.prob_miss);
  m->clamp_min_ = logodds(o.clamp_min);
  m->clamp_max_ = logodds(o.clamp_max);
  m->threshold_ = logodds(o.occupancy_threshold);
  // Unobserved under unknown_occupied: half a miss above the threshold, so one miss turns the cell free and one hit
  // keeps it occupied (octomap's isNodeOccupied: log-odds >= the threshold's).
  m->prior_ = m->threshold_ - 0.5f * m->log_miss_;
  if (!(m->prior_ < m->clamp_max_)) {
    return bad("occupancy_threshold too close to clamp_max for unknown_occupied's prior");
  }
  m->options_.unknown_occupied = o.unknown_occupied;
  m->fillUnobserved(o.unknown_occupied);
  if (o.hidden_space) m->setSpeedBound(o.speed_bound);
  return m;
}

/// What one camera's views left of a block: its footprint (valid where id equals the view's id: it depends on the
/// camera's pose and intrinsics only), the cells the view at epoch `at` saw free (a bit each, in the block's x, y, z
/// order; a cell it skipped, as hit or clamped free then, is 0), and end_hash_ at the camera's last view. One cache
/// line, and a superblock's blocks' records side by side (blockIndex): the update reads them in that order.
struct alignas(64) BlockRecord {
  Footprint fp;
  std::uint64_t id = 0, seen = 0, at = 0, end_hash = 0;
};
static_assert(sizeof(BlockRecord) == 64, "a block's record is one cache line");

/// What one camera's views left of a superblock: its footprint (valid where id equals the view's id); the epoch of the
/// last view whose record of its dirty blocks is their `seen` where their `at` equals base (none of their cells seen
/// free elsewhere), and that base: the epoch of the last view that evaluated it (or found it hidden; the views left
/// unchanged since repeat it); whether one of those records holds a cell (not clamped free); super_end_hash_ at the
/// camera's last view.
struct SuperRecord {
  Footprint fp;
  std::uint64_t id = 0, at = 0, base = 0, end_hash = 0;
  bool seen = false;
};

struct OccupancyMap::View {
  PinholeCamera camera;
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  std::uint64_t id = 0;    ///< the epoch this camera was first seen at: tags the footprints computed for it
  std::uint64_t last = 0;  ///< the epoch of its last view (0: none)
  std::vector<float> free_depth, past_depth;         ///< that view's depths (computeUpdateProjective's)
  std::vector<float> reach;                          ///< per pixel: the z-depth where its ray reaches max_range
  std::vector<BlockRecord> blocks;                   ///< per block (blockIndex)
  std::vector<SuperRecord> supers;                   ///< per superblock
  std::vector<std::int64_t> end_blocks, end_supers;  ///< the blocks (superblocks) whose end_hash is not 0
  /// Per block, its cells' projections (kBlockCells each, in the block's x, y, z order), for this camera (freed when
  /// the view takes another): allocated when a later view of this camera (not its first) first evaluates the block,
  /// and only when skip_unchanged_blocks (a map that evaluates every block computes every cell's projection afresh:
  /// the tests that compare the two compare these too).
  std::vector<std::unique_ptr<CellProjection[]>> cells;
};

/// Cache-line aligned: the workers' counters must not share a line.
struct alignas(64) OccupancyMap::Scratch {
  std::vector<std::uint64_t> misses;
  std::size_t free_cells = 0, reused = 0;
  Footprint f;
  CellProjection cells[kBlockCells];  ///< a block's cell projections when the view keeps none
};

OccupancyMap::~OccupancyMap() = default;

void OccupancyMap::boxesOf(std::int64_t c, std::int64_t* block, std::int64_t* super, std::uint64_t* bit) const {
  std::int64_t at[3];
  unravel(c, size_, at);
  const std::int64_t i = at[0], j = at[1], k = at[2];
  *block = blockIndex(i >> kBlockShift, j >> kBlockShift, k >> kBlockShift);
  *super = superIndex(i >> kSuperShift, j >> kSuperShift, k >> kSuperShift);
  constexpr std::int64_t m = (1 << kBlockShift) - 1;
  if (bit != nullptr) *bit = std::uint64_t{1} << ((((i & m) << kBlockShift | (j & m)) << kBlockShift) | (k & m));
}

std::size_t OccupancyMap::slot(std::int64_t c) const {
  // Fibonacci hashing, then linear probing to c's slot or the first empty one.
  const std::size_t mask = slots_.size() - 1;
  std::size_t at =
      static_cast<std::size_t>((static_cast<std::uint64_t>(c) * 0x9e3779b97f4a7c15ULL) >> (64 - slot_bits_));
  while (slots_[at].key != c && slots_[at].key != -1) at = (at + 1) & mask;  // (key: int32, c < kMaxCells)
  return at;
}

void OccupancyMap::growSlots() {
  slot_bits_ = std::max(12, slot_bits_ + 1);
  slots_.assign(std::size_t{1} << slot_bits_, Slot());
  for (std::size_t n = 0; n < order_.size(); ++n) {
    const std::size_t at = slot(order_[n]);
    slots_[at] = {static_cast<std::int32_t>(order_[n]), static_cast<std::uint32_t>(n)};
    order_slot_[n] = at;
  }
}

void OccupancyMap::collectEndCells(const std::vector<Eigen::Vector3d>& points,
                                   const std::vector<std::uint8_t>& robot_mask, const Eigen::Vector3d& origin,
                                   MapUpdate* out, bool beams, WorkerPool* pool) {
  out->hits.clear();
  out->misses.clear();
  out->fixed.clear();
  out->stale.clear();
  out->close = out->forget = false;
  out->late = options_.hidden_space && !recording_;  // hidden_space: a view beginView did not place in the open batch
  out->stamp = recording_ ? batch_stamp_ : std::numeric_limits<double>::quiet_NaN();
  out->stats = MapUpdateStats();
  out->stats.points = points.size();
  const bool masked = robot_mask.size() == points.size();
  // 1. End points (beyond max_range: cut there, free space only), grouped by cell: one beam per end cell (step 3),
  //    to the centroid of the cell's points (beams: order_end_ sums them, order_count_ counts them). order_flags_
  //    holds the flags of each cell's points, order_ the cells in the order of their first point (neighbouring pixels
  //    cast neighbouring beams one after another: cache). The cells are found in a small hash table (slots_), not in
  //    a per-cell array: a cloud's end cells are scattered over the grid, and each would miss the cache.
  //    Each point's cell and flags first (point_cell_, point_flags_: kInvalidPoint for a non-finite one; without beams
  //    a run of points per cell), in parts on the pool; then the table, in the points' order.
  point_cell_.resize(points.size());
  point_flags_.resize(points.size());
  // A beam's end: cut at max_range (flags 0), or a fixture point pulled back toward the sensor (fixture_pullback).
  auto end_of = [&](const Eigen::Vector3d& p, std::uint8_t flags) -> Eigen::Vector3d {
    if (flags == 0) return origin + (p - origin) * (options_.max_range / (p - origin).norm());
    if (flags == kFixture && options_.fixture_pullback > 0.0) {
      const double d = (p - origin).norm();
      return d > options_.fixture_pullback ? Eigen::Vector3d(p - (p - origin) * (options_.fixture_pullback / d)) : p;
    }
    return p;
  };
  // Without beams a part also folds its points into runs (the points that end in one cell one after another, invalid
  // points and points without a cell skipped: neighbouring pixels), written over its own first elements of point_cell_
  // and point_flags_, and counts its points' kinds: the table below then looks up a run, not a point (a 640x480 cloud
  // has several points per run). The runs keep the points' order, so the table is the same.
  struct PartRuns {
    std::size_t begin, runs;
    std::size_t invalid, beyond_range, fixture, robot;
  };
  std::vector<PartRuns> parts;
  std::mutex parts_mutex;
  WorkerPool::runParts(pool, points.size(), WorkerPool::kCheapPart, [&](std::size_t begin, std::size_t end, int) {
    PartRuns part{begin, begin, 0, 0, 0, 0};
    std::int32_t last_cell = -1;
    for (std::size_t k = begin; k < end; ++k) {
      const Eigen::Vector3d& p = points[k];
      if (!p.allFinite()) {
        if (beams) point_flags_[k] = kInvalidPoint;
        ++part.invalid;
        continue;
      }
      std::uint8_t flag = kHit;
      if ((p - origin).squaredNorm() > max_range2_) {
        flag = 0;
        ++part.beyond_range;
      } else if (masked && robot_mask[k] == kPointOnFixture) {
        flag = kFixture;
        ++part.fixture;
      } else if (masked && robot_mask[k] != kPointObstacle) {
        flag = kRobot;
        ++part.robot;
      }
      if (flag == 0 && !beams) continue;  // no beam to cut at max_range: projection sees free space from the depths
      // The end point's cell from float coordinates, as octomap's keys of point3d (a point on a cell boundary in
      // double may lie across it in float). g++ -O3 was seen to skip the rounding to float otherwise: each float is
      // kept as rounded, in a register (an empty asm that may change it; a volatile's trip through memory cost about a
      // fifth of this loop at 640x480), or through memory where that asm is not written.
      const Eigen::Vector3d e = end_of(p, flag);
#if defined(__GNUC__) && (defined(__x86_64__) || defined(__i386__))
      float fx = static_cast<float>(e.x()), fy = static_cast<float>(e.y()), fz = static_cast<float>(e.z());
      asm("" : "+x"(fx), "+x"(fy), "+x"(fz));
#else
      const volatile float fx = static_cast<float>(e.x()), fy = static_cast<float>(e.y()),
                           fz = static_cast<float>(e.z());
#endif
      const auto c = static_cast<std::int32_t>(cellOf(Eigen::Vector3d(fx, fy, fz)));  // -1 outside (kMaxCells)
      if (beams) {
        point_flags_[k] = flag;
        point_cell_[k] = c;
      } else if (c < 0) {
        continue;
      } else if (c == last_cell) {
        point_flags_[part.runs - 1] |= flag;
      } else {
        point_cell_[part.runs] = c;  // part.runs <= k: this part's points before k are read already
        point_flags_[part.runs] = flag;
        ++part.runs;
        last_cell = c;
      }
    }
    const std::lock_guard<std::mutex> lock(parts_mutex);
    parts.push_back(part);
  });
  for (const PartRuns& part : parts) {
    out->stats.invalid += part.invalid;
    out->stats.beyond_range += part.beyond_range;
    out->stats.fixture += part.fixture;
    out->stats.robot += part.robot;
  }
  for (std::size_t at : order_slot_) slots_[at].key = -1;  // the last cloud's (by place: a probe needs the chain)
  order_slot_.clear();
  order_.clear();
  order_flags_.clear();
  order_end_.clear();
  order_count_.clear();
  // Cell c's index in order_, added there (flags 0) when it is new.
  auto index_of = [&](std::int64_t c) -> std::uint32_t {
    if (2 * (order_.size() + 1) > slots_.size()) growSlots();
    const std::size_t at = slot(c);
    if (slots_[at].key == c) return slots_[at].index;
    const auto n = static_cast<std::uint32_t>(order_.size());
    slots_[at] = {static_cast<std::int32_t>(c), n};
    order_slot_.push_back(at);
    order_.push_back(c);
    order_flags_.push_back(0);
    if (beams) {
      order_end_.push_back(Eigen::Vector3d::Zero());
      order_count_.push_back(0);
    }
    return n;
  };
  std::int64_t last_cell = -1;
  std::uint32_t last_index = 0;
  if (beams) {
    for (std::size_t k = 0; k < points.size(); ++k) {
      const std::uint8_t flag = point_flags_[k];
      const std::int64_t c = point_cell_[k];
      if (flag == kInvalidPoint || c < 0) continue;
      if (c != last_cell) {  // not the previous point's cell (neighbouring pixels): a look-up
        last_index = index_of(c);
        last_cell = c;
      }
      order_flags_[last_index] |= flag;
      order_end_[last_index] += end_of(points[k], flag);
      ++order_count_[last_index];
    }
  } else {
    std::sort(parts.begin(), parts.end(), [](const PartRuns& a, const PartRuns& b) { return a.begin < b.begin; });
    for (const PartRuns& part : parts) {
      for (std::size_t r = part.begin; r < part.runs; ++r) {
        const std::int64_t c = point_cell_[r];
        if (c != last_cell) {  // (a part's last run and the next part's first may share a cell)
          last_index = index_of(c);
          last_cell = c;
        }
        order_flags_[last_index] |= point_flags_[r];
      }
    }
  }
  // 2. This cloud's marks: a bit per cell for "seen free" and one for "hit".
  std::fill(seen_.begin(), seen_.end(), 0);
  std::fill(hit_.begin(), hit_.end(), 0);
  // Hits first (occupied wins: a cell hit by one beam stays occupied even when others cross it). A cell that holds an
  // obstacle point is hit even when robot or fixture points end in it too: something else is there (a hand next to a
  // link).
  std::size_t hit_cells = 0;
  for (std::size_t n = 0; n < order_.size(); ++n) {
    if ((order_flags_[n] & kHit) == 0) continue;
    const std::int64_t c = order_[n];
    setBit(&hit_, c);
    ++hit_cells;
    if (!(value_[c] == clamp_max_)) out->hits.push_back(static_cast<std::uint64_t>(c));  // a hit changes it
  }
  out->stats.hit_cells = hit_cells;
}

void OccupancyMap::computeUpdate(const std::vector<Eigen::Vector3d>& points,
                                 const std::vector<std::uint8_t>& robot_mask, const Eigen::Vector3d& origin,
                                 MapUpdate* out) {
  ++epoch_;
  collectEndCells(points, robot_mask, origin, out, true, nullptr);
  // 3. Beams from the origin to the centroid of each end cell's points (octomap's discretized insertion casts to the
  //    cell's centre: with a sparse cloud of a static scene the same centres are hit every view, and a cell that no
  //    centre's beam crosses is never seen free again once a person left it, although a point's own line of sight
  //    crosses it; a lone point's beam is its line of sight), clipped to the map bounds: the cells from the first one
  //    up to, excluding, the end cell (as octomap's computeRayKeys), each counted once per cloud. A 3D DDA over the
  //    grid's indices (Amanatides & Woo). A cell where only fixture points end was seen down to the fixture's surface
  //    (anything above it would have stopped a beam): the end cell counts as seen free too. A robot's end cell marks
  //    nothing: what was seen there stays (a hand that was seen keeps its cells when it comes within the filter).
  std::size_t free_cells = 0;
  const double inv = inv_resolution_;
  const std::int64_t stride[3] = {size_[1] * size_[2], size_[2], 1};
  for (std::size_t n = 0; n < order_.size(); ++n) {
    const std::int64_t c_end = order_[n];
    // The centroid of the points that end in the cell, kept inside it (a lone point: the point itself).
    std::int64_t e[3];
    unravel(c_end, size_, e);
    const Eigen::Array3d lo = centre(e[0], e[1], e[2]).array() - 0.5 * options_.resolution;
    const double inset = 1e-6 * options_.resolution;
    const Eigen::Vector3d end =
        (order_end_[n].array() / order_count_[n]).max(lo + inset).min(lo + (options_.resolution - inset)).matrix();
    const bool through_end = onlyFixtureEnds(order_flags_[n]);
    double t0, t1;
    if (!clipToBox(origin, end, options_.bounds, &t0, &t1)) continue;
    const Eigen::Vector3d a = origin + t0 * (end - origin),
                          b = t1 >= 1.0 ? end : Eigen::Vector3d(origin + t1 * (end - origin)), d = b - a;
    std::int64_t at[3], last[3], step[3];
    double t_max[3], t_delta[3];
    bool inside = true;
    for (int i = 0; i < 3; ++i) {
      const double fa = std::floor(a[i] * inv), fb = std::floor(b[i] * inv);
      at[i] = static_cast<std::int64_t>(fa) - offset_[i];
      last[i] = static_cast<std::int64_t>(fb) - offset_[i];
      inside = inside && at[i] >= 0 && at[i] < size_[i];
      if (d[i] > 0.0) {
        step[i] = 1;
        t_max[i] = ((fa + 1.0) * options_.resolution - a[i]) / d[i];
        t_delta[i] = options_.resolution / d[i];
      } else if (d[i] < 0.0) {
        step[i] = -1;
        t_max[i] = (fa * options_.resolution - a[i]) / d[i];
        t_delta[i] = -options_.resolution / d[i];
      } else {
        step[i] = 0;
        t_max[i] = t_delta[i] = std::numeric_limits<double>::infinity();
      }
    }
    if (!inside) continue;
    std::int64_t k = cellId(at[0], at[1], at[2]);
    const double res = options_.resolution;
    for (;;) {
      const bool at_last = at[0] == last[0] && at[1] == last[1] && at[2] == last[2];
      if (at_last && !through_end) break;
      const std::int64_t block = blockIndex(at[0] >> kBlockShift, at[1] >> kBlockShift, at[2] >> kBlockShift);
      if ((block_clamped_[block] & ~watchedBits(block)) == kAllCells && !at_last) {
        // Every cell of this block is clamped at clamp_min (the free space the cameras keep seeing): a miss changes
        // none of them. Jump to where the beam leaves the block, unless it ends in it.
        bool ends_here = true;
        for (int i = 0; i < 3; ++i) ends_here = ends_here && (last[i] >> kBlockShift) == (at[i] >> kBlockShift);
        if (!ends_here) {
          double t_exit = std::numeric_limits<double>::infinity();
          for (int i = 0; i < 3; ++i) {
            if (step[i] == 0) continue;
            const std::int64_t edge =
                step[i] > 0 ? ((at[i] >> kBlockShift) + 1) << kBlockShift : (at[i] >> kBlockShift) << kBlockShift;
            t_exit = std::min(t_exit, ((edge + offset_[i]) * res - a[i]) / d[i]);
          }
          if (!(t_exit < 1.0)) break;  // rounding: the end lies beyond b
          // Restart the traversal just past the block's face (the cells there are the ones the beam enters).
          const double t = t_exit + 1e-9;
          std::int64_t next[3];
          bool same = true, out = false;
          for (int i = 0; i < 3; ++i) {
            const double x = a[i] + t * d[i];
            const double f = std::floor(x * inv);
            next[i] = static_cast<std::int64_t>(f) - offset_[i];
            out = out || next[i] < 0 || next[i] >= size_[i];
            same = same && (next[i] >> kBlockShift) == (at[i] >> kBlockShift);
            if (step[i] > 0) {
              t_max[i] = t + ((f + 1.0) * res - x) / d[i];
            } else if (step[i] < 0) {
              t_max[i] = t + (f * res - x) / d[i];
            }
          }
          if (out) break;
          if (!same) {
            for (int i = 0; i < 3; ++i) at[i] = next[i];
            k = cellId(at[0], at[1], at[2]);
            continue;
          }
          // Rounding kept the point in the block: fall back to the cell steps from it.
          for (int i = 0; i < 3; ++i) at[i] = next[i];
          k = cellId(at[0], at[1], at[2]);
        }
      } else {
        const std::uint64_t bit = std::uint64_t{1} << (k & 63);
        std::uint64_t& seen = seen_[k >> 6];
        if ((seen & bit) == 0 && (hit_[k >> 6] & bit) == 0) {
          seen |= bit;
          ++free_cells;
          // A free cell already clamped at clamp_min does not change: nothing to apply (a bit, not the value: the
          // values are 4 bytes a cell, too many for the cache).
          if ((clamped_[k >> 6] & bit) == 0) out->misses.push_back(static_cast<std::uint64_t>(k));
          if (recording_) {
            constexpr std::int64_t m = (1 << kBlockShift) - 1;
            batch_seen_[block] |= std::uint64_t{1}
                                  << ((((at[0] & m) << kBlockShift | (at[1] & m)) << kBlockShift) | (at[2] & m));
          }
        }
        if (at_last) break;  // a fixture's end cell, done
      }
      const int axis = t_max[0] < t_max[1] ? (t_max[0] < t_max[2] ? 0 : 2) : (t_max[1] < t_max[2] ? 1 : 2);
      if (t_max[axis] > 1.0) break;  // rounding: b's cell was not reached exactly
      at[axis] += step[axis];
      if (at[axis] < 0 || at[axis] >= size_[axis]) break;
      k += step[axis] * stride[axis];
      t_max[axis] += t_delta[axis];
    }
  }
  out->stats.free_cells = free_cells;
  out->stats.changed_cells = out->hits.size() + out->misses.size();
}

void OccupancyMap::computeUpdateProjective(const std::vector<Eigen::Vector3d>& points,
                                           const std::vector<std::uint8_t>& robot_mask, const std::vector<float>& depth,
                                           const std::vector<std::uint8_t>& pixel_mask, const PinholeCamera& fitted,
                                           const Eigen::Isometry3d& fitted_pose, MapUpdate* out, WorkerPool* pool) {
  ++epoch_;
  const int w = fitted.width, h = fitted.height;
  // 1-2. End cells and hits, as computeUpdate's.
  collectEndCells(points, robot_mask, fitted_pose.translation(), out, false, pool);
  if (w <= 0 || h <= 0 || w > kMaxPinholeSide || h > kMaxPinholeSide ||
      depth.size() != static_cast<std::size_t>(w) * h || !(fitted.fx > 0) || !(fitted.fy > 0)) {
    // A caller's error: nothing is seen free (the hits still count).
    out->stats.changed_cells = out->hits.size();
    return;
  }
  // The camera: a remembered one when this cloud comes from its pose and intrinsics (kSameCameraPx, kSamePose), whose
  // values are used from here on; else a new one, in place of the one seen longest ago.
  View* view = nullptr;
  for (auto& v : views_) {
    if (sameCamera(v->camera, fitted) && samePose(v->pose, fitted_pose)) view = v.get();
  }
  if (view == nullptr) {
    if (views_.size() < kMaxViews) {
      views_.push_back(std::make_unique<View>());
      view = views_.back().get();
      view->blocks.resize(block_clamped_.size());
      view->supers.resize(super_dirty_.size());
      if (options_.skip_unchanged_blocks) view->cells.resize(block_clamped_.size());
    } else {
      view = std::min_element(views_.begin(), views_.end(), [](const auto& a, const auto& b) {
               return a->last < b->last;
             })->get();
    }
    view->camera = fitted;
    view->pose = fitted_pose;
    view->id = epoch_;
    view->last = 0;
    for (auto& kept : view->cells) kept.reset();  // another camera's
    for (std::int64_t b : view->end_blocks) view->blocks[b].end_hash = 0;
    for (std::int64_t b : view->end_supers) view->supers[b].end_hash = 0;
    view->end_blocks.clear();
    view->end_supers.clear();
  }
  const PinholeCamera& camera = view->camera;
  const Eigen::Isometry3d& sensor_pose = view->pose;
  // The end cells per block (a sum of hashes of their ids and flags): the cloud's points in a block, as far as they
  // decide its cells (hits, and the fixture end cells seen free below, take no part in the projection).
  for (std::size_t n = 0; n < order_.size(); ++n) {
    if ((order_flags_[n] & (kHit | kFixture)) == 0) continue;
    const std::int64_t c = order_[n];
    std::int64_t b, sb;
    std::uint64_t bit;
    boxesOf(c, &b, &sb, &bit);
    const std::uint64_t hash = mix((static_cast<std::uint64_t>(c) << 8) | order_flags_[n]);
    if (end_hash_[b] == 0) end_blocks_.push_back(b);
    if (super_end_hash_[sb] == 0) end_supers_.push_back(sb);
    end_hash_[b] += hash;
    super_end_hash_[sb] += hash;
    // Hit (hit_), or seen free below as a fixture's end cell (seen_): not to be seen free by projection.
    if ((order_flags_[n] & kHit) != 0 || onlyFixtureEnds(order_flags_[n])) block_ended_[b] |= bit;
  }
  std::size_t free_cells = 0;
  auto see = [&](std::int64_t k) {
    setBit(&seen_, k);
    ++free_cells;
    if (!testBit(clamped_, k)) out->misses.push_back(static_cast<std::uint64_t>(k));
  };
  // A cell where only fixture points end was seen down to the fixture's surface: seen free (computeUpdate's rule).
  for (std::size_t n = 0; n < order_.size(); ++n) {
    if (onlyFixtureEnds(order_flags_[n]) && !testBit(seen_, order_[n])) {
      see(order_[n]);
      if (recording_) {
        std::int64_t b, sb;
        std::uint64_t bit;
        boxesOf(order_[n], &b, &sb, &bit);
        batch_seen_[b] |= bit;
      }
    }
  }
  // 3. Free space by projection. Each pixel's depth as far as it sees free: its z-depth, cut where its ray reaches
  //    max_range (a beam is integrated up to max_range, and a no-return at the far plane clears up to it); 0 for a
  //    pixel without a return (nothing along it is known).
  //    A pixel on the robot (pixel_mask) does not stop a cell from being seen free by the other pixels (as a beam of
  //    ray casting that passes a cell beside a link sees it free, whatever the link hides of it: the robot's blind
  //    zone), but it never sees a cell free itself: a cell whose only crossing rays end on the robot stays as it was.
  //    past_depth holds those depths (the min pyramid: robot pixels at their reach).
  //    Pyramids of the smallest and largest of those depths over tiles of 2^L x 2^L pixels; their level 0 (the pixels)
  //    is past_depth and free_depth.
  const std::size_t pixels = depth.size();
  const bool masked_pixels = pixel_mask.size() == pixels;
  int levels = 1;
  for (int lw = w, lh = h; lw > 1 || lh > 1; lw = (lw + 1) / 2, lh = (lh + 1) / 2) ++levels;
  for (auto* pyramid : {&min_depth_, &max_depth_, &changed_max_}) {
    pyramid->resize(static_cast<std::size_t>(levels));
    (*pyramid)[0].resize(pixels);
  }
  std::vector<float>& free_depth = max_depth_[0];
  std::vector<float>& past_depth = min_depth_[0];
  if (view->reach.size() != pixels || view->last == 0) {  // a camera new here, or after a clear
    view->reach.resize(pixels);
    for (int v = 0; v < h; ++v) {
      const double ry = (v - camera.cy) / camera.fy;
      for (int u = 0; u < w; ++u) {
        const double rx = (u - camera.cx) / camera.fx;
        view->reach[static_cast<std::size_t>(v) * w + u] =
            static_cast<float>(options_.max_range / std::sqrt(rx * rx + ry * ry + 1.0));
      }
    }
  }
  WorkerPool::runParts(pool, pixels, WorkerPool::kCheapPart, [&](std::size_t begin, std::size_t end, int) {
    for (std::size_t k = begin; k < end; ++k) {
      const float z = depth[k], reach = view->reach[k];
      free_depth[k] = std::isfinite(z) && z > 0.0f ? std::min(z, reach) : 0.0f;
      past_depth[k] = masked_pixels && pixel_mask[k] == kPointOnRobot ? reach : free_depth[k];
    }
  });
  // A pyramid's levels from its level 0: each tile the smallest (largest) of the 2 x 2 below it (clipped at the edges).
  auto build = [&](std::vector<std::vector<float>>* pyramid, bool smallest) {
    int lw = w, lh = h;
    for (std::size_t level = 1; level < pyramid->size(); ++level) {
      const int nw = (lw + 1) / 2, nh = (lh + 1) / 2;
      const std::vector<float>& f = (*pyramid)[level - 1];
      std::vector<float>& n = (*pyramid)[level];
      n.resize(static_cast<std::size_t>(nw) * nh);
      for (int y = 0; y < nh; ++y) {
        const float* r0 = &f[static_cast<std::size_t>(2 * y) * lw];
        const float* r1 = &f[static_cast<std::size_t>(std::min(2 * y + 1, lh - 1)) * lw];
        float* out = &n[static_cast<std::size_t>(y) * nw];
        for (int x = 0; x < nw; ++x) {
          const int x0 = 2 * x, x1 = std::min(2 * x + 1, lw - 1);
          out[x] = smallest ? std::min(std::min(r0[x0], r0[x1]), std::min(r1[x0], r1[x1]))
                            : std::max(std::max(r0[x0], r0[x1]), std::max(r1[x0], r1[x1]));
        }
      }
      lw = nw;
      lh = nh;
    }
  };
  // The smallest (largest) free depth over the pixels [u0, u1] x [v0, v1], from at most 16 tiles of the coarsest level
  // that needs no more: over a superset of the rectangle (smaller, larger: conservative both ways).
  auto over = [&](const std::vector<std::vector<float>>& pyramid, bool smallest, int u0, int u1, int v0, int v1) {
    int level = 0;
    while (((u1 >> level) - (u0 >> level) + 1) * ((v1 >> level) - (v0 >> level) + 1) > 16) ++level;
    const int lw = ((w - 1) >> level) + 1;
    const std::vector<float>& f = pyramid[static_cast<std::size_t>(level)];
    float m = f[static_cast<std::size_t>(v0 >> level) * lw + (u0 >> level)];
    for (int y = v0 >> level; y <= v1 >> level; ++y) {
      for (int x = u0 >> level; x <= u1 >> level; ++x) {
        const float q = f[static_cast<std::size_t>(y) * lw + x];
        m = smallest ? std::min(m, q) : std::max(m, q);
      }
    }
    return m;
  };
  // skip_unchanged_blocks: what changed since this camera's last view. A block's cells are decided by the depths over
  // its rectangle (through the pyramids: over the tiles that cover it, which lie within the tiles `changed` looks at
  // over the rectangle one pixel wider), the cloud's end cells in it (hits, fixture cells) and which of its cells are
  // clamped free. When none of these changed, this view sees free the cells that one saw free (block_seen), less those
  // clamped free since; a block that turned dirty since (block_dirtied_) is looked at again.
  const std::uint64_t last = options_.skip_unchanged_blocks ? view->last : 0;
  // The pyramids, each a task on the pool.
  auto pyramid = [&](std::size_t task, int) {
    if (task == 0) {
      build(&min_depth_, true);
    } else if (task == 1) {
      build(&max_depth_, false);
    } else {
      std::vector<float>& changed = changed_max_[0];
      for (std::size_t k = 0; k < pixels; ++k) {
        changed[k] = free_depth[k] != view->free_depth[k] || past_depth[k] != view->past_depth[k] ? 1.0f : 0.0f;
      }
      build(&changed_max_, false);
    }
  };
  const std::size_t pyramids = last != 0 ? 3 : 2;
  if (pool != nullptr) {
    pool->run(pyramids, pyramid);
  } else {
    for (std::size_t t = 0; t < pyramids; ++t) pyramid(t, 0);
  }
  // Each pixel column's and row's ray direction (optical frame, z = 1): x and y.
  ray_x_.resize(static_cast<std::size_t>(w));
  ray_y_.resize(static_cast<std::size_t>(h));
  for (int u = 0; u < w; ++u) ray_x_[u] = (u - camera.cx) / camera.fx;
  for (int v = 0; v < h; ++v) ray_y_[v] = (v - camera.cy) / camera.fy;
  const Eigen::Matrix3d rt = sensor_pose.linear().transpose();
  const Eigen::Vector3d tr = sensor_pose.translation();
  const double res = options_.resolution;
  const Eigen::Vector3d axis[3] = {rt.col(0) * res, rt.col(1) * res, rt.col(2) * res};  // one cell along x, y, z
  constexpr double kNear = 1e-6;
  // The pixels whose centres lie within [umin, umax] x [vmin, vmax], clipped to the image: f's rectangle (state 1 when
  // none). The bounds are clamped to the image's neighbourhood first (floorOf and ceilOf take moderate values).
  auto rectangle = [&](double umin, double umax, double vmin, double vmax, Footprint* f) {
    // A pixel whose centre lies on the rectangle's edge is in it, whatever the rounding of the corners' projections
    // (its ray may touch the box: it must see past it too).
    umin -= kEdgePx;
    vmin -= kEdgePx;
    umax += kEdgePx;
    vmax += kEdgePx;
    f->u0 = static_cast<std::int16_t>(std::max(0.0, ceilOf(std::min(std::max(umin, -1.0), static_cast<double>(w)))));
    f->u1 =
        static_cast<std::int16_t>(std::min(w - 1.0, floorOf(std::min(std::max(umax, -1.0), static_cast<double>(w)))));
    f->v0 = static_cast<std::int16_t>(std::max(0.0, ceilOf(std::min(std::max(vmin, -1.0), static_cast<double>(h)))));
    f->v1 =
        static_cast<std::int16_t>(std::min(h - 1.0, floorOf(std::min(std::max(vmax, -1.0), static_cast<double>(h)))));
    f->state = f->u0 > f->u1 || f->v0 > f->v1 ? 1 : 0;
  };
  auto footprint = [&](const std::int64_t* a, const std::int64_t* b, Footprint* f) {
    // Cells [a, b] (inclusive): the box from a's low corner to b's high corner, in the optical frame.
    const Eigen::Vector3d lo((a[0] + offset_[0]) * res, (a[1] + offset_[1]) * res, (a[2] + offset_[2]) * res);
    const Eigen::Vector3d s0 = rt * (lo - tr);
    Eigen::Vector3d e[3];
    for (int i = 0; i < 3; ++i) e[i] = axis[i] * static_cast<double>(b[i] - a[i] + 1);
    f->zmin = f->zmax = s0.z();
    for (int i = 0; i < 3; ++i) (e[i].z() < 0 ? f->zmin : f->zmax) += e[i].z();
    if (f->zmax <= kNear) {
      f->state = 1;
      return;
    }
    if (f->zmin <= kNear) {
      // Across the camera's plane: no projection. Still nothing to see when the box lies wholly beyond one of the
      // image's four sides, a plane through the camera: u < 0 where fx x + cx z < 0 (z > 0), u > w - 1 where
      // fx x + (cx - w + 1) z > 0, and so on (linear in the box's points: its corners decide).
      // (a, b, axis): a coordinate + b z < 0 for every corner puts the box beyond that side.
      const double side[4][3] = {{camera.fx, camera.cx, 0},
                                 {-camera.fx, w - 1.0 - camera.cx, 0},
                                 {camera.fy, camera.cy, 1},
                                 {-camera.fy, h - 1.0 - camera.cy, 1}};
      for (const auto& pl : side) {
        const int i = static_cast<int>(pl[2]);
        // The largest of a p_i + b p_z over the box's corners: from s0, each edge adds where it adds.
        double most = pl[0] * s0[i] + pl[1] * s0.z();
        for (int k = 0; k < 3; ++k) most += std::max(0.0, pl[0] * e[k][i] + pl[1] * e[k].z());
        if (most < 0.0) {
          f->state = 1;
          return;
        }
      }
      f->state = 2;
      return;
    }
    double umin = std::numeric_limits<double>::infinity(), umax = -umin, vmin = umin, vmax = -umin;
    for (int c = 0; c < 8; ++c) {
      const Eigen::Vector3d p = s0 + ((c & 1) ? e[0] : Eigen::Vector3d::Zero()) +
                                ((c & 2) ? e[1] : Eigen::Vector3d::Zero()) + ((c & 4) ? e[2] : Eigen::Vector3d::Zero());
      const double u = camera.fx * p.x() / p.z() + camera.cx, v = camera.fy * p.y() / p.z() + camera.cy;
      umin = std::min(umin, u);
      umax = std::max(umax, u);
      vmin = std::min(vmin, v);
      vmax = std::max(vmax, v);
    }
    rectangle(umin, umax, vmin, vmax, f);
  };
  // A block's or superblock's footprint, computed once per camera (it depends on the pose and intrinsics only).
  auto cached = [&](auto* record, const std::int64_t* a, const std::int64_t* b) -> const Footprint& {
    if (record->id != view->id) {
      footprint(a, b, &record->fp);
      record->id = view->id;
    }
    return record->fp;
  };
  // No pixel changed since the camera's last view over the tiles a box's rectangle reads (one pixel wider); a box
  // across the camera's plane has no rectangle (its cells' pixels are anywhere): changed.
  auto unchanged = [&](const Footprint& f) {
    return f.state == 0 && over(changed_max_, false, std::max(0, f.u0 - 1), std::min(w - 1, f.u1 + 1),
                                std::max(0, f.v0 - 1), std::min(h - 1, f.v1 + 1)) == 0.0f;
  };
  // A box wholly behind what every pixel that may see it saw holds nothing this cloud sees free.
  auto hidden = [&](const Footprint& f) {
    return f.state == 1 || (f.state == 0 && f.zmin > over(max_depth_, false, f.u0, f.u1, f.v0, f.v1));
  };
  // The squared radius of a cell's inscribed sphere, kInside of a cell smaller: a ray that passes within it enters
  // the cell (one tangent to the sphere where it meets a face would only touch that face).
  const double r2 = 0.25 * res * res * (1.0 - 4.0 * kInside);
  // How far a cell reaches in depth beyond its centre: half the sum of its edges' depth components.
  const double half_depth = 0.5 * (std::fabs(axis[0].z()) + std::fabs(axis[1].z()) + std::fabs(axis[2].z()));
  // A cell's footprint from its centre c (optical frame): as footprint's of the cell, with the corners c +- half
  // edges, one division each (a cell across the camera's plane, or nearer than kNear, sees nothing: state 2 or 1, both
  // "not seen" to the loop below).
  Eigen::Vector3d corner[8];
  for (int k = 0; k < 8; ++k) {
    corner[k] =
        0.5 * ((k & 1 ? 1.0 : -1.0) * axis[0] + (k & 2 ? 1.0 : -1.0) * axis[1] + (k & 4 ? 1.0 : -1.0) * axis[2]);
  }
  // Each cell of a block (its bit n: x, y, z within the block) from the block's first cell: its centre's offset in
  // the optical frame (its id's is cell_offset_).
  Eigen::Vector3d cell_step[kBlockCells];
  for (int n = 0; n < kBlockCells; ++n) {
    cell_step[n] = static_cast<double>(n >> (2 * kBlockShift)) * axis[0] +
                   static_cast<double>((n >> kBlockShift) & ((1 << kBlockShift) - 1)) * axis[1] +
                   static_cast<double>(n & ((1 << kBlockShift) - 1)) * axis[2];
  }
  auto cellFootprint = [&](const Eigen::Vector3d& c, Footprint* f) {
    f->zmin = c.z() - half_depth;
    f->zmax = c.z() + half_depth;
    if (f->zmin <= kNear) {
      f->state = f->zmax <= kNear ? 1 : 2;
      return;
    }
    double umin = std::numeric_limits<double>::infinity(), umax = -umin, vmin = umin, vmax = -umin;
    for (const Eigen::Vector3d& k : corner) {
      const Eigen::Vector3d p = c + k;
      const double inv = 1.0 / p.z(), u = camera.fx * p.x() * inv + camera.cx, v = camera.fy * p.y() * inv + camera.cy;
      umin = std::min(umin, u);
      umax = std::max(umax, u);
      vmin = std::min(vmin, v);
      vmax = std::max(vmax, v);
    }
    rectangle(umin, umax, vmin, vmax, f);
  };
  // The superblocks holding cells not clamped free, each a task for the workers (they write disjoint cells, blocks
  // and superblocks; a cell's bit in seen_ shares its word with other superblocks' cells: set atomically). Each task's
  // misses go to its worker's list and are joined in the superblocks' order: the update is the same, in the same
  // order, whatever the number of workers.
  tasks_.clear();
  for (std::int64_t si = 0; si < static_cast<std::int64_t>(super_dirty_.size()); ++si) {
    if (super_dirty_[si] != 0 || (!super_watched_.empty() && super_watched_[si] != 0)) tasks_.push_back(si);
  }
  const int workers = pool == nullptr ? 1 : pool->threads();
  if (static_cast<int>(scratch_.size()) < workers) scratch_.resize(static_cast<std::size_t>(workers));
  for (int k = 0; k < workers; ++k) {
    scratch_[k].misses.clear();
    scratch_[k].free_cells = 0;
    scratch_[k].reused = 0;
  }
  task_misses_.resize(tasks_.size());
  auto superblock = [&](std::size_t task, int worker) {
    Scratch& sc = scratch_[static_cast<std::size_t>(worker)];
    const std::size_t misses_before = sc.misses.size();
    const std::int64_t si = tasks_[task];
    auto see = [&](std::int64_t k) {
      __atomic_fetch_or(&seen_[static_cast<std::size_t>(k >> 6)], std::uint64_t{1} << (k & 63), __ATOMIC_RELAXED);
      ++sc.free_cells;
      sc.misses.push_back(static_cast<std::uint64_t>(k));  // (never a cell clamped free: the callers leave those)
    };
    std::int64_t s[3], sa[3], sb[3], bl[3], ba[3], bb[3];
    unravel(si, supers_, s);
    Footprint& f = sc.f;
    for (int i = 0; i < 3; ++i) {
      sa[i] = s[i] << kSuperShift;
      sb[i] = std::min(size_[i] - 1, ((s[i] + 1) << kSuperShift) - 1);
    }
    task_misses_[task] = {worker, misses_before, misses_before};
    // A block's cells that the last view saw free (bits), seen free again where still to be seen (not hit, nor seen
    // free already). Returns those bits less the cells clamped free by now: they stay clamped while the block is left
    // unevaluated (a cell that leaves clamp_min has it evaluated again).
    auto repeat = [&](std::uint64_t bits, std::int64_t bi) {
      ++sc.reused;
      const std::uint64_t still =
          bits & ~(block_clamped_[bi] & ~watchedBits(bi));  // watched: looked at, clamped or not
      const std::int64_t k0 = cellId(ba[0], ba[1], ba[2]);
      for (std::uint64_t todo = still & ~block_ended_[bi] & ~block_clamped_[bi]; todo != 0; todo &= todo - 1) {
        see(k0 + cell_offset_[__builtin_ctzll(todo)]);
      }
      if (recording_) batch_seen_[bi] |= still & ~block_ended_[bi];
      return still;
    };
    SuperRecord& sr = view->supers[static_cast<std::size_t>(si)];
    const Footprint& fs = cached(&sr, sa, sb);
    // The last view's record of each of its dirty blocks: a block's `seen` where its `at` is the superblock's base,
    // else none of its cells seen free (it was hidden then).
    const bool was_whole = last != 0 && sr.at == last;
    const std::uint64_t base = sr.base;
    sr.at = epoch_;
    if (hidden(fs)) {
      sr.base = epoch_;
      sr.seen = false;
      return;
    }
    // A superblock whose inputs did not change (as a block's below, over its own rectangle's tiles, which hold its
    // blocks'): each of its blocks as the last view saw it, without a test. Its records stay as they are: no cell in
    // it has left clamp_min since they were made (each view since was such a one), so no block turned dirty.
    if (was_whole && super_dirtied_[si] < last && super_end_hash_[si] == sr.end_hash && unchanged(fs)) {
      bool any = false;  // a block's record still holds a cell to see free
      for (bl[0] = sa[0] >> kBlockShift; bl[0] <= sb[0] >> kBlockShift; ++bl[0]) {
        for (bl[1] = sa[1] >> kBlockShift; bl[1] <= sb[1] >> kBlockShift; ++bl[1]) {
          for (bl[2] = sa[2] >> kBlockShift; bl[2] <= sb[2] >> kBlockShift; ++bl[2]) {
            const std::int64_t bi = blockIndex(bl[0], bl[1], bl[2]);
            if ((block_clamped_[bi] & ~watchedBits(bi)) == kAllCells) continue;
            if (!sr.seen) {  // no record holds a cell: counted only
              ++sc.reused;
              continue;
            }
            for (int i = 0; i < 3; ++i) ba[i] = bl[i] << kBlockShift;
            BlockRecord& br = view->blocks[static_cast<std::size_t>(bi)];
            const std::uint64_t bits = br.at == base ? br.seen : 0;
            const std::uint64_t still = repeat(bits, bi);
            if (still != bits) br.seen = still;
            any = any || still != 0;
          }
        }
      }
      sr.seen = any;
      task_misses_[task].end = sc.misses.size();
      return;
    }
    sr.base = epoch_;
    bool any = false;
    for (bl[0] = sa[0] >> kBlockShift; bl[0] <= sb[0] >> kBlockShift; ++bl[0]) {
      for (bl[1] = sa[1] >> kBlockShift; bl[1] <= sb[1] >> kBlockShift; ++bl[1]) {
        for (bl[2] = sa[2] >> kBlockShift; bl[2] <= sb[2] >> kBlockShift; ++bl[2]) {
          const std::int64_t bi = blockIndex(bl[0], bl[1], bl[2]);
          if ((block_clamped_[bi] & ~watchedBits(bi)) == kAllCells) continue;
          for (int i = 0; i < 3; ++i) {
            ba[i] = bl[i] << kBlockShift;
            bb[i] = std::min(size_[i] - 1, ((bl[i] + 1) << kBlockShift) - 1);
          }
          BlockRecord& br = view->blocks[static_cast<std::size_t>(bi)];
          const Footprint& fb = cached(&br, ba, bb);
          if (hidden(fb)) {
            br.seen = 0;
            br.at = epoch_;
            continue;
          }
          // Nothing the block's cells depend on changed since the last view, and no cell in it has left clamp_min
          // since (each cell not clamped free now was tested then): it sees free what that view saw, less the
          // cells clamped free since.
          if (was_whole && block_dirtied_[bi] < last && end_hash_[bi] == br.end_hash && unchanged(fb)) {
            br.seen = repeat(br.at == base ? br.seen : 0, bi);
            br.at = epoch_;
            any = any || br.seen != 0;
            continue;
          }
          std::uint64_t seen_bits = 0;
          // A block wholly in front of what every pixel that may see it saw (robot pixels aside): each of its
          // cells passes the rectangle test; a pixel crossing the cell and seeing past it is what is left.
          const bool in_front = fb.state == 0 && over(min_depth_, true, fb.u0, fb.u1, fb.v0, fb.v1) >= fb.zmax;
          // The block's first cell centre in the optical frame; the others one cell step (axis[]) apart.
          const Eigen::Vector3d c0 = rt * (centre(ba[0], ba[1], ba[2]) - tr);
          // Its cells' projections: the camera's, kept from its earlier views, or afresh (a camera's first view
          // keeps none: a camera that moves takes a new record at each pose and would never read them).
          CellProjection* proj = sc.cells;
          if (!view->cells.empty() && last != 0) {
            std::unique_ptr<CellProjection[]>& kept = view->cells[static_cast<std::size_t>(bi)];
            if (kept == nullptr) kept.reset(new CellProjection[kBlockCells]);  // each kNotYet
            proj = kept.get();
          } else {
            std::fill(proj, proj + kBlockCells, CellProjection());
          }
          // The cells neither clamped free nor hit nor seen free already (a block's words: no test per cell), each
          // at its offset from the block's first cell (its id, its centre in the optical frame, its projection).
          const std::int64_t k0 = cellId(ba[0], ba[1], ba[2]);
          // Watched cells clamped free are looked at too (hidden_space), but a miss would not change them.
          const std::uint64_t clamped = block_clamped_[bi];
          auto seen_cell = [&](std::int64_t k, int n) {
            if (((clamped >> n) & 1u) == 0) see(k);
            seen_bits |= std::uint64_t{1} << n;
          };
          for (std::uint64_t todo = ~((clamped & ~watchedBits(bi)) | block_ended_[bi]); todo != 0; todo &= todo - 1) {
            const int n = __builtin_ctzll(todo);
            const std::int64_t k = k0 + cell_offset_[n];
            const Eigen::Vector3d c = c0 + cell_step[n];
            CellProjection* q = proj + n;
            // Seen free: some pixel's ray passes through the cell and sees past all of it (a cell between the rays
            // of a sparse image is not seen), and every pixel whose ray may cross the cell (its rectangle),
            // robot pixels aside, sees past all of it too. Tests, cheapest first: the pixel nearest the
            // centre's projection, whose ray surely crosses the cell when it passes within the inscribed
            // sphere (most cells that get here lie behind a surface and stop there); the rectangle's depths
            // (pyramid); then, unless the first pixel settled it, each pixel of the rectangle (exact slabs).
            if (!(c.z() > half_depth)) continue;
            const double zmax = c.z() + half_depth;
            if (q->nearest == CellProjection::kNotYet) {
              const double inv_z = 1.0 / c.z();
              const double uf = camera.fx * c.x() * inv_z + camera.cx + 0.5;
              const double vf = camera.fy * c.y() * inv_z + camera.cy + 0.5;
              q->nearest = -1;
              if (uf >= 0.0 && uf < w && vf >= 0.0 && vf < h) {
                const int u = static_cast<int>(uf), v = static_cast<int>(vf);
                const Eigen::Vector3d ray(ray_x_[u], ray_y_[v], 1.0);
                q->nearest = 2 * (v * w + u) + (c.cross(ray).squaredNorm() < r2 * ray.squaredNorm() ? 1 : 0);
              }
            }
            bool crossed = false;  // a pixel's ray crosses the cell and sees past it
            if (q->nearest >= 0 && (q->nearest & 1) != 0) {
              // The pixel nearest the centre's projection surely crosses the cell (its ray passes within the
              // inscribed sphere): a surface it sees short of the far side settles the cell.
              const std::size_t p = static_cast<std::size_t>(q->nearest >> 1);
              if (past_depth[p] < zmax) continue;
              crossed = free_depth[p] >= zmax;
            }
            if (crossed && in_front) {
              seen_cell(k, n);
              continue;
            }
            if (q->u0 == CellProjection::kNotYet16) {
              cellFootprint(c, &f);
              if (f.state == 0) {
                q->u0 = static_cast<std::int16_t>(f.u0);
                q->u1 = static_cast<std::int16_t>(f.u1);
                q->v0 = static_cast<std::int16_t>(f.v0);
                q->v1 = static_cast<std::int16_t>(f.v1);
              } else {
                q->u0 = 1;
                q->u1 = 0;
              }
            }
            f.u0 = q->u0;
            f.u1 = q->u1;
            f.v0 = q->v0;
            f.v1 = q->v1;
            if (f.u0 > f.u1 || (!in_front && over(min_depth_, true, f.u0, f.u1, f.v0, f.v1) < zmax)) continue;
            if (!crossed) {
              // Another pixel of the rectangle whose ray crosses the cell (slabs along the cell's edges, in
              // the optical frame) and sees past it: beside the robot, whose pixels hide part of the cell.
              const Eigen::Vector3d s0 = c - 0.5 * (axis[0] + axis[1] + axis[2]);
              const double o[3] = {s0.dot(axis[0]), s0.dot(axis[1]), s0.dot(axis[2])}, e = res * res;
              for (int v = f.v0; v <= f.v1 && !crossed; ++v) {
                for (int u = f.u0; u <= f.u1 && !crossed; ++u) {
                  if (free_depth[static_cast<std::size_t>(v) * w + u] < zmax) continue;
                  const Eigen::Vector3d ray(ray_x_[u], ray_y_[v], 1.0);
                  double t0 = 0.0, t1 = std::numeric_limits<double>::infinity();
                  for (int i = 0; i < 3 && t0 <= t1; ++i) {
                    const double dd = ray.dot(axis[i]);  // the ray's rate along edge i, x res
                    if (std::fabs(dd) < 1e-15) {
                      // parallel: inside the slab by kInside of a cell, or not (one along a face only touches)
                      if (!(o[i] < -kInside * e && o[i] > -e + kInside * e)) t1 = -1.0;
                      continue;
                    }
                    double ta = o[i] / dd, tb = (o[i] + e) / dd;
                    if (ta > tb) std::swap(ta, tb);
                    t0 = std::max(t0, ta);
                    t1 = std::min(t1, tb);
                  }
                  crossed = t1 - t0 > kInside * res;  // through the cell, not touching an edge or corner
                }
              }
              if (!crossed) continue;
            }
            seen_cell(k, n);
          }
          br.seen = seen_bits;
          br.at = epoch_;
          if (recording_) batch_seen_[bi] |= seen_bits;
          any = any || seen_bits != 0;
        }
      }
    }
    sr.seen = any;
    task_misses_[task].end = sc.misses.size();
  };
  if (pool != nullptr) {
    pool->run(tasks_.size(), superblock);
  } else {
    for (std::size_t t = 0; t < tasks_.size(); ++t) superblock(t, 0);
  }
  std::size_t reused = 0;
  for (int k = 0; k < workers; ++k) {
    free_cells += scratch_[k].free_cells;
    reused += scratch_[k].reused;
  }
  for (const TaskMisses& t : task_misses_) {
    const std::vector<std::uint64_t>& m = scratch_[static_cast<std::size_t>(t.worker)].misses;
    out->misses.insert(out->misses.end(), m.begin() + static_cast<std::ptrdiff_t>(t.begin),
                       m.begin() + static_cast<std::ptrdiff_t>(t.end));
  }
  // This view, for the camera's next one.
  view->last = epoch_;
  view->free_depth.swap(free_depth);
  view->past_depth.swap(past_depth);
  auto keep = [](std::vector<std::uint64_t>* now, std::vector<std::int64_t>* now_listed, auto* records,
                 std::vector<std::int64_t>* kept_listed) {
    for (std::int64_t b : *kept_listed) (*records)[b].end_hash = 0;
    kept_listed->clear();
    for (std::int64_t b : *now_listed) {
      (*records)[b].end_hash = (*now)[b];
      if ((*now)[b] != 0) kept_listed->push_back(b);
      (*now)[b] = 0;
    }
    now_listed->clear();
  };
  for (std::int64_t b : end_blocks_) block_ended_[b] = 0;
  keep(&end_hash_, &end_blocks_, &view->blocks, &view->end_blocks);
  keep(&super_end_hash_, &end_supers_, &view->supers, &view->end_supers);
  out->stats.free_cells = free_cells;
  out->stats.reused_blocks = reused;
  out->stats.changed_cells = out->hits.size() + out->misses.size();
}

// As octomap's updateNode: a new node starts at log-odds 0, then the update is added and clamped.
float OccupancyMap::updated(float v, float update) const {
  const float base = std::isnan(v) ? 0.0f : v;
  return std::min(std::max(base + update, clamp_min_), clamp_max_);
}

void OccupancyMap::setValue(std::int64_t c, float v) {
  const bool was_dirty = !(value_[c] == clamp_min_), dirty = !(v == clamp_min_);  // NaN (unknown) is dirty
  value_[c] = v;
  if (dirty) {
    clearBit(&clamped_, c);
  } else {
    setBit(&clamped_, c);
  }
  const bool now = v >= threshold_;  // false for NaN (unknown)
  if (now == testBit(occupied_, c) && was_dirty == dirty) return;
  std::int64_t b, s;
  std::uint64_t bit;
  boxesOf(c, &b, &s, &bit);
  block_clamped_[b] = dirty ? block_clamped_[b] & ~bit : block_clamped_[b] | bit;
  if (dirty && !was_dirty) block_dirtied_[b] = super_dirtied_[s] = epoch_;
  super_dirty_[s] = static_cast<std::uint16_t>(super_dirty_[s] + dirty - was_dirty);
  if (now == testBit(occupied_, c)) return;
  if (!grown_mark_.empty() && grown_mark_[b] == 0) {
    grown_mark_[b] = 1;  // hidden_space: the cells watched around it change at the batch's close
    grown_blocks_.push_back(b);
  }
  if (now) {
    setBit(&occupied_, c);
    ++block_count_[b];
    ++super_count_[s];
  } else {
    clearBit(&occupied_, c);
    --block_count_[b];
    --super_count_[s];
  }
}

void OccupancyMap::addKnownFree(const std::vector<std::uint64_t>& keys, bool fixed, MapUpdate* out) {
  for (std::uint64_t key : keys) {
    const auto c = static_cast<std::int64_t>(key);
    if (c < 0 || c >= static_cast<std::int64_t>(value_.size()) || testBit(hit_, c)) continue;
    if (recording_) {  // vouched for as free by this view
      std::int64_t b, s;
      std::uint64_t bit;
      boxesOf(c, &b, &s, &bit);
      batch_seen_[b] |= bit;
    }
    if (fixed && !fixed_.empty()) out->fixed.push_back(key);
    const bool possibly_occupied = !testBit(observed_, c) || (!stale_.empty() && testBit(stale_, c));
    if (!possibly_occupied || testBit(seen_, c)) continue;
    setBit(&seen_, c);
    out->misses.push_back(key);  // prior + one miss: free
    ++out->stats.known_free;
    ++out->stats.changed_cells;
  }
}

void OccupancyMap::knownFreeCells(const Eigen::AlignedBox3d& box, bool fixed, std::vector<Eigen::Vector3d>* centers,
                                  std::vector<std::uint64_t>* keys) const {
  if (!hiddenSpaceActive()) {
    unobservedCells(box, centers, keys);
    return;
  }
  centers->clear();
  keys->clear();
  if (box.isEmpty()) return;
  const double r = options_.resolution;
  std::int64_t lo[3], hi[3];
  for (int i = 0; i < 3; ++i) {
    lo[i] = std::max<std::int64_t>(0, static_cast<std::int64_t>(std::ceil(box.min()[i] / r - 0.5)) - offset_[i]);
    hi[i] = std::min<std::int64_t>(size_[i] - 1,
                                   static_cast<std::int64_t>(std::floor(box.max()[i] / r - 0.5)) - offset_[i]);
    if (lo[i] > hi[i]) return;
  }
  for (std::int64_t i = lo[0]; i <= hi[0]; ++i) {
    for (std::int64_t j = lo[1]; j <= hi[1]; ++j) {
      for (std::int64_t k = lo[2]; k <= hi[2]; ++k) {
        const std::int64_t c = cellId(i, j, k);
        const bool observed = testBit(observed_, c), occupied = testBit(occupied_, c);
        bool take;
        if (!observed || testBit(stale_, c)) {
          take = true;  // never seen, or possibly occupied since last seen free
        } else if (occupied) {
          take = false;  // seen occupied: stays
        } else {
          take = fixed && !testBit(fixed_, c);  // free, to be free for good
        }
        if (!take) continue;
        centers->push_back(centre(i, j, k));
        keys->push_back(static_cast<std::uint64_t>(c));
      }
    }
  }
}

bool OccupancyMap::stale(const Eigen::Vector3d& p) const {
  const std::int64_t c = cellOf(p);
  return c >= 0 && !stale_.empty() && testBit(stale_, c);
}

void OccupancyMap::apply(const MapUpdate& update) {
  ++epoch_;  // cells it turns not clamped free are newer than every view so far
  revision_ = nextRevision();
  if (update.close) {
    applyClose(update);
    return;
  }
  const bool hold = options_.hidden_space;
  for (std::uint64_t key : update.fixed) {
    const auto c = static_cast<std::int64_t>(key);
    if (c >= 0 && c < static_cast<std::int64_t>(value_.size()) && !fixed_.empty()) setBit(&fixed_, c);
  }
  for (const auto* cells : {&update.hits, &update.misses}) {
    const bool hits = cells == &update.hits;
    for (std::uint64_t key : *cells) {
      const auto c = static_cast<std::int64_t>(key);
      if (c < 0 || c >= static_cast<std::int64_t>(value_.size())) continue;
      if (!hits && hold && testBit(occupied_, c)) {
        // hidden_space: a possibly-occupied cell seen free goes free at the batch's close (another view of the
        // instant may show what came), and never from a late view (it may have been entered since).
        if (!update.late) held_misses_.push_back(key);
        continue;
      }
      applyOne(c, hits);
    }
  }
}

void OccupancyMap::applyOne(std::int64_t c, bool hit) {
  const bool observed = testBit(observed_, c);
  const bool was = observed && value_[c] >= threshold_;
  const bool was_occupied = testBit(occupied_, c);
  // A stale cell seen free again is free as it was before it went stale (seen free then, often enough to be clamped):
  // staleness is what may have come, not what a camera saw.
  const bool restore = !hit && !stale_.empty() && testBit(stale_, c);
  setValue(c, restore ? clamp_min_ : updated(value_[c], hit ? log_hit_ : log_miss_));
  if (!observed) {
    setBit(&observed_, c);
    ++observed_cells_;
  }
  const bool now = value_[c] >= threshold_;
  if (now != was) countSeen(c, now ? 1 : -1);
  if (!stale_.empty()) {
    if (!observed || was_occupied != testBit(occupied_, c)) {
      refreshFree(c);
      if (was_occupied && !testBit(occupied_, c)) {  // possibly occupied until now: seen free at this batch
        std::int64_t b, s;
        std::uint64_t bit;
        boxesOf(c, &b, &s, &bit);
        turned_free_[b] |= bit;
      }
    }
    if (testBit(stale_, c)) {  // seen again: what the view says
      clearBit(&stale_, c);
      --stale_cells_;
    }
  }
}

void OccupancyMap::clear() {
  std::fill(observed_.begin(), observed_.end(), 0);
  observed_cells_ = 0;
  if (options_.hidden_space) {
    std::fill(stale_.begin(), stale_.end(), 0);
    std::fill(fixed_.begin(), fixed_.end(), 0);
    std::fill(batch_seen_.begin(), batch_seen_.end(), 0);
    std::fill(free_until_.begin(), free_until_.end(), std::numeric_limits<float>::quiet_NaN());
    stale_cells_ = 0;
    held_misses_.clear();
    batch_stamp_ = std::numeric_limits<double>::quiet_NaN();
    map_time_ = -std::numeric_limits<double>::infinity();
    std::fill(intervals_, intervals_ + kIntervals, options_.watch_time);
    if (watch_cells_ >= 0) watch_cells_ = cellsWithin(options_.watch_time);
    recording_ = false;
  }
  fillUnobserved(options_.unknown_occupied);
}

void OccupancyMap::countSeen(std::int64_t c, int delta) {
  std::int64_t b, s;
  boxesOf(c, &b, &s);
  seen_block_count_[b] = static_cast<std::uint8_t>(seen_block_count_[b] + delta);
  seen_super_count_[s] = static_cast<std::uint16_t>(seen_super_count_[s] + delta);
  seen_occupied_ += delta;
}

void OccupancyMap::setUnknownOccupied(bool on) {
  if (on == options_.unknown_occupied) return;
  options_.unknown_occupied = on;
  fillUnobserved(on);
}

void OccupancyMap::fillUnobserved(bool on) {
  ++epoch_;
  revision_ = nextRevision();
  for (auto& view : views_) view->last = 0;  // every cell may change: no view is up to date
  const float unknown = std::numeric_limits<float>::quiet_NaN();
  std::fill(occupied_.begin(), occupied_.end(), 0);
  std::fill(block_count_.begin(), block_count_.end(), 0);
  std::fill(super_count_.begin(), super_count_.end(), 0);
  std::fill(seen_block_count_.begin(), seen_block_count_.end(), 0);
  std::fill(seen_super_count_.begin(), seen_super_count_.end(), 0);
  seen_occupied_ = 0;
  // Every cell counts as dirty (unknown) until setValue says otherwise: each superblock as many as it holds, and no
  // cell of a block is clamped free (a block's bits past the grid's end are set: those cells never count).
  std::int64_t at[3], n[3];
  for (at[0] = 0; at[0] < supers_[0]; ++at[0]) {
    for (at[1] = 0; at[1] < supers_[1]; ++at[1]) {
      for (at[2] = 0; at[2] < supers_[2]; ++at[2]) {
        for (int i = 0; i < 3; ++i) n[i] = std::min(size_[i], (at[i] + 1) << kSuperShift) - (at[i] << kSuperShift);
        super_dirty_[superIndex(at[0], at[1], at[2])] = static_cast<std::uint16_t>(n[0] * n[1] * n[2]);
      }
    }
  }
  std::fill(block_clamped_.begin(), block_clamped_.end(), kAllCells);  // the blocks past the grid's end
  for (at[0] = 0; at[0] < blocks_[0]; ++at[0]) {
    for (at[1] = 0; at[1] < blocks_[1]; ++at[1]) {
      for (at[2] = 0; at[2] < blocks_[2]; ++at[2]) {
        for (int i = 0; i < 3; ++i) n[i] = std::min(size_[i], (at[i] + 1) << kBlockShift) - (at[i] << kBlockShift);
        std::uint64_t inside = 0;
        for (std::int64_t x = 0; x < n[0]; ++x) {
          for (std::int64_t y = 0; y < n[1]; ++y) {
            for (std::int64_t z = 0; z < n[2]; ++z)
              inside |= std::uint64_t{1} << (((x << kBlockShift | y) << kBlockShift) | z);
          }
        }
        block_clamped_[static_cast<std::size_t>(blockIndex(at[0], at[1], at[2]))] = ~inside;
      }
    }
  }
  const auto cells = static_cast<std::int64_t>(value_.size());
  if (!on && !stale_.empty()) {
    // Unknown space counts as free: what may have come into hidden space since it was seen free too (hidden space).
    for (std::int64_t c = 0; c < cells; ++c) {
      if (!testBit(stale_, c)) continue;
      value_[c] = clamp_min_;
      clearBit(&stale_, c);
    }
    stale_cells_ = 0;
  }
  for (std::int64_t c = 0; c < cells; ++c) {
    if (!testBit(observed_, c)) value_[c] = on ? prior_ : unknown;
    const float v = value_[c];
    value_[c] = unknown;  // setValue counts from an unoccupied, dirty cell
    setValue(c, v);
    if (testBit(observed_, c) && v >= threshold_) countSeen(c, 1);
  }
  if (options_.hidden_space) {
    // A free cell is an observed one (never a fresh map's): only those, word by word.
    std::fill(block_free_.begin(), block_free_.end(), 0);
    for (std::size_t w = 0; w < observed_.size(); ++w) {
      for (std::uint64_t bits = observed_[w] & ~occupied_[w]; bits != 0; bits &= bits - 1) {
        refreshFree(static_cast<std::int64_t>(w * 64 + static_cast<std::size_t>(__builtin_ctzll(bits))));
      }
    }
    updateWatched(true);
  }
}

void OccupancyMap::unobservedCells(const Eigen::AlignedBox3d& box, std::vector<Eigen::Vector3d>* centers,
                                   std::vector<std::uint64_t>* keys) const {
  centers->clear();
  keys->clear();
  if (!options_.unknown_occupied || box.isEmpty()) return;
  // Grid index ranges of the cells whose centre lies in the box.
  const double r = options_.resolution;
  std::int64_t lo[3], hi[3];
  for (int i = 0; i < 3; ++i) {
    lo[i] = std::max<std::int64_t>(0, static_cast<std::int64_t>(std::ceil(box.min()[i] / r - 0.5)) - offset_[i]);
    hi[i] = std::min<std::int64_t>(size_[i] - 1,
                                   static_cast<std::int64_t>(std::floor(box.max()[i] / r - 0.5)) - offset_[i]);
    if (lo[i] > hi[i]) return;
  }
  // Each row of cells along z a word of observed_ at a time: a robot's boxes are mostly observed (every cloud asks).
  for (std::int64_t i = lo[0]; i <= hi[0]; ++i) {
    for (std::int64_t j = lo[1]; j <= hi[1]; ++j) {
      const std::int64_t row = cellId(i, j, 0), first = row + lo[2], last = row + hi[2];
      for (std::int64_t word = first >> 6; word <= last >> 6; ++word) {
        std::uint64_t unseen = ~observed_[static_cast<std::size_t>(word)];
        if (word == first >> 6) unseen &= ~std::uint64_t{0} << (first & 63);
        if (word == last >> 6) unseen &= ~std::uint64_t{0} >> (63 - (last & 63));
        for (; unseen != 0; unseen &= unseen - 1) {
          const std::int64_t c = (word << 6) + __builtin_ctzll(unseen);
          centers->push_back(centre(i, j, c - row));
          keys->push_back(static_cast<std::uint64_t>(c));
        }
      }
    }
  }
}

std::size_t OccupancyMap::unobservedCount() const {
  if (!options_.unknown_occupied) return 0;
  return value_.size() - observed_cells_;
}

bool OccupancyMap::occupied(const Eigen::Vector3d& p) const {
  const std::int64_t c = cellOf(p);
  return c >= 0 && testBit(occupied_, c);
}

bool OccupancyMap::observed(const Eigen::Vector3d& p) const {
  const std::int64_t c = cellOf(p);
  return c >= 0 && testBit(observed_, c);
}

float OccupancyMap::logOdds(const Eigen::Vector3d& p) const {
  const std::int64_t c = cellOf(p);
  return c >= 0 ? value_[c] : std::numeric_limits<float>::quiet_NaN();
}

void OccupancyMap::occupiedLeaves(std::vector<Eigen::Vector3d>* centers, std::vector<double>* sizes) const {
  centers->clear();
  if (sizes != nullptr) sizes->clear();
  for (std::size_t w = 0; w < occupied_.size(); ++w) {
    std::uint64_t bits = occupied_[w] & observed_[w];  // seen occupied: not the unknown_occupied prior
    while (bits != 0) {
      const auto c = static_cast<std::int64_t>(w * 64 + static_cast<std::size_t>(__builtin_ctzll(bits)));
      bits &= bits - 1;
      centers->push_back(cellCentre(static_cast<std::uint64_t>(c)));
      if (sizes != nullptr) sizes->push_back(options_.resolution);
    }
  }
}

std::size_t OccupancyMap::occupiedLeafCount() const { return static_cast<std::size_t>(seen_occupied_); }

bool OccupancyMap::anyOccupied(const Eigen::AlignedBox3d& region, const BoxTest& meets, CellClass which) const {
  // A box of occupied cells that the shape meets: one of them meets it.
  return visitOccupied(region, meets, [](const Eigen::AlignedBox3d&) { return true; }, which);
}

bool OccupancyMap::visitOccupied(const Eigen::AlignedBox3d& region, const BoxTest& near, const BoxTest& visit,
                                 CellClass which, bool whole_blocks, const ExcludeTest* exclude) const {
  std::int64_t lo[3], hi[3];
  for (int i = 0; i < 3; ++i) {
    lo[i] = std::max<std::int64_t>(0, indexOf(region.min()[i], i));
    hi[i] = std::min<std::int64_t>(size_[i] - 1, indexOf(region.max()[i], i));
    if (lo[i] > hi[i]) return false;
  }
  const double r = options_.resolution;
  // The box of grid cells [a, b] (inclusive) per axis.
  auto box = [&](const std::int64_t* a, const std::int64_t* b) {
    return Eigen::AlignedBox3d(
        Eigen::Vector3d((a[0] + offset_[0]) * r, (a[1] + offset_[1]) * r, (a[2] + offset_[2]) * r),
        Eigen::Vector3d((b[0] + offset_[0] + 1) * r, (b[1] + offset_[1] + 1) * r, (b[2] + offset_[2] + 1) * r));
  };
  // The cells [a, b] of a (super)block at index (bi, bj, bk) with edge 2^shift, clipped to the grid.
  auto span = [&](const std::int64_t* at, int shift, std::int64_t* a, std::int64_t* b) {
    std::int64_t n = 1;
    for (int i = 0; i < 3; ++i) {
      a[i] = at[i] << shift;
      b[i] = std::min(size_[i] - 1, ((at[i] + 1) << shift) - 1);
      n *= b[i] - a[i] + 1;
    }
    return n;
  };
  // Occupied cells of the class asked for: in a (super)block, and one by one.
  auto super_count = [&](std::int64_t x) -> std::int64_t {
    switch (which) {
      case CellClass::kSeen:
        return seen_super_count_[x];
      case CellClass::kUnseen:
        return super_count_[x] - seen_super_count_[x];
      default:
        return super_count_[x];
    }
  };
  auto block_count = [&](std::int64_t x) -> std::int64_t {
    switch (which) {
      case CellClass::kSeen:
        return seen_block_count_[x];
      case CellClass::kUnseen:
        return block_count_[x] - seen_block_count_[x];
      default:
        return block_count_[x];
    }
  };
  auto cell_counts = [&](std::int64_t c) {
    if (!testBit(occupied_, c)) return false;
    switch (which) {
      case CellClass::kSeen:
        return testBit(observed_, c);
      case CellClass::kUnseen:
        return !testBit(observed_, c);
      default:
        return true;
    }
  };
  std::int64_t s[3], sa[3], sb[3], bl[3], ba[3], bb[3];
  for (s[0] = lo[0] >> kSuperShift; s[0] <= hi[0] >> kSuperShift; ++s[0]) {
    for (s[1] = lo[1] >> kSuperShift; s[1] <= hi[1] >> kSuperShift; ++s[1]) {
      for (s[2] = lo[2] >> kSuperShift; s[2] <= hi[2] >> kSuperShift; ++s[2]) {
        const std::int64_t sc = super_count(superIndex(s[0], s[1], s[2]));
        if (sc == 0) continue;
        const std::int64_t cells = span(s, kSuperShift, sa, sb);
        const Eigen::AlignedBox3d super_box = box(sa, sb);
        const Excluded super_out = exclude != nullptr ? (*exclude)(super_box) : Excluded::kNone;
        if (super_out == Excluded::kWholly || !near(super_box)) continue;
        if (sc == cells && super_out == Excluded::kNone) {  // full
          if (visit(super_box)) return true;
          continue;
        }
        for (bl[0] = std::max(lo[0], sa[0]) >> kBlockShift; bl[0] <= std::min(hi[0], sb[0]) >> kBlockShift; ++bl[0]) {
          for (bl[1] = std::max(lo[1], sa[1]) >> kBlockShift; bl[1] <= std::min(hi[1], sb[1]) >> kBlockShift; ++bl[1]) {
            for (bl[2] = std::max(lo[2], sa[2]) >> kBlockShift; bl[2] <= std::min(hi[2], sb[2]) >> kBlockShift;
                 ++bl[2]) {
              const std::int64_t bc = block_count(blockIndex(bl[0], bl[1], bl[2]));
              if (bc == 0) continue;
              const std::int64_t bcells = span(bl, kBlockShift, ba, bb);
              const Eigen::AlignedBox3d block_box = box(ba, bb);
              const Excluded block_out = exclude != nullptr ? (*exclude)(block_box) : Excluded::kNone;
              if (block_out == Excluded::kWholly || !near(block_box)) continue;
              if ((bc == bcells && block_out == Excluded::kNone) || whole_blocks) {  // full, or not to be looked into
                if (visit(block_box)) return true;
                continue;
              }
              for (std::int64_t i = std::max(lo[0], ba[0]); i <= std::min(hi[0], bb[0]); ++i) {
                for (std::int64_t j = std::max(lo[1], ba[1]); j <= std::min(hi[1], bb[1]); ++j) {
                  for (std::int64_t k = std::max(lo[2], ba[2]); k <= std::min(hi[2], bb[2]); ++k) {
                    if (!cell_counts(cellId(i, j, k))) continue;
                    const std::int64_t c[3] = {i, j, k};
                    const Eigen::AlignedBox3d cell_box = box(c, c);
                    if (block_out != Excluded::kNone && (*exclude)(cell_box) == Excluded::kWholly) continue;
                    if (near(cell_box) && visit(cell_box)) return true;
                  }
                }
              }
            }
          }
        }
      }
    }
  }
  return false;
}

}  // namespace moverl_planning_scene
