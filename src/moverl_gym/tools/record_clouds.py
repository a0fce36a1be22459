#!/usr/bin/env python3
"""Record the point clouds a world's simulated depth cameras produce, exactly as the simulator publishes them on
~points (Simulator.render_points in a Simulator built as the sim node builds it), with the robot at its
config's home (or swinging about it: --arm-swing) and the world's moving obstacles where their motions put them at each
instant, into a directory a C++ benchmark reads. In this process, no ROS.

    python src/moverl_gym/tools/record_clouds.py --world human --out /tmp/rec_human --duration 6 --rate 2
    python src/moverl_gym/tools/record_clouds.py --world human --out /tmp/rec_640 --size 640x480 --times 0 0.5 1.0

--arm-swing A (rad) moves the arm as an agent's actions move it while the cameras look: each controlled joint j at
home_j + A sin(2 pi t / T_j + j), T_j = 2 + 0.5 j s, clipped to its limits (the robot's pixels change from view to
view, as in a rollout; at home they stay).

Instants: --times (simulated seconds), or t = 0, 1/R, 2/R, ... < D (--duration D --rate R, the same for every camera).
Every camera renders at every instant. t is simulated time since the simulator started, which is also the motion time
of the obstacles (motion epoch 0: the sim node's motions start with it).

The output directory:

* ``recording.yaml`` (written last): ``world`` (absolute path of the world file), ``robot``, ``base_frame`` (the
  robot config's base link: every pose below is in its frame), ``joint_names`` (the controlled joints, the order of
  every ``joints``), ``static_objects`` (the objects without a motion: ``id``, ``type`` box | sphere | cylinder | cone,
  ``dimensions`` (box [x, y, z] full sizes; sphere [radius]; cylinder and cone [height, radius]), ``xyz`` (the
  shape's centre), ``quat`` [qx, qy, qz, qw]), and ``clouds``: one entry per cloud, in the order rendered (instant by
  instant, the world's cameras in their order): ``file``, ``camera`` (its id), ``t`` (s), ``width``, ``height``,
  ``xyz`` and ``quat`` (the camera's optical frame, REP 103: z forward, x right, y down) and ``joints`` (the robot's
  configuration when rendered).
* ``cloud_NNNN.f32``: height * width * 3 float32 little-endian, pixel by pixel in row-major order (row v, then column
  u), x y z in the optical frame; a pixel without a return is the point of its ray at z = far.

An existing --out directory must be empty or hold only a previous recording (recording.yaml, cloud_*.f32), which is
replaced.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import re
import sys
import time
from pathlib import Path

import numpy as np

RECORDING = "recording.yaml"
CLOUD_FILE = re.compile(r"^cloud_\d{4,}\.f32$")
DEFAULT_DURATION = 6.0  # s
DEFAULT_RATE = 2.0  # instants per simulated second


def parse_size(text: str) -> tuple[int, int]:
    """'WxH' -> (width, height), both positive integers (argparse type)."""
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not m or int(m.group(1)) < 1 or int(m.group(2)) < 1:
        raise argparse.ArgumentTypeError(
            f"expected WIDTHxHEIGHT in pixels, both positive integers (e.g. 640x480), got {text!r}"
        )
    return int(m.group(1)), int(m.group(2))


def finite_number(text: str, zero_allowed: bool) -> float:
    """A finite number > 0 (>= 0 when zero_allowed), for argparse: raises ArgumentTypeError naming the bound."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (math.isfinite(value) and (value >= 0.0 if zero_allowed else value > 0.0)):
        raise argparse.ArgumentTypeError(f"expected a finite number {'>=' if zero_allowed else '>'} 0, got {text!r}")
    return value


def positive_number(text: str) -> float:
    """A finite number > 0 (argparse type: --duration, --rate)."""
    return finite_number(text, zero_allowed=False)


def nonnegative_number(text: str) -> float:
    """A finite number >= 0 (argparse type: seconds of --times, radians of --arm-swing)."""
    return finite_number(text, zero_allowed=True)


def instants(duration: float, rate: float) -> list[float]:
    """t = k / rate for k = 0, 1, ... while t < duration (a t within a nanosecond of duration is left out)."""
    return [k / rate for k in range(max(1, math.ceil(duration * rate - 1e-9)))]


ARM_PERIOD_S, ARM_PERIOD_STEP_S = 2.0, 0.5  # joint j's swing period: ARM_PERIOD_S + j * ARM_PERIOD_STEP_S


