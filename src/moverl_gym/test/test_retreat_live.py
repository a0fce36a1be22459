"""Out of a person's way (issue 28), on the live graph, obstacles:=sensed, lockstep: a robot parked where a sensed
person walks up to it.

The world is worlds/human.yaml's table, cameras and sensing, with the person replaced by a "visitor" (a 10 x 30 x
30 cm box) that steps back and then walks straight at the Panda's parked hand (x(t) = 0.75 + 0.3 sin(2 pi t / 6 s),
at most 0.31 m/s; at t = 4.5 s its near face comes 5 cm past the hand) and a speed bound that covers it. The agent
commands nothing (zero actions: stay where you are) for one period of the walk. (Stepping back first: the simulator
does not teleport the robot where a moving obstacle will walk into it within reset_clearance_time, config/sim.yaml.)

* strategy plan (today's shield): every step holds still, and the visitor walks into the parked hand: contacts,
  all with the robot at rest;
* strategy retreat: the shield backs the hand away while the visitor comes (verdict RETREATED) and no contact
  happens at all;
* safety ssm (ISO/TS 15066's speed and separation monitoring: the margin is ISO 13855's approach distance, not the
  world's bound), the walk five times faster, and an agent that keeps pushing the hand into the visitor's path: the
  visitor may touch the robot at rest (ssm allows it), never while it moves. A threatened robot holds still under ssm
  (backing away, a hand at 2.0 m/s catches it moving), so here it holds while the visitor walks into it;
* strategy retreat with the walk played five times faster than the world's bound says (motion_time_scale 5, up to
  1.57 m/s against 0.32): the margin no longer covers where the visitor may be between two views, and the robot is
  hit. The bound is the cell's promise; a person faster than it is not covered. (Three times faster, 0.94 m/s, the
  robot now escapes: the space the box hides from the cameras counts as possibly occupied, so it backs away sooner.
  That is luck, not a guarantee.)
"""

import numpy as np
import pytest
import yaml
from live_helpers import Tool

from moverl_gym.env import MoveRLReachEnv
from moverl_gym.paths import world_file

pytestmark = pytest.mark.live

ROBOT = "panda"
PARKED = [0.42, 0.0, 0.25]  # the hand's position (m, pointing down) where the robot is parked
VISITOR = {
    "id": "visitor",
    "shape": "box",
    "size": [0.1, 0.3, 0.3],
    "xyz": [0.75, 0.0, 0.25],
    "motion": {"type": "oscillate", "axis": [1, 0, 0], "amplitude": 0.3, "period": 6.0},
    "observed": True,
}
STEPS = 120  # one period of the walk at the env's dt (0.05 s)
GOAL = [-1.0, -1.0, 1.0]  # beyond the arm's reach (1.56 m from its shoulder): no episode ends on success


def _world(tmp_path):
    data = yaml.safe_load(world_file("human").read_text())
    data["name"] = "visitor"
    data["objects"] = [o for o in data["objects"] if not o["id"].startswith("human_")] + [VISITOR]
    data["sensing"]["speed_bound"] = 0.32  # the visitor's top speed: 2 pi x 0.3 m / 6 s = 0.314 m/s
    data["people"] = [{"body": "v1", "parts": {"torso": {"object": "visitor"}}}]  # for people:=tracked
    path = tmp_path / "visitor.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


@pytest.fixture(scope="module")
def parked():
    tool = Tool(ROBOT)
    try:
        q = tool.ik(PARKED, tool.home)
        assert np.linalg.norm(tool.ee_xyz(q) - PARKED) < 0.01, "no configuration with the hand at PARKED"
        yield q
    finally:
        tool.close()


def _park(tmp_path, parked, strategy, motion_time_scale=1.0, safety=""):
    """One walk of the visitor (STEPS env steps) with the robot told to stay: (verdict counts, contacts moving,
    contacts at rest, largest joint motion from the parked state). motion_time_scale > 1 plays the walk that many
    times faster than the world declares; safety: the launch argument (empty: config/planning_scene.yaml's)."""
    extra = {"motion_time_scale": motion_time_scale} if motion_time_scale != 1.0 else {}
    extra.update({"safety": safety} if safety else {})
    env = MoveRLReachEnv(
        world=str(_world(tmp_path)),
        graph="launch",
        goal=GOAL,
        task={"max_episode_steps": STEPS + 1},
        launch_args={"obstacles": "sensed", "strategy": strategy, **extra},
    )
    try:
        env.reset(options={"start": parked})
        inner = env.unwrapped
        verdicts, moving, resting, moved = {}, 0, 0, 0.0
        zero = np.zeros(env.action_space.shape, dtype=np.float32)
        for _ in range(STEPS):
            _, _, term, trunc, info = env.step(zero)
            verdicts[info["verdict"]] = verdicts.get(info["verdict"], 0) + 1
            moving += max(info["contacts_moving"], 0)
            resting += max(info["contacts_resting"], 0)
            moved = max(moved, float(np.max(np.abs(inner.q - parked))))
            assert not (term or trunc), f"the episode ended: {info}"
        return verdicts, moving, resting, moved
    finally:
        env.close()


def test_a_parked_robot_held_still_is_walked_into(tmp_path, parked):
    verdicts, moving, resting, moved = _park(tmp_path, parked, "plan")
    print(f"plan: verdicts {verdicts}, contacts {moving} moving / {resting} at rest, moved {moved:.4f} rad")
    assert moved < 1e-3, "told to stay and never allowed to back away, the robot stays"
    assert moving == 0
    assert resting > 0, "the visitor walks into the parked hand"


