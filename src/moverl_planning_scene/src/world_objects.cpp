/**
 * \file world_objects.cpp
 * \brief FclCollisionChecker: world obstacles, padded, and the volumes moving ones sweep in a motion-time window.
 */
#include <cmath>
#include <limits>
#include <set>
#include <utility>
#include <vector>

#include <fcl/geometry/bvh/BVH_model.h>
#include <fcl/geometry/shape/box.h>
#include <fcl/geometry/shape/capsule.h>
#include <fcl/geometry/shape/cone.h>
#include <fcl/geometry/shape/convex.h>
#include <fcl/geometry/shape/cylinder.h>
#include <fcl/geometry/shape/sphere.h>
#include <fcl/math/bv/OBBRSS.h>
#include <fcl/narrowphase/collision.h>

#include "fcl_checker_internal.h"
#include "moverl_planning_scene/worker_pool.h"

namespace moverl_planning_scene {
namespace {

/// Geometry of object o padded by p and translated along its motion axis by every s in [lo, hi] from its pose at
/// t = 0: a superset of the swept volume (exact for spheres -> capsules, boxes translating along a box axis and
/// cylinders translating along their own axis; otherwise the shape's local bounding box stretched along the motion).
/// With lo = hi = 0 it is the padded object itself. Returns false for a bad shape (message in *why).
bool sweptGeometry(const WorldObject& o, double p, double lo, double hi,
                   std::shared_ptr<fcl::CollisionGeometry<double>>* geom, Eigen::Isometry3d* pose, double* radius,
                   std::string* why) {
  const std::vector<double>& d = o.dimensions;
  const double h = 0.5 * (hi - lo);         // half the travel
  const Eigen::Vector3d a = o.motion.axis;  // unit
  *pose = o.pose;
  pose->translation() += a * (0.5 * (lo + hi));  // centre of the travel
  const Eigen::Matrix3d R = o.pose.linear();
  const Eigen::Vector3d u = R.transpose() * a;  // motion axis in the object's frame
  constexpr double kAligned = 1.0 - 1e-9;
  auto box = [&](double x, double y, double z) {
    // A box of these (padded) dims in the frame *pose, swept along u by +/- h: |x_i + s u_i| <= d_i/2 + h |u_i|.
    const Eigen::Vector3d dims(x + 2 * h * std::fabs(u[0]), y + 2 * h * std::fabs(u[1]), z + 2 * h * std::fabs(u[2]));
    *geom = std::make_shared<fcl::Boxd>(dims[0], dims[1], dims[2]);
    *radius = 0.5 * dims.norm();
  };
  switch (o.type) {
    case ShapeType::kBox:
      if (d.size() != 3) return (*why = "BOX needs 3 dimensions [x, y, z]", false);
      box(d[0] + 2 * p, d[1] + 2 * p, d[2] + 2 * p);
      return true;
    case ShapeType::kSphere:
      if (d.size() != 1) return (*why = "SPHERE needs 1 dimension [radius]", false);
      if (h <= 0.0) {
        *geom = std::make_shared<fcl::Sphered>(d[0] + p);
      } else {  // a capsule along the motion axis (fcl capsules lie along local z)
        *geom = std::make_shared<fcl::Capsuled>(d[0] + p, 2 * h);
        pose->linear() = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), a).toRotationMatrix();
      }
      *radius = d[0] + p + h;
      return true;
    case ShapeType::kCylinder:
    case ShapeType::kCone: {
      if (d.size() != 2) return (*why = "CYLINDER/CONE needs 2 dimensions [height, radius]", false);
      const double r = d[1] + p, len = d[0] + 2 * p;
      if (h <= 0.0 || std::fabs(u[2]) >= kAligned) {  // static, or moving along its own axis: longer cylinder
        if (o.type == ShapeType::kCylinder) {
          *geom = std::make_shared<fcl::Cylinderd>(r, len + 2 * h);
        } else if (h <= 0.0) {
          *geom = std::make_shared<fcl::Coned>(r, len);
        } else {
          *geom = std::make_shared<fcl::Cylinderd>(r, len + 2 * h);  // cone within its cylinder
        }
        *radius = std::hypot(r, 0.5 * len + h);
        return true;
      }
      // Rotate the (symmetric) local frame about z so that the in-plane part of u lies along x; bound the
      // cylinder by its box (2r, 2r, len) and sweep that.
      const double angle = std::atan2(u[1], u[0]);
      pose->linear() = R * Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitZ()).toRotationMatrix();
      const Eigen::Vector3d u2(std::hypot(u[0], u[1]), 0.0, u[2]);
      const Eigen::Vector3d dims(2 * r + 2 * h * u2[0], 2 * r, len + 2 * h * std::fabs(u2[2]));
      *geom = std::make_shared<fcl::Boxd>(dims[0], dims[1], dims[2]);
      *radius = 0.5 * dims.norm();
      return true;
    }
    default:
      return (*why = "unsupported shape type", false);
  }
}

