#include "moverl_planning_scene/occupancy_map.h"

#include <octomap/OcTree.h>

#include <algorithm>
#include <cmath>
#include <iterator>
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
  std::unique_ptr<OccupancyMap> m(new OccupancyMap());
  m->options_ = o;
  m->tree_ = std::make_shared<octomap::OcTree>(o.resolution);
  m->tree_->setProbHit(o.prob_hit);
  m->tree_->setProbMiss(o.prob_miss);
  m->tree_->setClampingThresMin(o.clamp_min);
  m->tree_->setClampingThresMax(o.clamp_max);
  m->tree_->setOccupancyThres(o.occupancy_threshold);
  return m;
}

OccupancyMap::~OccupancyMap() = default;

namespace {

/// Clips the segment a -> b to the box: the parameters [*t0, *t1] of the part inside. False when it misses the box.
bool clipToBox(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::AlignedBox3d& box, double* t0,
               double* t1) {
  *t0 = 0.0;
  *t1 = 1.0;
  if (box.isEmpty()) return true;  // unbounded map
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

constexpr std::uint8_t kHit = 1, kRobot = 2;

}  // namespace

void OccupancyMap::computeUpdate(const std::vector<Eigen::Vector3d>& points,
                                 const std::vector<std::uint8_t>& robot_mask, const Eigen::Vector3d& origin,
                                 MapUpdate* out) const {
  out->hits.clear();
  out->misses.clear();
  out->stats = MapUpdateStats();
  out->stats.points = points.size();
  const bool masked = robot_mask.size() == points.size();
  // 1. End points (beyond max_range: cut there, free space only), grouped by cell as octomap's discretized
  //    insertion does: one beam per end cell. A cell with any robot point marks nothing.
  std::unordered_map<std::uint64_t, std::uint8_t> ends;
  ends.reserve(points.size());
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
    } else if (masked && robot_mask[k] != 0) {
      flag = kRobot;
      ++out->stats.robot;
    }
    octomap::OcTreeKey key;
    if (!tree_->coordToKeyChecked(toOcto(end), key)) continue;
    ends[pack(key)] |= flag;
  }
  // 2. Beams from the origin to each end cell's centre, clipped to the map bounds.
  std::vector<std::uint64_t> misses;
  octomap::KeyRay ray;
  for (const auto& e : ends) {
    const octomap::point3d c = tree_->keyToCoord(unpack(e.first));
    const Eigen::Vector3d end(c.x(), c.y(), c.z());
    double t0, t1;
    if (!clipToBox(origin, end, options_.bounds, &t0, &t1)) continue;
    const Eigen::Vector3d a = origin + t0 * (end - origin), b = origin + t1 * (end - origin);
    // computeRayKeys: the cells from a's up to, excluding, b's cell.
    if (tree_->computeRayKeys(toOcto(a), toOcto(b), ray)) {
      for (const octomap::OcTreeKey& key : ray) misses.push_back(pack(key));
    }
    if (e.second == kHit && t1 >= 1.0) out->hits.push_back(e.first);
  }
  std::sort(out->hits.begin(), out->hits.end());
  std::sort(misses.begin(), misses.end());
  misses.erase(std::unique(misses.begin(), misses.end()), misses.end());
  // Occupied wins: a cell hit by one beam stays occupied even when others cross it.
  std::set_difference(misses.begin(), misses.end(), out->hits.begin(), out->hits.end(),
                      std::back_inserter(out->misses));
  out->stats.hit_cells = out->hits.size();
  out->stats.free_cells = out->misses.size();
}

void OccupancyMap::apply(const MapUpdate& update) {
  for (std::uint64_t h : update.hits) tree_->updateNode(unpack(h), true, /*lazy_eval=*/true);
  for (std::uint64_t m : update.misses) tree_->updateNode(unpack(m), false, /*lazy_eval=*/true);
  tree_->updateInnerOccupancy();  // inner nodes hold their children's maximum (FCL prunes free subtrees by it)
}

void OccupancyMap::clear() { tree_->clear(); }

std::shared_ptr<const octomap::OcTree> OccupancyMap::tree() const { return tree_; }

bool OccupancyMap::occupied(const Eigen::Vector3d& p) const {
  const octomap::OcTreeNode* n = tree_->search(toOcto(p));
  return n != nullptr && tree_->isNodeOccupied(n);
}

void OccupancyMap::occupiedLeaves(std::vector<Eigen::Vector3d>* centers, std::vector<double>* sizes) const {
  centers->clear();
  if (sizes != nullptr) sizes->clear();
  for (auto it = tree_->begin_leafs(), end = tree_->end_leafs(); it != end; ++it) {
    if (!tree_->isNodeOccupied(*it)) continue;
    centers->emplace_back(it.getX(), it.getY(), it.getZ());
    if (sizes != nullptr) sizes->push_back(it.getSize());
  }
}

std::size_t OccupancyMap::occupiedLeafCount() const {
  std::size_t n = 0;
  for (auto it = tree_->begin_leafs(), end = tree_->end_leafs(); it != end; ++it) {
    if (tree_->isNodeOccupied(*it)) ++n;
  }
  return n;
}

}  // namespace moverl_planning_scene
