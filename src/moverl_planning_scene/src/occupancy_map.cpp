#include "moverl_planning_scene/occupancy_map.h"

#include <octomap/OcTree.h>

#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>
#include <unordered_map>

namespace moverl_planning_scene {
namespace {

// octomap keys are three 16-bit indices: pack them into one integer for hashing and sorting.
std::uint64_t pack(const octomap::OcTreeKey& k) {
  return (static_cast<std::uint64_t>(k[0]) << 32) | (static_cast<std::uint64_t>(k[1]) << 16) | k[2];
}

octomap::OcTreeKey unpack(std::uint64_t v) {
  return octomap::OcTreeKey(static_cast<octomap::key_type>(v >> 32), static_cast<octomap::key_type>(v >> 16),
                            static_cast<octomap::key_type>(v));
}

octomap::point3d toOcto(const Eigen::Vector3d& p) {
  return octomap::point3d(static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z()));
}

bool probability(double p) { return std::isfinite(p) && p > 0.0 && p < 1.0; }

/// The dense grid's largest size (cells): 8 bytes each.
constexpr std::int64_t kMaxCells = 64 * 1024 * 1024;

}  // namespace

std::unique_ptr<OccupancyMap> OccupancyMap::create(const OccupancyMapOptions& o, std::string* error) {
  auto bad = [&](const std::string& why) {
    if (error != nullptr) *error = "octomap: " + why;
    return nullptr;
  };
  if (!std::isfinite(o.resolution) || o.resolution <= 0.0) return bad("resolution must be > 0");
  if (!std::isfinite(o.max_range) || o.max_range <= 0.0) return bad("max_range must be > 0");
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
  std::unique_ptr<OccupancyMap> m(new OccupancyMap());
  m->options_ = o;
  m->tree_ = std::make_shared<octomap::OcTree>(o.resolution);
  m->tree_->setProbHit(o.prob_hit);
  m->tree_->setProbMiss(o.prob_miss);
  m->tree_->setClampingThresMin(o.clamp_min);
  m->tree_->setClampingThresMax(o.clamp_max);
  m->tree_->setOccupancyThres(o.occupancy_threshold);
  if (o.bounds.isEmpty() || !o.bounds.min().allFinite() || !o.bounds.max().allFinite()) {
    return bad("bounds (the mapped box) must be set");
  }
  octomap::OcTreeKey lo, hi;
  if (!m->tree_->coordToKeyChecked(toOcto(o.bounds.min()), lo) ||
      !m->tree_->coordToKeyChecked(toOcto(o.bounds.max()), hi)) {
    return bad("bounds lie beyond the octree's extent at this resolution");
  }
  std::int64_t cells = 1;
  for (int i = 0; i < 3; ++i) {
    m->key_min_[i] = lo[i];
    m->size_[i] = static_cast<std::int64_t>(hi[i]) - lo[i] + 1;
    cells *= m->size_[i];
  }
  if (cells > kMaxCells) {
    return bad("bounds hold " + std::to_string(cells) + " cells at this resolution (at most " +
               std::to_string(kMaxCells) + ")");
  }
  m->value_.assign(static_cast<std::size_t>(cells), std::numeric_limits<float>::quiet_NaN());
  m->seen_.assign(static_cast<std::size_t>((cells + 63) / 64), 0);
  m->hit_.assign(m->seen_.size(), 0);
  m->threshold_ = m->tree_->getOccupancyThresLog();
  m->log_hit_ = m->tree_->getProbHitLog();
  m->log_miss_ = m->tree_->getProbMissLog();
  m->clamp_min_ = m->tree_->getClampingThresMinLog();
  m->clamp_max_ = m->tree_->getClampingThresMaxLog();
  // Unobserved under unknown_occupied: half a miss above the threshold, so one miss turns the cell free and one hit
  // keeps it occupied (octomap's isNodeOccupied: log-odds >= the threshold's).
  m->prior_ = m->tree_->getOccupancyThresLog() - 0.5f * m->log_miss_;
  if (!(m->prior_ < m->clamp_max_))
    return bad("occupancy_threshold too close to clamp_max for unknown_occupied's prior");
  m->observed_.assign(m->seen_.size(), 0);
  m->options_.unknown_occupied = false;
  m->setUnknownOccupied(o.unknown_occupied);
  return m;
}

OccupancyMap::~OccupancyMap() = default;

