#include "moverl_planning_scene/occupancy_map.h"

#include <octomap/OcTree.h>

#include <cmath>
#include <unordered_set>

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

void OccupancyMap::computeUpdate(const std::vector<Eigen::Vector3d>& points, const std::vector<std::uint8_t>& robot_mask,
                                 const Eigen::Vector3d& origin, MapUpdate* out) const {
  out->hits.clear();
  out->misses.clear();
  out->stats = MapUpdateStats();
  out->stats.points = points.size();
  std::unordered_set<std::uint64_t> hits, misses;
  octomap::KeyRay ray;
  const octomap::point3d o = toOcto(origin);
  const bool masked = robot_mask.size() == points.size();
  for (std::size_t k = 0; k < points.size(); ++k) {
    const Eigen::Vector3d& p = points[k];
    if (!p.allFinite()) {
      ++out->stats.invalid;
      continue;
    }
    const Eigen::Vector3d d = p - origin;
    const double range = d.norm();
    const bool robot = masked && robot_mask[k] != 0;
    Eigen::Vector3d end = p;
    bool hit = !robot;
    if (range > options_.max_range) {
      end = origin + d * (options_.max_range / range);
      hit = false;
      ++out->stats.beyond_range;
    } else if (robot) {
      ++out->stats.robot;
    }
    // computeRayKeys: the cells from the origin's up to, excluding, the end point's cell.
    if (tree_->computeRayKeys(o, toOcto(end), ray)) {
      for (const octomap::OcTreeKey& key : ray) misses.insert(pack(key));
    }
    if (hit) {
      octomap::OcTreeKey key;
      if (tree_->coordToKeyChecked(toOcto(end), key)) hits.insert(pack(key));
    }
  }
  out->hits.assign(hits.begin(), hits.end());
  out->misses.reserve(misses.size());
  for (std::uint64_t m : misses) {
    if (hits.count(m) == 0) out->misses.push_back(m);
  }
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