def test_a_parked_robot_backs_away_from_a_sensed_person(tmp_path, parked):
    verdicts, moving, resting, moved = _park(tmp_path, parked, "retreat")
    print(f"retreat: verdicts {verdicts}, contacts {moving} moving / {resting} at rest, moved {moved:.4f} rad")
    assert verdicts.get("retreated", 0) > 0, verdicts
    assert moved > 0.05, "the hand backed away"
    assert moving == 0 and resting == 0, f"{moving} contacts while backing away, {resting} at rest"


def test_a_visitor_faster_than_the_declared_bound_is_not_covered(tmp_path, parked):
    # The same walk played 5 times faster (up to 1.57 m/s) than the world's bound of 0.32 m/s says, as a real person
    # the world file does not describe: the margin no longer covers where the visitor may be between two views, and
    # backing away starts too late. The speed bound is the cell's promise, not something the shield can check
    # (declared as played, such a world is refused before anything starts: test_launch_args.py).
    verdicts, moving, resting, moved = _park(tmp_path, parked, "retreat", motion_time_scale=5.0)
    print(f"retreat, 5x faster: verdicts {verdicts}, contacts {moving} moving / {resting} at rest, moved {moved:.4f}")
    assert moving + resting > 0, f"the visitor faster than the bound never reached the robot: {verdicts}"


INTO = [0.62, 0.0, 0.25]  # the hand 20 cm further out, inside the visitor's walk (its near face reaches x = 0.40)


def _push(tmp_path, parked, **launch):
    """The agent pushes at full speed towards INTO for two periods of the walk played 5x faster than declared (up to
    1.57 m/s), under safety:=ssm with strategy retreat and `launch`: (verdict counts, contacts moving, at rest, the
    nearest the hand came to INTO in joint space, where it started)."""
    tool = Tool(ROBOT)
    try:
        into = tool.ik(INTO, parked)
        assert np.linalg.norm(tool.ee_xyz(into) - INTO) < 0.01, "no configuration with the hand at INTO"
    finally:
        tool.close()
    env = MoveRLReachEnv(
        world=str(_world(tmp_path)),
        graph="launch",
        goal=GOAL,
        task={"max_episode_steps": 2 * STEPS + 1},
        launch_args={"obstacles": "sensed", "strategy": "retreat", "safety": "ssm", "motion_time_scale": 5.0, **launch},
    )
    try:
        env.reset(options={"start": parked})
        inner = env.unwrapped
        verdicts, moving, resting, closest = {}, 0, 0, np.inf
        for _ in range(2 * STEPS):
            action = np.clip((into - inner.q) / inner.scaler.max_delta, -1.0, 1.0).astype(np.float32)
            _, _, term, trunc, info = env.step(action)
            verdicts[info["verdict"]] = verdicts.get(info["verdict"], 0) + 1
            moving += max(info["contacts_moving"], 0)
            resting += max(info["contacts_resting"], 0)
            closest = min(closest, float(np.max(np.abs(inner.q - into))))
            assert not (term or trunc), f"the episode ended: {info}"
    finally:
        env.close()
    return verdicts, moving, resting, closest, float(np.max(np.abs(parked - into)))


def test_ssm_never_moves_into_a_visitor_faster_than_declared(tmp_path, parked):
    # safety:=ssm: the sensed cells approach at ISO 13855's speeds (2.0 m/s within 0.5 m), whatever the world says;
    # the walk at 5x (up to 1.57 m/s) is within them.
    verdicts, moving, resting, closest, start = _push(tmp_path, parked)
    print(
        f"ssm, 5x faster, pushing: verdicts {verdicts}, contacts {moving} moving / {resting} at rest; nearest INTO "
        f"{closest:.3f} rad (from {start:.3f})"
    )
    assert moving == 0, f"{moving} contacts while the robot moved: {verdicts}"
    # The visitor did reach the robot (the case was played), and the robot held still rather than back away.
    assert resting > 0, f"the visitor never touched the robot: {verdicts}"
    assert verdicts.get("retreated", 0) == 0, f"the robot backed away under ssm: {verdicts}"


@pytest.mark.parametrize("fault", ["none", "frozen", "offset"])
def test_ssm_with_the_visitor_tracked_never_moves_into_it_even_when_the_tracker_lies(tmp_path, parked, fault):
    # people:=tracked: the simulator's tracker (30 Hz, 0.05 s latency, 1 cm noise, dropouts) reports the visitor as a
    # REP 155 body (its torso frame), and the seen cells it explains count from the track's newer measurement, not
    # only from the map's (2 Hz cameras). A frozen track (the visitor's first pose, freshly stamped) or one 0.5 m
    # beside it explains none of the visitor's cells once it has moved away: they keep ISO's margin.
    verdicts, moving, resting, closest, start = _push(
        tmp_path, parked, people="tracked", obstacle_poses="tracker", tracker_fault=fault
    )
    print(
        f"ssm, tracked ({fault}), 5x faster, pushing: verdicts {verdicts}, contacts {moving} moving / {resting} at "
        f"rest; nearest INTO {closest:.3f} rad (from {start:.3f})"
    )
    assert moving == 0, f"{moving} contacts while the robot moved: {verdicts}"
