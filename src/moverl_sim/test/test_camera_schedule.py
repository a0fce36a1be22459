"""When the depth cameras render (moverl_sim.camera_schedule). No roscore.

The sim node's lockstep ~execute is moverl_sim.lockstep.run_motion with the node's CameraSchedule: the cameras due at
the start of a move render, then the motion runs in pieces of CameraSchedule.piece substeps, the due cameras rendering
after each piece, and those due at the end after the move (the node, once it published the final state). run_move
below does exactly that on a real Simulator whose robot stands still, and reports the substeps (the simulator's own
count) at which cameras rendered. The camera thread's choices (CameraSchedule.next_renders) are tested at the end.
"""

import math

import pytest
from conftest import HOME, make_sim

from moverl_sim.camera_schedule import DUE_TOLERANCE, CameraSchedule, due_cameras, substeps_until_due
from moverl_sim.lockstep import run_motion

pytestmark = pytest.mark.core

HZ = 240.0


@pytest.fixture(scope="module")
def still(panda_urdf, table_world):
    """A simulator at HZ whose robot stands at HOME (moves of n substeps that stay there)."""
    s = make_sim(panda_urdf, table_world, physics_hz=HZ)
    s.reset_robot(HOME)
    yield s
    s.close()


def schedule_of(last, periods):
    """A CameraSchedule with these last renders (None: never rendered), nothing pending."""
    schedule = CameraSchedule(periods)
    schedule.last = list(last)
    schedule.pending = [False] * len(periods)
    return schedule


def run_move(sim, schedule, start, n):
    """A move of n substeps from the simulator's substep `start` (reached by holding still): [(substep, cameras
    rendered there)] as the sim node renders them (during the move, then those due at its end)."""
    assert sim.substeps_total <= start, "the simulator is already past this substep: use a new schedule's times"
    sim.hold(start - sim.substeps_total)
    renders = []

    def render(due, during):
        assert during == (sim.substeps_total not in (start, start + n)), (sim.substeps_total, during)
        renders.append((sim.substeps_total, due))
        for i in due:
            schedule.rendered(i, sim.sim_time)
        return [sim.substeps_total]

    motion = sim.prepare([n / HZ], [HOME])
    assert motion.n == n
    result, out = run_motion(sim, motion, schedule if len(schedule) else None, render)
    assert result.contacts.substeps == n and sim.substeps_total == start + n
    assert out == [k for k, _ in renders]  # what the renders returned, in order
    due = schedule.due_now(sim.sim_time)  # due at the end: the node renders them after the final state
    if due:
        render(due, False)
    return renders


class Moves:
    """Moves one after the other on the shared simulator: substeps counted from where it stands (offset)."""

    def __init__(self, sim):
        self.sim, self.offset = sim, sim.substeps_total

    def schedule(self, last, periods):
        """A schedule whose last renders are given relative to the offset."""
        return schedule_of([None if t is None else self.offset / HZ + t for t in last], periods)

    def run(self, schedule, start, n):
        return [(k - self.offset, due) for k, due in run_move(self.sim, schedule, self.offset + start, n)]

    def last(self, schedule):
        return [None if t is None else round((t - self.offset / HZ) * HZ) for t in schedule.last]


def test_never_rendered_is_due_now():
    assert due_cameras([None, 0.0], [0.25, 0.25], 0.0) == [0]
    assert due_cameras([None, None], [0.25, 0.5], 3.0) == [0, 1]
    assert substeps_until_due([None, 0.0], [0.25, 0.25], 0.0, HZ) == 0
    schedule = CameraSchedule([0.25, 0.5])  # a new schedule: every camera pending
    assert schedule.due_now(123.0) == [0, 1] and schedule.next_due == -math.inf


def test_no_cameras(still):
    assert due_cameras([], [], 1.0) == []
    assert substeps_until_due([], [], 1.0, HZ) is None
    schedule = CameraSchedule([])
    assert schedule.due_now(1.0) == [] and schedule.piece(1.0, 17, HZ) == 17
    assert Moves(still).run(schedule, 0, 100) == []


@pytest.mark.parametrize("rate, substeps", [(4.0, 60), (2.0, 120), (3.0, 80), (7.0, 35), (30.0, 8), (240.0, 1)])
def test_due_exactly_at_the_due_substep_despite_float_rounding(rate, substeps):
    """From any render substep m, the camera is next due after ceil(physics_hz / rate) substeps: not one earlier
    (sim time m/hz + 1/rate and (m + k)/hz differ in their last bits), and substeps_until_due says so."""
    period = 1.0 / rate
    for m in list(range(0, 5000, 7)) + [10**6, 10**7 + 3]:
        last = [m / HZ]
        assert substeps_until_due(last, [period], m / HZ, HZ) == substeps, m
        assert due_cameras(last, [period], (m + substeps) / HZ) == [0], m
        assert due_cameras(last, [period], (m + substeps - 1) / HZ) == [], m
        schedule = schedule_of(last, [period])
        assert schedule.piece(m / HZ, 10**9, HZ) == substeps and schedule.piece(m / HZ, 3, HZ) == min(3, substeps)
        # Half-way there: the rest.
        half = substeps // 2
        if half:
            assert substeps_until_due(last, [period], (m + half) / HZ, HZ) == substeps - half, m


