/**
 * \file fcl_checker_internal.h
 * \brief What the FclCollisionChecker's source files share (not installed): the link and obstacle records. The checker
 *        is split by concern: fcl_collision_checker.cpp (state, path and point queries), link_geometry.cpp (the robot's
 *        collision geometry: meshes, hulls, padding), world_objects.cpp (obstacles and the volumes moving ones sweep),
 *        acm.cpp (the allowed-collision matrix and its cache).
 */
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <fcl/geometry/collision_geometry.h>
#include <Eigen/Geometry>
#include <array>

#include "moverl_planning_scene/fcl_collision_checker.h"

namespace moverl_planning_scene {

/// A convex hull's distance field on a grid in the shape's frame: each grid vertex's distance to the hull (0 inside),
/// for the self filter's point test (FclCollisionChecker::pointMask). The distance to a convex set is a convex function
/// that changes no faster than the point moves, so the eight vertices of the grid cell around a point bound its
/// distance: from above by their trilinear interpolation (the weights are a convex combination of the vertices that
/// reproduces the point: Jensen's inequality), from below by the nearest vertex's distance less the way to it. Most of
/// a cloud's points on or near a link are settled by these bounds; the hull's faces answer the rest.
struct HullDistanceGrid {
  Eigen::Vector3d lo = Eigen::Vector3d::Zero();  ///< the first vertex (shape frame)
  double h = 0.0, inv_h = 0.0;                   ///< vertex spacing (m) and its inverse
  double margin = 0.0;  ///< the grid reaches this far beyond the hull's box: a point outside is farther from the hull
  std::array<int, 3> n{{0, 0, 0}};  ///< vertices per axis
  std::vector<float> d;             ///< distances, x fastest (rounded up to a float)
  /// 1: x (shape frame) lies within pad of the hull; -1: farther; 0: the bounds do not settle it.
  int classify(const Eigen::Vector3d& x, double pad) const;
};

/// The distance field of the hull (vertices, triangles, planes as in Geom) on a grid of spacing h reaching margin
/// beyond its box.
std::shared_ptr<const HullDistanceGrid> buildHullDistanceGrid(const std::vector<Eigen::Vector3d>& vertices,
                                                              const std::vector<std::array<int, 3>>& faces,
                                                              const std::vector<Eigen::Vector4d>& planes, double h,
                                                              double margin);

struct FclCollisionChecker::Geom {
  int link = -1;
  ShapeType type = ShapeType::kBox;
  std::string piece;                               // mesh piece name (OBJ object/group)
  Eigen::Vector3d dims = Eigen::Vector3d::Zero();  // primitives (CollisionShapeSpec::dims)
  std::vector<Eigen::Vector3d> vertices;           // meshes: the points whose hull is geom (shape frame)
  // Convex hull meshes whose hull is exactly geom (no loose points): its triangles (indices into vertices) and their
  // planes (unit outward normal, offset: n . x <= d inside), shape frame, for the exact point tests of linkPointMask.
  // Empty otherwise (FCL answers).
  std::vector<std::array<int, 3>> faces;
  std::vector<Eigen::Vector4d> planes;
  // The hull's distance field (with planes only): built when pointMask first tests the shape, under grids_mutex_.
  mutable std::shared_ptr<const HullDistanceGrid> distance_grid;
  std::shared_ptr<fcl::CollisionGeometry<double>> geom;
  Eigen::Isometry3d origin = Eigen::Isometry3d::Identity();  // shape in link frame
  Eigen::Vector3d center_local = Eigen::Vector3d::Zero();    // bounding sphere centre, link frame
  double radius = 0.0;                                       // bounding sphere radius
  Eigen::Isometry3d world_tf = Eigen::Isometry3d::Identity();
  Eigen::Vector3d world_center = Eigen::Vector3d::Zero();
  // The same shape inflated by >= self_padding, for self-collision checks (== geom when self_padding is 0).
  std::shared_ptr<fcl::CollisionGeometry<double>> padded;
  double padded_radius = 0.0;
  // The same shape inflated by >= padding, checked against the sensed octree (whose cells cannot be inflated).
  std::shared_ptr<fcl::CollisionGeometry<double>> octo;
  // The shape inflated by a given amount (m), as octo is by padding: builds the sensed margin's levels.
  std::function<std::shared_ptr<fcl::CollisionGeometry<double>>(double)> inflate;
  // octo_levels[k]: the shape inflated by padding + k * kMarginStep (built when first needed; [0] unused).
  std::vector<std::shared_ptr<fcl::CollisionGeometry<double>>> octo_levels;
};

struct FclCollisionChecker::Obstacle {
  std::string id;
  std::shared_ptr<fcl::CollisionGeometry<double>> geom;
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  double radius = 0.0;  // bounding sphere about pose.translation()
  WorldObject source;   // the object as given (pose at t = 0, unpadded dimensions, motion)
};

}  // namespace moverl_planning_scene
