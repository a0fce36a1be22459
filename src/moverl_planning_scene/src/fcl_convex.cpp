#include "moverl_planning_scene/fcl_convex.h"

#include "moverl_planning_scene/convex_hull.h"

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

}  // namespace moverl_planning_scene
