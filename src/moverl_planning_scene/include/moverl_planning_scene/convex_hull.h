/**
 * \file convex_hull.h
 * \brief 3-D convex hulls of point sets and their outward inflation (ROS-free).
 *
 * PyBullet turns every mesh piece of a link into the convex hull of its vertices (btConvexHullShape), so the scene
 * needs the same hull: all of its extreme points (a point set that misses one is a smaller shape), and its faces to
 * inflate it exactly by a padding.
 */
#pragma once

#include <Eigen/Core>
#include <array>
#include <vector>

namespace moverl_planning_scene {

/// \brief Convex hull of a point set.
struct ConvexHull {
  /// Points whose convex hull contains every input point: the hull's vertices plus, rarely, input points that
  /// round-off left a hair's breadth outside the computed faces (`loose`).
  std::vector<Eigen::Vector3d> vertices;
  /// Triangles of the hull's surface (indices into vertices, counter-clockwise seen from outside). Empty when
  /// degenerate.
  std::vector<std::array<int, 3>> faces;
  /// Unit outward normal of each face.
  std::vector<Eigen::Vector3d> normals;
  /// Number of leading entries of `vertices` that are vertices of the faces; the rest are loose points.
  std::size_t face_vertices = 0;
  /// True when the input has fewer than 4 distinct points, or they are (nearly) coplanar or collinear, or the hull
  /// computation could not be verified: then `vertices` holds every distinct input point and there are no faces.
  bool degenerate = false;
};

/// \brief Convex hull of `points` (incremental quickhull; the result is verified: a closed surface whose faces have
///        every vertex on their inner side and every input point inside, else it falls back to `degenerate`).
ConvexHull computeConvexHull(const std::vector<Eigen::Vector3d>& points);

/// \brief Points whose convex hull contains the Minkowski sum of the hull with a ball of radius `padding`.
///
/// A hull vertex v moves to v + m / k * padding, where m is the unit mean of the outward normals n_f of its faces and
/// k = min_f m . n_f: every direction u of v's normal cone is a non-negative combination of the n_f, so
/// u . m / k >= |u| and the support function grows by at least `padding` in every direction of the cone (and by at
/// most padding / k). A vertex with a wide normal cone (k < 0.9) gets one such point per sub-cone (m, n_j, n_j+1)
/// between consecutive faces around it (split into four, up to 3 times, until none overshoots by more than 25 %);
/// if that fails, and for loose points and
/// degenerate hulls, the 12 vertices of an icosahedron around it whose inscribed sphere has radius `padding` (26 %).
std::vector<Eigen::Vector3d> inflateHull(const ConvexHull& hull, double padding);

}  // namespace moverl_planning_scene
