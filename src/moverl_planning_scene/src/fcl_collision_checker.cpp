/**
 * \file fcl_collision_checker.cpp
 * \brief FclCollisionChecker: creation, state and path checks, the sensed map, point masks (the rest: see
 *        fcl_checker_internal.h).
 */
#include "moverl_planning_scene/fcl_collision_checker.h"

#include "fcl_checker_internal.h"
#include "moverl_planning_scene/fcl_convex.h"
#include "moverl_planning_scene/worker_pool.h"

#include <unistd.h>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <random>
#include <set>
#include <sstream>

#include <fcl/geometry/bvh/BVH_model.h>
#include <fcl/geometry/shape/box.h>
#include <fcl/geometry/shape/capsule.h>
#include <fcl/geometry/shape/cone.h>
#include <fcl/geometry/shape/convex.h>
#include <fcl/geometry/shape/cylinder.h>
#include <fcl/geometry/shape/sphere.h>
#include <fcl/math/bv/OBB.h>
#include <fcl/math/bv/OBBRSS.h>
#include <fcl/narrowphase/collision.h>
#include <fcl/narrowphase/distance.h>

namespace moverl_planning_scene {
namespace {

constexpr std::size_t kMaxInteriorStates = 1000000;  // guard against absurd segments
// checkPath culls from this many states on (below, the culling's own queries cost about what they save).
constexpr std::size_t kCullFromStates = 4;
// The occupancy map's shapes are culled for a segment from this many states on: its queries (one per shape, grown by
// the shape's motion) cost about five states' (step_cost.py, the sensed human world at 10 Hz: 250 us against 47 us a
// state unculled, 15 us culled).
constexpr std::size_t kCullOccupancyFromStates = 8;
// m: a culled pair's separation must exceed its motion by this much: far above the rounding of the dot products that
// certify it, of the order of GJK's own tolerance (libccd decides intersection near machine precision).
constexpr double kCullSlack = 1e-6;

/// True when a plane separates shape a (at ta, bounding sphere (ca, ra)) from shape b by more than `motion`: the two
/// cannot meet while their points move by at most `motion` relative to each other. Tries, cheapest first, the
/// bounding spheres, the plane that separated them last time (memory, turned with a), the plane across the line
/// between their centres, and the plane through GJK's nearest points; GJK is skipped when the memory's bound shows
/// them no farther apart than `motion` (no plane can then do). Every answer is certified by the shapes' own support
/// values: the memory and GJK only propose planes, so what they hold changes how often pairs are culled, never
/// whether a culled pair could meet.
bool farApart(const fcl::CollisionGeometryd& a, const Eigen::Isometry3d& ta, const Eigen::Vector3d& ca, double ra,
              const fcl::CollisionGeometryd& b, const Eigen::Isometry3d& tb, const Eigen::Vector3d& cb, double rb,
              double motion, FclCollisionChecker::PairMemory* memory) {
  const Eigen::Vector3d d = cb - ca;
  const double gap = d.norm();
  if (gap - ra - rb > motion) return true;
  // The separation along a unit n, b on its + side: min over b of n . x minus max over a of n . x.
  auto separated = [&](const Eigen::Vector3d& n) {
    if (!(-shapeSupport(b, tb, -n) - shapeSupport(a, ta, n) > motion)) return false;
    memory->plane = ta.linear().transpose() * n;
    return true;
  };
  if (memory->plane.squaredNorm() > 0.0 && separated(ta.linear() * memory->plane)) return true;
  if (gap > 0.0 && separated(d / gap)) return true;
  memory->plane.setZero();
  if (!(memory->upper > motion) || !hasShapeSupport(a) || !hasShapeSupport(b)) {
    return false;  // no support function (triangle meshes): never culled, no GJK spent on them
  }
  fcl::DistanceRequestd request(true);  // with the nearest points
  fcl::DistanceResultd result;
  const double distance =
      fcl::distance(&a, fcl::Transform3d(ta.matrix()), &b, fcl::Transform3d(tb.matrix()), request, result);
  memory->upper = distance >= 0.0 ? distance : std::numeric_limits<double>::infinity();
  if (!(distance > motion)) return false;
  const Eigen::Vector3d n = result.nearest_points[1] - result.nearest_points[0];
  const double norm = n.norm();
  return norm > 0.0 && separated(n / norm);
}

}  // namespace

FclCollisionChecker::FclCollisionChecker(const RobotModel& model) : model_(model) {}
FclCollisionChecker::~FclCollisionChecker() = default;

std::unique_ptr<FclCollisionChecker> FclCollisionChecker::create(const RobotModel& model,
                                                                 const FclCheckerOptions& options, std::string* error) {
  std::string dummy;
  if (error == nullptr) error = &dummy;
  if (!(options.padding >= 0.0) || !std::isfinite(options.padding)) {
    *error = "padding must be >= 0";
    return nullptr;
  }
  if (!(options.path_resolution > 0.0) || !std::isfinite(options.path_resolution)) {
    *error = "path_resolution must be > 0";
    return nullptr;
  }
  if (!(options.self_padding >= 0.0) || !std::isfinite(options.self_padding)) {
    *error = "self_padding must be >= 0";
    return nullptr;
  }
  if (options.acm_samples < 0) {
    *error = "acm_samples must be >= 0";
    return nullptr;
  }
  std::unique_ptr<FclCollisionChecker> c(new FclCollisionChecker(model));
  c->options_ = options;
  if (!c->loadGeometry(error)) return nullptr;
  c->computeAcm();
  return c;
}

void FclCollisionChecker::updateTransforms(const double* q) {
  model_.computeLinkTransforms(q, &link_poses_);
  for (Geom& g : geoms_) {
    const Eigen::Isometry3d& p = link_poses_[g.link];
    g.world_tf = p * g.origin;
    g.world_center = p * g.center_local;
  }
}

bool FclCollisionChecker::geomPairCollides(const Geom& a, const Geom& b, bool compute_depth, double* depth,
                                           bool padded) const {
  const double r = padded ? a.padded_radius + b.padded_radius : a.radius + b.radius;
  if ((a.world_center - b.world_center).squaredNorm() > r * r) return false;
  fcl::CollisionRequestd req(1, compute_depth);
  fcl::CollisionResultd res;
  fcl::collide(padded ? a.padded.get() : a.geom.get(), a.world_tf, padded ? b.padded.get() : b.geom.get(), b.world_tf,
               req, res);
  if (!res.isCollision()) return false;
  if (compute_depth && depth != nullptr && res.numContacts() > 0) {
    *depth = std::max(*depth, res.getContact(0).penetration_depth);
  }
  return true;
}

bool FclCollisionChecker::linkPairCollides(int la, int lb, bool padded) {
  for (int ga : link_geoms_[la]) {
    for (int gb : link_geoms_[lb]) {
      if (geomPairCollides(geoms_[ga], geoms_[gb], false, nullptr, padded)) return true;
    }
  }
  return false;
}

void FclCollisionChecker::checkState(const double* q, const CollisionRequest& request, CollisionResult* result) {
  const std::size_t bytes = model_.dof() * sizeof(double);
  const bool end = culled_stamp_ == world_stamp_ &&
                   (std::memcmp(q, culled_q0_.data(), bytes) == 0 || std::memcmp(q, culled_q1_.data(), bytes) == 0);
  checkStateImpl(q, request, result, end);
}

void FclCollisionChecker::prepareSegment(const double* q0, const double* q1) {
  if (cullable(q0, q1) && !culledFor(q0, q1)) cullPairs(q0, q1);
}

bool FclCollisionChecker::culledFor(const double* q0, const double* q1) const {
  const std::size_t bytes = model_.dof() * sizeof(double);
  return culled_stamp_ == world_stamp_ && std::memcmp(q0, culled_q0_.data(), bytes) == 0 &&
         std::memcmp(q1, culled_q1_.data(), bytes) == 0;
}

void FclCollisionChecker::checkStateImpl(const double* q, const CollisionRequest& request, CollisionResult* result,
                                         bool culled) {
  result->clear();
  // The occupancy map's culling for the segment, when first needed (it leaves the transforms at the midpoint).
  const bool occupancy_culled =
      culled && occupancy_ != nullptr && request.check_world && request.check_occupancy && occupancyCulled();
  updateTransforms(q);
  const auto& names = model_.linkNames();
  if (request.check_self) {
    std::size_t next = 0;  // self_active_'s index of the pair's first shape pair
    for (const auto& lp : self_pairs_) {
      const std::vector<int>& gas = link_geoms_[lp.first];
      const std::vector<int>& gbs = link_geoms_[lp.second];
      const std::uint8_t* active = culled ? self_active_.data() + next : nullptr;
      next += gas.size() * gbs.size();
      double depth = 0.0;
      bool hit = false;
      for (std::size_t ia = 0; ia < gas.size(); ++ia) {
        for (std::size_t ib = 0; ib < gbs.size(); ++ib) {
          if (active != nullptr && active[ia * gbs.size() + ib] == 0) continue;
          if (geomPairCollides(geoms_[gas[ia]], geoms_[gbs[ib]], request.compute_depth, &depth, /*padded=*/true)) {
            hit = true;
            if (!request.compute_depth) break;
          }
        }
        if (hit && !request.compute_depth) break;
      }
      if (!hit) continue;
      result->status = CollisionStatus::kSelf;
      if (request.max_pairs == 0) return;
      result->pairs.push_back(ContactPair{names[lp.first], names[lp.second], depth});
      if (result->pairs.size() >= request.max_pairs) return;
    }
    if (result->collision()) return;
  }
  if (!request.check_world) return;
  const std::size_t n_world = world_geoms_.size();
  for (std::size_t o = 0; o < world_.size(); ++o) {
    const Obstacle& ob = world_[o];
    const Eigen::Vector3d oc = ob.pose.translation();
    const std::uint8_t* active = culled ? world_active_.data() + o * n_world : nullptr;
    int last_link = -1;
    for (std::size_t w = 0; w < n_world; ++w) {
      if (active != nullptr && active[w] == 0) continue;
      const Geom& g = geoms_[world_geoms_[w]];
      if (g.link == last_link) continue;  // this link already reported with this obstacle
      const double r = g.radius + ob.radius;
      if ((g.world_center - oc).squaredNorm() > r * r) continue;
      fcl::CollisionRequestd req(1, request.compute_depth);
      fcl::CollisionResultd res;
      fcl::collide(g.geom.get(), g.world_tf, ob.geom.get(), ob.pose, req, res);
      if (!res.isCollision()) continue;
      result->status = CollisionStatus::kWorld;
      if (request.max_pairs == 0) return;
      const double depth = request.compute_depth && res.numContacts() > 0 ? res.getContact(0).penetration_depth : 0.0;
      result->pairs.push_back(ContactPair{names[g.link], ob.id, depth});
      last_link = g.link;
      if (result->pairs.size() >= request.max_pairs) return;
    }
  }
  if (occupancy_ == nullptr || !request.check_occupancy) return;
  const bool tracked = parts_ != nullptr && !parts_->empty();
  int last_link = -1;
  for (std::size_t w = 0; w < world_geoms_.size(); ++w) {
    const int gi = world_geoms_[w];
    const Geom& g = geoms_[gi];
    if (g.link == last_link) continue;
    if (occupancy_culled && occupancy_active_[w] == 0) continue;
    const auto& shape = octoGeom(geoms_[gi]);
    if (!(tracked ? meetsTracked(shape, g) : meetsOccupied(shape, g.world_tf))) continue;
    result->status = CollisionStatus::kWorld;
    if (request.max_pairs == 0) return;
    result->pairs.push_back(ContactPair{names[g.link], kOctomapId, 0.0});
    last_link = g.link;
    if (result->pairs.size() >= request.max_pairs) return;
  }
}

void FclCollisionChecker::cullPairs(const double* q0, const double* q1) {
  // Every state of the segment lies within half of it from the midpoint, so a point of a shape moves from where it is
  // at the midpoint by at most sum_i |q1_i - q0_i| / 2 * (its radius about joint i): pairs farther apart there than
  // that can close (relative motion: self pairs; the shape's own: world pairs, whose obstacles hold still during a
  // check) meet at none of the states and are left out.
  const std::size_t dof = model_.dof();
  half_dq_.resize(dof);
  drift_.assign(dof, 0.0);  // how far each joint is from the last culling's midpoint (the memory's bounds grow by it)
  for (std::size_t i = 0; i < dof; ++i) {
    q_scratch_[i] = q0[i] + 0.5 * (q1[i] - q0[i]);
    half_dq_[i] = 0.5 * std::fabs(q1[i] - q0[i]);
    if (memory_mid_.size() == dof) drift_[i] = std::fabs(q_scratch_[i] - memory_mid_[i]);
  }
  memory_mid_.assign(q_scratch_.begin(), q_scratch_.end());
  updateTransforms(q_scratch_.data());
  culled_stamp_ = 0;  // no culling holds while this one is made (the stamp is set last)
  ++cull_serial_;     // nor the occupancy map's of the segment before
  cull_states_ = interiorStateCount(q0, q1) + 2;
  // Per pair, its motion over half the segment, and the memory's distance bound carried over to this midpoint.
  auto motion = [&](const std::vector<double>& radius, PairMemory* memory) {
    double m = kCullSlack, drift = 0.0;
    for (std::size_t i = 0; i < dof; ++i) {
      m += half_dq_[i] * radius[i];
      drift += drift_[i] * radius[i];
    }
    memory->upper += drift;
    if (!(memory->upper >= 0.0)) memory->upper = std::numeric_limits<double>::infinity();  // (NaN: forget it)
    return m;
  };
  std::size_t k = 0;  // the shape pair's index in self_active_ and self_memory_
  self_active_.resize(self_memory_.size());
  for (std::size_t p = 0; p < self_pairs_.size(); ++p) {
    for (int ga : link_geoms_[self_pairs_[p].first]) {
      for (int gb : link_geoms_[self_pairs_[p].second]) {
        const Geom& a = geoms_[ga];
        const Geom& b = geoms_[gb];
        PairMemory* memory = &self_memory_[k];
        const double m = motion(pair_joint_radius_[p], memory);
        self_active_[k++] = !farApart(*a.padded, a.world_tf, a.world_center, a.padded_radius, *b.padded, b.world_tf,
                                      b.world_center, b.padded_radius, m, memory);
      }
    }
  }
  const std::size_t n_world = world_geoms_.size();
  if (world_memory_.size() != world_.size() * n_world) {
    world_memory_.assign(world_.size() * n_world, PairMemory());  // other obstacles: nothing remembered applies
  } else if (memory_world_stamp_ != world_stamp_) {
    // The obstacles changed shape or place (a moving one's window): their distance bounds no longer hold; the planes
    // are only proposals and mostly still separate.
    for (PairMemory& m : world_memory_) m.upper = std::numeric_limits<double>::infinity();
  }
  memory_world_stamp_ = world_stamp_;
  world_active_.resize(world_.size() * n_world);  // every entry written below
  for (std::size_t w = 0; w < n_world; ++w) {
    const Geom& g = geoms_[world_geoms_[w]];
    for (std::size_t o = 0; o < world_.size(); ++o) {
      const Obstacle& ob = world_[o];
      PairMemory* memory = &world_memory_[o * n_world + w];
      const double m = motion(geom_joint_radius_[world_geoms_[w]], memory);
      world_active_[o * n_world + w] = !farApart(*g.geom, g.world_tf, g.world_center, g.radius, *ob.geom, ob.pose,
                                                 ob.pose.translation(), ob.radius, m, memory);
    }
  }
  culled_q0_.assign(q0, q0 + dof);
  culled_q1_.assign(q1, q1 + dof);
  culled_stamp_ = world_stamp_;
}

bool FclCollisionChecker::occupancyCulled() {
  if (cull_states_ < kCullOccupancyFromStates) return false;
  if (occupancy_culled_serial_ == cull_serial_ && occupancy_culled_revision_ == occupancy_->revision()) {
    return occupancy_culled_level_ == octo_level_;
  }
  // On the segment every point of a shape stays within its motion over half the segment of where it is at the
  // midpoint (memory_mid_): half_dq_ times each joint's lever, the joints between (chainOffsetBound) and the shape's
  // own extent at this margin. A shape that no occupied cell comes within that of meets none on the way.
  updateTransforms(memory_mid_.data());
  occupancy_active_.resize(world_geoms_.size());
  for (std::size_t w = 0; w < world_geoms_.size(); ++w) {
    Geom& g = geoms_[world_geoms_[w]];
    const auto& shape = octoGeom(g);
    const double extent = (g.origin * shape->aabb_center).norm() + shape->aabb_radius;
    double motion = kCullSlack;
    for (std::size_t i = 0; i < model_.dof(); ++i) {
      const double chain = model_.chainOffsetBound(i, g.link);
      if (chain >= 0.0) motion += half_dq_[i] * (model_.isPrismatic(i) ? 1.0 : chain + extent);
    }
    occupancy_active_[w] = meetsOccupied(shape, g.world_tf, CellClass::kAll, motion) ? 1 : 0;
  }
  occupancy_culled_serial_ = cull_serial_;
  occupancy_culled_revision_ = occupancy_->revision();
  occupancy_culled_level_ = octo_level_;
  return true;
}

bool FclCollisionChecker::cullable(const double* q0, const double* q1) const {
  // The motion bound counts a prismatic joint's travel within its limits (RobotModel::chainOffsetBound): beyond them
  // (a measured state a little past a limit) it does not hold. Both ends within: every state between is.
  const auto& lower = model_.lowerLimits();
  const auto& upper = model_.upperLimits();
  for (std::size_t i = 0; i < model_.dof(); ++i) {
    if (!model_.isPrismatic(i)) continue;
    for (const double* q : {q0, q1}) {
      if (!(q[i] >= lower[i] && q[i] <= upper[i])) return false;
    }
  }
  return options_.cull_path_pairs;
}

bool FclCollisionChecker::setOctreeMargin(double margin) {
  if (!(margin >= 0.0 && margin <= kMaxMargin)) return false;
  octo_level_ = static_cast<int>(std::ceil(margin / kMarginStep - 1e-9));
  return true;
}

bool FclCollisionChecker::occupancyFree(const double* q, CellClass which) {
  if (occupancy_ == nullptr) return true;
  updateTransforms(q);
  for (int gi : world_geoms_) {
    if (meetsOccupied(octoGeom(geoms_[gi]), geoms_[gi].world_tf, which)) return false;
  }
  return true;
}

double FclCollisionChecker::occupancyDistance(const double* q, double below, double above, CellClass which) {
  if (occupancy_ == nullptr) return std::numeric_limits<double>::infinity();
  updateTransforms(q);
  double best = above;
  fcl::DistanceRequestd request;
  request.distance_tolerance = 1e-4;  // m: far below the cells' size
  for (int gi : world_geoms_) {
    const Geom& g = geoms_[gi];
    // The link's world box (its local box's corners, transformed) and bounding sphere: both bound the distance to a
    // box of cells from below.
    const fcl::AABBd& local = g.geom->aabb_local;
    Eigen::AlignedBox3d link_box;
    for (int c = 0; c < 8; ++c) {
      link_box.extend(g.world_tf * Eigen::Vector3d(c & 1 ? local.max_.x() : local.min_.x(),
                                                   c & 2 ? local.max_.y() : local.min_.y(),
                                                   c & 4 ? local.max_.z() : local.min_.z()));
    }
    auto lower = [&](const Eigen::AlignedBox3d& box) {
      const Eigen::Vector3d gap =
          (box.min() - link_box.max()).cwiseMax(link_box.min() - box.max()).cwiseMax(Eigen::Vector3d::Zero());
      return std::max(gap.norm(), box.exteriorDistance(g.world_center) - g.radius);
    };
    // The boxes of occupied cells nearer than the best so far, nearest first: GJK only until the next cannot beat it.
    near_boxes_.clear();
    const Eigen::AlignedBox3d region(link_box.min().array() - best, link_box.max().array() + best);
    occupancy_->visitOccupied(
        region, [&](const Eigen::AlignedBox3d& box) { return lower(box) < best; },
        [&](const Eigen::AlignedBox3d& box) {
          near_boxes_.emplace_back(lower(box), box);
          return false;
        },
        which);
    std::sort(near_boxes_.begin(), near_boxes_.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    for (const auto& [bound, box] : near_boxes_) {
      if (bound >= best) break;
      const fcl::Boxd cells(box.sizes());
      fcl::Transform3d at = fcl::Transform3d::Identity();
      at.translation() = box.center();
      fcl::DistanceResultd result;
      const double d = fcl::distance(&cells, at, g.geom.get(), g.world_tf, request, result);
      best = std::min(best, std::max(d, 0.0));  // FCL reports a negative value (or -1) for shapes that meet
      if (best < below) return best;
    }
  }
  return best;
}

const std::shared_ptr<fcl::CollisionGeometry<double>>& FclCollisionChecker::octoGeom(Geom& g) {
  if (octo_level_ == 0 || !g.inflate) return g.octo;
  if (g.octo_levels.size() <= static_cast<std::size_t>(octo_level_)) g.octo_levels.resize(octo_level_ + 1);
  auto& level = g.octo_levels[octo_level_];
  if (!level) {
    level = g.inflate(options_.padding + octo_level_ * kMarginStep);
    level->computeLocalAABB();
  }
  return level;
}

bool FclCollisionChecker::meetsTracked(const std::shared_ptr<fcl::CollisionGeometry<double>>& shape,
                                       const Geom& g) const {
  // Only a cell a camera saw occupied may be a part's: unseen and stale cells may hold anything.
  if (meetsOccupied(shape, g.world_tf, CellClass::kUnseen)) return true;
  // The seen cells no part explains (not wholly within any part's `explains`).
  const OccupancyMap::ExcludeTest explained = [this](const Eigen::AlignedBox3d& box) {
    OccupancyMap::Excluded out = OccupancyMap::Excluded::kNone;
    for (const ExplainedPart& p : *parts_) {
      const OccupancyMap::Excluded in = within(box, p);
      if (in == OccupancyMap::Excluded::kWholly) return in;
      if (in == OccupancyMap::Excluded::kPartly) out = in;
    }
    return out;
  };
  if (meetsOccupied(shape, g.world_tf, CellClass::kSeen, 0.0, &explained)) return true;
  // A part's cells: where the map saw them (ISO's margin from then) and where its newer track puts it (its ball) must
  // both reach the link: the part is in the intersection of the two.
  for (const ExplainedPart& p : *parts_) {
    if (!meetsBall(g, p)) continue;
    const OccupancyMap::ExcludeTest outside = [&p](const Eigen::AlignedBox3d& box) {
      const OccupancyMap::Excluded in = within(box, p);
      return in == OccupancyMap::Excluded::kNone ? OccupancyMap::Excluded::kWholly : OccupancyMap::Excluded::kNone;
    };
    if (meetsOccupied(shape, g.world_tf, CellClass::kSeen, 0.0, &outside)) return true;
  }
  return false;
}

OccupancyMap::Excluded FclCollisionChecker::within(const Eigen::AlignedBox3d& box, const ExplainedPart& p) {
  if (box.exteriorDistance(p.centre) >= p.explains) return OccupancyMap::Excluded::kNone;
  // The box's corner farthest from the centre.
  const Eigen::Vector3d far = (box.min() - p.centre).cwiseAbs().cwiseMax((box.max() - p.centre).cwiseAbs());
  return far.norm() <= p.explains ? OccupancyMap::Excluded::kWholly : OccupancyMap::Excluded::kPartly;
}

bool FclCollisionChecker::meetsBall(const Geom& g, const ExplainedPart& p) const {
  const auto& shape = g.octo;  // padded, no margin: the ball holds the part's whole reach
  const double r = shape->aabb_radius + p.keep_out;
  if ((g.world_tf * shape->aabb_center - p.centre).squaredNorm() > r * r) return false;
  const fcl::Sphered ball(p.keep_out);
  fcl::Transform3d at = fcl::Transform3d::Identity();
  at.translation() = p.centre;
  fcl::CollisionRequestd req(1, false);
  fcl::CollisionResultd res;
  fcl::collide(&ball, at, shape.get(), g.world_tf, req, res);
  return res.isCollision();
}

bool FclCollisionChecker::meetsOccupied(const std::shared_ptr<fcl::CollisionGeometry<double>>& shape,
                                        const Eigen::Isometry3d& tf, CellClass which, double grow,
                                        const OccupancyMap::ExcludeTest* exclude) const {
  // The shape's world box (its local box's corners, transformed; grown) bounds the cells to look at; its bounding
  // sphere rejects boxes cheaply before GJK.
  const fcl::AABBd& local = shape->aabb_local;
  Eigen::AlignedBox3d region;
  for (int c = 0; c < 8; ++c) {
    region.extend(tf * Eigen::Vector3d(c & 1 ? local.max_.x() : local.min_.x(), c & 2 ? local.max_.y() : local.min_.y(),
                                       c & 4 ? local.max_.z() : local.min_.z()));
  }
  region = Eigen::AlignedBox3d(region.min().array() - grow, region.max().array() + grow);
  const Eigen::Vector3d centre = tf * shape->aabb_center;
  const double radius = shape->aabb_radius + grow;
  // The shape's local box, placed at tf (tighter than the sphere around a long link), as FCL's OBB test takes it: the
  // cell's centre in its frame, the cell's axes its rotation's transpose.
  const Eigen::Matrix3d to_box = tf.linear().transpose();
  const Eigen::Vector3d box_centre = tf * local.center(), box_half = 0.5 * (local.max_ - local.min_);
  // A box of occupied cells that the shape meets: one of them meets it. A culling's question (grow > 0) takes a block
  // that meets for any of its cells, without looking into it: its answer may only be yes more often.
  return occupancy_->visitOccupied(
      region,
      [&](const Eigen::AlignedBox3d& box) {
        if (box.exteriorDistance(centre) > radius) return false;
        if (fcl::obbDisjoint<double>(to_box, to_box * (box.center() - box_centre), box_half,
                                     (0.5 * box.sizes().array() + grow).matrix())) {
          return false;
        }
        const fcl::Boxd cell(box.sizes().array() + 2.0 * grow);
        fcl::Transform3d at = fcl::Transform3d::Identity();
        at.translation() = box.center();
        fcl::CollisionRequestd req(1, false);
        fcl::CollisionResultd res;
        fcl::collide(&cell, at, shape.get(), tf, req, res);
        return res.isCollision();
      },
      [](const Eigen::AlignedBox3d&) { return true; }, which, /*whole_blocks=*/grow > 0.0, exclude);
}

void FclCollisionChecker::robotPointMask(const double* q, const std::vector<Eigen::Vector3d>& points, double padding,
                                         std::vector<std::uint8_t>* mask, const std::vector<std::uint8_t>* skip,
                                         WorkerPool* pool) const {
  pointMask(q, -1, points, padding, mask, skip, pool);
}

void FclCollisionChecker::robotBoundingBoxes(const double* q, double padding,
                                             std::vector<Eigen::AlignedBox3d>* boxes) const {
  boxes->clear();
  std::vector<Eigen::Isometry3d> poses;
  model_.computeLinkTransforms(q, &poses);
  for (const Geom& g : geoms_) {
    const Eigen::Vector3d center = poses[g.link] * g.center_local;
    const Eigen::Vector3d r = Eigen::Vector3d::Constant(g.radius + std::max(padding, 0.0));
    boxes->emplace_back(center - r, center + r);
  }
}

namespace {

/// Squared distance from p to the triangle (a, b, c) (Ericson, Real-Time Collision Detection, 5.1.5).
double pointTriangleDistanceSquared(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                    const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0.0 && d2 <= 0.0) return ap.squaredNorm();
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0.0 && d4 <= d3) return bp.squaredNorm();
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return (ap - ab * (d1 / (d1 - d3))).squaredNorm();
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0.0 && d5 <= d6) return cp.squaredNorm();
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return (ap - ac * (d2 / (d2 - d6))).squaredNorm();
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) {
    return (bp - (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)))).squaredNorm();
  }
  const double denom = 1.0 / (va + vb + vc);
  return (ap - ab * (vb * denom) - ac * (vc * denom)).squaredNorm();
}

