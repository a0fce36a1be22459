#!/usr/bin/env python3
"""Fuzz every service and subscribed topic of every node of a MoveRL graph with malformed inputs.

    python src/moverl_gym/tools/fuzz_graph.py [--out docs/fuzz]

Two graphs, each launched on a free port in its own worker process:
  lockstep    the simulator's services, obstacles:=both (the planning scene subscribes to the world, the joint
              states and the depth cameras' point clouds as well)
  standard    driver:=follow_joint_trajectory: the simulator's FollowJointTrajectory server in real time, the
              shield's action client and joint-state subscriber, the world server

Every input (moverl_gym.fuzz: wrong sizes, NaN / inf / huge values, unknown or duplicated joint names, empty or
non-monotonic trajectories, malformed worlds, point clouds with missing or wrong fields, garbage bytes on the
services' sockets) is followed by a probe of every node (a valid request each must answer within 2 s) and a check
that its process is alive. Service answers are classified: a clear error (the response's own refusal code with a
message), accepted (valid inputs among the variants, e.g. shuffled joint names), or a bare service failure (the
handler failed without a response: not a clear error). Prints and writes (with --out) a table per service and topic:
inputs, clear errors, accepted, bare failures, node deaths, hangs. Exit code 1 if any node died or hung, or any
service failed without a clear error.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import socket
import sys
import time
from pathlib import Path

from moverl_gym.workers import run_json_worker
from moverl_msgs.srv import (
    CheckPathResponse,
    CheckStateResponse,
    ExecuteTrajectoryResponse,
    PlanPathResponse,
    ShieldStepResponse,
    ValidateMotionResponse,
)

HOME = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]
TABLE_COLLIDING = [0.0, 1.2, 0.0, -1.0, 0.0, 1.571, 0.785]
PROBE_TIMEOUT = 2.0


def _safe_at(res, q) -> bool:
    """A shield step's answer is right: safe (or unchecked), and the robot is at q afterwards."""
    return (
        res.verdict in (ShieldStepResponse.SAFE, ShieldStepResponse.UNCHECKED)
        and max(abs(a - b) for a, b in zip(res.state.position, q)) < 1e-3
    )


