"""When the depth cameras render in lockstep mode (moverl_sim.camera.due_cameras, substeps_until_due). No roscore.

The sim node's lockstep ~execute renders the cameras due at the start of a move, then runs the motion in pieces of
substeps_until_due substeps, rendering the due cameras after each piece (at the end after the last one). run_move
below is that loop, with sim time counted as the simulator counts it (substeps / physics_hz).
"""

import pytest

from moverl_sim.camera import due_cameras, substeps_until_due

HZ = 240.0


def run_move(last, periods, start, n, hz=HZ):
    """A move of n substeps from substep `start`: [(substep, cameras rendered there)]; updates last in place."""
    renders = []
    k = start

    def render_due():
        due = due_cameras(last, periods, k / hz)
        for i in due:
            last[i] = k / hz
        if due:
            renders.append((k, due))

    render_due()
    while k < start + n:
        piece = substeps_until_due(last, periods, k / hz, hz)  # (None: no cameras, the move in one piece)
        k += start + n - k if piece is None else min(start + n - k, max(1, piece))
        render_due()
    return renders


def test_never_rendered_is_due_now():
    assert due_cameras([None, 0.0], [0.25, 0.25], 0.0) == [0]
    assert due_cameras([None, None], [0.25, 0.5], 3.0) == [0, 1]
    assert substeps_until_due([None, 0.0], [0.25, 0.25], 0.0, HZ) == 0


def test_no_cameras():
    assert due_cameras([], [], 1.0) == []
    assert substeps_until_due([], [], 1.0, HZ) is None
    assert run_move([], [], 0, 100) == []


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
        # Half-way there: the rest.
        half = substeps // 2
        if half:
            assert substeps_until_due(last, [period], (m + half) / HZ, HZ) == substeps - half, m


def test_several_cameras_due_in_one_step():
    # Same rate: both at once; rates 4 and 2: both at 0.5 s, only the first at 0.25 s and 0.75 s.
    assert due_cameras([0.0, 0.0], [0.25, 0.25], 60 / HZ) == [0, 1]
    assert run_move([0.0, 0.0], [0.25, 0.5], 0, 180) == [(60, [0]), (120, [0, 1]), (180, [0])]


def test_the_earliest_camera_sets_the_next_piece():
    last, periods = [0.0, 0.1], [0.25, 0.25]
    assert substeps_until_due(last, periods, 0.05, HZ) == 48  # 0.25 - 0.05 s of camera 0
    assert substeps_until_due(last, periods, 0.3, HZ) == 0  # camera 0 overdue
    assert due_cameras(last, periods, 0.3) == [0]
    assert substeps_until_due([0.25, 0.1], periods, 0.3, HZ) == 12  # camera 1 at 0.35 s


def test_moves_shorter_than_a_period():
    """Env steps of dt = 0.05 s (12 substeps) and a 4 Hz camera: a render at the end of every 5th step only."""
    last, renders = [0.0], []
    for step in range(12):
        renders += run_move(last, [0.25], 12 * step, 12)
    assert renders == [(60, [0]), (120, [0])]
    assert last == [0.5]


def test_a_move_spanning_several_periods_renders_several_times():
    """A 0.6 s hold from 0.05 s after the last render: renders at 0.25 s and 0.5 s, in the middle of the move."""
    last = [0.0]
    assert run_move(last, [0.25], 12, 144) == [(60, [0]), (120, [0])]
    assert last == [120 / HZ]
    # A camera that never rendered renders at the start, then every period of the move.
    last = [None, 0.0]
    assert run_move(last, [0.25, 1.0], 0, 300) == [
        (0, [0]),
        (60, [0]),
        (120, [0]),
        (180, [0]),
        (240, [0, 1]),
        (300, [0]),
    ]
