"""Moving obstacles: the world file's `motion:` key, the motion model and the simulator placing them in sim time."""

import math

import pytest
from conftest import HOME, make_sim

from moverl_sim.world import ObjectMotion, WorldFileError, parse_world

pytestmark = pytest.mark.core


def _world(motion, **obj):
    o = {"id": "ball", "shape": "sphere", "size": [0.05], "xyz": [0.307, 0.5, 0.59], "motion": motion}
    o.update(obj)
    return parse_world({"name": "m", "objects": [o]})


def test_motion_is_parsed_and_the_axis_normalised():
    w = _world({"type": "oscillate", "axis": [0, 2, 0], "amplitude": 0.5, "period": 2.0, "phase": 0.3})
    m = w.objects[0].motion
    assert m == ObjectMotion(type="oscillate", axis=(0.0, 1.0, 0.0), amplitude=0.5, period=2.0, phase=0.3)
    assert w.moving_objects == w.objects
    assert _world(None).objects[0].motion is None and _world(None).moving_objects == ()
    assert _world({"type": "oscillate", "axis": [1, 0, 0], "amplitude": 1, "period": 3}).objects[0].motion.phase == 0


def test_oscillation_model():
    m = ObjectMotion(axis=(0.0, 1.0, 0.0), amplitude=0.5, period=2.0, phase=0.0)
    assert m.displacement(0.0) == pytest.approx(0.0)
    assert m.displacement(0.5) == pytest.approx(0.5)  # quarter period: +amplitude
    assert m.displacement(1.5) == pytest.approx(-0.5)
    assert m.displacement(2.0) == pytest.approx(0.0, abs=1e-12)
    assert m.max_speed == pytest.approx(math.pi * 0.5)
    o = _world({"type": "oscillate", "axis": [0, 1, 0], "amplitude": 0.5, "period": 2.0}).objects[0]
    assert o.position_at(0.5) == pytest.approx((0.307, 1.0, 0.59))  # xyz is the centre of the swing
    assert o.position_at(0.0) == pytest.approx(o.xyz)


#: A reach motion: 0.3 m along x in 0.25 s each way, held 0.5 s, in half of the 4 s cycles.
REACH = {"type": "reach", "axis": [1, 0, 0], "amplitude": 0.3, "period": 4.0, "move": 0.25, "hold": 0.5, "chance": 0.5}


def test_reach_model():
    """Every cycle rests, reaches out along the axis in `move` s (top speed pi A / (2 move)), holds, comes back;
    cycles reach by a seeded draw. xyz is where the object rests; the envelope is [0, amplitude]."""
    m = _world({**REACH, "chance": 1.0}).objects[0].motion
    assert m.max_speed == pytest.approx(math.pi * 0.3 / 0.5)
    assert [m.displacement(t) for t in (0.0, 2.9, 3.25, 3.6, 4.0)] == pytest.approx([0, 0, 0.3, 0.3, 0])
    assert m.displacement(3.125) == pytest.approx(0.15)  # half way out, at the top speed
    assert m.envelope() == (0.0, 0.3)
    dt = 1e-4
    fastest = max(abs(m.displacement(t + dt) - m.displacement(t)) / dt for t in [3.0 + k * 1e-3 for k in range(1000)])
    assert fastest == pytest.approx(m.max_speed, rel=1e-3)
    seeded = _world({**REACH, "seed": 7}).objects[0].motion
    reached = [seeded.offset(k * 4.0 + 3.4) > 0 for k in range(200)]
    assert 70 < sum(reached) < 130, sum(reached)  # about half of the cycles
    assert reached == [_world({**REACH, "seed": 7}).objects[0].motion.offset(k * 4.0 + 3.4) > 0 for k in range(200)]
    assert reached != [_world({**REACH, "seed": 8}).objects[0].motion.offset(k * 4.0 + 3.4) > 0 for k in range(200)]
    mid = _world({**REACH, "chance": 1.0, "phase": 2 * math.pi * 3.5 / 4.0}).objects[0]  # t = 0 during the hold
    assert mid.start == pytest.approx((0.307 + 0.3, 0.5, 0.59))
    assert mid.motion.envelope() == pytest.approx((-0.3, 0.0))