class Fuzzer:
    def __init__(self, nodes: dict):
        import rospy

        self.rospy = rospy
        self.nodes = nodes  # node name -> probe callable
        self.pids = {n: self._pid(n) for n in nodes}
        self.rows = {}  # per target: inputs and how they ended

    def _pid(self, node):
        import xmlrpc.client

        import rosgraph

        uri = rosgraph.Master("/fuzz").lookupNode(node)
        return xmlrpc.client.ServerProxy(uri).getPid("/fuzz")[2]

    def _row(self, target):
        return self.rows.setdefault(
            target,
            {
                "target": target,
                "inputs": 0,
                "clear_errors": 0,
                "accepted": 0,
                "bare_failures": 0,
                "deaths": 0,
                "hangs": 0,
                "corrupted": 0,
                "examples": [],
            },
        )

    def check_nodes(self, target, label=""):
        """Every node alive, answering and sane (its probe, a valid request, gets the right answer); failures counted
        against the target that was just fuzzed."""
        row = self._row(target)
        for node, probe in self.nodes.items():
            try:
                os.kill(self.pids[node], 0)
            except ProcessLookupError:
                row["deaths"] += 1
                row["examples"].append(f"{label}: {node} died")
                raise SystemExit(f"{node} died while fuzzing {target} ({label})")
            answered, healthy = _within(probe, PROBE_TIMEOUT)
            if not answered:
                row["hangs"] += 1
                row["examples"].append(f"{label}: {node} did not answer within {PROBE_TIMEOUT} s")
            elif not healthy:
                row["corrupted"] += 1
                row["examples"].append(f"{label}: {node} answers a valid request wrongly")

    def service(self, name, srv_type, requests, refused, expect_accepted=()):
        """Call `name` with every (label, request); refused(response) -> True when it is a clear refusal."""
        proxy = self.rospy.ServiceProxy(name, srv_type)
        for label, req in requests:
            row = self._row(name)
            row["inputs"] += 1
            try:
                res = _call(proxy, req)
            except TimeoutError:
                row["hangs"] += 1
                row["examples"].append(f"{label}: no answer within {PROBE_TIMEOUT * 5} s")
                res = None
            except Exception as exc:  # rospy.ServiceException: the handler failed without a response
                row["bare_failures"] += 1
                row["examples"].append(f"{label}: {exc}")
                res = None
            if res is not None:
                self._count(row, label, refused(res), expect_accepted)
            self.check_nodes(name, label)

    @staticmethod
    def _count(row, label, refused, expect_accepted):
        if refused:
            row["clear_errors"] += 1
        elif label in expect_accepted:
            row["accepted"] += 1
        else:
            row["bare_failures"] += 1
            row["examples"].append(f"{label}: accepted without an error")

    def topic(self, name, msg_type, messages, refused=None, expect_accepted=(), settle=0.05, impostor=False):
        """Publish every (label, message); refused(label) -> True when the subscriber visibly dropped it (its state
        shows it), None when nothing can tell (then only survival is checked). impostor: a second publisher of an
        action server's own topic (status, result, feedback) confuses actionlib's connection monitor while it is
        there (ROS 1 has no authentication): the nodes are checked after it left."""
        pub = self.rospy.Publisher(name, msg_type, queue_size=100)
        deadline = time.monotonic() + 5
        while pub.get_num_connections() == 0 and time.monotonic() < deadline:
            time.sleep(0.05)  # set-up: wait for the subscriber's connection
        for label, msg in messages:
            row = self._row(name)
            row["inputs"] += 1
            pub.publish(msg)
            time.sleep(settle)
            if refused is not None:
                self._count(row, label, refused(label), expect_accepted)
            if not impostor:
                self.check_nodes(name, label)
        pub.unregister()
        if impostor:
            time.sleep(0.5)
            self.check_nodes(name, "after the impostor publisher left")

    def garbage(self, service):
        """Bytes that are not TCPROS on the service's socket: headers cut short, huge lengths, random bytes."""
        import rosgraph

        uri = rosgraph.Master("/fuzz").lookupService(service)
        host, port = uri.replace("rosrpc://", "").rstrip("/").split(":")
        payloads = [
            b"",
            b"\x00",
            b"\xff\xff\xff\xff",
            b"\x10\x00\x00\x00garbage",
            os.urandom(4096),
            b"\x04\x00\x00\x00\x00\x00\x00\x00" * 64,
        ]
        target = service + " (raw bytes)"
        for data in payloads:
            row = self._row(target)
            row["inputs"] += 1
            try:
                with socket.create_connection((host, int(port)), timeout=2) as s:
                    s.sendall(data)
                    s.shutdown(socket.SHUT_WR)
                    try:
                        s.recv(64)
                    except OSError:
                        pass
            except OSError:
                pass
            row["clear_errors"] += 1  # the node dropped the connection (checked alive below)
            self.check_nodes(target)


def _call(proxy, req):
    import threading

    out = {}

    def run():
        try:
            out["res"] = proxy.call(req)
        except Exception as exc:  # noqa: BLE001 - reported to the caller
            out["exc"] = exc

    t = threading.Thread(target=run, daemon=True)
    t.start()
    t.join(PROBE_TIMEOUT * 5)
    if t.is_alive():
        proxy.close()
        raise TimeoutError
    if "exc" in out:
        raise out["exc"]
    return out["res"]


def _within(fn, timeout):
    """(answered within timeout, answer is right): fn returns True for a right answer."""
    import threading

    out = {"healthy": False}
    done = threading.Event()

    def run():
        try:
            out["healthy"] = bool(fn())
        except Exception:  # noqa: BLE001 - an error answer is still an answer, but not a right one
            pass
        done.set()

    threading.Thread(target=run, daemon=True).start()
    return done.wait(timeout), out["healthy"]


