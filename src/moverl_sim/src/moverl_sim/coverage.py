"""How much of the obstacle surface the robot can reach do a world's depth cameras see? ROS-free.

Used to place the cameras of the repo worlds (``render_world --cameras`` prints it; a unit test keeps it
high). The obstacle surfaces are sampled on a grid (about one sample per 2 x 2 cm).

A sample is *reachable* when a probe ball (radius 3 cm, a finger) can get there from the robot: the point 5 cm
out along the sample's outward normal lies in the free space (probe centres clear of every object) that is
within the robot's reach of its shoulder (moverl_sim.workspace.Workspace, from the robot's model: for the Panda
0.98 m around (0, 0, 0.333), its 0.858 m flange reach plus its open hand) and above the table top (z >= 0: the
robot works on its table, so surfaces below the table top such as its edges do not count; the OctoMap cells of
the table top hold the edges' top 2 cm), and is connected to the space around the robot (flood fill on a 2 cm
grid from within 0.3 m of the shoulder). Surfaces covered by another object (the table top under the case
floor) and the table top under the robot's base (within the base's radius of its axis: Workspace.base_radius,
0.155 m for the Panda) do not count either.

A sample is *seen* by a camera when it lies in the camera's image and clip range and within ``max_range`` of
the camera (default 3.0 m, the planning scene's OctoMap max_range: longer beams only clear free space), faces
the camera (at most 81 deg from head-on), and the rendered depth at its pixel is not in front of it by more
than 1 cm plus one pixel's depth slope (nothing, the robot included, occludes it).
"""

import math
from dataclasses import dataclass
from typing import Dict, Tuple

import numpy as np

from .camera import quaternion_to_rotation

__all__ = [
    "SurfaceSamples",
    "surface_samples",
    "reachable_mask",
    "visible_mask",
    "coverage_report",
]

PROBE = 0.03  # radius of the ball that must get to a surface (m)
VOXEL = 0.02  # free-space grid (m)
SEED_RADIUS = 0.3  # the flood fill of the accessible space starts from the free space this close to the shoulder (m)
MIN_FACING_COS = 0.15  # surfaces seen more obliquely than ~81 deg do not count
DEPTH_TOL = 0.01  # m
MAX_RANGE = 3.0  # the planning scene's OctoMap max_range (config/planning_scene.yaml)


@dataclass
class SurfaceSamples:
    points: np.ndarray  # N x 3, world frame
    normals: np.ndarray  # N x 3, outward unit normals
    objects: np.ndarray  # N, index into ids
    ids: Tuple[str, ...]


def _box(size, spacing):
    pts, nrm = [], []
    half = np.asarray(size, dtype=float) / 2.0
    for axis in range(3):
        a, b = [i for i in range(3) if i != axis]
        na, nb = (max(1, int(math.ceil(size[i] / spacing))) for i in (a, b))
        ga = (np.arange(na) + 0.5) / na * size[a] - half[a]
        gb = (np.arange(nb) + 0.5) / nb * size[b] - half[b]
        A, B = np.meshgrid(ga, gb)
        for sign in (-1.0, 1.0):
            p = np.zeros((A.size, 3))
            p[:, a], p[:, b], p[:, axis] = A.ravel(), B.ravel(), sign * half[axis]
            n = np.zeros_like(p)
            n[:, axis] = sign
            pts.append(p)
            nrm.append(n)
    return np.vstack(pts), np.vstack(nrm)


def _cylinder(height, radius, spacing):
    """PyBullet cylinder: axis along local z, centred."""
    nt = max(8, int(math.ceil(2 * math.pi * radius / spacing)))
    nz = max(1, int(math.ceil(height / spacing)))
    th = (np.arange(nt) + 0.5) / nt * 2 * math.pi
    zs = (np.arange(nz) + 0.5) / nz * height - height / 2.0
    T, Z = np.meshgrid(th, zs)
    side = np.column_stack((radius * np.cos(T.ravel()), radius * np.sin(T.ravel()), Z.ravel()))
    side_n = np.column_stack((np.cos(T.ravel()), np.sin(T.ravel()), np.zeros(T.size)))
    cap = [np.zeros((1, 2))]
    nr = max(1, int(math.ceil(radius / spacing)))
    for k in range(1, nr + 1):
        r = radius * (k - 0.5) / nr
        m = max(6, int(math.ceil(2 * math.pi * r / spacing)))
        a = (np.arange(m) + 0.5) / m * 2 * math.pi
        cap.append(np.column_stack((r * np.cos(a), r * np.sin(a))))
    cap = np.vstack(cap)
    pts, nrm = [side], [side_n]
    for sign in (-1.0, 1.0):
        pts.append(np.column_stack((cap, np.full(len(cap), sign * height / 2.0))))
        nrm.append(np.tile([0.0, 0.0, sign], (len(cap), 1)))
    return np.vstack(pts), np.vstack(nrm)


