"""Simulated depth cameras: render a world camera (moverl_sim.world.WorldCamera) into a 3-D point cloud.

ROS-free. A ``Camera`` holds one camera's geometry, computed once from its xyz / target / up:

* its pose (world -> optical frame, REP 103 optical convention: z forward along the view direction, x right,
  y down in the image), published by the sim node as the static TF ``<id>_optical_frame``;
* PyBullet's view matrix, built from that same pose (so the render and the TF cannot disagree), and the
  projection matrix (vertical ``fov``, aspect width / height, ``near`` / ``far`` clip planes);
* the ray of every pixel.

``Camera.render(client_id)`` renders with PyBullet's TinyRenderer (``getCameraImage``, no segmentation mask),
converts the depth buffer to metric z-depth, ``z = far * near / (far - (far - near) * zbuf)``, and back-projects
every pixel to a point in the optical frame: an (height * width) x 3 float32 array, row-major (pixel (u, v)
is row ``v * width + u``; v = 0 is the top image row).

No return: a pixel whose ray hits nothing before the far clip plane (zbuf = 1) is reported as the point on its
ray at z = far, i.e. a reading at the sensor's range limit. Consumers treat beams at (or beyond) their maximum
range as free space only (no obstacle endpoint), so keep ``far`` above the consumer's max range.
Surfaces closer than ``near`` are clipped away and so also read as no return.

Pixel sampling: TinyRenderer samples pixel (u, v) at the image-plane point x = (u - width/2) / f,
y = (v + 1 - height/2) / f (z = 1), with f = (height/2) / tan(fov/2) pixels; both its depth and its coverage
use that point (measured; the unit tests check it), so ``principal_point`` is (width/2, height/2 - 1) in pixel
indices: for even sizes the pixel (width/2, height/2 - 1) looks exactly along the optical axis.
"""

import math

import numpy as np
import pybullet

from .world import WorldCamera

__all__ = [
    "Camera",
    "look_at_rotation",
    "rotation_to_quaternion",
    "quaternion_to_rotation",
    "depth_from_zbuffer",
]


def look_at_rotation(xyz, target, up=(0.0, 0.0, 1.0)):
    """Rotation matrix (3 x 3, columns = optical x, y, z axes in the world frame) of a camera at xyz looking at
    target, with ``up`` appearing up in the image: z = (target - xyz) normalised, x = z cross up normalised
    (image right), y = z cross x (image down). Raises ValueError when up is parallel to the view direction."""
    z = np.asarray(target, dtype=float) - np.asarray(xyz, dtype=float)
    nz = np.linalg.norm(z)
    if nz < 1e-9:
        raise ValueError("camera target equals its position %r" % (list(xyz),))
    z /= nz
    x = np.cross(z, np.asarray(up, dtype=float))
    nx = np.linalg.norm(x)
    if nx < 1e-9:
        raise ValueError("camera up %r is parallel to its view direction %r" % (list(up), z.tolist()))
    x /= nx
    y = np.cross(z, x)
    return np.column_stack((x, y, z))


