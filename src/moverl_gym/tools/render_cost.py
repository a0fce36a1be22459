#!/usr/bin/env python3
"""What one depth image costs: each camera of a world rendered by PyBullet's TinyRenderer and by the simulator's own
rasterizer (config/sim.yaml camera_renderer: tinyrenderer, raster), with the robot drawn as its visual meshes, as
those meshes simplified and as its collision shapes (config/sim.yaml robot_visuals: what the simulator's cameras
see), and by PyBullet's batched ray test over the same pixel rays (collision shapes), on one thread and on all, in
this process (no ROS).

    python src/moverl_gym/tools/render_cost.py --world human --renders 10
    python src/moverl_gym/tools/render_cost.py --world human --renders 300 --by-body

The robot stands at its home configuration. Prints, per camera, CPU ms (this process, all threads) and wall ms per
image, how far the other methods' depths are from TinyRenderer's with the visual meshes, and how far each image reads
behind the world file's own shapes (ray-cast exactly, moverl_sim.depth_scene.world_depth) (z-depth, metres; pixels
without a return count as the far plane in both). A baseline for a faster depth camera (issue 25).

--by-body: where the default camera (the rasterizer, the robot simplified) spends an image instead: CPU ms per image
with every body drawn, with none (what a render costs besides triangles: the poses, every vertex into the camera's
frame, the image's buffers), and with each body alone, every camera rendered in turn, twice.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np
import pybullet

#: Rays per rayTestBatch call: below PyBullet's limit (MAX_RAY_INTERSECTION_BATCH_SIZE, 16384; a call of exactly
#: that many answered one ray fewer here).
RAY_BATCH = 16000


def ray_depth(camera, client_id: int, threads: int) -> np.ndarray:
    """z-depth image of `camera` from rayTestBatch over its pixel rays (height x width, far where nothing is hit)."""
    directions = np.stack([camera._rays_x, camera._rays_y, np.ones_like(camera._rays_x)], axis=1) @ camera.rotation.T
    origin = np.asarray(camera.position)
    ends = origin + directions * camera.far  # a ray of z-length far: the far plane, as the renderer's
    starts = np.broadcast_to(origin, ends.shape)
    fractions = []
    for k in range(0, len(ends), RAY_BATCH):
        hits = pybullet.rayTestBatch(
            starts[k : k + RAY_BATCH].tolist(),
            ends[k : k + RAY_BATCH].tolist(),
            numThreads=threads,
            physicsClientId=client_id,
        )
        fractions += [h[2] for h in hits]
    return (np.asarray(fractions) * camera.far).reshape(camera.height, camera.width)


def timed(fn, n: int) -> tuple[float, float, object]:
    """(CPU ms, wall ms) per call of fn over n calls, and its last result."""
    c0, w0 = time.process_time(), time.perf_counter()
    for _ in range(n):
        out = fn()
    return 1e3 * (time.process_time() - c0) / n, 1e3 * (time.perf_counter() - w0) / n, out


def print_behind(image: np.ndarray, exact: np.ndarray) -> None:
    """How far an image reads behind the world file's own shapes (exact: their ray-cast z-depth, inf where a ray misses
    them), over the pixels whose rays hit one: a renderer that draws a surface behind where it is lets the map see
    free what is occupied (the robot, nearer, never reads behind)."""
    hit = np.isfinite(exact)
    gap = (image - exact)[hit]
    on = np.abs(gap) < 0.05  # the pixels that see the shape the ray hits first (not the robot before it)
    print(
        f"{'':8s} {'':>9s}   against the world file's shapes: {100 * np.mean(gap > 1e-3):.2f} % of the {hit.sum()} "
        f"pixels that hit one read > 1 mm behind it (p99 {1e3 * np.percentile(gap[on], 99):+.1f} mm where they see it)"
    )


def print_shares(other: np.ndarray, depth: np.ndarray) -> None:
    """Where another image differs from the reference: nearer (it hides more than the arm) or farther (the camera would
    see past the arm's surface), by more than 1 mm and by more than 1 cm."""
    share = [np.mean(other < depth - t) for t in (1e-3, 1e-2)] + [np.mean(other > depth + t) for t in (1e-3, 1e-2)]
    print(
        f"{'':8s} {'':>9s}   pixels nearer by > 1 mm {100 * share[0]:.2f} %, > 1 cm {100 * share[1]:.2f} %;"
        f" farther by > 1 mm {100 * share[2]:.2f} %, > 1 cm {100 * share[3]:.2f} %"
    )


def by_body(rc, world, renders: int) -> int:
    """Print the default camera's CPU ms per image with every body drawn, none, and each body alone (--by-body)."""
    from moverl_sim.camera import Camera
    from moverl_sim.settings import simulator_for

    sim = simulator_for(rc, world, robot_visuals="simplified", camera_renderer="raster")
    try:
        sim.reset_robot(rc["home"])
        scene = sim.depth_scene  # what the simulator's cameras draw
        if scene is None:
            raise SystemExit(f"render_cost.py: the rasterizer cannot draw this scene: {sim.camera_renderer_fallback}")
        cams = [Camera(spec) for spec in world.cameras]
        uids = sorted({uid for uid, _ in scene.parts})
        objects = {}  # body -> the world objects it is made of
        for oid, (uid, _) in sim.object_bodies.items():
            objects.setdefault(uid, []).append(oid)
        names = {uid: ", ".join(objects[uid]) if uid in objects else f"{rc['name']} (the robot)" for uid in uids}
        drawn = [("every body", scene), ("none (no triangle)", scene.drawing_only([]))]
        drawn += [(f"only {names[uid]}", scene.drawing_only([uid])) for uid in uids]

        def per_image(s) -> float:
            cpu, _, _ = timed(lambda: [s.render(cam) for cam in cams], renders)
            return cpu / len(cams)

        print(f"{world.source}, robot {rc['name']} at home (simplified), the rasterizer, {len(cams)} cameras in turn")
        print(f"{'CPU ms per image, two runs':>26s} {'triangles':>9s}  drawn")
        for label, s in drawn:
            print(f"{per_image(s):13.3f} {per_image(s):12.3f} {s.triangle_count:9d}  {label}")
    finally:
        sim.close()
    return 0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--world", default="human", help="world name (worlds/<name>.yaml) or file")
    p.add_argument("--robot", default="panda", help="config/robots/<robot>.yaml")
    p.add_argument("--renders", type=int, default=10, help="images per camera and method")
    p.add_argument("--by-body", action="store_true", help="the default camera's CPU per image by body drawn")
    args = p.parse_args(argv)
    if args.renders < 1:
        p.error("--renders must be at least 1")

    from moverl_gym.paths import robot_config_file, world_file
    from moverl_sim.camera import Camera
    from moverl_sim.depth_scene import world_depth
    from moverl_sim.robot_config import load_robot_config
    from moverl_sim.settings import simulator_for
    from moverl_sim.world import load_world

    world = load_world(world_file(args.world))
    if not world.cameras:
        raise SystemExit(f"render_cost.py: {world.source} has no cameras")
    rc = load_robot_config(robot_config_file(args.robot))
    if args.by_body:
        return by_body(rc, world, args.renders)
    # camera_renderer raster: each sim's render_depth is the rasterizer's image; cam.render_depth(client) TinyRenderer's
    sims = {
        looks: simulator_for(rc, world, robot_visuals=looks, camera_renderer="raster")
        for looks in ("visual", "simplified", "collision")
    }
    sim = sims["visual"]
    try:
        for s in sims.values():
            s.reset_robot(rc["home"])
        cid = sim.client_id
        print(f"{world.source}, robot {rc['name']} at home, {args.renders} images per camera and method")
        head = f"{'camera':8s} {'pixels':>9s} {'method':28s} {'CPU ms':>8s} {'wall ms':>8s}"
        print(f"{head} {'|dz| median':>12s} {'max':>7s}")
        for spec in world.cameras:
            cam = Camera(spec)
            exact = world_depth(world.objects, 0.0, cam)  # the obstacles at motion time 0, where the sims hold them
            cpu, wall, depth = timed(lambda: cam.render_depth(cid), args.renders)
            size = f"{cam.width}x{cam.height}"
            print(f"{cam.id:8s} {size:>9s} {'TinyRenderer, visual meshes':28s} {cpu:8.1f} {wall:8.1f}")
            print_behind(depth, exact)
            for looks, label in (("simplified", "TinyRenderer, simplified"), ("collision", "TinyRenderer, hulls")):
                cpu, wall, other = timed(lambda: cam.render_depth(sims[looks].client_id), args.renders)
                dz = np.abs(other - depth)
                print(f"{'':8s} {'':>9s} {label:28s} {cpu:8.1f} {wall:8.1f} {np.median(dz):12.4f} {dz.max():7.3f}")
                print_shares(other, depth)
                print_behind(other, exact)
            for looks in ("visual", "simplified", "collision"):
                cpu, wall, other = timed(lambda: sims[looks].render_depth(cam), args.renders)
                dz = np.abs(other - depth)
                label = f"raster, {looks}"
                print(f"{'':8s} {'':>9s} {label:28s} {cpu:8.1f} {wall:8.1f} {np.median(dz):12.4f} {dz.max():7.3f}")
                print_shares(other, depth)
                print_behind(other, exact)
            for threads, label in ((1, "rayTestBatch, 1 thread"), (0, "rayTestBatch, all threads")):
                cpu, wall, rays = timed(lambda: ray_depth(cam, cid, threads), args.renders)
                dz = np.abs(rays - depth)
                print(f"{'':8s} {'':>9s} {label:28s} {cpu:8.1f} {wall:8.1f} {np.median(dz):12.4f} {dz.max():7.3f}")
    finally:
        for s in sims.values():
            s.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