def _sphere(radius, spacing):
    n = max(20, int(math.ceil(4 * math.pi * radius**2 / spacing**2)))
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    th = math.pi * (1 + 5**0.5) * i
    nrm = np.column_stack((np.cos(th) * np.sin(phi), np.sin(th) * np.sin(phi), np.cos(phi)))
    return radius * nrm, nrm


def surface_samples(world, spacing=0.02, t=0.0):
    """Sample every object's surface (about one point per spacing x spacing), objects at motion time t."""
    pts, nrm, idx = [], [], []
    for k, obj in enumerate(world.objects):
        if obj.shape == "box":
            p, n = _box(obj.size, spacing)
        elif obj.shape == "cylinder":
            p, n = _cylinder(obj.size[0], obj.size[1], spacing)
        else:
            p, n = _sphere(obj.size[0], spacing)
        R = quaternion_to_rotation(obj.quaternion)
        pts.append(p @ R.T + np.asarray(obj.position_at(t)))
        nrm.append(n @ R.T)
        idx.append(np.full(len(p), k))
    if not pts:
        return SurfaceSamples(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, dtype=int), ())
    return SurfaceSamples(np.vstack(pts), np.vstack(nrm), np.concatenate(idx), tuple(o.id for o in world.objects))


def _distance(obj, points, t):
    """Euclidean distance of each point to the object (0 inside)."""
    R = quaternion_to_rotation(obj.quaternion)
    local = (np.asarray(points, dtype=float) - np.asarray(obj.position_at(t))) @ R
    if obj.shape == "box":
        return np.linalg.norm(np.maximum(np.abs(local) - np.asarray(obj.size) / 2.0, 0.0), axis=1)
    if obj.shape == "sphere":
        return np.maximum(np.linalg.norm(local, axis=1) - obj.size[0], 0.0)
    h, r = obj.size
    radial = np.maximum(np.hypot(local[:, 0], local[:, 1]) - r, 0.0)
    axial = np.maximum(np.abs(local[:, 2]) - h / 2.0, 0.0)
    return np.hypot(radial, axial)


def accessible_space(world, workspace, t=0.0, probe=PROBE, voxel=VOXEL):
    """Boolean grid of the probe-ball centres the robot can bring there (module docstring), and a lookup
    function points -> bool. ``workspace``: the robot's moverl_sim.workspace.Workspace."""
    c = np.asarray(workspace.shoulder, dtype=float)
    reach = workspace.reach
    lo = c - reach
    lo[2] = max(lo[2], 0.0)
    n = np.ceil((c + reach - lo) / voxel).astype(int) + 1
    axes = [lo[i] + voxel * np.arange(n[i]) for i in range(3)]
    X, Y, Z = np.meshgrid(*axes, indexing="ij")
    centres = np.column_stack((X.ravel(), Y.ravel(), Z.ravel()))
    free = np.linalg.norm(centres - c, axis=1) <= reach
    for obj in world.objects:
        sel = np.flatnonzero(free)
        free[sel] &= _distance(obj, centres[sel], t) > probe
    free = free.reshape(n)
    # Flood fill from the free space near the shoulder.
    reached = free & (np.linalg.norm(centres - c, axis=1) <= SEED_RADIUS).reshape(n)
    while True:
        grown = reached.copy()
        grown[1:] |= reached[:-1]
        grown[:-1] |= reached[1:]
        grown[:, 1:] |= reached[:, :-1]
        grown[:, :-1] |= reached[:, 1:]
        grown[:, :, 1:] |= reached[:, :, :-1]
        grown[:, :, :-1] |= reached[:, :, 1:]
        grown &= free
        if np.array_equal(grown, reached):
            break
        reached = grown

    def lookup(points):
        idx = np.rint((np.asarray(points, dtype=float) - lo) / voxel).astype(int)
        ok = np.all((idx >= 0) & (idx < n), axis=1)
        out = np.zeros(len(idx), dtype=bool)
        out[ok] = reached[idx[ok, 0], idx[ok, 1], idx[ok, 2]]
        return out

    return reached, lookup