def rotation_to_quaternion(R):
    """3 x 3 rotation matrix -> unit quaternion (x, y, z, w), w >= 0."""
    R = np.asarray(R, dtype=float)
    tr = R[0, 0] + R[1, 1] + R[2, 2]
    if tr > 0.0:
        s = 2.0 * math.sqrt(tr + 1.0)
        q = ((R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, 0.25 * s)
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = 2.0 * math.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = (0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s, (R[2, 1] - R[1, 2]) / s)
    elif R[1, 1] > R[2, 2]:
        s = 2.0 * math.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        q = ((R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s, (R[0, 2] - R[2, 0]) / s)
    else:
        s = 2.0 * math.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        q = ((R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s, (R[1, 0] - R[0, 1]) / s)
    q = np.array(q)
    q /= np.linalg.norm(q)
    if q[3] < 0.0:
        q = -q
    return tuple(float(v) for v in q)


def quaternion_to_rotation(q):
    """Unit quaternion (x, y, z, w) -> 3 x 3 rotation matrix; an array of quaternions (..., 4) -> (..., 3, 3)."""
    q = np.asarray(q, dtype=float)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    R = np.empty(q.shape[:-1] + (3, 3))
    R[..., 0, 0] = 1 - 2 * (y * y + z * z)
    R[..., 0, 1] = 2 * (x * y - z * w)
    R[..., 0, 2] = 2 * (x * z + y * w)
    R[..., 1, 0] = 2 * (x * y + z * w)
    R[..., 1, 1] = 1 - 2 * (x * x + z * z)
    R[..., 1, 2] = 2 * (y * z - x * w)
    R[..., 2, 0] = 2 * (x * z - y * w)
    R[..., 2, 1] = 2 * (y * z + x * w)
    R[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def depth_from_zbuffer(zbuf, near, far):
    """OpenGL depth buffer values (0 at near, 1 at far) -> metric z-depth along the optical axis (float64).
    Values >= 1 (nothing hit) give exactly far."""
    zbuf = np.asarray(zbuf, dtype=np.float64)
    depth = far * near / (far - (far - near) * zbuf)
    depth[zbuf >= 1.0] = far
    return depth


class Camera:
    """Geometry and rendering of one WorldCamera (see the module docstring)."""

    def __init__(self, spec: WorldCamera):
        self.spec = spec
        self.id = spec.id
        self.frame_id = spec.optical_frame
        self.width, self.height = int(spec.width), int(spec.height)
        self.near, self.far = float(spec.near), float(spec.far)
        self.period = 1.0 / float(spec.rate)  # simulated seconds between renders
        # Pose: world -> optical frame.
        self.position = tuple(float(v) for v in spec.xyz)
        self.rotation = look_at_rotation(spec.xyz, spec.target, spec.up)  # optical axes in world coordinates
        self.quaternion = rotation_to_quaternion(self.rotation)
        # PyBullet's view matrix from the same pose. OpenGL camera axes: x right = optical x, y up = -optical y,
        # z backwards = -optical z. View = inverse(camera -> world); PyBullet takes 16 floats, column-major.
        R_gl = self.rotation * np.array([1.0, -1.0, -1.0])
        view = np.eye(4)
        view[:3, :3] = R_gl.T
        view[:3, 3] = -R_gl.T @ np.asarray(self.position)
        self.view_matrix = [float(v) for v in view.flatten(order="F")]
        self.projection_matrix = [
            float(v)
            for v in pybullet.computeProjectionMatrixFOV(
                fov=float(spec.fov), aspect=self.width / float(self.height), nearVal=self.near, farVal=self.far
            )
        ]
        # Pinhole model of TinyRenderer's sampling (module docstring).
        self.focal = 0.5 * self.height / math.tan(math.radians(spec.fov) / 2.0)  # pixels
        self.principal_point = (0.5 * self.width, 0.5 * self.height - 1.0)
        cx, cy = self.principal_point
        rx = (np.arange(self.width, dtype=np.float64) - cx) / self.focal
        ry = (np.arange(self.height, dtype=np.float64) - cy) / self.focal
        self._rays_x = np.tile(rx, self.height)  # per pixel, row-major
        self._rays_y = np.repeat(ry, self.width)

    # ------------------------------------------------------------------ geometry
    @property
    def pose(self):
        """((x, y, z), (qx, qy, qz, qw)): the optical frame in the world frame (the camera's static TF)."""
        return self.position, self.quaternion

    def pixel_ray(self, u, v):
        """Direction (x, y, 1) in the optical frame of the ray that pixel (u, v) samples."""
        cx, cy = self.principal_point
        return np.array([(u - cx) / self.focal, (v - cy) / self.focal, 1.0])

    def optical_to_world(self, points):
        """Optical-frame points (N x 3) -> world-frame points (N x 3, float64)."""
        return np.asarray(points, dtype=np.float64) @ self.rotation.T + np.asarray(self.position)

    def world_to_optical(self, points):
        """World-frame points (N x 3) -> optical-frame points (N x 3, float64)."""
        return (np.asarray(points, dtype=np.float64) - np.asarray(self.position)) @ self.rotation

    def project(self, points_optical):
        """Optical-frame points (N x 3, z > 0) -> continuous pixel coordinates (u, v) of the pixels sampling them."""
        p = np.asarray(points_optical, dtype=np.float64)
        cx, cy = self.principal_point
        return p[:, 0] / p[:, 2] * self.focal + cx, p[:, 1] / p[:, 2] * self.focal + cy

    def points_from_depth(self, depth):
        """z-depth image (height x width, metres) -> optical-frame points, (height * width) x 3 float32."""
        z = np.asarray(depth, dtype=np.float64).reshape(-1)
        out = np.empty((z.shape[0], 3), dtype=np.float32)
        out[:, 0] = self._rays_x * z
        out[:, 1] = self._rays_y * z
        out[:, 2] = z
        return out

    # ------------------------------------------------------------------ rendering
    def _image(self, client_id, flags):
        """PyBullet's TinyRenderer image of this camera in physics client ``client_id``: (zbuf, segmentation)."""
        _, _, _, zbuf, seg = pybullet.getCameraImage(
            self.width,
            self.height,
            viewMatrix=self.view_matrix,
            projectionMatrix=self.projection_matrix,
            renderer=pybullet.ER_TINY_RENDERER,
            flags=flags,
            shadow=0,
            physicsClientId=client_id,
        )
        return zbuf, seg

    def render_zbuffer(self, client_id):
        """Render the depth buffer (height x width float32, 0 at near .. 1 at far / no return) with PyBullet's
        TinyRenderer in physics client ``client_id`` (e.g. Simulator.client_id)."""
        zbuf, _ = self._image(client_id, pybullet.ER_NO_SEGMENTATION_MASK)
        return np.asarray(zbuf, dtype=np.float32).reshape(self.height, self.width)

    def render_segmented(self, client_id):
        """Metric z-depth image (as render_depth) and what each pixel sees: PyBullet's segmentation mask (height x
        width int, (link + 1) << 24 | body unique id; -1: no return)."""
        zbuf, seg = self._image(client_id, pybullet.ER_SEGMENTATION_MASK_OBJECT_AND_LINKINDEX)
        depth = depth_from_zbuffer(
            np.asarray(zbuf, dtype=np.float32).reshape(self.height, self.width), self.near, self.far
        )
        return depth, np.asarray(seg).reshape(self.height, self.width)

    def render_depth(self, client_id):
        """Metric z-depth image (height x width, float64; no return = far)."""
        return depth_from_zbuffer(self.render_zbuffer(client_id), self.near, self.far)

    def render(self, client_id):
        """Render and back-project: (height * width) x 3 float32 points in the optical frame (no return: z = far)."""
        return self.points_from_depth(self.render_depth(client_id))