def test_reach_matches_the_shared_cases():
    """The cases the C++ twin (ObstacleMotion, kReach) is checked on."""
    import os

    import numpy as np

    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "fixtures", "reach_motion_cases.txt")
    cases = np.loadtxt(path)
    assert cases.shape == (33, 9)
    for amplitude, period, phase, move, hold, chance, seed, t, expected in cases:
        m = ObjectMotion(
            type="reach",
            axis=(0.0, 0.0, 1.0),
            amplitude=amplitude,
            period=period,
            phase=phase,
            move=move,
            hold=hold,
            chance=chance,
            seed=int(seed),
        )
        assert m.displacement(t) == pytest.approx(expected, abs=1e-12), (amplitude, period, phase, t)


@pytest.mark.parametrize(
    "motion, key, words",
    [
        ("fast", "motion", "expected a mapping"),
        ({"axis": [0, 1, 0], "amplitude": 0.1, "period": 1}, "motion.type", "missing required key"),
        ({"type": "circle", "axis": [0, 1, 0], "amplitude": 0.1, "period": 1}, "motion.type", "unknown motion type"),
        ({"type": "oscillate", "amplitude": 0.1, "period": 1}, "motion.axis", "missing required key"),
        ({"type": "oscillate", "axis": [0, 0, 0], "amplitude": 0.1, "period": 1}, "motion.axis", "non-zero"),
        ({"type": "oscillate", "axis": [0, 1], "amplitude": 0.1, "period": 1}, "motion.axis", "expected 3 numbers"),
        ({"type": "oscillate", "axis": [0, 1, 0], "amplitude": -0.1, "period": 1}, "motion.amplitude", ">= 0"),
        ({"type": "oscillate", "axis": [0, 1, 0], "amplitude": 0.1, "period": 0}, "motion.period", "> 0"),
        (
            {"type": "oscillate", "axis": [0, 1, 0], "amplitude": "big", "period": 1},
            "motion.amplitude",
            "finite number",
        ),
        (
            {"type": "oscillate", "axis": [0, 1, 0], "amplitude": 0.1, "period": float("inf")},
            "motion.period",
            "finite number",
        ),
        (
            {"type": "oscillate", "axis": [0, 1, 0], "amplitude": 0.1, "period": 1, "speed": 2},
            "motion.speed",
            "unknown key",
        ),
        ({**REACH, "move": 0.0}, "motion.move", "> 0"),
        ({**REACH, "hold": -1.0}, "motion.hold", ">= 0"),
        ({**REACH, "period": 0.9}, "motion.period", "at least 2 move + hold = 1 s"),
        ({**REACH, "chance": 1.5}, "motion.chance", "in [0, 1]"),
        ({**REACH, "seed": -1}, "motion.seed", "integer in [0, 2^32)"),
        ({k: v for k, v in REACH.items() if k != "chance"}, "motion.chance", "missing required key"),
        ({"type": "oscillate", "axis": [0, 1, 0], "amplitude": 0.1, "period": 1, "move": 2}, "motion.move", "unknown"),
    ],
)
def test_malformed_motions_name_the_key(motion, key, words):
    with pytest.raises(WorldFileError) as err:
        _world(motion)
    msg = str(err.value)
    assert "objects[0] (id ball).%s" % key in msg and words in msg, msg