def reachable_mask(samples, world, workspace, t=0.0, probe=PROBE):
    """Samples on a surface the robot (its moverl_sim.workspace.Workspace) can touch (module docstring)."""
    p, n = samples.points, samples.normals
    if len(p) == 0:
        return np.zeros(0, dtype=bool)
    _, lookup = accessible_space(world, workspace, t, probe)
    q = p + (probe + VOXEL) * n
    ok = lookup(q) & (q[:, 2] >= 0.0)
    ok &= ~((np.hypot(p[:, 0], p[:, 1]) < workspace.base_radius) & (np.abs(p[:, 2]) < 1e-3) & (n[:, 2] > 0.5))
    just_out = p + 0.002 * n  # covered by another object (the table top under the case floor)
    for k, obj in enumerate(world.objects):
        other = np.flatnonzero(ok & (samples.objects != k))
        ok[other] &= _distance(obj, just_out[other], t) > 0.0
    return ok


def visible_mask(camera, depth, samples, max_range=MAX_RANGE, max_spacing=None):
    """Samples that ``camera`` (moverl_sim.camera.Camera) sees in its rendered z-depth image ``depth``.
    With ``max_spacing`` (m), only where neighbouring pixels' points are at most that far apart on the surface
    (distance / focal length / cos(incidence))."""
    p = camera.world_to_optical(samples.points)
    z = p[:, 2]
    seen = np.zeros(len(p), dtype=bool)
    front = (z > camera.near) & (z < camera.far) & (np.linalg.norm(p, axis=1) < max_range)
    if not front.any():
        return seen
    u, v = camera.project(p[front])
    ui, vi = np.rint(u).astype(int), np.rint(v).astype(int)
    inside = (ui >= 0) & (ui < camera.width) & (vi >= 0) & (vi < camera.height)
    to_cam = np.asarray(camera.position) - samples.points[front]
    cos = np.einsum("ij,ij->i", to_cam, samples.normals[front]) / np.linalg.norm(to_cam, axis=1)
    facing = cos >= MIN_FACING_COS
    ok = inside & facing
    zf = z[front]
    rendered = np.full(len(zf), -np.inf)
    rendered[ok] = depth[vi[ok], ui[ok]]
    tan = np.sqrt(np.maximum(0.0, 1.0 - cos**2)) / np.maximum(cos, MIN_FACING_COS)
    tol = DEPTH_TOL + zf / camera.focal * tan
    ok &= rendered >= zf - tol
    if max_spacing is not None:
        dist = np.linalg.norm(to_cam, axis=1)
        ok &= dist / camera.focal / np.maximum(cos, 1e-6) <= max_spacing
    seen[np.flatnonzero(front)] = ok
    return seen


def coverage_report(world, cameras, depths, samples, workspace, t=0.0, max_range=MAX_RANGE):
    """{object id: (reachable samples, seen by at least one camera)}, per-camera seen masks and the
    reachable mask. ``depths``: each camera's rendered z-depth image, same order as ``cameras``; ``workspace``: the
    robot's moverl_sim.workspace.Workspace."""
    reach = reachable_mask(samples, world, workspace, t)
    per_camera = [visible_mask(c, d, samples, max_range) for c, d in zip(cameras, depths)]
    seen = np.zeros(len(samples.points), dtype=bool)
    for m in per_camera:
        seen |= m
    table: Dict[str, Tuple[int, int]] = {}
    for k, oid in enumerate(samples.ids):
        sel = reach & (samples.objects == k)
        if sel.any():
            table[oid] = (int(sel.sum()), int((sel & seen).sum()))
    return table, per_camera, reach, seen
