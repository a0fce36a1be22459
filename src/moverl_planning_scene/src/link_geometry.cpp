/**
 * \file link_geometry.cpp
 * \brief FclCollisionChecker: the robot's collision geometry (URDF primitives, meshes as convex hulls or triangles,
 *        the padded copies for self checks and the sensed map).
 */
#include <cmath>
#include <limits>
#include <map>
#include <set>

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
#include "moverl_planning_scene/convex_hull.h"
#include "moverl_planning_scene/fcl_convex.h"
#include "moverl_planning_scene/mesh_loader.h"

namespace moverl_planning_scene {
namespace {

/// Triangles mode: every vertex of the mesh moved along m_v / k_v * padding, where m_v is the unit mean of the outward
/// normals n_f of the mesh triangles around v that support the mesh (every vertex on one side of their plane) and
/// k_v = min_f m_v . n_f. This inflates the surface near its convex parts; it is no exact superset of a non-convex
/// mesh (convex_hull mode inflates the hull exactly, see inflateHull).
std::vector<fcl::Vector3d> inflateTriangles(const MeshPiece& mesh, double padding) {
  if (padding <= 0.0) return mesh.vertices;
  const std::size_t nv = mesh.vertices.size();
  // Weld duplicated vertices so that normals gather per position.
  std::map<std::array<long long, 3>, std::size_t> ids;
  std::vector<std::size_t> weld(nv);
  constexpr double kWeld = 1e-7;
  for (std::size_t i = 0; i < nv; ++i) {
    const auto& v = mesh.vertices[i];
    const std::array<long long, 3> key{std::llround(v.x() / kWeld), std::llround(v.y() / kWeld),
                                       std::llround(v.z() / kWeld)};
    weld[i] = ids.emplace(key, ids.size()).first->second;
  }
  std::vector<std::vector<fcl::Vector3d>> normals(ids.size());
  for (const auto& t : mesh.triangles) {
    const fcl::Vector3d& a = mesh.vertices[t[0]];
    const fcl::Vector3d n = (mesh.vertices[t[1]] - a).cross(mesh.vertices[t[2]] - a);
    const double norm = n.norm();
    if (norm < 1e-12) continue;  // degenerate triangle
    fcl::Vector3d u = n / norm;
    double lo = 0.0, hi = 0.0;
    for (const auto& v : mesh.vertices) {
      const double side = u.dot(v - a);
      lo = std::min(lo, side);
      hi = std::max(hi, side);
    }
    constexpr double kTolerance = 1e-6;
    if (lo < -kTolerance && hi > kTolerance) continue;  // not a supporting plane
    if (hi > kTolerance) u = -u;                        // outward: the mesh lies on the negative side
    for (int k = 0; k < 3; ++k) normals[weld[t[k]]].push_back(u);
  }
  constexpr double kMaxStretch = 10.0;  // very sharp vertices: cap the offset at 10 * padding
  std::vector<fcl::Vector3d> out(mesh.vertices);
  for (std::size_t i = 0; i < nv; ++i) {
    const auto& ns = normals[weld[i]];
    if (ns.empty()) continue;
    fcl::Vector3d m = fcl::Vector3d::Zero();
    for (const auto& n : ns) m += n;
    if (m.norm() < 1e-9) continue;
    m.normalize();
    double k = 1.0;
    for (const auto& n : ns) k = std::min(k, m.dot(n));
    out[i] += m * padding * std::min(1.0 / std::max(k, 1e-9), kMaxStretch);
  }
  return out;
}

/// The triangles themselves (mesh_mode triangles).
std::shared_ptr<fcl::CollisionGeometry<double>> bvhGeometry(const std::vector<fcl::Vector3d>& vertices,
                                                            const std::vector<std::array<int, 3>>& triangles) {
  std::vector<fcl::Triangle> tris;
  tris.reserve(triangles.size());
  for (const auto& t : triangles) tris.emplace_back(t[0], t[1], t[2]);
  auto bvh = std::make_shared<fcl::BVHModel<fcl::OBBRSSd>>();
  bvh->beginModel(static_cast<int>(tris.size()), static_cast<int>(vertices.size()));
  bvh->addSubModel(vertices, tris);
  bvh->endModel();
  return bvh;
}

}  // namespace

bool FclCollisionChecker::loadGeometry(std::string* error) {
  const std::size_t n_links = model_.linkNames().size();
  link_geoms_.assign(n_links, {});
  const double sp = options_.self_padding, wp = options_.padding;
  // Adds g (shape frame = spec.origin, bounding sphere centred at center_shape in the shape frame).
  auto add = [&](Geom g, const Eigen::Vector3d& center_shape) {
    g.geom->computeLocalAABB();
    if (sp <= 0.0) g.padded = g.geom;
    if (wp <= 0.0) g.octo = g.geom;
    g.padded->computeLocalAABB();
    g.octo->computeLocalAABB();
    if (g.padded_radius < 0.0) g.padded_radius = g.radius + 2.0 * sp;
    g.center_local = g.origin * center_shape;
    link_geoms_[g.link].push_back(static_cast<int>(geoms_.size()));
    geoms_.push_back(std::move(g));
  };
  for (std::size_t l = 0; l < n_links; ++l) {
    for (const CollisionShapeSpec& s : model_.collisionShapes(static_cast<int>(l))) {
      Geom g;
      g.link = static_cast<int>(l);
      g.origin = s.origin;
      g.type = s.type;
      g.dims = s.dims;
      g.padded_radius = -1.0;  // primitives: radius + 2 * sp (set by add); meshes compute it exactly
      const Eigen::Vector3d d = s.dims;
      switch (s.type) {
        case ShapeType::kBox:
          g.inflate = [d](double pad) -> std::shared_ptr<fcl::CollisionGeometryd> {
            return std::make_shared<fcl::Boxd>(d.x() + 2 * pad, d.y() + 2 * pad, d.z() + 2 * pad);
          };
          g.geom = std::make_shared<fcl::Boxd>(s.dims.x(), s.dims.y(), s.dims.z());
          g.radius = 0.5 * s.dims.norm();
          g.padded = std::make_shared<fcl::Boxd>(s.dims.x() + 2 * sp, s.dims.y() + 2 * sp, s.dims.z() + 2 * sp);
          g.octo = std::make_shared<fcl::Boxd>(s.dims.x() + 2 * wp, s.dims.y() + 2 * wp, s.dims.z() + 2 * wp);
          break;
        case ShapeType::kSphere:
          g.inflate = [d](double pad) -> std::shared_ptr<fcl::CollisionGeometryd> {
            return std::make_shared<fcl::Sphered>(d.x() + pad);
          };
          g.geom = std::make_shared<fcl::Sphered>(s.dims.x());
          g.radius = s.dims.x();
          g.padded = std::make_shared<fcl::Sphered>(s.dims.x() + sp);
          g.octo = std::make_shared<fcl::Sphered>(s.dims.x() + wp);
          break;
        case ShapeType::kCylinder:
          g.inflate = [d](double pad) -> std::shared_ptr<fcl::CollisionGeometryd> {
            return std::make_shared<fcl::Cylinderd>(d.x() + pad, d.y() + 2 * pad);
          };
          g.geom = std::make_shared<fcl::Cylinderd>(s.dims.x(), s.dims.y());
          g.radius = std::hypot(s.dims.x(), 0.5 * s.dims.y());
          g.padded = std::make_shared<fcl::Cylinderd>(s.dims.x() + sp, s.dims.y() + 2 * sp);
          g.octo = std::make_shared<fcl::Cylinderd>(s.dims.x() + wp, s.dims.y() + 2 * wp);
          break;
        case ShapeType::kCone:
          g.inflate = [d](double pad) -> std::shared_ptr<fcl::CollisionGeometryd> {
            return std::make_shared<fcl::Coned>(d.x() + pad, d.y() + 2 * pad);
          };
          g.geom = std::make_shared<fcl::Coned>(s.dims.x(), s.dims.y());
          g.radius = std::hypot(s.dims.x(), 0.5 * s.dims.y());
          g.padded = std::make_shared<fcl::Coned>(s.dims.x() + sp, s.dims.y() + 2 * sp);
          g.octo = std::make_shared<fcl::Coned>(s.dims.x() + wp, s.dims.y() + 2 * wp);
          break;
        case ShapeType::kMesh: {
          // One geometry per piece: PyBullet makes one convex hull per OBJ object/group (mesh_loader.h).
          const bool hull_mode = options_.mesh_mode == MeshMode::kConvexHull;
          std::vector<MeshPiece> pieces;
          if (!loadMeshPieces(s.mesh_path, s.scale, hull_mode, &pieces, error)) return false;
          for (const MeshPiece& piece : pieces) {
            Geom pg = g;
            pg.piece = piece.name;
            std::vector<Eigen::Vector3d> base, padded, octo;
            if (hull_mode) {
              const ConvexHull hull = computeConvexHull(piece.vertices);
              degenerate_hulls_ += hull.degenerate;
              base = hull.vertices;
              if (!hull.degenerate && hull.face_vertices == hull.vertices.size()) {
                pg.faces = hull.faces;
                for (std::size_t f = 0; f < hull.faces.size(); ++f) {
                  const Eigen::Vector3d& n = hull.normals[f];
                  pg.planes.emplace_back(n.x(), n.y(), n.z(), n.dot(hull.vertices[hull.faces[f][0]]));
                }
              }
              padded = inflateHull(hull, sp);
              octo = inflateHull(hull, wp);
              pg.inflate = [hull](double pad) -> std::shared_ptr<fcl::CollisionGeometryd> {
                return makeFclConvex(inflateHull(hull, pad));
              };
            } else {
              base = piece.vertices;
              padded = inflateTriangles(piece, sp);
              octo = inflateTriangles(piece, wp);
              pg.inflate = [piece](double pad) -> std::shared_ptr<fcl::CollisionGeometryd> {
                return bvhGeometry(inflateTriangles(piece, pad), piece.triangles);
              };
            }
            if (base.empty()) continue;
            Eigen::Vector3d lo = base.front(), hi = lo;
            for (const auto& v : base) {
              lo = lo.cwiseMin(v);
              hi = hi.cwiseMax(v);
            }
            const Eigen::Vector3d center_shape = 0.5 * (lo + hi);
            pg.radius = 0.0;
            for (const auto& v : base) pg.radius = std::max(pg.radius, (v - center_shape).norm());
            pg.padded_radius = pg.radius;
            for (const auto& v : padded) pg.padded_radius = std::max(pg.padded_radius, (v - center_shape).norm());
            if (hull_mode) {
              pg.geom = makeFclConvex(base);
              pg.padded = sp > 0.0 ? makeFclConvex(padded) : pg.geom;
              pg.octo = wp > 0.0 ? makeFclConvex(octo) : pg.geom;
            } else {
              pg.geom = bvhGeometry(base, piece.triangles);
              pg.padded = sp > 0.0 ? bvhGeometry(padded, piece.triangles) : pg.geom;
              pg.octo = wp > 0.0 ? bvhGeometry(octo, piece.triangles) : pg.geom;
            }
            pg.vertices = std::move(base);
            add(std::move(pg), center_shape);
          }
          continue;
        }
      }
      add(std::move(g), Eigen::Vector3d::Zero());
    }
  }
  const std::size_t dof = model_.dof();
  // Reach: bound on the distance of any collision-geometry point from the base origin, in every configuration.
  {
    std::vector<Eigen::Isometry3d> poses;
    const std::vector<double> q0(dof, 0.0);
    model_.computeLinkTransforms(q0.data(), &poses);
    double d0 = 0.0;  // distance of joint 0's origin (= the origin of its child link) from the base origin
    for (std::size_t l = 0; l < n_links; ++l) {
      if (dof > 0 && model_.chainOffsetBound(0, static_cast<int>(l)) == 0.0) {
        d0 = std::max(d0, poses[l].translation().norm());
      }
    }
    reach_radius_ = 0.0;
    for (const Geom& g : geoms_) {
      const double c = dof > 0 ? model_.chainOffsetBound(0, g.link) : -1.0;
      const double r =
          c < 0.0 ? (poses[g.link] * g.center_local).norm() + g.radius : d0 + c + g.center_local.norm() + g.radius;
      reach_radius_ = std::max(reach_radius_, r);
    }
  }
  // r_i: bound on the distance of any geometry point moved by joint i from the joint axis.
  joint_radius_.assign(dof, 0.0);
  for (std::size_t i = 0; i < dof; ++i) {
    if (model_.isPrismatic(i)) {
      joint_radius_[i] = 1.0;  // every moved point travels exactly |dq_i|
      continue;
    }
    for (const Geom& g : geoms_) {
      const double chain = model_.chainOffsetBound(i, g.link);
      if (chain < 0.0) continue;
      joint_radius_[i] = std::max(joint_radius_[i], chain + g.center_local.norm() + g.radius);
    }
  }
  // Per shape, the same bound for its padded points (checkPath's culling): m per rad of joint i, 0 when i does not
  // move the shape.
  geom_joint_radius_.assign(geoms_.size(), std::vector<double>(dof, 0.0));
  for (std::size_t gi = 0; gi < geoms_.size(); ++gi) {
    const Geom& g = geoms_[gi];
    for (std::size_t i = 0; i < dof; ++i) {
      const double chain = model_.chainOffsetBound(i, g.link);
      if (chain < 0.0) continue;
      geom_joint_radius_[gi][i] =
          model_.isPrismatic(i) ? 1.0 : chain + g.center_local.norm() + std::max(g.radius, g.padded_radius);
    }
  }
  link_poses_.resize(n_links);
  q_scratch_.resize(dof);
  return true;
}

std::vector<LinkGeometry> FclCollisionChecker::linkGeometry(int link) const {
  std::vector<LinkGeometry> out;
  if (link < 0 || link >= static_cast<int>(link_geoms_.size())) return out;
  for (int gi : link_geoms_[link]) {
    const Geom& g = geoms_[gi];
    out.push_back(LinkGeometry{g.type, g.piece, g.origin, g.dims, g.vertices});
  }
  return out;
}

}  // namespace moverl_planning_scene
