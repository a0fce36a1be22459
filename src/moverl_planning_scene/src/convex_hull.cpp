#include "moverl_planning_scene/convex_hull.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <map>
#include <utility>

namespace moverl_planning_scene {
namespace {

// Plane tolerance of the construction, relative to the point set's scale (coordinates and extent): a point less
// than this above a face counts as on it. 1e-9 of 1 m is 1 nm, far below anything physical, far above round-off.
constexpr double kPlaneEps = 1e-9;
// A face whose vertex lies this far above its plane makes the hull non-convex: the construction failed (relative).
constexpr double kConvexityEps = 1e-7;
// Input points farther than this outside the faces are kept as loose points (relative).
constexpr double kLooseEps = 1e-12;
// Inflation: one offset point per vertex when it overshoots by at most 1 / kOneCos (11 %); else one per sub-cone of
// the normal cone when none overshoots by more than 1 / kSubCos (25 %); else an icosahedron (26 %).
constexpr double kOneCos = 0.9;
constexpr double kSubCos = 0.8;
constexpr int kSplitDepth = 3;  // a sub-cone is split into at most 4^3 = 64

struct Face {
  std::array<int, 3> v{};   // point indices, counter-clockwise seen from outside
  std::array<int, 3> nb{};  // neighbour across edge (v[i], v[i + 1])
  Eigen::Vector3d n = Eigen::Vector3d::Zero();
  double d = 0.0;  // plane: n . x = d (n = 0 for a zero-area face: never visible)
  std::vector<int> outside;
  int furthest = -1;
  double furthest_dist = 0.0;
  bool alive = true;
  int visible_stamp = -1, tested_stamp = -1;
};

class QuickHull {
 public:
  QuickHull(const std::vector<Eigen::Vector3d>& p, double eps) : p_(p), eps_(eps) {}

  /// Builds the hull; false when the input is degenerate or the topology broke.
  bool run() {
    if (!initialSimplex()) return false;
    std::vector<int> stack;
    for (int f = 0; f < static_cast<int>(faces_.size()); ++f) stack.push_back(f);
    int stamp = 0;
    while (!stack.empty()) {
      const int fi = stack.back();
      stack.pop_back();
      if (!faces_[fi].alive || faces_[fi].outside.empty()) continue;
      if (!addPoint(fi, ++stamp, &stack)) return false;
    }
    return true;
  }
  const std::vector<Face>& faces() const { return faces_; }

 private:
  double dist(const Face& f, int i) const { return f.n.dot(p_[i]) - f.d; }

  int makeFace(int a, int b, int c) {
    Face f;
    f.v = {a, b, c};
    const Eigen::Vector3d n = (p_[b] - p_[a]).cross(p_[c] - p_[a]);
    const double norm = n.norm();
    if (norm > 0.0) {
      f.n = n / norm;
      f.d = f.n.dot((p_[a] + p_[b] + p_[c]) / 3.0);
    }
    faces_.push_back(std::move(f));
    return static_cast<int>(faces_.size()) - 1;
  }

  void assign(int point, const std::vector<int>& candidates) {
    for (int f : candidates) {
      Face& face = faces_[f];
      const double d = dist(face, point);
      if (d > eps_) {
        face.outside.push_back(point);
        if (d > face.furthest_dist) {
          face.furthest_dist = d;
          face.furthest = point;
        }
        return;
      }
    }  // inside every candidate: not on the hull
  }