def test_simulator_moves_obstacles_in_sim_time(panda_urdf):
    # A ball swinging along y through the resting hand (home: hand at about (0.307, 0, 0.59)):
    # y(t) = 0.5 + 0.5 sin(pi t): clear at t = 0, through the hand at t = 1.5 s.
    w = _world({"type": "oscillate", "axis": [0, 1, 0], "amplitude": 0.5, "period": 2.0})
    s = make_sim(panda_urdf, w)
    try:
        s.reset_robot(HOME)
        assert s.has_moving_obstacles and s.motion_time == 0.0
        assert s.contacts_now().world_contacts == 0
        # Hold still for 1 s (a zero-motion trajectory): sim time and motion time advance, the ball is not there yet.
        r = s.execute([1.0], [HOME])
        assert r.contacts.world_contacts == 0 and s.motion_time == pytest.approx(1.0)
        assert s.obstacle_positions()["ball"] == pytest.approx((0.307, 0.5, 0.59), abs=1e-9)
        # The next second sweeps the ball through the hand: contacts at the substeps, robot still.
        r = s.execute([1.0], [HOME])
        assert ("panda_hand", "ball") in r.contacts.world_pairs or r.contacts.world_contacts > 0
        assert 0 < r.contacts.substeps_in_contact < r.contacts.substeps
        # Restart: motion time 0 again (sim time keeps going), the ball is back at its start.
        t = s.sim_time
        s.restart_motions()
        assert s.motion_time == 0.0 and s.sim_time == t
        assert s.contacts_now().world_contacts == 0
        # hold() (real-time idling) moves the obstacles too.
        s.hold(int(1.5 * s.physics_hz))
        assert s.obstacle_positions()["ball"] == pytest.approx((0.307, 0.0, 0.59), abs=1e-9)
        assert s.contacts_now().world_contacts > 0
    finally:
        s.close()


def test_moving_obstacles_are_deterministic(panda_urdf):
    w = _world({"type": "oscillate", "axis": [0, 1, 0], "amplitude": 0.5, "period": 2.0})
    runs = []
    for _ in range(2):
        s = make_sim(panda_urdf, w)
        try:
            s.reset_robot(HOME)
            out = []
            for _ in range(5):
                r = s.execute([0.37], [HOME])
                out.append(
                    (
                        s.obstacle_positions()["ball"],
                        r.contacts.substeps_in_contact,
                        sorted(r.contacts.world_pairs.items()),
                    )
                )
            runs.append(out)
        finally:
            s.close()
    assert runs[0] == runs[1]


def test_world_message_carries_the_motion():
    pytest.importorskip("moverl_msgs", reason="moverl_msgs not built/sourced (source devel/setup.bash)")
    from moverl_msgs.msg import ObstacleMotion
    from moverl_sim.ros_conversions import world_to_msg

    w = _world({"type": "oscillate", "axis": [0, 1, 0], "amplitude": 0.5, "period": 2.0, "phase": math.pi / 2})
    o = world_to_msg(w).objects[0]
    assert o.motion.type == ObstacleMotion.OSCILLATE and list(o.motion.axis) == [0, 1, 0]
    assert (o.motion.amplitude, o.motion.period, o.motion.phase) == (0.5, 2.0, math.pi / 2)
    assert o.pose.position.y == pytest.approx(1.0)  # the pose at t = 0: centre + amplitude * sin(phase)
    static = world_to_msg(_world(None)).objects[0]
    assert static.motion.type == ObstacleMotion.NONE and static.pose.position.y == pytest.approx(0.5)


def test_world_message_carries_a_reach():
    from moverl_msgs.msg import ObstacleMotion
    from moverl_sim.ros_conversions import world_to_msg

    o = world_to_msg(_world({**REACH, "seed": 3})).objects[0]
    assert o.motion.type == ObstacleMotion.REACH
    assert (o.motion.move, o.motion.hold, o.motion.chance, o.motion.seed) == (0.25, 0.5, 0.5, 3)


def test_displacement_matches_the_shared_cases():
    """The same cases the C++ twin (the planning scene's ObstacleMotion::displacement) is checked on."""
    import os

    import numpy as np

    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "fixtures", "obstacle_motion_cases.txt")
    cases = np.loadtxt(path)
    assert cases.shape == (40, 5)
    for amplitude, period, phase, t, expected in cases:
        m = ObjectMotion(axis=(0.0, 0.0, 1.0), amplitude=amplitude, period=period, phase=phase)
        assert m.displacement(t) == pytest.approx(expected, abs=1e-12), (amplitude, period, phase, t)


def test_position_at_starts_where_the_swing_begins():
    o = _world(
        {"type": "oscillate", "axis": [0, 0, 1], "amplitude": 0.75, "period": 1.0, "phase": math.pi / 2}
    ).objects[0]
    assert o.start == pytest.approx((o.xyz[0], o.xyz[1], o.xyz[2] + 0.75))  # the top of its swing
    assert o.position_at(0.5) == pytest.approx((o.xyz[0], o.xyz[1], o.xyz[2] - 0.75))
