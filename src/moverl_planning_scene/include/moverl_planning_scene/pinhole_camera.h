/**
 * \file pinhole_camera.h
 * \brief The pinhole model of an organized depth-camera cloud, read from the cloud itself. ROS-free.
 *
 * A depth camera's driver (depth_image_proc's point_cloud_xyz, the simulator's cameras) publishes an organized cloud
 * (one point per pixel, row-major) in the camera's optical frame (REP 103: z forward, x right, y down). Every point of
 * pixel (u, v) lies on that pixel's ray, ((u - cx) / fx, (v - cy) / fy, 1) z, so the intrinsics can be fitted from the
 * points (a least-squares line per image axis) and the fit checked: a cloud whose points stray from the fitted rays by
 * more than a tolerance (a distorted image, a cloud in a frame turned from the optical one, an unorganized cloud) is
 * not a pinhole image, and the occupancy map integrates it by ray casting instead (OccupancyMap::computeUpdate). No
 * CameraInfo topic is needed: the cloud carries its own geometry. One case the fit cannot tell: a cloud of a single
 * flat wall facing the camera, in a frame shifted from the optical centre, fits other intrinsics exactly (ray casting
 * would cast from the same wrong origin); the cloud's frame must be the camera's optical frame, as REP 103 says.
 */
#pragma once

#include <string>

namespace moverl_planning_scene {

/// \brief Intrinsics in pixel indices: pixel (u, v), u the column and v the row from 0, samples the ray
///        ((u - cx) / fx, (v - cy) / fy, 1) of the optical frame.
struct PinholeCamera {
  int width = 0;
  int height = 0;
  double fx = 0.0, fy = 0.0, cx = 0.0, cy = 0.0;
};

/// \brief The widest and tallest image fitPinhole fits (the projective update keeps pixel rectangles in 16 bits).
constexpr int kMaxPinholeSide = 32767;

/// \brief The least-squares sums of a pinhole fit (x / z = a u + b per axis), row by row: the rows' sums added in
///        row order give the same intrinsics however the rows were shared out (fitPinhole, CloudIntegrator's passes).
struct PinholeFit {
  double n = 0, su = 0, suu = 0, sx = 0, sux = 0, sv = 0, svv = 0, sy = 0, svy = 0;
  /// Adds row v's points (width of them, x y z each) in every stride-th column (no return: skipped).
  void addRow(const float* row_xyz, int v, int width, int stride);
  void add(const PinholeFit& other);
  /// The intrinsics of an image width x height; false with *why when too few points fall on distinct rows and
  /// columns, or when they do not lie on an optical frame's rays.
  bool solve(int width, int height, PinholeCamera* out, std::string* why) const;
};

/// \brief True when an image width x height can be fitted (at least 2 x 2, at most kMaxPinholeSide a side); else
///        false with *why.
bool pinholeImageSize(int width, int height, std::string* why);

/// \brief The largest distance (pixels) from its pixel's ray of row v's points (width of them) that lie farther than
///        `tolerance`; 0 when none does.
double pinholeRowResidual(const PinholeCamera& camera, const float* row_xyz, int v, double tolerance);

/// \brief True when `worst` (pinholeRowResidual's largest over the rows) is within `tolerance`; else false with *why.
bool pinholeWithin(double worst, double tolerance, std::string* why);

/// \brief Fits the pinhole model of an organized cloud: xyz holds width * height points (x, y, z, row-major, optical
///        frame; non-finite or z <= 0: no return, skipped). Every `stride`-th row and column take part (1: all).
///        False with *why for an image wider or taller than kMaxPinholeSide, when too few points fall on distinct rows
///        and columns, or when any point (all of them are checked) lies farther than `tolerance` pixels from its
///        pixel's fitted ray (*residual: the largest distance over the threshold, pixels; 0 when none is).
bool fitPinhole(const float* xyz, int width, int height, int stride, double tolerance, PinholeCamera* out,
                double* residual, std::string* why);

}  // namespace moverl_planning_scene