namespace {

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

constexpr std::uint8_t kHit = 1, kRobot = 2, kFixture = 4;

bool testBit(const std::vector<std::uint64_t>& bits, std::int64_t k) { return ((bits[k >> 6] >> (k & 63)) & 1u) != 0; }
void setBit(std::vector<std::uint64_t>* bits, std::int64_t k) { (*bits)[k >> 6] |= std::uint64_t{1} << (k & 63); }
/// apply: beyond this many changed cells, update lazily and fix the inner nodes once.
constexpr std::size_t kLazyAbove = 20000;
/// octomap's key of coordinate x is floor(x / resolution) + this (its tree_max_val for 16 levels).
constexpr std::int64_t kKeyOffset = 32768;

}  // namespace

void OccupancyMap::computeUpdate(const std::vector<Eigen::Vector3d>& points,
                                 const std::vector<std::uint8_t>& robot_mask, const Eigen::Vector3d& origin,
                                 MapUpdate* out) {
  out->hits.clear();
  out->misses.clear();
  out->stats = MapUpdateStats();
  out->stats.points = points.size();
  const bool masked = robot_mask.size() == points.size();
  // 1. End points (beyond max_range: cut there, free space only), grouped by cell as octomap's discretized
  //    insertion does: one beam per end cell. A cell with any robot point marks nothing.
  // ends: each end cell's flags; order: the end cells in the order of their first point (neighbouring pixels cast
  // neighbouring beams one after another, which keeps the grid's cells in cache).
  std::unordered_map<std::uint64_t, std::uint8_t> ends;
  std::vector<std::uint64_t> order;
  ends.reserve(points.size());
  order.reserve(points.size());
  for (std::size_t k = 0; k < points.size(); ++k) {
    const Eigen::Vector3d& p = points[k];
    if (!p.allFinite()) {
      ++out->stats.invalid;
      continue;
    }
    const Eigen::Vector3d d = p - origin;
    const double range = d.norm();
    Eigen::Vector3d end = p;
    std::uint8_t flag = kHit;
    if (range > options_.max_range) {
      end = origin + d * (options_.max_range / range);
      flag = 0;
      ++out->stats.beyond_range;
    } else if (masked && robot_mask[k] == kPointOnFixture) {
      flag = kFixture;
      ++out->stats.fixture;
    } else if (masked && robot_mask[k] != kPointObstacle) {
      flag = kRobot;
      ++out->stats.robot;
    }
    octomap::OcTreeKey key;
    if (!tree_->coordToKeyChecked(toOcto(end), key)) continue;
    const auto slot = ends.emplace(pack(key), 0);
    if (slot.second) order.push_back(pack(key));
    slot.first->second |= flag;
  }
  // 2. This cloud's marks: a bit per cell for "seen free" and one for "hit" (small enough to stay in cache).
  std::fill(seen_.begin(), seen_.end(), 0);
  std::fill(hit_.begin(), hit_.end(), 0);
  const auto& test = testBit;
  const auto& set = setBit;
  // Hits first (occupied wins: a cell hit by one beam stays occupied even when others cross it); only ends inside
  // the bounds mark anything. A cell that holds an obstacle point is hit even when robot or fixture points end in it
  // too: something else is there (a hand next to a link).
  std::size_t hit_cells = 0;
  for (std::uint64_t packed : order) {
    if ((ends[packed] & kHit) == 0) continue;
    const std::int64_t c = cell(packed);
    if (c < 0) continue;
    set(&hit_, c);
    ++hit_cells;
    if (updated(value_[c], log_hit_) != value_[c]) out->hits.push_back(packed);
  }
  // 3. Beams from the origin to each end cell's centre, clipped to the map bounds: the cells from the first one up
  //    to, excluding, the end cell (as octomap's computeRayKeys), each counted once per cloud. A 3D DDA over the
  //    grid's indices (Amanatides & Woo). A cell where only fixture points end was seen down to the fixture's surface
  //    (anything above it would have stopped a beam): the end cell counts as seen free too. A robot's end cell marks
  //    nothing: what was seen there stays (a hand that was seen keeps its cells when it comes within the filter).
  std::size_t free_cells = 0;
  const double inv = 1.0 / options_.resolution;
  const std::int64_t stride[3] = {size_[1] * size_[2], size_[2], 1};
  for (std::uint64_t packed_end : order) {
    const octomap::point3d c = tree_->keyToCoord(unpack(packed_end));
    const Eigen::Vector3d end(c.x(), c.y(), c.z());
    double t0, t1;
    if (!clipToBox(origin, end, options_.bounds, &t0, &t1)) continue;
    const Eigen::Vector3d a = origin + t0 * (end - origin), b = origin + t1 * (end - origin), d = b - a;
    std::int64_t at[3], last[3], step[3];
    double t_max[3], t_delta[3];
    bool inside = true;
    for (int i = 0; i < 3; ++i) {
      // The grid index of a coordinate, as octomap's coordToKey computes keys.
      const double fa = std::floor(a[i] * inv), fb = std::floor(b[i] * inv);
      at[i] = static_cast<std::int64_t>(fa) + kKeyOffset - key_min_[i];
      last[i] = static_cast<std::int64_t>(fb) + kKeyOffset - key_min_[i];
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
    std::int64_t k = (at[0] * size_[1] + at[1]) * size_[2] + at[2];
    const bool through_end = ends[packed_end] == kFixture;
    while (at[0] != last[0] || at[1] != last[1] || at[2] != last[2] || through_end) {
      if (!test(seen_, k) && !test(hit_, k)) {
        set(&seen_, k);
        ++free_cells;
        // A free cell already clamped at clamp_min does not change: the tree is not touched.
        if (updated(value_[k], log_miss_) != value_[k]) out->misses.push_back(packAt(at));
      }
      if (at[0] == last[0] && at[1] == last[1] && at[2] == last[2]) break;  // a fixture's end cell, done
      const int axis = t_max[0] < t_max[1] ? (t_max[0] < t_max[2] ? 0 : 2) : (t_max[1] < t_max[2] ? 1 : 2);
      if (t_max[axis] > 1.0) break;  // rounding: b's cell was not reached exactly
      at[axis] += step[axis];
      if (at[axis] < 0 || at[axis] >= size_[axis]) break;
      k += step[axis] * stride[axis];
      t_max[axis] += t_delta[axis];
    }
  }
  out->stats.hit_cells = hit_cells;
  out->stats.free_cells = free_cells;
  out->stats.changed_cells = out->hits.size() + out->misses.size();
}

std::uint64_t OccupancyMap::packAt(const std::int64_t* at) const {
  return (static_cast<std::uint64_t>(at[0] + key_min_[0]) << 32) |
         (static_cast<std::uint64_t>(at[1] + key_min_[1]) << 16) | static_cast<std::uint64_t>(at[2] + key_min_[2]);
}

std::int64_t OccupancyMap::cell(std::uint64_t packed) const {
  const std::int64_t i = static_cast<std::int64_t>((packed >> 32) & 0xffff) - key_min_[0];
  const std::int64_t j = static_cast<std::int64_t>((packed >> 16) & 0xffff) - key_min_[1];
  const std::int64_t k = static_cast<std::int64_t>(packed & 0xffff) - key_min_[2];
  if (i < 0 || j < 0 || k < 0 || i >= size_[0] || j >= size_[1] || k >= size_[2]) return -1;
  return (i * size_[1] + j) * size_[2] + k;
}

// As octomap's updateNode: a new node starts at log-odds 0, then the update is added and clamped.
float OccupancyMap::updated(float v, float update) const {
  const float base = std::isnan(v) ? 0.0f : v;
  return std::min(std::max(base + update, clamp_min_), clamp_max_);
}

void OccupancyMap::addKnownFree(const std::vector<std::uint64_t>& keys, MapUpdate* out) {
  for (std::uint64_t packed : keys) {
    const std::int64_t c = cell(packed);
    if (c < 0 || testBit(observed_, c) || testBit(hit_, c) || testBit(seen_, c)) continue;
    setBit(&seen_, c);
    out->misses.push_back(packed);  // prior + one miss: free
    ++out->stats.known_free;
    ++out->stats.changed_cells;
  }
}

void OccupancyMap::apply(const MapUpdate& update) {
  // Few changes (the usual cloud once the scene is known): each update fixes its parents on the way (and prunes).
  // Many (the first views): lazy updates, then one pass over the inner nodes.
  const bool lazy = update.hits.size() + update.misses.size() > kLazyAbove;
  for (const auto* keys : {&update.hits, &update.misses}) {
    const float u = keys == &update.hits ? log_hit_ : log_miss_;
    for (std::uint64_t packed : *keys) {
      const std::int64_t c = cell(packed);
      if (c < 0) continue;
      const bool was = seenOccupiedValue(value_[c], testBit(observed_, c));
      value_[c] = updated(value_[c], u);
      setBit(&observed_, c);
      seen_occupied_ += static_cast<std::int64_t>(value_[c] >= threshold_) - static_cast<std::int64_t>(was);
      tree_->setNodeValue(unpack(packed), value_[c], lazy);
    }
  }
  if (lazy) tree_->updateInnerOccupancy();  // inner nodes hold their children's maximum (FCL prunes free subtrees)
}

void OccupancyMap::clear() {
  tree_->clear();
  seen_occupied_ = 0;
  std::fill(value_.begin(), value_.end(), std::numeric_limits<float>::quiet_NaN());
  std::fill(observed_.begin(), observed_.end(), 0);
  if (options_.unknown_occupied) fillUnobserved(true);
}

void OccupancyMap::setUnknownOccupied(bool on) {
  if (on == options_.unknown_occupied) return;
  options_.unknown_occupied = on;
  fillUnobserved(on);
}

void OccupancyMap::fillUnobserved(bool on) {
  // The tree is rebuilt from the grid (deleting single leaves of pruned nodes trips octomap's node assertions).
  const float unknown = std::numeric_limits<float>::quiet_NaN();
  tree_->clear();
  std::int64_t at[3];
  std::int64_t k = 0;
  for (at[0] = 0; at[0] < size_[0]; ++at[0]) {
    for (at[1] = 0; at[1] < size_[1]; ++at[1]) {
      for (at[2] = 0; at[2] < size_[2]; ++at[2], ++k) {
        if (!testBit(observed_, k)) value_[k] = on ? prior_ : unknown;
        if (!std::isnan(value_[k])) tree_->setNodeValue(unpack(packAt(at)), value_[k], /*lazy_eval=*/true);
      }
    }
  }
  tree_->updateInnerOccupancy();
  tree_->prune();  // blocks of equal cells (the prior, space clamped free) collapse into larger leaves
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
    lo[i] = std::max<std::int64_t>(
        0, static_cast<std::int64_t>(std::ceil(box.min()[i] / r - 0.5)) + kKeyOffset - key_min_[i]);
    hi[i] = std::min<std::int64_t>(
        size_[i] - 1, static_cast<std::int64_t>(std::floor(box.max()[i] / r - 0.5)) + kKeyOffset - key_min_[i]);
    if (lo[i] > hi[i]) return;
  }
  std::int64_t at[3];
  for (at[0] = lo[0]; at[0] <= hi[0]; ++at[0]) {
    for (at[1] = lo[1]; at[1] <= hi[1]; ++at[1]) {
      for (at[2] = lo[2]; at[2] <= hi[2]; ++at[2]) {
        const std::int64_t k = (at[0] * size_[1] + at[1]) * size_[2] + at[2];
        if (testBit(observed_, k)) continue;
        const std::uint64_t packed = packAt(at);
        const octomap::point3d c = tree_->keyToCoord(unpack(packed));
        centers->emplace_back(c.x(), c.y(), c.z());
        keys->push_back(packed);
      }
    }
  }
}