/// The squared distance from p, outside a convex hull, to the hull: to the nearest of the faces `front`, the faces
/// whose planes p lies in front of (the nearest point of a convex polytope to a point outside lies on such a face); or
/// to the first of them found within stop2 (*which, if given: that face, else the nearest).
double frontFacesDistance2(const Eigen::Vector3d& p, const std::vector<Eigen::Vector3d>& vertices,
                           const std::vector<std::array<int, 3>>& faces, const std::vector<int>& front, double stop2,
                           int* which) {
  double nearest2 = std::numeric_limits<double>::infinity();
  for (int f : front) {
    const auto& t = faces[static_cast<std::size_t>(f)];
    const double d2 = pointTriangleDistanceSquared(p, vertices[t[0]], vertices[t[1]], vertices[t[2]]);
    if (d2 < nearest2) {
      nearest2 = d2;
      if (which != nullptr) *which = f;
    }
    if (d2 <= stop2) break;
  }
  return nearest2;
}

}  // namespace

std::shared_ptr<const HullDistanceGrid> buildHullDistanceGrid(const std::vector<Eigen::Vector3d>& vertices,
                                                              const std::vector<std::array<int, 3>>& faces,
                                                              const std::vector<Eigen::Vector4d>& planes, double h,
                                                              double margin) {
  auto grid = std::make_shared<HullDistanceGrid>();
  Eigen::Vector3d lo = vertices.front(), hi = lo;
  for (const Eigen::Vector3d& v : vertices) {
    lo = lo.cwiseMin(v);
    hi = hi.cwiseMax(v);
  }
  grid->h = h;
  grid->inv_h = 1.0 / h;
  grid->margin = margin;
  grid->lo = lo - Eigen::Vector3d::Constant(margin);
  for (int a = 0; a < 3; ++a) grid->n[a] = static_cast<int>(std::ceil((hi[a] - lo[a] + 2.0 * margin) / h)) + 1;
  grid->d.resize(static_cast<std::size_t>(grid->n[0]) * grid->n[1] * grid->n[2]);
  std::size_t at = 0;
  std::vector<int> front;
  for (int z = 0; z < grid->n[2]; ++z) {
    for (int y = 0; y < grid->n[1]; ++y) {
      for (int x = 0; x < grid->n[0]; ++x, ++at) {
        const Eigen::Vector3d p = grid->lo + h * Eigen::Vector3d(x, y, z);
        // Inside every face's plane: 0. Outside, the distance is at least the largest of the planes' (each plane
        // bounds a half-space holding the hull), and it is that when the point lies in front of that plane's face
        // (tried first); otherwise the nearest of the faces the point is in front of.
        double most = 0.0;
        int most_face = -1;
        front.clear();
        for (std::size_t f = 0; f < planes.size(); ++f) {
          const double e = planes[f].head<3>().dot(p) - planes[f][3];
          if (e > most) {
            most = e;
            most_face = static_cast<int>(f);
          }
          if (e > 0.0) front.push_back(static_cast<int>(f));
        }
        double dist = 0.0;
        if (most_face >= 0) {
          std::swap(front.front(), *std::find(front.begin(), front.end(), most_face));
          dist = std::sqrt(frontFacesDistance2(p, vertices, faces, front, most * most * (1.0 + 1e-12), nullptr));
        }
        float stored = static_cast<float>(dist);
        if (stored < dist) stored = std::nextafter(stored, std::numeric_limits<float>::infinity());
        grid->d[at] = stored;
      }
    }
  }
  return grid;
}

