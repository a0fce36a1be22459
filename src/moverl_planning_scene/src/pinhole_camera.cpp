#include "moverl_planning_scene/pinhole_camera.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace moverl_planning_scene {

namespace {

/// A point with a return in front of the camera.
bool ok(const float* p) { return std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]) && p[2] > 0; }

}  // namespace

void PinholeFit::addRow(const float* row_xyz, int v, int width, int stride) {
  stride = std::max(1, stride);
  for (int u = 0; u < width; u += stride) {
    const float* p = row_xyz + 3 * static_cast<long>(u);
    if (!ok(p)) continue;
    const double inv_z = 1.0 / static_cast<double>(p[2]), rx = p[0] * inv_z, ry = p[1] * inv_z;
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

void PinholeFit::add(const PinholeFit& o) {
  n += o.n;
  su += o.su;
  suu += o.suu;
  sx += o.sx;
  sux += o.sux;
  sv += o.sv;
  svv += o.svv;
  sy += o.sy;
  svy += o.svy;
}

bool PinholeFit::solve(int width, int height, PinholeCamera* out, std::string* why) const {
  const double du = n * suu - su * su, dv = n * svv - sv * sv;
  if (n < 3 || du <= 0 || dv <= 0) {
    if (why != nullptr) *why = "too few points with a return on distinct rows and columns";
    return false;
  }
  const double ax = (n * sux - su * sx) / du, bx = (sx - ax * su) / n;
  const double ay = (n * svy - sv * sy) / dv, by = (sy - ay * sv) / n;
  if (!(ax > 0) || !(ay > 0)) {
    if (why != nullptr) *why = "points do not lie on a pinhole image's rays in an optical frame (z forward)";
    return false;
  }
  out->width = width;
  out->height = height;
  out->fx = 1.0 / ax;
  out->fy = 1.0 / ay;
  out->cx = -bx * out->fx;
  out->cy = -by * out->fy;
  return true;
}

bool pinholeImageSize(int width, int height, std::string* why) {
  if (width < 2 || height < 2) {
    if (why != nullptr) *why = "an organized cloud of at least 2 x 2 points is needed";
    return false;
  }
  if (width > kMaxPinholeSide || height > kMaxPinholeSide) {
    if (why != nullptr) {
      *why = "an organized cloud of at most " + std::to_string(kMaxPinholeSide) + " points a side is fitted";
    }
    return false;
  }
  return true;
}

double pinholeRowResidual(const PinholeCamera& c, const float* row_xyz, int v, double tolerance) {
  // |fx x / z + cx - u| <= tolerance as |fx x + (cx - u) z| <= tolerance z: no division. First whether any point is
  // over, without a branch per point (a value minus itself is 0 only when finite; a NaN fails every comparison); the
  // distances only for a row that has one.
  const double fx = c.fx, fy = c.fy, cx = c.cx, cy = c.cy - v;
  bool over = false;
  double cu = cx;  // cx - u (carried along: up to rounding in its last bits, far below any tolerance)
  for (int u = 0; u < c.width; ++u, cu -= 1.0) {
    const float* p = row_xyz + 3 * static_cast<long>(u);
    const double x = p[0], y = p[1], z = p[2], tz = tolerance * z;
    const bool valid = (x - x == 0.0) & (y - y == 0.0) & (z - z == 0.0) & (z > 0.0);
    over |= valid & ((std::fabs(fx * x + cu * z) > tz) | (std::fabs(fy * y + cy * z) > tz));
  }
  if (!over) return 0.0;
  double worst = 0.0;
  for (int u = 0; u < c.width; ++u) {
    const float* p = row_xyz + 3 * static_cast<long>(u);
    if (!ok(p)) continue;
    const double z = p[2];
    const double eu = std::fabs(c.fx * p[0] + (c.cx - u) * z), ev = std::fabs(c.fy * p[1] + (c.cy - v) * z);
    if (eu > tolerance * z || ev > tolerance * z) worst = std::max(worst, std::max(eu, ev) / z);
  }
  return worst;
}

bool pinholeWithin(double worst, double tolerance, std::string* why) {
  if (worst <= tolerance) return true;
  if (why != nullptr) {
    *why = "points lie up to " + std::to_string(worst) + " px from a pinhole image's rays (tolerance " +
           std::to_string(tolerance) + " px)";
  }
  return false;
}

bool fitPinhole(const float* xyz, int width, int height, int stride, double tolerance, PinholeCamera* out,
                double* residual, std::string* why) {
  if (residual != nullptr) *residual = std::numeric_limits<double>::infinity();
  if (!pinholeImageSize(width, height, why)) return false;
  stride = std::max(1, stride);
  auto row = [&](int v) { return xyz + 3 * static_cast<long>(v) * width; };
  PinholeFit fit;
  for (int v = 0; v < height; v += stride) {
    PinholeFit r;  // each row's sums on their own, as CloudIntegrator's passes add them
    r.addRow(row(v), v, width, stride);
    fit.add(r);
  }
  PinholeCamera c;
  if (!fit.solve(width, height, &c, why)) return false;
  // The check covers every point, not only the fitted subset (a camera's columns off their rays between the strides
  // would go unseen).
  double worst = 0.0;
  for (int v = 0; v < height; ++v) worst = std::max(worst, pinholeRowResidual(c, row(v), v, tolerance));
  if (residual != nullptr) *residual = worst;
  if (!pinholeWithin(worst, tolerance, why)) return false;
  *out = c;
  return true;
}

}  // namespace moverl_planning_scene