# ------------------------------------------------------------------------------------------------------- graphs
def worker_lockstep() -> dict:
    import rospy
    from sensor_msgs.msg import JointState, PointCloud2
    from std_srvs.srv import Empty

    from moverl_gym import fuzz
    from moverl_gym import ros_backend as backend
    from moverl_gym.graph import LaunchedGraph
    from moverl_msgs.msg import OctomapStatus, World
    from moverl_msgs.srv import (
        CheckPath,
        CheckState,
        ExecuteTrajectory,
        GetFK,
        GetWorld,
        PlanPath,
        ResetRobot,
        ShieldStep,
        ValidateMotion,
    )

    graph = LaunchedGraph(
        {"world_file": str(_repo() / "worlds" / "table.yaml"), "obstacles": "both"}, wait_for=backend.REQUIRED_SERVICES
    )
    try:
        backend.init_node(graph.uri)
        joints = list(rospy.get_param("/robot/joints"))
        free = [0.3] + HOME[1:]
        step = rospy.ServiceProxy("/shield/step", ShieldStep)
        check = rospy.ServiceProxy("/planning_scene/check_state", CheckState)
        world_proxy = rospy.ServiceProxy("/sim/get_world", GetWorld)
        world = world_proxy().world
        scene_world = rospy.ServiceProxy("/planning_scene/get_world", GetWorld)
        status = {}
        rospy.Subscriber("/planning_scene/octomap_status", OctomapStatus, lambda m: status.update(dropped=m.dropped))
        # Probes: placed at `free` through the shield (the fuzzed simulator moved the robot behind its back), a
        # zero-length step is safe and reports `free`; the table still collides where it is.
        reset = rospy.ServiceProxy("/shield/reset", ResetRobot)
        # The shield's process hosts the planning scene (scene_process:=shield, the default): its probe asks both.
        f = Fuzzer(
            {
                "/shield": lambda: (
                    reset(positions=free).success
                    and _safe_at(step(target=free, duration=0.05), free)
                    and check(positions=TABLE_COLLIDING).outcome == CheckStateResponse.WORLD_COLLISION
                    and check(positions=free).outcome == CheckStateResponse.VALID
                ),
                "/sim": lambda: world_proxy().world.name == world.name,
            }
        )
        rospy.ServiceProxy("/shield/reset", ResetRobot)(positions=free)
        vec = fuzz.float_vectors(HOME)
        f.service(
            "/shield/step",
            ShieldStep,
            [(label, _req(ShieldStep, target=v, duration=0.05)) for label, v in vec]
            + [
                (f"duration {n}", _req(ShieldStep, target=free, duration=x))
                for n, x in fuzz.POISON + (("negative", -1.0),)
            ],
            lambda r: r.verdict == ShieldStepResponse.INVALID_REQUEST and r.message,
        )
        f.service(
            "/shield/reset",
            ResetRobot,
            [(label, _req(ResetRobot, positions=v)) for label, v in vec if label != "empty"],
            lambda r: not r.success and r.message,
        )
        f.service(
            "/planning_scene/check_state",
            CheckState,
            [(label, _req(CheckState, positions=v)) for label, v in vec],
            lambda r: r.outcome == CheckStateResponse.INVALID_REQUEST and r.message,
        )
        f.service(
            "/planning_scene/check_path",
            CheckPath,
            [(f"start {label}", _req(CheckPath, start=v, goal=HOME)) for label, v in vec]
            + [(f"goal {label}", _req(CheckPath, start=HOME, goal=v)) for label, v in vec],
            lambda r: r.outcome == CheckPathResponse.INVALID_REQUEST and r.message,
        )
        f.service(
            "/planning_scene/plan",
            PlanPath,
            [(f"goal {label}", _req(PlanPath, start=free, goal=v)) for label, v in vec]
            + [("unknown planner", _req(PlanPath, start=free, goal=HOME, planner="NoSuchPlanner"))]
            + [
                (f"time limit {n}", _req(PlanPath, start=free, goal=[0.4] + HOME[1:], time_limit=x))
                for n, x in fuzz.POISON + (("negative", -1.0),)
            ],
            lambda r: r.outcome == PlanPathResponse.INVALID_REQUEST and r.message,
        )
        f.service(
            "/planning_scene/fk",
            GetFK,
            [(label, _req(GetFK, positions=v)) for label, v in vec]
            + [("unknown link", _req(GetFK, positions=HOME, links=["no_link"]))],
            lambda r: not r.success and r.message,
        )
        f.service(
            "/planning_scene/validate_motion",
            ValidateMotion,
            [(f"goal {label}", _req(ValidateMotion, start=free, goal=v)) for label, v in vec]
            + [
                (f"start_time {n}", _req(ValidateMotion, start=free, goal=free, start_time=x))
                for n, x in fuzz.POISON
                if not n.endswith("huge")
            ]
            + [
                (f"duration {n}", _req(ValidateMotion, start=free, goal=free, duration=x))
                for n, x in (("nan", math.nan), ("negative", -1.0))
            ],
            lambda r: r.outcome == ValidateMotionResponse.INVALID_REQUEST and r.message,
        )
        trajs = fuzz.trajectories(joints, free)
        f.service(
            "/sim/execute",
            ExecuteTrajectory,
            [(label, _req(ExecuteTrajectory, trajectory=t)) for label, t in trajs],
            lambda r: (
                r.outcome in (ExecuteTrajectoryResponse.INVALID_TRAJECTORY, ExecuteTrajectoryResponse.LIMIT_VIOLATION)
                and r.message
            ),
            expect_accepted={"shuffled joints", "10000 points"},
        )
        rospy.ServiceProxy("/shield/reset", ResetRobot)(positions=free)  # the valid moves moved the robot
        f.service(
            "/sim/reset_robot",
            ResetRobot,
            [(label, _req(ResetRobot, positions=v)) for label, v in vec],
            lambda r: not r.success and r.message,
        )
        f.service(
            "/planning_scene/clear_octomap",
            Empty,
            [("empty request", Empty._request_class())],
            lambda r: False,
            expect_accepted={"empty request"},
        )
        # A malformed world is refused when the scene keeps the world it had (the real one).
        f.topic(
            "/sim/world",
            World,
            fuzz.worlds(world),
            refused=lambda _l: len(scene_world().world.objects) == len(world.objects),
            expect_accepted={"10000 objects"},
            settle=0.3,
        )
        f.topic("/sim/world", World, [("the real world again", world)], settle=0.5)
        f.topic("/joint_states", JointState, fuzz.joint_states(joints, free))
        # A malformed cloud is refused when the scene counts it as dropped.
        clouds = fuzz.point_clouds("left_optical_frame")
        seen = {"dropped": status.get("dropped", 0)}

        def dropped(_label):
            deadline = time.monotonic() + 1.5  # the scene may wait up to joint_state_wait for a joint state
            while status.get("dropped", 0) <= seen["dropped"] and time.monotonic() < deadline:
                time.sleep(0.05)
            now = status.get("dropped", 0)
            refused, seen["dropped"] = now > seen["dropped"], now
            return refused

        f.topic(
            "/sim/points", PointCloud2, clouds, refused=dropped, expect_accepted={"empty", "nan points", "inf points"}
        )
        for service in ("/shield/step", "/planning_scene/validate_motion", "/sim/execute"):
            f.garbage(service)
        # After all that the graph still works: a free move executes and the world is the real one again.
        rospy.ServiceProxy("/shield/reset", ResetRobot)(positions=free)
        res = step(target=[0.35] + HOME[1:], duration=0.05)
        return {
            "rows": list(f.rows.values()),
            "final_step": res.verdict,
            "final_contacts": res.contacts.world_contacts + res.contacts.self_contacts,
        }
    finally:
        graph.close()