/// A static object's half extents in its own frame, as staticObjectPointMask tests it (a box: its half sizes; a sphere:
/// its radius on each axis; a cylinder or a cone, by its bounding cylinder: radius, radius, half length); false for a
/// shape on which no point is masked.
bool maskedHalf(const WorldObject& o, Eigen::Vector3d* half) {
  const auto& d = o.dimensions;
  switch (o.type) {
    case ShapeType::kBox:
      *half = 0.5 * Eigen::Vector3d(d[0], d[1], d[2]);
      return true;
    case ShapeType::kSphere:
      *half = Eigen::Vector3d::Constant(d[0]);
      return true;
    case ShapeType::kCylinder:
    case ShapeType::kCone:
      *half = Eigen::Vector3d(d[1], d[1], 0.5 * d[0]);
      return true;
    default:
      return false;
  }
}

/// The object's half extents grown by padding (>= 0), rotated into the base frame: the box around it there, whose
/// extent along each axis is |R| * (half + padding).
Eigen::AlignedBox3d paddedBox(const WorldObject& o, const Eigen::Vector3d& half, double padding) {
  const Eigen::Vector3d extent =
      o.pose.linear().cwiseAbs() * (half + Eigen::Vector3d::Constant(std::max(padding, 0.0)));
  return Eigen::AlignedBox3d(o.pose.translation() - extent, o.pose.translation() + extent);
}

}  // namespace

std::size_t FclCollisionChecker::worldSize() const { return world_.size(); }