int HullDistanceGrid::classify(const Eigen::Vector3d& x, double pad) const {
  std::array<int, 3> i;
  std::array<double, 3> t;
  for (int a = 0; a < 3; ++a) {
    const double g = (x[a] - lo[a]) * inv_h, f = std::floor(g);
    if (!(f >= 0.0 && f < n[a] - 1)) return pad < margin ? -1 : 0;  // beyond the grid: farther than margin
    i[a] = static_cast<int>(f);
    t[a] = g - f;
  }
  const std::size_t sy = static_cast<std::size_t>(n[0]), sz = sy * static_cast<std::size_t>(n[1]);
  const float* c = &d[static_cast<std::size_t>(i[0]) + sy * i[1] + sz * i[2]];
  const double c000 = c[0], c100 = c[1], c010 = c[sy], c110 = c[sy + 1];
  const double c001 = c[sz], c101 = c[sz + 1], c011 = c[sz + sy], c111 = c[sz + sy + 1];
  const double c00 = c000 + (c100 - c000) * t[0], c10 = c010 + (c110 - c010) * t[0];
  const double c01 = c001 + (c101 - c001) * t[0], c11 = c011 + (c111 - c011) * t[0];
  const double c0 = c00 + (c10 - c00) * t[1], c1 = c01 + (c11 - c01) * t[1];
  if (c0 + (c1 - c0) * t[2] <= pad) return 1;
  // The nearest vertex, less the way to it (a float's rounding of the stored distance: 1e-8 m kept in hand).
  const int nx = t[0] >= 0.5, ny = t[1] >= 0.5, nz = t[2] >= 0.5;
  const double ex = nx ? 1.0 - t[0] : t[0], ey = ny ? 1.0 - t[1] : t[1], ez = nz ? 1.0 - t[2] : t[2];
  const double nearest = c[nx + sy * ny + sz * nz];
  if (nearest - h * std::sqrt(ex * ex + ey * ey + ez * ez) - 1e-8 > pad) return -1;
  return 0;
}