  bool initialSimplex() {
    const int n = static_cast<int>(p_.size());
    Eigen::Vector3d lo = p_[0], hi = p_[0];
    for (const auto& q : p_) {
      lo = lo.cwiseMin(q);
      hi = hi.cwiseMax(q);
    }
    int axis = 0;
    (hi - lo).maxCoeff(&axis);
    int i0 = 0, i1 = 0;
    for (int i = 0; i < n; ++i) {
      if (p_[i][axis] < p_[i0][axis]) i0 = i;
      if (p_[i][axis] > p_[i1][axis]) i1 = i;
    }
    if ((p_[i1] - p_[i0]).norm() <= eps_) return false;
    const Eigen::Vector3d dir = (p_[i1] - p_[i0]).normalized();
    int i2 = -1;
    double best = eps_;
    for (int i = 0; i < n; ++i) {
      const double d = (p_[i] - p_[i0]).cross(dir).norm();
      if (d > best) best = d, i2 = i;
    }
    if (i2 < 0) return false;  // collinear
    const Eigen::Vector3d normal = (p_[i1] - p_[i0]).cross(p_[i2] - p_[i0]).normalized();
    int i3 = -1;
    best = eps_;
    for (int i = 0; i < n; ++i) {
      const double d = std::fabs(normal.dot(p_[i] - p_[i0]));
      if (d > best) best = d, i3 = i;
    }
    if (i3 < 0) return false;  // coplanar
    const std::array<int, 4> s = {i0, i1, i2, i3};
    const Eigen::Vector3d centre = (p_[i0] + p_[i1] + p_[i2] + p_[i3]) / 4.0;
    const int tri[4][3] = {{0, 1, 2}, {0, 3, 1}, {0, 2, 3}, {1, 3, 2}};
    for (const auto& t : tri) {
      int a = s[t[0]], b = s[t[1]], c = s[t[2]];
      const Eigen::Vector3d nn = (p_[b] - p_[a]).cross(p_[c] - p_[a]);
      if (nn.dot(centre - p_[a]) > 0.0) std::swap(b, c);  // the centre must be below
      makeFace(a, b, c);
    }
    // Neighbours: the face holding the reversed edge.
    std::map<std::pair<int, int>, int> edge_face;
    for (int f = 0; f < 4; ++f) {
      for (int e = 0; e < 3; ++e) edge_face[{faces_[f].v[e], faces_[f].v[(e + 1) % 3]}] = f;
    }
    for (int f = 0; f < 4; ++f) {
      for (int e = 0; e < 3; ++e) {
        const auto it = edge_face.find({faces_[f].v[(e + 1) % 3], faces_[f].v[e]});
        if (it == edge_face.end()) return false;
        faces_[f].nb[e] = it->second;
      }
    }
    const std::vector<int> all = {0, 1, 2, 3};
    for (int i = 0; i < n; ++i) {
      if (i != i0 && i != i1 && i != i2 && i != i3) assign(i, all);
    }
    return true;
  }

  bool addPoint(int fi, int stamp, std::vector<int>* stack) {
    const int p = faces_[fi].furthest;
    // Faces visible from p, connected to fi.
    std::vector<int> visible{fi}, todo{fi};
    faces_[fi].visible_stamp = faces_[fi].tested_stamp = stamp;
    while (!todo.empty()) {
      const int f = todo.back();
      todo.pop_back();
      for (int nb : faces_[f].nb) {
        Face& g = faces_[nb];
        if (g.tested_stamp == stamp) continue;
        g.tested_stamp = stamp;
        if (dist(g, p) > eps_) {
          g.visible_stamp = stamp;
          visible.push_back(nb);
          todo.push_back(nb);
        }
      }
    }
    // Horizon: edges of visible faces whose neighbour is not visible, as in the visible face (a -> b).
    struct Edge {
      int a, b, outer;
    };
    std::vector<Edge> horizon;
    for (int f : visible) {
      for (int e = 0; e < 3; ++e) {
        const int nb = faces_[f].nb[e];
        if (faces_[nb].visible_stamp != stamp) horizon.push_back({faces_[f].v[e], faces_[f].v[(e + 1) % 3], nb});
      }
    }
    if (horizon.size() < 3) return false;
    std::map<int, int> by_start;  // horizon edge start vertex -> new face
    std::vector<int> created;
    for (const Edge& h : horizon) {
      const int nf = makeFace(h.a, h.b, p);
      if (!by_start.emplace(h.a, nf).second) return false;  // the horizon is not a simple loop
      created.push_back(nf);
      Face& outer = faces_[h.outer];
      int j = 0;
      while (j < 3 && !(outer.v[j] == h.b && outer.v[(j + 1) % 3] == h.a)) ++j;
      if (j == 3) return false;
      outer.nb[j] = nf;
      faces_[nf].nb[0] = h.outer;
    }
    for (int nf : created) {
      const int b = faces_[nf].v[1];
      const auto it = by_start.find(b);
      if (it == by_start.end()) return false;
      faces_[nf].nb[1] = it->second;  // edge (b, p) <-> edge (p, b) of the face starting at b
      faces_[it->second].nb[2] = nf;
    }
    std::vector<int> points;
    for (int f : visible) {
      faces_[f].alive = false;
      for (int q : faces_[f].outside) {
        if (q != p) points.push_back(q);
      }
      std::vector<int>().swap(faces_[f].outside);
    }
    for (int q : points) assign(q, created);
    stack->insert(stack->end(), created.begin(), created.end());
    return true;
  }

