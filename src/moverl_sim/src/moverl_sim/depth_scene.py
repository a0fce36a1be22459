"""The depth cameras' own renderer: a PyBullet world's visual shapes drawn as triangles by a depth-only rasterizer.

ROS-free. PyBullet's TinyRenderer shades colour at every pixel; a depth camera needs only the nearest surface's
z, which a rasterizer of its own (src/depth_raster, C++ with a C ABI, loaded here with ctypes) draws in a fraction
of the time (``render_cost.py`` measures both). ``DepthScene.from_client`` reads every body's visual shapes once
(``getVisualShapeData``: boxes, spheres, cylinders, capsules, OBJ/STL meshes with their scale and local frame) as
triangles in the frames of their links; ``render`` asks PyBullet where the links are now and draws them with a
``moverl_sim.camera.Camera``'s intrinsics, pose and clip planes, with the camera's conventions (z-depth, far =
no return, nearer than near clipped).

Curved primitives are drawn as polyhedra that enclose them: every face lies on a tangent plane (the rings of a
surface of revolution widened by 1 / cos of half their angular step), so a pixel whose ray hits the shape is never
missed and reads at most ~0.5 % of the radius nearer (``CURVE_SEGMENTS`` around, ``CURVE_STACKS`` from pole to
pole). A shape this renderer does not draw (a plane, a mesh of another format, a mesh built from vertices in
memory) is refused when the scene is built, naming what is drawn.
"""

from __future__ import annotations

import ctypes
import math
from dataclasses import dataclass

import numpy as np
import pybullet

from .camera import Camera, quaternion_to_rotation
from .meshes import SIMPLIFIABLE, read_mesh

__all__ = [
    "DepthScene",
    "world_depth",
    "ray_depth",
    "revolved",
    "box_mesh",
    "sphere_mesh",
    "cylinder_mesh",
    "capsule_mesh",
    "CURVE_SEGMENTS",
]

#: Segments around a curved primitive's axis, and stacks from pole to pole of a sphere (a capsule's caps share them).
CURVE_SEGMENTS = 48
CURVE_STACKS = 24

#: PyBullet geometry types this renderer draws, by name (for the error naming them).
DRAWN = {
    pybullet.GEOM_BOX: "box",
    pybullet.GEOM_SPHERE: "sphere",
    pybullet.GEOM_CYLINDER: "cylinder",
    pybullet.GEOM_CAPSULE: "capsule",
    pybullet.GEOM_MESH: "mesh (%s)" % ", ".join(SIMPLIFIABLE),
}

_LIBRARY = "libmoverl_depth_raster.so"
_STATUS = {-1: "bad image (size, focal length or clip planes)", -2: "a missing vertex or part", -3: "bad counts"}
_raster = None


def _rasterizer():
    """moverl_depth_raster from the library catkin builds into devel/lib (on the library path once env.sh or
    devel/setup.bash is sourced)."""
    global _raster
    if _raster is None:
        try:
            lib = ctypes.CDLL(_LIBRARY)
        except OSError as exc:
            raise RuntimeError(
                "the depth cameras' rasterizer %s is not on the library path (catkin_make builds it into devel/lib; "
                "source env.sh): %s" % (_LIBRARY, exc)
            ) from None
        fn = lib.moverl_depth_raster
        c_int, c_double, ptr = ctypes.c_int, ctypes.c_double, ctypes.c_void_p
        fn.argtypes = [c_int, c_int] + [c_double] * 5 + [c_int, ptr, ptr, c_int, ptr, ptr, c_int, ptr, ptr, ptr]
        fn.restype = c_int
        _raster = fn
    return _raster


def revolved(profile, segments=CURVE_SEGMENTS):
    """A surface of revolution about z: ``profile`` is a list of (radius, z) from one end to the other (radius 0 at
    a closed end). Each ring is widened by 1 / cos(pi / segments), so that its faces are tangent to the surface the
    profile's own (radius, z) points lie on. Returns (vertices n x 3, triangles m x 3)."""
    widen = 1.0 / math.cos(math.pi / segments)
    phi = 2.0 * math.pi * np.arange(segments) / segments
    ring_xy = np.column_stack((np.cos(phi), np.sin(phi))) * widen
    vertices = np.concatenate([np.column_stack((ring_xy * rho, np.full(segments, z))) for rho, z in profile]).astype(
        np.float64
    )
    j = np.arange(segments)
    k = (j + 1) % segments
    triangles = []
    for i in range(len(profile) - 1):
        a, b = i * segments, (i + 1) * segments
        triangles.append(np.column_stack((a + j, a + k, b + k)))
        triangles.append(np.column_stack((a + j, b + k, b + j)))
    return vertices, np.concatenate(triangles).astype(np.int64)


