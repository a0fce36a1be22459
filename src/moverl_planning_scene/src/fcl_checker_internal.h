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