def test_several_cameras_due_in_one_step(still):
    # Same rate: both at once; rates 4 and 2: both at 0.5 s, only the first at 0.25 s and 0.75 s.
    assert due_cameras([0.0, 0.0], [0.25, 0.25], 60 / HZ) == [0, 1]
    moves = Moves(still)
    assert moves.run(moves.schedule([0.0, 0.0], [0.25, 0.5]), 0, 180) == [(60, [0]), (120, [0, 1]), (180, [0])]


def test_the_earliest_camera_sets_the_next_piece():
    last, periods = [0.0, 0.1], [0.25, 0.25]
    assert substeps_until_due(last, periods, 0.05, HZ) == 48  # 0.25 - 0.05 s of camera 0
    assert substeps_until_due(last, periods, 0.3, HZ) == 0  # camera 0 overdue
    assert due_cameras(last, periods, 0.3) == [0]
    assert substeps_until_due([0.25, 0.1], periods, 0.3, HZ) == 12  # camera 1 at 0.35 s
    assert schedule_of([0.25, 0.1], periods).piece(0.3, 100, HZ) == 12


def test_moves_shorter_than_a_period(still):
    """Env steps of dt = 0.05 s (12 substeps) and a 4 Hz camera: a render at the end of every 5th step only."""
    moves = Moves(still)
    schedule, renders = moves.schedule([0.0], [0.25]), []
    for step in range(12):
        renders += moves.run(schedule, 12 * step, 12)
    assert renders == [(60, [0]), (120, [0])]
    assert moves.last(schedule) == [120]


def test_a_move_spanning_several_periods_renders_several_times(still):
    """A 0.6 s hold from 0.05 s after the last render: renders at 0.25 s and 0.5 s, in the middle of the move."""
    moves = Moves(still)
    schedule = moves.schedule([0.0], [0.25])
    assert moves.run(schedule, 12, 144) == [(60, [0]), (120, [0])]
    assert moves.last(schedule) == [120]
    # A camera that never rendered renders at the start, then every period of the move.
    moves = Moves(still)
    schedule = moves.schedule([None, 0.0], [0.25, 1.0])
    assert moves.run(schedule, 0, 300) == [(0, [0]), (60, [0]), (120, [0]), (180, [0]), (240, [0, 1]), (300, [0])]


def test_pending_cameras_render_at_once_then_on_their_period(still):
    """A new subscriber or a reset (request_all): every camera renders at the next ~execute's start whatever its last
    render, and the periods count from there."""
    moves = Moves(still)
    schedule = moves.schedule([0.0, 0.0], [0.25, 0.5])
    schedule.request_all()
    assert schedule.next_due == -math.inf
    assert moves.run(schedule, 30, 100) == [(30, [0, 1]), (90, [0])]
    assert moves.last(schedule) == [90, 30]


def test_a_stopped_schedule_renders_nothing_and_runs_moves_in_one_piece():
    schedule = schedule_of([None, 0.0], [0.25, 0.5])
    schedule.stop()
    assert schedule.stopped
    assert schedule.due_now(10.0) == [] and schedule.piece(10.0, 500, HZ) == 500
    assert schedule.next_renders(10.0, realtime=True) == []


def test_the_camera_thread_renders_every_due_camera_at_once_most_overdue_first():
    """next_renders: pending cameras (in both modes) and (real time only) those due, together, most overdue first:
    pending, then never rendered, then the oldest render; with nothing due, next_due is the earliest due time (real
    time) or never (lockstep)."""
    periods = [0.5, 0.5, 0.5]
    schedule = schedule_of([0.4, 0.1, 0.7], periods)
    assert schedule.next_renders(1.0, realtime=False) == [] and schedule.next_due == math.inf
    assert schedule.next_renders(1.0, realtime=True) == [1, 0]  # due since 0.6 s and 0.9 s; camera 2 at 1.2 s
    schedule.rendered(1, 1.0)
    schedule.rendered(0, 1.0)
    assert schedule.next_renders(1.0, realtime=True) == []
    assert schedule.next_due == pytest.approx(1.2 - DUE_TOLERANCE, abs=1e-15)  # camera 2's
    assert schedule.next_renders(1.3, realtime=True) == [2]
    schedule.last[1] = None  # never rendered: before the overdue camera 2
    assert schedule.next_renders(1.3, realtime=True) == [1, 2]
    schedule.pending[0] = True  # pending: before a never-rendered one although it rendered last; in lockstep only it
    assert schedule.next_renders(1.3, realtime=True) == [0] and schedule.next_renders(1.3, realtime=False) == [0]
    schedule.rendered(0, 1.3)
    assert schedule.next_renders(1.3, realtime=False) == []  # lockstep: only pending ones
    assert schedule.pending == [False, False, False] and schedule.last == [1.3, None, 0.7]
    # Cameras that rendered together stay together: at 1.5 s both 1 and 2 are due again (2 since 1.2 s).
    schedule.rendered(1, 1.3)
    schedule.rendered(2, 1.3)
    assert schedule.next_renders(1.8, realtime=True) == [0, 1, 2]