std::size_t OccupancyMap::unobservedCount() const {
  if (!options_.unknown_occupied) return 0;
  std::size_t seen = 0;
  for (std::uint64_t w : observed_) seen += static_cast<std::size_t>(__builtin_popcountll(w));
  return value_.size() - seen;
}

std::shared_ptr<const octomap::OcTree> OccupancyMap::tree() const { return tree_; }

bool OccupancyMap::occupied(const Eigen::Vector3d& p) const {
  const octomap::OcTreeNode* n = tree_->search(toOcto(p));
  return n != nullptr && tree_->isNodeOccupied(n);
}

// Unobserved cells hold exactly the prior (pruned blocks of them too); an observed cell's log-odds is the prior or 0
// plus hits and misses, clamped, never the prior itself in practice.
bool OccupancyMap::seenOccupied(const octomap::OcTreeNode& node) const {
  return tree_->isNodeOccupied(node) && !(options_.unknown_occupied && node.getLogOdds() == prior_);
}

void OccupancyMap::occupiedLeaves(std::vector<Eigen::Vector3d>* centers, std::vector<double>* sizes) const {
  centers->clear();
  if (sizes != nullptr) sizes->clear();
  for (auto it = tree_->begin_leafs(), end = tree_->end_leafs(); it != end; ++it) {
    if (!seenOccupied(*it)) continue;
    centers->emplace_back(it.getX(), it.getY(), it.getZ());
    if (sizes != nullptr) sizes->push_back(it.getSize());
  }
}

std::size_t OccupancyMap::occupiedLeafCount() const { return static_cast<std::size_t>(seen_occupied_); }

}  // namespace moverl_planning_scene