void FclCollisionChecker::linkPointMask(const double* q, int link, const std::vector<Eigen::Vector3d>& points,
                                        double padding, std::vector<std::uint8_t>* mask,
                                        const std::vector<std::uint8_t>* skip) const {
  pointMask(q, link, points, padding, mask, skip, nullptr);
}

void FclCollisionChecker::pointMask(const double* q, int link, const std::vector<Eigen::Vector3d>& points,
                                    double padding, std::vector<std::uint8_t>* mask,
                                    const std::vector<std::uint8_t>* skip, WorkerPool* pool) const {
  mask->assign(points.size(), 0);
  if (skip != nullptr && skip->size() != points.size()) skip = nullptr;  // not the points' own: tests every point
  std::vector<Eigen::Isometry3d> poses;
  model_.computeLinkTransforms(q, &poses);
  const double pad = std::max(padding, 1e-6), pad2 = pad * pad;
  auto probe = std::make_shared<fcl::Sphered>(pad);
  fcl::CollisionRequestd req(1, false);
  // The hulls' distance fields (HullDistanceGrid), built once, when a hull is first tested (about 0.14 s for the
  // Panda's): vertices 1 cm apart (on the recorded clouds 1 cm and 2 cm spacing filtered as fast, 5 mm slower: its
  // fields are 8 times larger), reaching 3 cm beyond each hull's box, which covers the self filter's padding and the
  // known-free pass's (padding + half a cell's diagonal: 2.7 cm with the defaults); a point beyond a field with a
  // larger pad is left to the faces.
  constexpr double kGridSpacing = 0.01, kGridMargin = 0.03;
  // Each shape in the base frame: pose, bounding sphere (grown by pad) and, for an exact convex hull, its planes and
  // vertices; the box around all the spheres rejects most of a cloud's points with six comparisons.
  struct Shape {
    const Geom* g;
    Eigen::Isometry3d tf;
    Eigen::Vector3d center;
    double r2;
    std::vector<Eigen::Vector4d> planes;
    std::vector<Eigen::Vector3d> vertices;
    const HullDistanceGrid* grid;  // the hull's distance field (null: none)
    Eigen::Isometry3d inv;         // base frame -> shape frame
  };
  std::vector<Shape> shapes;
  Eigen::AlignedBox3d reach;
  for (const Geom& g : geoms_) {
    if (link >= 0 && g.link != link) continue;
    Shape sh{&g, poses[g.link] * g.origin, poses[g.link] * g.center_local, 0.0, {}, {}, nullptr, {}};
    const double r = g.radius + pad;
    sh.r2 = r * r;
    reach.extend(sh.center - Eigen::Vector3d::Constant(r));
    reach.extend(sh.center + Eigen::Vector3d::Constant(r));
    if (!g.planes.empty()) {
      for (const Eigen::Vector4d& pl : g.planes) {
        const Eigen::Vector3d n = sh.tf.linear() * pl.head<3>();
        sh.planes.emplace_back(n.x(), n.y(), n.z(), pl[3] + n.dot(sh.tf.translation()));
      }
      for (const Eigen::Vector3d& v : g.vertices) sh.vertices.push_back(sh.tf * v);
      {
        std::lock_guard<std::mutex> lock(grids_mutex_);
        if (g.distance_grid == nullptr) {
          g.distance_grid = buildHullDistanceGrid(g.vertices, g.faces, g.planes, kGridSpacing, kGridMargin);
        }
        sh.grid = g.distance_grid.get();  // the shape keeps it while the checker lives
      }
      sh.inv = sh.tf.inverse();
    }
    shapes.push_back(std::move(sh));
  }
  // What a hull's answer for one point tells of the points near it (a cloud's next points lie near its last): a point
  // within pad of the hull whose distance to it is at most d makes every point within pad - d of it within pad too; a
  // point farther than pad, at least D away, makes every point within D - pad of it farther too (the distance to a
  // set changes no faster than the point moves). Each radius is kept 1e-9 m short (rounding).
  // And two faces are tried first, as they are likely to settle the next point too (a cloud's points on a link are
  // mostly within pad of its hull, and each such point passed every one of its 150-odd planes): the last face found
  // within pad of a point (a point within pad of a face is within pad of the hull), and the face whose plane put the
  // last point beyond pad.
  struct Memo {
    Eigen::Vector3d in = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN()), out = in;
    double in2 = -1.0, out2 = -1.0;  ///< squared radii (negative: none)
    int near = -1;                   ///< the face within pad of a point (-1: none yet)
    std::size_t beyond = 0;          ///< the face whose plane is tried first
  };
  auto remember = [](Eigen::Vector3d* at, double* r2, const Eigen::Vector3d& p, double radius) {
    radius -= 1e-9;
    *at = p;
    *r2 = radius > 0.0 ? radius * radius : -1.0;
  };
  // Within pad of a convex hull: inside every face's plane, or, outside, within pad of a face it lies in front of
  // (the nearest point of a convex polytope to a point outside lies on such a face); farther than pad beyond any
  // plane: not. Exact, as FCL's sphere test (which answers the shapes without planes). front: the caller's scratch.
  auto within = [&](const Shape& sh, const Eigen::Vector3d& p, std::vector<int>& front, Memo& memo) {
    if (sh.planes.empty()) {
      Eigen::Isometry3d at = Eigen::Isometry3d::Identity();
      at.translation() = p;
      fcl::CollisionResultd res;
      fcl::collide(probe.get(), at, sh.g->geom.get(), sh.tf, req, res);
      return res.isCollision();
    }
    const int bounds = sh.grid->classify(sh.inv * p, pad);
    if (bounds != 0) return bounds > 0;
    if ((p - memo.in).squaredNorm() <= memo.in2) return true;
    if ((p - memo.out).squaredNorm() <= memo.out2) return false;
    if (memo.near >= 0) {
      const auto& t = sh.g->faces[static_cast<std::size_t>(memo.near)];
      const double d2 = pointTriangleDistanceSquared(p, sh.vertices[t[0]], sh.vertices[t[1]], sh.vertices[t[2]]);
      if (d2 <= pad2) {
        remember(&memo.in, &memo.in2, p, pad - std::sqrt(d2));
        return true;
      }
    }
    front.clear();
    double most = -std::numeric_limits<double>::infinity();  // the largest plane distance: inside when <= 0
    int most_face = -1;
    const std::size_t faces = sh.planes.size();
    for (std::size_t i = 0, f = memo.beyond; i < faces; ++i, f = f + 1 == faces ? 0 : f + 1) {
      const double e = sh.planes[f].head<3>().dot(p) - sh.planes[f][3];
      if (e > pad) {
        remember(&memo.out, &memo.out2, p, e - pad);  // at least e away
        memo.beyond = f;
        return false;
      }
      if (e > most) {
        most = e;
        most_face = static_cast<int>(f);
      }
      if (e > 0.0) front.push_back(static_cast<int>(f));
    }
    if (front.empty()) {
      remember(&memo.in, &memo.in2, p, pad - most);  // inside, at least -most deep
      memo.near = most_face;  // the face nearest the point's plane-wise: likely its neighbours' within pad
      return true;
    }
    int face = -1;
    const double d2 = frontFacesDistance2(p, sh.vertices, sh.g->faces, front, pad2, &face);
    if (d2 <= pad2) {
      remember(&memo.in, &memo.in2, p, pad - std::sqrt(d2));
      memo.near = face;
      return true;
    }
    remember(&memo.out, &memo.out2, p, std::sqrt(d2) - pad);
    return false;
  };
  auto test = [&](std::size_t begin, std::size_t end) {
    std::vector<int> front;
    std::vector<Memo> memos(shapes.size());
    for (std::size_t k = begin; k < end; ++k) {
      const Eigen::Vector3d& p = points[k];
      if (!reach.contains(p) || (skip != nullptr && (*skip)[k] != 0)) continue;
      for (std::size_t i = 0; i < shapes.size(); ++i) {
        const Shape& sh = shapes[i];
        if ((p - sh.center).squaredNorm() <= sh.r2 && within(sh, p, front, memos[i])) {
          (*mask)[k] = 1;
          break;
        }
      }
    }
  };
  // Parts of the cloud on the pool's threads (a point's test against the link shapes is worth a thread's wake-up
  // from about a thousand points); the shapes above placed once for all.
  constexpr std::size_t kSelfFilterPart = 1024;
  WorkerPool::runParts(pool, points.size(), kSelfFilterPart,
                       [&](std::size_t begin, std::size_t end, int) { test(begin, end); });
}