def _outward(vertices, triangles):
    """A convex solid's triangles about the origin, each wound counter-clockwise seen from outside (its normal
    (b - a) x (c - a) pointing away from the origin), the degenerate ones (a pole's) left out: the rasterizer culls
    the back faces of such a part."""
    a, b, c = (vertices[triangles[:, i]] for i in range(3))
    normal = np.cross(b - a, c - a)
    keep = np.linalg.norm(normal, axis=1) > 1e-12 * max(1.0, float(np.abs(vertices).max()) ** 2)
    inward = np.einsum("ij,ij->i", normal, a + b + c) < 0.0
    triangles = np.where(inward[:, None], triangles[:, [0, 2, 1]], triangles)
    return vertices, triangles[keep]


def _arc(radius, stacks, z_offset, first, last):
    """Profile points of a sphere's meridian at polar angles first..last (indices of stacks steps from the +z pole),
    on the circle whose chords are tangent to the sphere of this radius."""
    step = math.pi / stacks
    r = radius / math.cos(step / 2.0)
    return [(r * math.sin(i * step), r * math.cos(i * step) + z_offset) for i in range(first, last + 1)]


# The primitives, centred on their frames (cylinders and capsules along z, PyBullet's): closed, wound outwards.
def sphere_mesh(radius):
    return _outward(*revolved(_arc(radius, CURVE_STACKS, 0.0, 0, CURVE_STACKS)))


def cylinder_mesh(radius, length):
    h = length / 2.0
    return _outward(*revolved([(0.0, -h), (radius, -h), (radius, h), (0.0, h)]))


def capsule_mesh(radius, length):
    half = CURVE_STACKS // 2
    h = length / 2.0
    return _outward(
        *revolved(_arc(radius, CURVE_STACKS, h, 0, half) + _arc(radius, CURVE_STACKS, -h, half, CURVE_STACKS))
    )


def box_mesh(size):
    s = np.asarray(size, dtype=np.float64) / 2.0
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=np.float64) * s
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    triangles = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    return _outward(corners, np.asarray(triangles, dtype=np.int64))


def _shape_mesh(body, link, geom, dims, filename):
    """Triangles of one visual shape in its own frame, or ValueError naming what is drawn."""
    if geom == pybullet.GEOM_BOX:
        return box_mesh(dims)
    if geom == pybullet.GEOM_SPHERE:
        return sphere_mesh(dims[0])
    if geom == pybullet.GEOM_CYLINDER:
        return cylinder_mesh(dims[1], dims[0])
    if geom == pybullet.GEOM_CAPSULE:
        return capsule_mesh(dims[1], dims[0])
    what = "geometry type %d" % geom
    if geom == pybullet.GEOM_MESH:
        if filename:
            try:
                vertices, triangles = read_mesh(filename)
            except (OSError, ValueError) as exc:
                raise ValueError("body %d link %d: the depth cameras' renderer cannot read %s" % (body, link, exc))
            return vertices * np.asarray(dims, dtype=np.float64), triangles
        what = "a mesh without a file"
    raise ValueError(
        "body %d link %d: the depth cameras' renderer does not draw %s; it draws %s (or set camera_renderer: "
        "tinyrenderer)" % (body, link, what, ", ".join(DRAWN.values()))
    )


@dataclass
class _Body:
    uid: int
    base: int  # part index of its base, or -1
    links: list  # link indices with visual shapes
    link_parts: np.ndarray  # their part indices
    inertial: tuple  # the base's local inertial frame (position, orientation): the base's visuals are placed in it