def worker_standard() -> dict:
    import rospy
    from actionlib_msgs.msg import GoalID, GoalStatus, GoalStatusArray
    from sensor_msgs.msg import JointState

    from control_msgs.msg import (
        FollowJointTrajectoryActionFeedback,
        FollowJointTrajectoryActionGoal,
        FollowJointTrajectoryActionResult,
        FollowJointTrajectoryResult,
    )
    from moverl_gym import fuzz
    from moverl_gym import ros_backend as backend
    from moverl_gym.graph import LaunchedGraph
    from moverl_msgs.srv import GetWorld, ShieldStep

    free = [0.3] + HOME[1:]
    graph = LaunchedGraph(
        {
            "world_file": str(_repo() / "worlds" / "table.yaml"),
            "driver": "follow_joint_trajectory",
            "initial_positions": str(free),
        },
        wait_for=backend.REQUIRED_SERVICES,
    )
    try:
        backend.init_node(graph.uri)
        joints = list(rospy.get_param("/robot/joints"))
        step = rospy.ServiceProxy("/shield/step", ShieldStep)
        world = rospy.ServiceProxy("/world/get_world", GetWorld)
        f = Fuzzer(
            {
                "/shield": lambda: _safe_at(step(target=free, duration=0.05), free),
                "/world": lambda: world().world.name == "table",
                "/sim": lambda: rospy.wait_for_message("/joint_states", JointState, timeout=1.0) is not None,
            }
        )
        ns = "/arm_controller/follow_joint_trajectory"
        goals = []
        for label, traj in fuzz.trajectories(joints, free):
            g = FollowJointTrajectoryActionGoal()
            g.goal_id.id = f"fuzz-{label}"
            g.goal.trajectory = traj
            goals.append((label, g))
        # The simulator's server answers every goal: a malformed one is rejected (status REJECTED, code and text).
        results = {}
        rospy.Subscriber(
            ns + "/result", FollowJointTrajectoryActionResult, lambda m: results.__setitem__(m.status.goal_id.id, m)
        )

        def rejected(label):
            r = results.get(f"fuzz-{label}")
            return (
                r is not None
                and r.status.status == GoalStatus.REJECTED
                and r.result.error_code != FollowJointTrajectoryResult.SUCCESSFUL
                and r.result.error_string
            )

        f.topic(
            ns + "/goal",
            FollowJointTrajectoryActionGoal,
            goals,
            refused=rejected,
            settle=0.6,
            expect_accepted={"shuffled joints", "10000 points", "no points"},
        )  # no points: stop (as the JTC)
        time.sleep(1.0)  # the valid goals end
        f.topic(ns + "/cancel", GoalID, [("unknown goal id", GoalID(id="no-such-goal")), ("cancel all", GoalID())])
        # What the shield's action client hears: results, feedback and status for goals it never sent.
        res = FollowJointTrajectoryActionResult()
        res.status.goal_id.id = "not-ours"
        res.status.status = GoalStatus.ABORTED
        res.result.error_code = FollowJointTrajectoryResult.PATH_TOLERANCE_VIOLATED
        fb = FollowJointTrajectoryActionFeedback()
        fb.status.goal_id.id = "not-ours"
        f.topic(ns + "/result", FollowJointTrajectoryActionResult, [("result of a goal not ours", res)], impostor=True)
        f.topic(
            ns + "/feedback", FollowJointTrajectoryActionFeedback, [("feedback of a goal not ours", fb)], impostor=True
        )
        f.topic(ns + "/status", GoalStatusArray, [("empty status", GoalStatusArray())], impostor=True)
        f.topic("/joint_states", JointState, fuzz.joint_states(joints, free))
        # After all that: a free move executes through the standard driver.
        time.sleep(0.6)
        final = step(target=[0.35] + HOME[1:], duration=0.05)
        return {"rows": list(f.rows.values()), "final_step": final.verdict, "final_message": final.message}
    finally:
        graph.close()