bool FclCollisionChecker::setWorld(const std::vector<WorldObject>& objects, std::string* error) {
  std::string dummy;
  if (error == nullptr) error = &dummy;
  std::vector<Obstacle> world;
  world.reserve(objects.size());
  std::vector<std::size_t> moving;
  const double p = options_.padding;
  // Nothing of a robot's world is kilometres away or wide: such numbers are corrupt input, not geometry.
  constexpr double kMaxExtent = 1e4;  // m
  std::set<std::string> ids;
  for (const WorldObject& o : objects) {
    const std::vector<double>& d = o.dimensions;
    auto bad = [&](const std::string& why) {
      *error = "world object '" + o.id + "': " + why;
      return false;
    };
    if (!ids.insert(o.id).second) return bad("id used twice");
    for (double v : d) {
      if (!std::isfinite(v) || v <= 0.0 || v > kMaxExtent) return bad("dimensions must be finite, > 0 and <= 1e4 m");
    }
    if (!o.pose.matrix().allFinite()) return bad("pose is not finite");
    if (!(o.pose.linear().transpose() * o.pose.linear()).isApprox(Eigen::Matrix3d::Identity(), 1e-6) ||
        o.pose.linear().determinant() < 0.0) {
      return bad("pose's rotation is not a rotation (orthonormal, determinant 1)");
    }
    if (o.pose.translation().norm() > kMaxExtent) return bad("pose is more than 1e4 m away");
    const ObstacleMotion& m = o.motion;
    if (m.type != ObstacleMotion::Type::kNone) {
      if (m.type != ObstacleMotion::Type::kOscillate && m.type != ObstacleMotion::Type::kReach) {
        return bad("unknown motion type");
      }
      if (!m.axis.allFinite() || std::fabs(m.axis.norm() - 1.0) > 1e-6) return bad("motion axis must be a unit vector");
      if (!std::isfinite(m.amplitude) || m.amplitude < 0.0 || m.amplitude > kMaxExtent) {
        return bad("motion amplitude must be finite, >= 0 and <= 1e4 m");
      }
      if (!std::isfinite(m.period) || m.period <= 0.0) return bad("motion period must be finite and > 0");
      if (!std::isfinite(m.phase)) return bad("motion phase must be finite");
      if (m.type == ObstacleMotion::Type::kReach) {
        if (!std::isfinite(m.move) || m.move <= 0.0) return bad("reach motion's move must be finite and > 0");
        if (!std::isfinite(m.hold) || m.hold < 0.0) return bad("reach motion's hold must be finite and >= 0");
        if (!(2.0 * m.move + m.hold <= m.period)) return bad("reach motion's period must be >= 2 move + hold");
        if (!(m.chance >= 0.0 && m.chance <= 1.0)) return bad("reach motion's chance must be in [0, 1]");
      }
    }
    Obstacle ob;
    ob.id = o.id;
    std::string why;
    double lo = 0.0, hi = 0.0;
    if (m.moving()) m.range(0.0, std::numeric_limits<double>::infinity(), &lo, &hi);  // whole envelope
    if (!sweptGeometry(o, p, lo, hi, &ob.geom, &ob.pose, &ob.radius, &why)) return bad(why);
    ob.geom->computeLocalAABB();
    ob.source = o;
    if (m.moving()) moving.push_back(world.size());
    world.push_back(std::move(ob));
  }
  moving_.swap(moving);
  window_t0_ = 0.0;
  window_t1_ = std::numeric_limits<double>::infinity();
  world_.swap(world);
  ++world_stamp_;
  return true;
}

void FclCollisionChecker::setMotionWindow(double t0, double t1) {
  if (moving_.empty()) return;
  const bool envelope = !(t1 < std::numeric_limits<double>::infinity());
  const bool current_envelope = !(window_t1_ < std::numeric_limits<double>::infinity());
  if (envelope ? current_envelope : (t0 == window_t0_ && t1 == window_t1_)) return;  // unchanged
  window_t0_ = t0;
  window_t1_ = envelope ? std::numeric_limits<double>::infinity() : t1;
  for (std::size_t i : moving_) {
    Obstacle& ob = world_[i];
    double lo, hi;
    ob.source.motion.range(t0, window_t1_, &lo, &hi);
    std::string why;
    sweptGeometry(ob.source, options_.padding, lo, hi, &ob.geom, &ob.pose, &ob.radius, &why);  // validated before
    ob.geom->computeLocalAABB();
  }
  ++world_stamp_;
}

double FclCollisionChecker::obstacleRadius(std::size_t i) const { return world_.at(i).radius; }
Eigen::Vector3d FclCollisionChecker::obstacleCenter(std::size_t i) const { return world_.at(i).pose.translation(); }

