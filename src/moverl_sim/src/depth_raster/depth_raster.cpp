// A depth-only triangle rasterizer for the simulator's depth cameras: see include/moverl_sim/depth_raster.h.
#include "moverl_sim/depth_raster.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

namespace {
/// Barycentric slack of the coverage test: a pixel on an edge two triangles share is covered by both, whatever the
/// rounding of the two edge functions (their values differ in the last bits).
constexpr double kCoverageSlack = 1e-6;

struct Point  // in the camera's optical frame
{
  double x, y, z;
};

struct Vertex  // projected: pixel coordinates and 1 / z (affine in the image, so interpolated linearly)
{
  double u, v, inv_z;
};

struct Image {
  int width, height;
  double focal, cx, cy, near_clip, far_clip;
  double inv_near;    // 1 / near_clip: a nearer surface (a larger 1 / z) is clipped away
  double* inv_depth;  // per pixel 1 / z of the nearest surface so far (1 / far_clip: none); max wins, no division
  int32_t* part;
};

Vertex project(const Image& im, const Point& p) {
  const double inv_z = 1.0 / p.z;
  return {p.x * inv_z * im.focal + im.cx, p.y * inv_z * im.focal + im.cy, inv_z};
}

/// Twice the signed area of the triangle (p, q, r) in the image.
inline double edge(double pu, double pv, double qu, double qv, double ru, double rv) {
  return (qu - pu) * (rv - pv) - (qv - pv) * (ru - pu);
}

void fill(const Image& im, const Vertex& a, const Vertex& b, const Vertex& c, int32_t part) {
  const double area = edge(a.u, a.v, b.u, b.v, c.u, c.v);
  if (!(std::fabs(area) > 1e-12)) return;  // edge-on (covers no sample point), or not finite
  const double lo_u = std::min({a.u, b.u, c.u}), hi_u = std::max({a.u, b.u, c.u});
  const double lo_v = std::min({a.v, b.v, c.v}), hi_v = std::max({a.v, b.v, c.v});
  // The slack widens a triangle by at most kCoverageSlack times its extent.
  const double slack = kCoverageSlack * std::max(hi_u - lo_u, hi_v - lo_v) + 1e-9;
  const double u0 = std::max(0.0, std::ceil(lo_u - slack)), u1 = std::min(im.width - 1.0, std::floor(hi_u + slack));
  const double v0 = std::max(0.0, std::ceil(lo_v - slack)), v1 = std::min(im.height - 1.0, std::floor(hi_v + slack));
  if (!(u0 <= u1 && v0 <= v1))
    return;  // no sample point inside the bounding box (the common case: a mesh's triangles are mostly sub-pixel)
  const double inv_area = 1.0 / area;
  // Along a row each barycentric weight is affine in u: w(u) = w(u_first) + slope * (u - u_first). In a triangle wider
  // than a few pixels, the span of the row where all three reach -slack is solved for first (widened by a pixel for
  // the rounding of that solution: the test per pixel decides), so a slanted sliver costs its pixels, not its box's.
  const double slope[3] = {(b.v - c.v) * inv_area, (c.v - a.v) * inv_area, (a.v - b.v) * inv_area};
  const bool solve_span = u1 - u0 >= 8.0;
  for (int v = static_cast<int>(v0); v <= static_cast<int>(v1); ++v) {
    double first = u0, last = u1;
    if (solve_span) {
      const double w0[3] = {edge(0.0, v, b.u, b.v, c.u, c.v) * inv_area, edge(0.0, v, c.u, c.v, a.u, a.v) * inv_area,
                            edge(0.0, v, a.u, a.v, b.u, b.v) * inv_area};
      for (int i = 0; i < 3; ++i) {
        const double bound = (-kCoverageSlack - w0[i]) / slope[i];  // +-inf or NaN when the slope is 0
        if (slope[i] > 0.0)
          first = std::max(first, std::ceil(bound) - 1.0);
        else if (slope[i] < 0.0)
          last = std::min(last, std::floor(bound) + 1.0);
        else if (w0[i] < -kCoverageSlack)
          last = first - 1.0;
      }
      if (!(first <= last)) continue;
    }
    double* row = im.inv_depth + static_cast<long>(v) * im.width;
    // Barycentric weights of a, b, c at the sample point (u, v): each the area of the triangle the point makes with
    // the opposite edge, over the whole.
    double wa = edge(first, v, b.u, b.v, c.u, c.v) * inv_area;
    double wb = edge(first, v, c.u, c.v, a.u, a.v) * inv_area;
    double wc = edge(first, v, a.u, a.v, b.u, b.v) * inv_area;
    for (int u = static_cast<int>(first); u <= static_cast<int>(last);
         ++u, wa += slope[0], wb += slope[1], wc += slope[2]) {
      if (wa < -kCoverageSlack || wb < -kCoverageSlack || wc < -kCoverageSlack) continue;
      const double inv_z = wa * a.inv_z + wb * b.inv_z + wc * c.inv_z;
      if (!(inv_z > row[u]) || inv_z > im.inv_near)
        continue;  // behind what the pixel sees (or beyond the far plane: row starts at 1 / far), or nearer than near
      row[u] = inv_z;
      if (im.part) im.part[static_cast<long>(v) * im.width + u] = part;
    }
  }
}

/// The triangle's part in front of the near plane (Sutherland-Hodgman against z >= near: 0, 3 or 4 corners),
/// drawn as a fan.
void clipAndFill(const Image& im, const Point (&p)[3], int32_t part) {
  Point poly[4];
  int n = 0;
  for (int i = 0; i < 3; ++i) {
    const Point& s = p[i];
    const Point& e = p[(i + 1) % 3];
    const bool s_in = s.z >= im.near_clip, e_in = e.z >= im.near_clip;
    if (s_in) poly[n++] = s;
    if (s_in != e_in) {
      const double t = (im.near_clip - s.z) / (e.z - s.z);
      poly[n++] = {s.x + t * (e.x - s.x), s.y + t * (e.y - s.y), im.near_clip};
    }
  }
  if (n < 3) return;
  Vertex q[4];
  for (int i = 0; i < n; ++i) q[i] = project(im, poly[i]);
  for (int i = 1; i + 1 < n; ++i) fill(im, q[0], q[i], q[i + 1], part);
}
}  // namespace

