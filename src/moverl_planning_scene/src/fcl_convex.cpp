#include "moverl_planning_scene/fcl_convex.h"

#include "moverl_planning_scene/convex_hull.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <fcl/geometry/shape/box.h>
#include <fcl/geometry/shape/capsule.h>
#include <fcl/geometry/shape/cone.h>
#include <fcl/geometry/shape/cylinder.h>
#include <fcl/geometry/shape/sphere.h>

namespace moverl_planning_scene {

std::shared_ptr<fcl::Convexd> makeFclConvex(const std::vector<Eigen::Vector3d>& points) {
  const ConvexHull hull = computeConvexHull(points);
  if (hull.degenerate || hull.face_vertices != hull.vertices.size()) {
    return std::make_shared<fcl::Convexd>(std::make_shared<const std::vector<fcl::Vector3d>>(points), 0,
                                          std::make_shared<const std::vector<int>>());
  }
  std::vector<int> faces;
  faces.reserve(hull.faces.size() * 4);
  for (const auto& f : hull.faces) faces.insert(faces.end(), {3, f[0], f[1], f[2]});
  return std::make_shared<fcl::Convexd>(std::make_shared<const std::vector<fcl::Vector3d>>(hull.vertices),
                                        static_cast<int>(hull.faces.size()),
                                        std::make_shared<const std::vector<int>>(std::move(faces)));
}

bool hasShapeSupport(const fcl::CollisionGeometryd& shape) {
  switch (shape.getNodeType()) {  // the shapes shapeSupport's switch answers
    case fcl::GEOM_CONVEX:
    case fcl::GEOM_BOX:
    case fcl::GEOM_SPHERE:
    case fcl::GEOM_CAPSULE:
    case fcl::GEOM_CYLINDER:
    case fcl::GEOM_CONE:
      return true;
    default:
      return false;
  }
}

double shapeSupport(const fcl::CollisionGeometryd& shape, const Eigen::Isometry3d& tf, const Eigen::Vector3d& n) {
  const Eigen::Vector3d l = tf.linear().transpose() * n;  // n in the shape's frame
  const double at = n.dot(tf.translation()), radial = std::hypot(l.x(), l.y());
  switch (shape.getNodeType()) {
    case fcl::GEOM_CONVEX: {
      double best = -std::numeric_limits<double>::infinity();
      for (const auto& v : static_cast<const fcl::Convexd&>(shape).getVertices()) best = std::max(best, l.dot(v));
      return at + best;
    }
    case fcl::GEOM_BOX:
      return at + 0.5 * static_cast<const fcl::Boxd&>(shape).side.cwiseProduct(l.cwiseAbs()).sum();
    case fcl::GEOM_SPHERE:
      return at + static_cast<const fcl::Sphered&>(shape).radius;
    case fcl::GEOM_CAPSULE: {
      const auto& c = static_cast<const fcl::Capsuled&>(shape);
      return at + c.radius + 0.5 * c.lz * std::fabs(l.z());
    }
    case fcl::GEOM_CYLINDER: {
      const auto& c = static_cast<const fcl::Cylinderd&>(shape);
      return at + c.radius * radial + 0.5 * c.lz * std::fabs(l.z());
    }
    case fcl::GEOM_CONE: {  // the apex, or the base circle's point farthest along n
      const auto& c = static_cast<const fcl::Coned&>(shape);
      return at + std::max(0.5 * c.lz * l.z(), -0.5 * c.lz * l.z() + c.radius * radial);
    }
    default:
      return std::numeric_limits<double>::infinity();
  }
}

}  // namespace moverl_planning_scene