void FclCollisionChecker::staticObjectSolidMask(const std::vector<Eigen::Vector3d>& points,
                                                std::vector<std::uint8_t>* mask) const {
  mask->assign(points.size(), 0);
  for (const Obstacle& ob : world_) {
    const WorldObject& o = ob.source;
    Eigen::Vector3d half;
    if (o.motion.moving() || o.type == ShapeType::kCone || !maskedHalf(o, &half)) continue;
    const Eigen::Isometry3d inv = o.pose.inverse();
    for (std::size_t k = 0; k < points.size(); ++k) {
      if ((*mask)[k] != 0) continue;
      const Eigen::Vector3d p = inv * points[k];  // in the object's frame (centred)
      bool in = false;
      switch (o.type) {
        case ShapeType::kBox:
          in = (p.cwiseAbs() - half).maxCoeff() <= 0.0;
          break;
        case ShapeType::kSphere:
          in = p.norm() <= half.x();
          break;
        default:  // a cylinder
          in = std::fabs(p.z()) <= half.z() && p.head<2>().norm() <= half.x();
          break;
      }
      if (in) (*mask)[k] = 1;
    }
  }
}

void FclCollisionChecker::staticObjectPointMask(const std::vector<Eigen::Vector3d>& points, double padding,
                                                std::vector<std::uint8_t>* mask, WorkerPool* pool) const {
  mask->assign(points.size(), 0);
  // Each static object as its test: its frame's inverse (centred), its half extents there (maskedHalf), and the box
  // around it grown by the padding in the base frame (paddedBox, and 1e-9 m more against rounding), which rejects most
  // points with six comparisons.
  struct Fixed {
    ShapeType type;
    Eigen::Isometry3d inv;
    Eigen::Vector3d half;
    Eigen::AlignedBox3d around;
  };
  std::vector<Fixed> fixed;
  for (const Obstacle& ob : world_) {
    const WorldObject& o = ob.source;
    Fixed f{o.type, o.pose.inverse(), Eigen::Vector3d::Zero(), {}};
    if (o.motion.moving() || !maskedHalf(o, &f.half)) continue;
    f.around = paddedBox(o, f.half, padding);
    f.around.extend(f.around.min() - Eigen::Vector3d::Constant(1e-9));
    f.around.extend(f.around.max() + Eigen::Vector3d::Constant(1e-9));
    fixed.push_back(f);
  }
  WorkerPool::runParts(pool, points.size(), WorkerPool::kCheapPart, [&](std::size_t begin, std::size_t end, int) {
    for (const Fixed& f : fixed) {
      for (std::size_t k = begin; k < end; ++k) {
        if ((*mask)[k] != 0 || !f.around.contains(points[k])) continue;
        const Eigen::Vector3d p = f.inv * points[k];  // in the object's frame (centred)
        bool in = false;
        switch (f.type) {
          case ShapeType::kBox:
            in = (p.cwiseAbs() - f.half).maxCoeff() <= padding;
            break;
          case ShapeType::kSphere:
            in = p.norm() <= f.half.x() + padding;
            break;
          default:  // a cylinder or a cone's bounding cylinder
            in = std::fabs(p.z()) <= f.half.z() + padding && p.head<2>().norm() <= f.half.x() + padding;
            break;
        }
        if (in) (*mask)[k] = 1;
      }
    }
  });
}

void FclCollisionChecker::staticObjectBoxes(double padding, std::vector<Eigen::AlignedBox3d>* boxes) const {
  boxes->clear();
  for (const Obstacle& ob : world_) {
    Eigen::Vector3d half;
    if (!ob.source.motion.moving() && maskedHalf(ob.source, &half)) {
      boxes->push_back(paddedBox(ob.source, half, padding));
    }
  }
}

bool FclCollisionChecker::obstacleContains(std::size_t i, const Eigen::Vector3d& point) const {
  const Obstacle& ob = world_.at(i);
  auto probe = std::make_shared<fcl::Sphered>(1e-6);
  Eigen::Isometry3d tf = Eigen::Isometry3d::Identity();
  tf.translation() = point;
  fcl::CollisionRequestd req(1, false);
  fcl::CollisionResultd res;
  fcl::collide(probe.get(), tf, ob.geom.get(), ob.pose, req, res);
  return res.isCollision();
}

}  // namespace moverl_planning_scene