void FclCollisionChecker::linkPointMaskFcl(const double* q, int link, const std::vector<Eigen::Vector3d>& points,
                                           double padding, std::vector<std::uint8_t>* mask) const {
  mask->assign(points.size(), 0);
  std::vector<Eigen::Isometry3d> poses;
  model_.computeLinkTransforms(q, &poses);
  const double pad = std::max(padding, 1e-6);
  auto probe = std::make_shared<fcl::Sphered>(pad);
  fcl::CollisionRequestd req(1, false);
  for (const Geom& g : geoms_) {
    if (link >= 0 && g.link != link) continue;
    const Eigen::Isometry3d tf = poses[g.link] * g.origin;
    const Eigen::Vector3d center = poses[g.link] * g.center_local;
    const double r = g.radius + pad, r2 = r * r;
    Eigen::Isometry3d at = Eigen::Isometry3d::Identity();
    for (std::size_t k = 0; k < points.size(); ++k) {
      if ((*mask)[k] != 0 || !((points[k] - center).squaredNorm() <= r2)) continue;
      at.translation() = points[k];
      fcl::CollisionResultd res;
      fcl::collide(probe.get(), at, g.geom.get(), tf, req, res);
      if (res.isCollision()) (*mask)[k] = 1;
    }
  }
}