def arm_at(home, lower, upper, swing: float, t: float) -> list[float]:
    """The joints at instant t with --arm-swing `swing` (rad): home_j + swing sin(2 pi t / T_j + j), clipped to
    [lower_j, upper_j]; home itself when swing is 0."""
    out = []
    for j, (h, lo, hi) in enumerate(zip(home, lower, upper)):
        q = h + swing * math.sin(2.0 * math.pi * t / (ARM_PERIOD_S + j * ARM_PERIOD_STEP_S) + j)
        out.append(float(min(max(q, lo), hi)))
    return out


def names_in(folder: Path) -> list[str]:
    """The names of the *.yaml files in folder, sorted (the valid --world and --robot names)."""
    return sorted(p.stem for p in folder.glob("*.yaml"))


def check_out(out: Path) -> list[Path]:
    """The files of a previous recording in `out` (to replace); raises SystemExit when `out` is not a directory or holds
    anything else."""
    if not out.exists():
        return []
    if not out.is_dir():
        raise SystemExit(f"record_clouds.py: --out {out} exists and is not a directory")
    entries = sorted(out.iterdir())
    others = [p.name for p in entries if not (p.is_file() and (p.name == RECORDING or CLOUD_FILE.match(p.name)))]
    if others:
        shown = ", ".join(others[:5]) + (f" and {len(others) - 5} more" if len(others) > 5 else "")
        raise SystemExit(
            f"record_clouds.py: --out {out} holds files other than a previous recording ({RECORDING}, cloud_*.f32): "
            f"{shown}; give an empty or new directory"
        )
    return entries


def in_base(base_pose, xyz, quat) -> tuple[list[float], list[float]]:
    """A pose given in the world frame -> (xyz, quat [qx, qy, qz, qw]) in the base frame (base_pose: the base link's
    pose in the world frame), as Python floats."""
    from moverl_sim.camera import quaternion_to_rotation, rotation_to_quaternion

    (bp, bq) = base_pose
    rb = quaternion_to_rotation(bq)
    p = rb.T @ (np.asarray(xyz, dtype=np.float64) - np.asarray(bp, dtype=np.float64))
    q = rotation_to_quaternion(rb.T @ quaternion_to_rotation(quat))
    return [float(v) for v in p], [float(v) for v in q]


def static_objects(world, base_pose) -> list[dict]:
    """The world's objects without a motion, in the base frame, as recording.yaml lists them."""
    out = []
    for obj in world.objects:
        if obj.motion is not None:
            continue
        # The world file's sizes follow shape_msgs/SolidPrimitive (moverl_sim.world.SHAPE_SIZES): box [x, y, z] full
        # sizes, sphere [radius], cylinder [height, radius] (and a cone would be [height, radius] too): the recording's
        # order, so the dimensions are copied as they are, no conversion. (World files have no cones today.)
        xyz, quat = in_base(base_pose, obj.xyz, obj.quaternion)
        out.append(
            {
                "id": obj.id,
                "type": obj.shape,
                "dimensions": [float(v) for v in obj.size],
                "xyz": xyz,
                "quat": quat,
            }
        )
    return out


