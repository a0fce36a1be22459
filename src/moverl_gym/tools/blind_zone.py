#!/usr/bin/env python3
"""How far the depth cameras' points on the robot and on the static objects lie from their collision shapes.

The sensed map leaves out the points that belong to the robot or (obstacles:=sensed) to a static object: those within
octomap/self_filter_padding of the robot's collision shapes, within octomap/static_filter_padding of a static object
(config/planning_scene.yaml). Whatever else lies in those zones is not seen: they are the map's blind zone, and they
must be as thin as the cameras allow (README, "A person seen only by cameras"). This tool measures what the cameras
need: it renders every camera of the worlds with PyBullet's segmentation mask, in random collision-free
configurations of the robot drawn as its visual meshes (as a real camera sees it), and measures the distance of every
point on the robot (on a static object) from that body's collision shapes in PyBullet (the planning scene's shapes
contain PyBullet's: test_geometry_parity.py, so the distance to the scene's shapes is at most this). Points inside a
shape count 0.

    python src/moverl_gym/tools/blind_zone.py [--robot panda | my_arm.yaml] [--worlds table human case]
        [-n 20] [--seed 0]

Prints, per world, the points on the robot and on static objects, and their largest and 99.9th-percentile distance
outside the shapes (mm). ROS-free (moverl_sim's core in this process).
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
import pybullet

from moverl_gym.paths import robot_config_file, world_file
from moverl_sim.camera import Camera
from moverl_sim.robot_config import load_robot_config
from moverl_sim.settings import simulator_for
from moverl_sim.world import load_world

PROBE_RADIUS = 1e-4  # m: the probe sphere that stands for a point
SEARCH = 0.2  # m: points farther than this from their body are reported as this


def _distances(p, probe, body, points):
    """Distance (m, >= 0) of each point from `body`'s collision shapes (0 inside)."""
    out = np.empty(len(points))
    for k, x in enumerate(points):
        p.resetBasePositionAndOrientation(probe, x.tolist(), [0, 0, 0, 1])
        closest = p.getClosestPoints(body, probe, SEARCH)
        d = min((c[8] for c in closest), default=SEARCH) + PROBE_RADIUS
        out[k] = max(0.0, d)
    return out


def measure(robot: str, world_name: str, n: int, seed: int, looks: str = "visual") -> dict:
    rc = load_robot_config(robot if robot.endswith(".yaml") else robot_config_file(robot))
    world = load_world(world_file(world_name))
    # The robot as a real camera sees it, its visual meshes by default (--robot-visuals: as the simulator's cameras
    # draw it, config/sim.yaml robot_visuals), so that the distance measured is that surface's from the shapes.
    sim = simulator_for(rc, world, robot_visuals=looks)
    p = sim.client
    # The probe is added only while distances are measured: the simulator's depth scene (camera_renderer raster) draws
    # the bodies it was built with and refuses to render once another is added.
    probe_shape = p.createCollisionShape(pybullet.GEOM_SPHERE, radius=PROBE_RADIUS)
    cams = [Camera(c) for c in world.cameras]
    static = {o.id for o in world.objects if o.motion is None}
    bodies = {}  # body unique id -> "robot" or a static object id
    for oid, (body, _) in sim.object_bodies.items():
        if oid in static:
            bodies[body] = oid
    bodies[sim.robot] = "robot"
    rng = np.random.default_rng(seed)
    robot_d, static_d = [], []
    configs = 0
    while configs < n:
        q = rng.uniform(sim.lower, sim.upper)
        sim.reset_robot(q.tolist())
        if sim.contacts_now().in_contact:
            continue
        configs += 1
        views = [(cam, *sim.render_segmented(cam)) for cam in cams]  # config/sim.yaml camera_renderer draws them
        probe = p.createMultiBody(0, probe_shape, -1, [9, 9, 9])
        for cam, depth, seg in views:
            seg = seg.reshape(-1)
            pts = cam.optical_to_world(cam.points_from_depth(depth))
            body_of = seg & ((1 << 24) - 1)  # PyBullet packs (link + 1) << 24 | body into the mask
            for body, name in bodies.items():
                mask = (seg >= 0) & (body_of == body)
                if not mask.any():
                    continue
                d = _distances(p, probe, body, pts[mask])
                (robot_d if name == "robot" else static_d).append(d)
        p.removeBody(probe)
    sim.close()

    def stats(ds):
        d = np.concatenate(ds) if ds else np.zeros(0)
        if d.size == 0:
            return {"points": 0, "max_mm": float("nan"), "p999_mm": float("nan")}
        return {"points": int(d.size), "max_mm": float(d.max() * 1e3), "p999_mm": float(np.percentile(d, 99.9) * 1e3)}

    return {"robot": stats(robot_d), "static": stats(static_d), "configurations": configs}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robot", default="panda", help="robot config name (config/robots/<robot>.yaml) or file")
    ap.add_argument("--worlds", nargs="+", default=["table", "human", "case"])
    ap.add_argument("-n", type=int, default=20, help="random collision-free configurations per world")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--robot-visuals",
        default="visual",
        choices=["visual", "simplified", "collision"],
        help="how the robot is drawn (default visual: as a real camera sees it; config/sim.yaml robot_visuals)",
    )
    args = ap.parse_args(argv)
    print(
        f"== points of the depth cameras outside the collision shapes of their body ({args.robot} drawn as "
        f"robot_visuals {args.robot_visuals}, {args.n} configurations per world)"
    )
    print(f"{'world':<8} {'body':<7} {'points':>8} {'max mm':>8} {'p99.9 mm':>9}")
    for w in args.worlds:
        r = measure(args.robot, w, args.n, args.seed, args.robot_visuals)
        for body in ("robot", "static"):
            s = r[body]
            print(f"{w:<8} {body:<7} {s['points']:>8} {s['max_mm']:>8.2f} {s['p999_mm']:>9.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