std::size_t FclCollisionChecker::interiorStateCount(const double* q0, const double* q1) const {
  double motion = 0.0;
  for (std::size_t i = 0; i < joint_radius_.size(); ++i) motion += joint_radius_[i] * std::fabs(q1[i] - q0[i]);
  const double n = std::ceil(motion / options_.path_resolution);
  if (!(n >= 0.0)) return 0;  // NaN guard (inputs are validated by callers)
  return n > static_cast<double>(kMaxInteriorStates) ? kMaxInteriorStates : static_cast<std::size_t>(n);
}

void FclCollisionChecker::checkPath(const double* q0, const double* q1, const PathCheckRequest& request,
                                    PathCheckResult* result) {
  result->clear();
  const std::size_t dof = model_.dof();
  const std::size_t n = interiorStateCount(q0, q1);
  const double denom = static_cast<double>(n + 1);
  double last_valid = 0.0;
  // Shape pairs that cannot meet anywhere on the segment are left out of its states (worth it from a few states on).
  const bool culled =
      cullable(q0, q1) && (culledFor(q0, q1) || n + request.check_start + request.check_goal >= kCullFromStates);
  if (culled && !culledFor(q0, q1)) cullPairs(q0, q1);
  // Checks the state at t; returns true when it collides (and fills the result).
  auto check_at = [&](double t) {
    for (std::size_t i = 0; i < dof; ++i) q_scratch_[i] = q0[i] + t * (q1[i] - q0[i]);
    if (t == 1.0) std::memcpy(q_scratch_.data(), q1, dof * sizeof(double));
    ++result->checked_states;
    checkStateImpl(q_scratch_.data(), request.state, &state_scratch_, culled);
    if (!state_scratch_.collision()) return false;
    result->status = state_scratch_.status;
    result->pairs.swap(state_scratch_.pairs);
    result->collision_fraction = t;
    result->last_valid_fraction = last_valid;
    return true;
  };
  if (request.find_first) {
    if (request.check_start && check_at(0.0)) return;
    for (std::size_t k = 1; k <= n; ++k) {
      const double t = static_cast<double>(k) / denom;
      if (check_at(t)) return;
      last_valid = t;
    }
    if (request.check_goal && check_at(1.0)) return;
    result->last_valid_fraction = 1.0;
    return;
  }
  // Rejection-first order: goal, start, then interior indices by bisection (coarse to fine).
  last_valid = 0.0;
  if (request.check_goal && check_at(1.0)) return;
  if (request.check_start && check_at(0.0)) return;
  if (n > 0) {
    // Coarse-to-fine bisection: at level `step`, the odd multiples of step (even ones were done at coarser levels).
    std::size_t step = 1;
    while (step < n + 1) step <<= 1;
    for (; step >= 1; step >>= 1) {
      for (std::size_t k = step; k <= n; k += 2 * step) {
        if (check_at(static_cast<double>(k) / denom)) {
          result->last_valid_fraction = 0.0;  // unknown in this order: be conservative
          return;
        }
      }
    }
  }
  result->last_valid_fraction = 1.0;
}

}  // namespace moverl_planning_scene
