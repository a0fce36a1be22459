#include "moverl_planning_scene/pinhole_camera.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace moverl_planning_scene {

bool fitPinhole(const float* xyz, int width, int height, int stride, double tolerance, PinholeCamera* out,
                double* residual, std::string* why) {
  auto fail = [&](const std::string& reason) {
    if (why != nullptr) *why = reason;
    return false;
  };
  if (residual != nullptr) *residual = std::numeric_limits<double>::infinity();
  if (width < 2 || height < 2) return fail("an organized cloud of at least 2 x 2 points is needed");
  if (width > kMaxPinholeSide || height > kMaxPinholeSide) {
    return fail("an organized cloud of at most " + std::to_string(kMaxPinholeSide) + " points a side is fitted");
  }
  stride = std::max(1, stride);
  // Least squares per axis: x / z = a u + b (a = 1 / fx, b = -cx / fx); likewise y / z against v.
  double n = 0, su = 0, suu = 0, sx = 0, sux = 0, sv = 0, svv = 0, sy = 0, svy = 0;
  auto ok = [](const float* p) {
    return std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]) && p[2] > 0;
  };
  for (int v = 0; v < height; v += stride) {
    for (int u = 0; u < width; u += stride) {
      const float* p = xyz + 3 * (static_cast<long>(v) * width + u);
      if (!ok(p)) continue;
      const double rx = p[0] / static_cast<double>(p[2]), ry = p[1] / static_cast<double>(p[2]);
      n += 1;
      su += u;
      suu += static_cast<double>(u) * u;
      sx += rx;
      sux += u * rx;
      sv += v;
      svv += static_cast<double>(v) * v;
      sy += ry;
      svy += v * ry;
    }
  }
  const double du = n * suu - su * su, dv = n * svv - sv * sv;
  if (n < 3 || du <= 0 || dv <= 0) return fail("too few points with a return on distinct rows and columns");
  const double ax = (n * sux - su * sx) / du, bx = (sx - ax * su) / n;
  const double ay = (n * svy - sv * sy) / dv, by = (sy - ay * sv) / n;
  if (!(ax > 0) || !(ay > 0))
    return fail("points do not lie on a pinhole image's rays in an optical frame (z forward)");
  PinholeCamera c;
  c.width = width;
  c.height = height;
  c.fx = 1.0 / ax;
  c.fy = 1.0 / ay;
  c.cx = -bx * c.fx;
  c.cy = -by * c.fy;
  // The check covers every point, not only the fitted subset (a camera's columns off their rays between the
  // strides would go unseen): |fx x / z + cx - u| <= tolerance as |fx x + (cx - u) z| <= tolerance z, no division.
  double worst = 0.0;
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u) {
      const float* p = xyz + 3 * (static_cast<long>(v) * width + u);
      if (!ok(p)) continue;
      const double z = p[2];
      const double eu = std::fabs(c.fx * p[0] + (c.cx - u) * z), ev = std::fabs(c.fy * p[1] + (c.cy - v) * z);
      if (eu > tolerance * z || ev > tolerance * z) worst = std::max(worst, std::max(eu, ev) / z);
    }
  }
  if (residual != nullptr) *residual = worst;
  if (!(worst <= tolerance)) {
    return fail("points lie up to " + std::to_string(worst) + " px from a pinhole image's rays (tolerance " +
                std::to_string(tolerance) + " px)");
  }
  *out = c;
  return true;
}

}  // namespace moverl_planning_scene
