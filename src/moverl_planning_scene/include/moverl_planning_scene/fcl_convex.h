/**
 * \file fcl_convex.h
 * \brief Convex hulls as FCL shapes, with the fastest exact support function FCL offers (ROS-free).
 */
#pragma once

#include <memory>
#include <vector>

#include <fcl/geometry/shape/convex.h>
#include <Eigen/Core>
#include <Eigen/Geometry>

namespace moverl_planning_scene {

/// The convex hull of `points` as an fcl::Convex. With the hull's faces, FCL's support function walks the hull's edge
/// graph (hill climbing, exact on a convex polytope: a vertex no neighbour beats is the maximum of a linear function)
/// instead of scanning every point: GJK's support calls were most of the shield's collision-checking time. When the
/// hull is not exact (degenerate, or points that round-off left outside its faces), no faces: FCL then scans every
/// point, which is exactly the support function of their convex hull too.
std::shared_ptr<fcl::Convexd> makeFclConvex(const std::vector<Eigen::Vector3d>& points);

/// The support value max{n . x : x in shape} of an FCL shape placed at tf, for a unit vector n (world frame): convex
/// hulls (every vertex), boxes, spheres, capsules, cylinders and cones (FCL's conventions: centred, axis z, a cone's
/// apex at +lz/2). Infinity for any other shape (triangle meshes, planes): no finite bound is claimed for it.
double shapeSupport(const fcl::CollisionGeometryd& shape, const Eigen::Isometry3d& tf, const Eigen::Vector3d& n);
/// True for the shapes shapeSupport answers (a finite value), false for the others; the two switches of fcl_convex.cpp
/// list the same shapes.
bool hasShapeSupport(const fcl::CollisionGeometryd& shape);

}  // namespace moverl_planning_scene