def ray_depth(obj, t, origin, dirs):
    """Ray parameter of each ray's first hit on a world object (moverl_sim.world.WorldObject: box, sphere or
    cylinder) at motion time t, rays from origin along dirs (n x 3); inf where it misses. With directions whose
    optical z is 1, the parameter is the z-depth."""
    R = quaternion_to_rotation(obj.quaternion)
    o = (origin - np.asarray(obj.position_at(t))) @ R
    d = dirs @ R
    with np.errstate(divide="ignore", invalid="ignore"):
        if obj.shape == "box":
            half = np.asarray(obj.size) / 2.0
            t1, t2 = (-half - o) / d, (half - o) / d
            near = np.nanmax(np.minimum(t1, t2), axis=1)
            far = np.nanmin(np.maximum(t1, t2), axis=1)
            return np.where((near <= far) & (near > 0), near, np.inf)
        if obj.shape == "sphere":
            r = obj.size[0]
            b = (d * o).sum(1)
            a = (d * d).sum(1)
            disc = b * b - a * ((o * o).sum() - r * r)
            hit = (-b - np.sqrt(disc)) / a
            return np.where((disc >= 0) & (hit > 0), hit, np.inf)
        h, r = obj.size
        a = d[:, 0] ** 2 + d[:, 1] ** 2
        b = o[0] * d[:, 0] + o[1] * d[:, 1]
        disc = b * b - a * (o[0] ** 2 + o[1] ** 2 - r * r)
        side = (-b - np.sqrt(disc)) / a
        best = np.where((disc >= 0) & (side > 0) & (np.abs(o[2] + side * d[:, 2]) <= h / 2), side, np.inf)
        for zc in (-h / 2, h / 2):
            cap = (zc - o[2]) / d[:, 2]
            on = (cap > 0) & ((o[0] + cap * d[:, 0]) ** 2 + (o[1] + cap * d[:, 1]) ** 2 <= r * r)
            best = np.where(on & (cap < best), cap, best)
        return best


def world_depth(objects, t, camera: Camera):
    """The exact z-depth image (height x width; inf: nothing) of a world file's objects at motion time t seen by
    camera, ray-cast shape by shape (no robot, no clip planes): what a renderer's image of them should read."""
    dirs = np.column_stack((camera._rays_x, camera._rays_y, np.ones_like(camera._rays_x))) @ camera.rotation.T
    origin = np.asarray(camera.position)
    hits = [ray_depth(o, t, origin, dirs) for o in objects]
    depth = np.min(hits, axis=0) if hits else np.full(len(dirs), np.inf)
    return depth.reshape(camera.height, camera.width)