extern "C" int moverl_depth_raster(int width, int height, double focal, double cx, double cy, double near_clip,
                                   double far_clip, int n_parts, const double* camera_from_part,
                                   const uint8_t* part_closed, int n_vertices, const float* vertices,
                                   const int32_t* vertex_part, int n_triangles, const int32_t* triangles, float* depth,
                                   int32_t* pixel_part) {
  if (width < 1 || height < 1 || !(focal > 0.0) || !(near_clip > 0.0) || !(far_clip > near_clip) ||
      !std::isfinite(far_clip) || !std::isfinite(cx) || !std::isfinite(cy) || !depth)
    return MOVERL_DEPTH_RASTER_BAD_IMAGE;
  if (n_parts < 0 || n_vertices < 0 || n_triangles < 0 || (n_parts > 0 && !camera_from_part) ||
      (n_vertices > 0 && (!vertices || !vertex_part)) || (n_triangles > 0 && !triangles))
    return MOVERL_DEPTH_RASTER_BAD_COUNT;
  for (int i = 0; i < n_vertices; ++i)
    if (vertex_part[i] < 0 || vertex_part[i] >= n_parts) return MOVERL_DEPTH_RASTER_BAD_INDEX;
  for (long i = 0; i < 3L * n_triangles; ++i)
    if (triangles[i] < 0 || triangles[i] >= n_vertices) return MOVERL_DEPTH_RASTER_BAD_INDEX;

  const long pixels = static_cast<long>(width) * height;
  std::vector<double> inv_depth(pixels, 1.0 / far_clip);
  const Image im{width, height, focal, cx, cy, near_clip, far_clip, 1.0 / near_clip, inv_depth.data(), pixel_part};
  if (pixel_part) std::fill(pixel_part, pixel_part + pixels, -1);

  // Every vertex into the camera frame once (vertices are shared by several triangles).
  std::vector<Point> cam(n_vertices);
  std::vector<Vertex> screen(n_vertices);
  // Each part's nearest vertex: a closed part the near plane cuts (its front faces clipped away; so does a part that
  // holds the camera, every face turned away) would vanish with its back faces culled, so it keeps them.
  std::vector<double> nearest(static_cast<std::size_t>(n_parts), std::numeric_limits<double>::infinity());
  for (int i = 0; i < n_vertices; ++i) {
    const double* m = camera_from_part + 12 * vertex_part[i];
    const double x = vertices[3 * i], y = vertices[3 * i + 1], z = vertices[3 * i + 2];
    cam[i] = {m[0] * x + m[1] * y + m[2] * z + m[9], m[3] * x + m[4] * y + m[5] * z + m[10],
              m[6] * x + m[7] * y + m[8] * z + m[11]};
    if (cam[i].z >= near_clip) screen[i] = project(im, cam[i]);
    double& n = nearest[static_cast<std::size_t>(vertex_part[i])];
    n = std::min(n, cam[i].z);
  }
  std::vector<std::uint8_t> cull(static_cast<std::size_t>(n_parts), 0);
  for (int k = 0; k < n_parts && part_closed; ++k) {
    cull[static_cast<std::size_t>(k)] = part_closed[k] && nearest[static_cast<std::size_t>(k)] >= near_clip;
  }
  for (int t = 0; t < n_triangles; ++t) {
    const int32_t* tri = triangles + 3 * t;
    const Point& a = cam[tri[0]];
    const Point& b = cam[tri[1]];
    const Point& c = cam[tri[2]];
    if (a.z >= far_clip && b.z >= far_clip && c.z >= far_clip) continue;  // wholly beyond the far plane
    const int32_t part = vertex_part[tri[0]];
    if (cull[static_cast<std::size_t>(part)]) {
      // A closed surface wound outwards, wholly beyond the near plane: a face turned away from the camera (its
      // normal along the ray to it) is hidden behind the part's front faces.
      const double ux = b.x - a.x, uy = b.y - a.y, uz = b.z - a.z, vx = c.x - a.x, vy = c.y - a.y, vz = c.z - a.z;
      if ((uy * vz - uz * vy) * a.x + (uz * vx - ux * vz) * a.y + (ux * vy - uy * vx) * a.z >= 0.0) continue;
    }
    if (a.z >= near_clip && b.z >= near_clip && c.z >= near_clip)
      fill(im, screen[tri[0]], screen[tri[1]], screen[tri[2]], part);
    else if (a.z >= near_clip || b.z >= near_clip || c.z >= near_clip) {
      const Point corners[3] = {a, b, c};
      clipAndFill(im, corners, part);
    }
  }
  const double none = 1.0 / far_clip;
  for (long i = 0; i < pixels; ++i)
    depth[i] = inv_depth[i] > none ? static_cast<float>(1.0 / inv_depth[i]) : static_cast<float>(far_clip);
  return MOVERL_DEPTH_RASTER_OK;
}
