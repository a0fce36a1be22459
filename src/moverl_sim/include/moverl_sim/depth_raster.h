// A depth-only triangle rasterizer for the simulator's depth cameras. ROS-free, no dependencies; a C ABI, because
// its caller is Python (moverl_sim.depth_scene, through ctypes).
//
// Why our own: PyBullet's TinyRenderer shades colour for every pixel and costs 1.8 ms for a 160x120 image of the
// human world without the robot (render_cost.py); a camera needs only the z-depth of the nearest surface, which for
// the same scene is a small fraction of that. The image follows moverl_sim.camera.Camera's conventions: REP 103
// optical frame (z forward, x right, y down), pixel (u, v) samples the image point ((u - cx) / f, (v - cy) / f, 1),
// depth is z (not the ray length), and a pixel whose nearest surface lies beyond the far plane, or that sees nothing,
// reads exactly `far_clip` (Camera's "no return"). Surfaces nearer than `near_clip` are clipped away.
//
// Coverage: a pixel is covered by a triangle when its sample point lies inside it or on its edges, with a tolerance
// of 1e-6 of the barycentric coordinates, so that the pixels on an edge two triangles share are covered by both
// (no crack through a closed mesh). Back faces are culled only in parts the caller marks closed and wound outwards
// (counter-clockwise seen from outside; the primitives moverl_sim.depth_scene builds): a mesh read from a file,
// whose winding nobody checked, is drawn whole.
#pragma once

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/// Return codes of moverl_depth_raster.
enum MoverlDepthRasterStatus {
  MOVERL_DEPTH_RASTER_OK = 0,
  MOVERL_DEPTH_RASTER_BAD_IMAGE = -1,  ///< width or height < 1, focal <= 0, not 0 < near_clip < far_clip
  MOVERL_DEPTH_RASTER_BAD_INDEX = -2,  ///< a triangle names a missing vertex, or a vertex a missing part
  MOVERL_DEPTH_RASTER_BAD_COUNT = -3,  ///< a negative count, or a null array with a nonzero count
};

/// Renders the triangles into `depth` (height * width floats, row-major: pixel (u, v) at v * width + u), which it
/// overwrites: each pixel the z of the nearest surface between near_clip and far_clip, else far_clip.
///
/// Vertices are given in the frames of rigid parts (a link, an object): `vertices` n_vertices x 3 floats,
/// `vertex_part` the part of each vertex, and `camera_from_part` n_parts x 12 doubles, each part's pose in the
/// camera's optical frame: a row-major rotation (9) then a translation (3); `part_closed` (nullable, n_parts): nonzero
/// for a part whose triangles bound a closed surface wound outwards (its back faces are skipped, unless the near plane
/// cuts the part, or the part holds the camera: it would vanish). `triangles`:
/// n_triangles x 3 vertex indices. `pixel_part` (nullable, height * width): the part of the nearest triangle at each
/// pixel, -1 where none. Returns a MoverlDepthRasterStatus; on an error the images are left untouched.
int moverl_depth_raster(int width, int height, double focal, double cx, double cy, double near_clip, double far_clip,
                        int n_parts, const double* camera_from_part, const uint8_t* part_closed, int n_vertices,
                        const float* vertices, const int32_t* vertex_part, int n_triangles, const int32_t* triangles,
                        float* depth, int32_t* pixel_part);

#ifdef __cplusplus
}
#endif