class DepthScene:
    """Every body's visual shapes in a PyBullet client, as triangles in their links' frames; rendered by a Camera."""

    def __init__(self, client_id, parts, closed, vertices, vertex_part, triangles, bodies, body_count=None):
        self.client_id = client_id
        self.parts = parts  # part index -> (body unique id, link index: -1 the base)
        self._closed = np.ascontiguousarray(closed, dtype=np.uint8)  # only primitives: back faces culled
        self._vertices = np.ascontiguousarray(vertices, dtype=np.float32)
        self._vertex_part = np.ascontiguousarray(vertex_part, dtype=np.int32)
        self._triangles = np.ascontiguousarray(triangles, dtype=np.int32)
        self._bodies = bodies
        # the bodies of the world it was built for (default: the client's now): a body added later is not drawn
        self._body_count = pybullet.getNumBodies(physicsClientId=client_id) if body_count is None else body_count
        self._positions = np.zeros((len(parts), 3))
        self._quaternions = np.zeros((len(parts), 4))

    @property
    def triangle_count(self):
        return len(self._triangles)

    def drawing_only(self, bodies):
        """This scene with only the triangles of `bodies` (PyBullet unique ids) drawn; every part is still placed.
        For measuring what each body's triangles cost a render (render_cost.py --by-body)."""
        body_of_part = np.asarray([uid for uid, _ in self.parts], dtype=np.int64)
        drawn = self._triangles
        if len(drawn):
            drawn = drawn[np.isin(body_of_part[self._vertex_part[drawn[:, 0]]], list(bodies))]
        return DepthScene(
            self.client_id,
            self.parts,
            self._closed,
            self._vertices,
            self._vertex_part,
            drawn.reshape(-1, 3),
            self._bodies,
            body_count=self._body_count,  # this scene's world: a body added since is refused as here
        )

    @classmethod
    def from_client(cls, client_id):
        """Reads every body's visual shapes (call once the world is built: bodies added later are not drawn)."""
        parts, part_of, verts, vpart, tris, closed = [], {}, [], [], [], []
        n_vertices = 0
        bodies = []
        for i in range(pybullet.getNumBodies(physicsClientId=client_id)):
            uid = pybullet.getBodyUniqueId(i, physicsClientId=client_id)
            for shape in pybullet.getVisualShapeData(uid, physicsClientId=client_id):
                _, link, geom, dims, filename, local_xyz, local_quat = shape[:7]
                v, t = _shape_mesh(uid, link, geom, dims, filename.decode("utf-8", "replace"))
                v = v @ quaternion_to_rotation(local_quat).T + np.asarray(local_xyz)
                key = (uid, link)
                if key not in part_of:
                    part_of[key] = len(parts)
                    parts.append(key)
                    closed.append(True)
                closed[part_of[key]] = closed[part_of[key]] and geom != pybullet.GEOM_MESH
                verts.append(v)
                vpart.append(np.full(len(v), part_of[key]))
                tris.append(t + n_vertices)
                n_vertices += len(v)
        for uid in sorted({u for u, _ in parts}):
            links = sorted(link for u, link in parts if u == uid and link >= 0)
            dyn = pybullet.getDynamicsInfo(uid, -1, physicsClientId=client_id)
            bodies.append(
                _Body(
                    uid,
                    part_of.get((uid, -1), -1),
                    links,
                    np.asarray([part_of[(uid, link)] for link in links], dtype=np.int64),
                    (dyn[3], dyn[4]),
                )
            )
        if not parts:
            return cls(client_id, [], [], np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3)), [])
        return cls(client_id, parts, closed, np.concatenate(verts), np.concatenate(vpart), np.concatenate(tris), bodies)

    def _poses(self):
        """Every part's link frame in the world now: fills self._positions, self._quaternions."""
        cid = self.client_id
        for body in self._bodies:
            if body.base >= 0:
                # PyBullet reports a base by its inertial frame; its visuals are given in the base's link frame.
                xyz, quat = pybullet.getBasePositionAndOrientation(body.uid, physicsClientId=cid)
                inv = pybullet.invertTransform(body.inertial[0], body.inertial[1])
                xyz, quat = pybullet.multiplyTransforms(xyz, quat, inv[0], inv[1])
                self._positions[body.base] = xyz
                self._quaternions[body.base] = quat
            if body.links:
                states = pybullet.getLinkStates(body.uid, body.links, computeForwardKinematics=1, physicsClientId=cid)
                for part, state in zip(body.link_parts, states):
                    self._positions[part] = state[4]  # the link (URDF) frame, not the inertial one
                    self._quaternions[part] = state[5]

    def render(self, camera: Camera, parts=False):
        """z-depth image (height x width float32, far = no return) of the scene now, seen by camera; with
        parts=True also which part each pixel sees (height x width int32, -1: none; self.parts names them)."""
        if pybullet.getNumBodies(physicsClientId=self.client_id) != self._body_count:
            raise ValueError(
                "camera %s: bodies were added or removed since the depth scene was built: it would not draw them "
                "(build the scene once the world is complete)" % camera.id
            )
        self._poses()
        if not (np.all(np.isfinite(self._positions)) and np.all(np.isfinite(self._quaternions))):
            raise ValueError("camera %s: a body's pose is not finite: nothing drawn would be right" % camera.id)
        rc = camera.rotation  # optical axes in the world
        # camera_from_part = R_c^T [R_p | p - c]
        rot = np.einsum("ji,njk->nik", rc, quaternion_to_rotation(self._quaternions))
        trans = (self._positions - np.asarray(camera.position)) @ rc
        poses = np.ascontiguousarray(np.concatenate((rot.reshape(-1, 9), trans), axis=1), dtype=np.float64)
        depth = np.empty((camera.height, camera.width), dtype=np.float32)
        seen = np.empty((camera.height, camera.width), dtype=np.int32) if parts else None
        cx, cy = camera.principal_point
        status = _rasterizer()(
            camera.width,
            camera.height,
            camera.focal,
            cx,
            cy,
            camera.near,
            camera.far,
            len(self.parts),
            poses.ctypes.data,
            self._closed.ctypes.data,
            len(self._vertex_part),
            self._vertices.ctypes.data,
            self._vertex_part.ctypes.data,
            len(self._triangles),
            self._triangles.ctypes.data,
            depth.ctypes.data,
            seen.ctypes.data if parts else None,
        )
        if status != 0:
            raise ValueError("camera %s: the rasterizer refused: %s" % (camera.id, _STATUS.get(status, status)))
        return (depth, seen) if parts else depth