def main(argv=None) -> int:
    from moverl_gym.paths import repo_root, robot_config_file, world_file
    from moverl_sim.settings import sim_settings

    worlds = names_in(repo_root() / "worlds")
    robots = names_in(repo_root() / "config" / "robots")
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--world", default="human", help=f"world name ({', '.join(worlds)}) or a world file (.yaml)")
    p.add_argument("--out", required=True, type=Path, help="directory to write (created; see above)")
    p.add_argument("--robot", default="panda", choices=robots, help="config/robots/<robot>.yaml (default panda)")
    p.add_argument(
        "--times",
        nargs="+",
        type=nonnegative_number,
        metavar="T",
        help="the instants (simulated s); not with --duration",
    )
    p.add_argument(
        "--duration",
        type=positive_number,
        help=f"instants t = 0, 1/rate, ... < duration (s; default {DEFAULT_DURATION:g})",
    )
    p.add_argument(
        "--rate", type=positive_number, help=f"instants per simulated second, every camera (default {DEFAULT_RATE:g})"
    )
    p.add_argument(
        "--size",
        type=parse_size,
        metavar="WxH",
        help="every camera's image size, its vertical fov kept (default: each camera's own from the world file)",
    )
    p.add_argument(
        "--arm-swing",
        type=nonnegative_number,
        default=0.0,
        metavar="RAD",
        help="swing every controlled joint about home by up to RAD (see above; default 0: the arm at home)",
    )
    default_looks = sim_settings()["robot_visuals"]
    p.add_argument(
        "--robot-visuals",
        choices=("visual", "collision"),
        default=default_looks,
        help=f"what the cameras see of the robot (default: config/sim.yaml's robot_visuals, {default_looks})",
    )
    args = p.parse_args(argv)
    if args.times is not None and (args.duration is not None or args.rate is not None):
        p.error("give either --times or --duration/--rate, not both")
    times = (
        list(args.times)
        if args.times is not None
        else instants(
            DEFAULT_DURATION if args.duration is None else args.duration,
            DEFAULT_RATE if args.rate is None else args.rate,
        )
    )
    wpath = world_file(args.world).resolve()
    if not wpath.is_file():
        p.error(f"argument --world: no world file {wpath} (worlds: {', '.join(worlds)}, or a path to a .yaml file)")

    from moverl_sim.camera import Camera
    from moverl_sim.robot_config import load_robot_config
    from moverl_sim.settings import simulator_for
    from moverl_sim.world import WorldFileError, load_world

    try:
        world = load_world(wpath)
    except WorldFileError as exc:
        raise SystemExit(f"record_clouds.py: {exc}") from None
    if not world.cameras:
        raise SystemExit(f"record_clouds.py: {wpath} has no cameras (its 'cameras:' list is empty or missing)")
    previous = check_out(args.out)
    rc = load_robot_config(robot_config_file(args.robot))
    specs = [
        dataclasses.replace(spec, width=args.size[0], height=args.size[1]) if args.size else spec
        for spec in world.cameras
    ]
    cameras = [Camera(spec) for spec in specs]

    import yaml

    t0 = time.perf_counter()
    sim = simulator_for(rc, world, robot_visuals=args.robot_visuals)
    try:
        # The planning scene works in the robot's base link frame. The simulator mounts the URDF's root at the world
        # origin, so the base link is the world frame for the robots shipped; a base link elsewhere (a URDF whose root
        # is a "world" link with an offset) is handled by expressing every pose relative to it.
        base_pose = sim.link_poses()[rc["base_link"]]
        for path in previous:
            path.unlink()
        args.out.mkdir(parents=True, exist_ok=True)
        statics = static_objects(world, base_pose)
        poses = [in_base(base_pose, *cam.pose) for cam in cameras]
        clouds, render_ms = [], []
        print(
            f"{wpath}: {len(cameras)} cameras x {len(times)} instants, robot {rc['name']} "
            f"{'swinging ' + format(args.arm_swing, 'g') + ' rad about home' if args.arm_swing else 'at home'} "
            f"({args.robot_visuals} meshes) -> {args.out}"
        )
        for t in times:
            pose = arm_at(rc["home"], sim.lower, sim.upper, args.arm_swing, t)
            joints = [float(v) for v in sim.reset_robot(pose)]
            sim.place_obstacles(t - sim.motion_epoch)  # the moving obstacles where their motions put them at t
            for cam, (xyz, quat) in zip(cameras, poses):
                r0 = time.perf_counter()
                points = sim.render_points(cam)
                ms = 1e3 * (time.perf_counter() - r0)
                name = f"cloud_{len(clouds):04d}.f32"
                np.ascontiguousarray(points, dtype="<f4").tofile(args.out / name)
                clouds.append(
                    {
                        "file": name,
                        "camera": cam.id,
                        "t": float(t),
                        "width": cam.width,
                        "height": cam.height,
                        # Copies: lists shared between entries would be written as YAML anchors and aliases.
                        "xyz": list(xyz),
                        "quat": list(quat),
                        "joints": list(joints),
                    }
                )
                render_ms.append(ms)
                print(f"{name}  {cam.id:8s} t {t:7.3f} s  {cam.width}x{cam.height}  {ms:7.1f} ms")
        doc = {
            "world": str(wpath),
            "robot": rc["name"],
            "base_frame": rc["base_link"],
            "joint_names": list(sim.joint_names),
            "static_objects": statics,
            "clouds": clouds,
        }
        with open(args.out / RECORDING, "w", encoding="utf-8") as f:
            yaml.safe_dump(doc, f, sort_keys=False, default_flow_style=None, width=200)
    finally:
        sim.close()
    size = sum((args.out / c["file"]).stat().st_size for c in clouds)
    print(
        f"{len(clouds)} clouds ({len(cameras)} cameras x {len(times)} instants), {size / 1e6:.1f} MB, render "
        f"{np.mean(render_ms):.1f} ms mean, {time.perf_counter() - t0:.1f} s in all: {args.out / RECORDING}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