  const std::vector<Eigen::Vector3d>& p_;
  const double eps_;
  std::vector<Face> faces_;
};

ConvexHull degenerateHull(std::vector<Eigen::Vector3d> points) {
  ConvexHull h;
  h.vertices = std::move(points);
  h.degenerate = true;
  return h;
}

/// The 12 vertices of an icosahedron centred at c whose inscribed sphere has radius r.
void icosahedron(const Eigen::Vector3d& c, double r, std::vector<Eigen::Vector3d>* out) {
  const double phi = 0.5 * (1.0 + std::sqrt(5.0));
  const double s = r / (phi * phi / std::sqrt(3.0));  // inradius of the (0, +-1, +-phi) icosahedron: phi^2 / sqrt(3)
  for (double a : {-1.0, 1.0}) {
    for (double b : {-phi, phi}) {
      out->push_back(c + s * Eigen::Vector3d(0.0, a, b));
      out->push_back(c + s * Eigen::Vector3d(a, b, 0.0));
      out->push_back(c + s * Eigen::Vector3d(b, 0.0, a));
    }
  }
}

}  // namespace

ConvexHull computeConvexHull(const std::vector<Eigen::Vector3d>& points) {
  std::vector<Eigen::Vector3d> pts;
  pts.reserve(points.size());
  for (const auto& q : points) {
    if (q.allFinite()) pts.push_back(q);
  }
  std::sort(pts.begin(), pts.end(), [](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    return std::lexicographical_compare(a.data(), a.data() + 3, b.data(), b.data() + 3);
  });
  pts.erase(std::unique(pts.begin(), pts.end()), pts.end());
  if (pts.size() < 4) return degenerateHull(std::move(pts));
  double scale = 0.0;
  Eigen::Vector3d lo = pts[0], hi = pts[0];
  for (const auto& q : pts) {
    scale = std::max(scale, q.cwiseAbs().maxCoeff());
    lo = lo.cwiseMin(q);
    hi = hi.cwiseMax(q);
  }
  scale = std::max(scale, (hi - lo).maxCoeff());
  QuickHull qh(pts, kPlaneEps * scale);
  if (!qh.run()) return degenerateHull(std::move(pts));

  // Collect the surface and verify it: closed (every edge shared by two live faces in opposite directions), convex
  // (no vertex above a face) and containing every input point.
  const std::vector<Face>& faces = qh.faces();
  std::map<int, int> index;  // point -> hull vertex
  ConvexHull h;
  for (const Face& f : faces) {
    if (!f.alive) continue;
    std::array<int, 3> t{};
    for (int e = 0; e < 3; ++e) {
      const Face& g = faces[f.nb[e]];
      bool shared = g.alive;
      if (shared) {
        shared = false;
        for (int j = 0; j < 3; ++j) shared |= g.v[j] == f.v[(e + 1) % 3] && g.v[(j + 1) % 3] == f.v[e];
      }
      if (!shared) return degenerateHull(std::move(pts));
      const auto it = index.emplace(f.v[e], static_cast<int>(h.vertices.size()));
      if (it.second) h.vertices.push_back(pts[f.v[e]]);
      t[e] = it.first->second;
    }
    h.faces.push_back(t);
    h.normals.push_back(f.n);
  }
  h.face_vertices = h.vertices.size();
  std::vector<double> offsets;
  for (const Face& f : faces) {
    if (f.alive) offsets.push_back(f.d);
  }
  for (std::size_t f = 0; f < h.faces.size(); ++f) {
    for (const auto& v : h.vertices) {
      if (h.normals[f].dot(v) - offsets[f] > kConvexityEps * scale) return degenerateHull(std::move(pts));
    }
  }
  for (std::size_t i = 0; i < pts.size(); ++i) {
    if (index.count(static_cast<int>(i))) continue;
    for (std::size_t f = 0; f < h.faces.size(); ++f) {
      if (h.normals[f].dot(pts[i]) - offsets[f] > kLooseEps * scale) {
        h.vertices.push_back(pts[i]);  // a hair outside: keep it, so that the point set's hull contains it
        break;
      }
    }
  }
  return h;
}

namespace {

/// Unit mean m of the directions and k = min m . n (0 when they cancel out): every non-negative combination u of
/// them has u . m >= k |u|.
double coneAxis(const std::vector<Eigen::Vector3d>& normals, Eigen::Vector3d* m) {
  *m = Eigen::Vector3d::Zero();
  for (const auto& n : normals) *m += n;
  if (m->norm() <= 1e-9) return 0.0;
  m->normalize();
  double k = 1.0;
  for (const auto& n : normals) k = std::min(k, m->dot(n));
  return k;
}

/// Offset points for v that cover the cone of the unit directions a, b, c (each overshooting by at most 1 / kSubCos),
/// splitting it into four (normalised edge midpoints) up to `depth` times. False when that is not enough.
bool coverCone(const Eigen::Vector3d& v, double padding, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
               const Eigen::Vector3d& c, int depth, std::vector<Eigen::Vector3d>* out) {
  Eigen::Vector3d m;
  const double k = coneAxis({a, b, c}, &m);
  if (k >= kSubCos) {
    out->push_back(v + m * (padding / k));
    return true;
  }
  const Eigen::Vector3d ab = a + b, bc = b + c, ca = c + a;
  if (depth == 0 || ab.norm() < 1e-9 || bc.norm() < 1e-9 || ca.norm() < 1e-9) return false;
  const Eigen::Vector3d mab = ab.normalized(), mbc = bc.normalized(), mca = ca.normalized();
  return coverCone(v, padding, a, mab, mca, depth - 1, out) && coverCone(v, padding, mab, b, mbc, depth - 1, out) &&
         coverCone(v, padding, mca, mbc, c, depth - 1, out) && coverCone(v, padding, mab, mbc, mca, depth - 1, out);
}

}  // namespace

std::vector<Eigen::Vector3d> inflateHull(const ConvexHull& hull, double padding) {
  if (!(padding > 0.0)) return hull.vertices;
  std::vector<Eigen::Vector3d> out;
  if (hull.degenerate) {
    for (const auto& v : hull.vertices) icosahedron(v, padding, &out);
    return out;
  }
  // Faces around each vertex, in order: face (v, a, b) is followed by the face whose vertex before v is a.
  std::vector<std::vector<int>> around(hull.face_vertices);
  for (std::size_t f = 0; f < hull.faces.size(); ++f) {
    for (int k : hull.faces[f]) around[k].push_back(static_cast<int>(f));
  }
  auto rotated = [&](int f, int v) {  // (v, after v, before v)
    const auto& t = hull.faces[f];
    const int j = t[0] == v ? 0 : (t[1] == v ? 1 : 2);
    return std::array<int, 3>{t[j], t[(j + 1) % 3], t[(j + 2) % 3]};
  };
  for (std::size_t i = 0; i < hull.vertices.size(); ++i) {
    const Eigen::Vector3d& v = hull.vertices[i];
    if (i >= hull.face_vertices) {  // loose point
      icosahedron(v, padding, &out);
      continue;
    }
    std::vector<Eigen::Vector3d> cone;  // the normal cone's generators (zero-area faces: their neighbours span it)
    for (int f : around[i]) {
      if (hull.normals[f].squaredNorm() > 0.0) cone.push_back(hull.normals[f]);
    }
    Eigen::Vector3d m;
    const double k = cone.empty() ? 0.0 : coneAxis(cone, &m);
    if (k >= kOneCos) {
      out.push_back(v + m * (padding / k));
      continue;
    }
    // Split the cone into the sub-cones (m, n_j, n_j+1) between consecutive faces around v (they cover it: m lies
    // inside), one offset point each, split further where that point would overshoot by more than 1 / kSubCos.
    std::vector<int> order;
    if (k > 0.0) {
      const int vi = static_cast<int>(i);
      std::map<int, int> by_before;  // vertex before v -> face
      for (int f : around[i]) by_before[rotated(f, vi)[2]] = f;
      int f = around[i].front();
      while (order.size() <= around[i].size()) {
        order.push_back(f);
        const auto next = by_before.find(rotated(f, vi)[1]);
        if (next == by_before.end() || next->second == order.front()) break;
        f = next->second;
      }
      if (order.size() != around[i].size() || by_before.size() != around[i].size()) order.clear();  // not a fan
    }
    std::vector<Eigen::Vector3d> points;
    for (std::size_t j = 0; j < order.size(); ++j) {
      const Eigen::Vector3d& a = hull.normals[order[j]];
      const Eigen::Vector3d& b = hull.normals[order[(j + 1) % order.size()]];
      const Eigen::Vector3d& na = a.squaredNorm() > 0.0 ? a : m;  // zero-area face: nothing to cover there
      const Eigen::Vector3d& nb = b.squaredNorm() > 0.0 ? b : m;
      if (!coverCone(v, padding, m, na, nb, kSplitDepth, &points)) {
        points.clear();
        break;
      }
    }
    if (points.empty()) {
      icosahedron(v, padding, &out);
    } else {
      out.insert(out.end(), points.begin(), points.end());
    }
  }
  return out;
}

}  // namespace moverl_planning_scene