def _req(srv, **fields):
    return srv._request_class(**fields)


def _repo() -> Path:
    from moverl_gym.paths import repo_root

    return repo_root()


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", help="write fuzz.md and fuzz.json into this folder")
    p.add_argument("--graphs", nargs="+", default=["lockstep", "standard"], choices=("lockstep", "standard"))
    p.add_argument("--worker", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker:
        print(json.dumps({"lockstep": worker_lockstep, "standard": worker_standard}[args.worker]()))
        return 0
    results, bad = {}, 0
    t0 = time.monotonic()
    for g in args.graphs:
        print(f"fuzzing the {g} graph ...", flush=True)
        results[g] = run_json_worker(__file__, ["--worker", g], f"fuzz worker {g}", timeout=1200)
    keys = ("inputs", "clear_errors", "accepted", "bare_failures", "deaths", "hangs", "corrupted")
    lines = [
        "| graph | service / topic | inputs | refused with a clear error | accepted (valid variants) | "
        "accepted or failed without a clear error | node deaths | hangs | nodes answering wrongly after |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    totals = [0] * len(keys)
    for g, r in results.items():
        for row in r["rows"]:
            vals = [row[k] for k in keys]
            totals = [a + b for a, b in zip(totals, vals)]
            lines.append(f"| {g} | `{row['target']}` | " + " | ".join(map(str, vals)) + " |")
            bad += row["bare_failures"] + row["deaths"] + row["hangs"] + row["corrupted"]
            for ex in row["examples"][:5]:
                print(f"  {g} {row['target']}: {ex}")
        print(f"{g}: after fuzzing, a free move's verdict: {r['final_step']} ({ShieldStepResponse.SAFE} = safe)")
        bad += r["final_step"] != ShieldStepResponse.SAFE
    lines.append("| all | | " + " | ".join(map(str, totals)) + " |")
    table = "\n".join(lines)
    print("\n" + table)
    print(
        f"\n{totals[0]} inputs, {totals[3]} without a clear error, {totals[4]} node deaths, {totals[5]} hangs, "
        f"{totals[6]} wrong answers after ({time.monotonic() - t0:.0f} s)"
    )
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "fuzz.json").write_text(json.dumps(results, indent=2))
        (out / "fuzz.md").write_text(
            "# Fuzzing every service and subscribed topic\n\nCommand: `python "
            "src/moverl_gym/tools/fuzz_graph.py --out docs/fuzz` (see its docstring). Topics "
            "have no reply: a malformed message counts as refused when the subscriber's state "
            "shows it dropped it (the scene kept its world; its OctoMap status counted the cloud "
            "as dropped; the simulator's action server rejected the goal with a code and a "
            "text); joint states and action messages for goals not ours are checked by the "
            "probes only (every node still answers a valid request rightly).\n\n" + table + "\n"
        )
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
