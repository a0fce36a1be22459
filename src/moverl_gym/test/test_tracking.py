"""The env's tracked obstacle poses (moverl_gym.tracking.TrackedPoses): held with their age, lost explicitly. No
roscore."""

import numpy as np
import pytest

from moverl_gym.tracking import TrackedPoses

pytestmark = pytest.mark.core

INITIAL = np.array([0.8, 0.0, 0.4, 0, 0, 0, 1, 0.8, 0.3, 0.4, 0, 0, 0, 1], dtype=float)


def test_before_a_pose_the_world_files_with_age_inf_and_lost():
    t = TrackedPoses(["torso", "arm"], INITIAL, timeout=0.5)
    poses, ages = t.read(3.0)
    np.testing.assert_array_equal(poses, INITIAL)
    assert np.isinf(ages).all() and t.lost(ages) == 2


def test_held_with_its_age_then_lost_after_the_timeout():
    t = TrackedPoses(["torso", "arm"], INITIAL, timeout=0.5)
    t.update("torso", 1.0, (0.9, 0.1, 0.4, 0, 0, 0, 1))
    t.update("arm", 1.2, (0.9, 0.4, 0.4, 0, 0, 0, 1))
    poses, ages = t.read(1.3)
    np.testing.assert_allclose(poses[:3], [0.9, 0.1, 0.4])
    np.testing.assert_allclose(ages, [0.3, 0.1])
    assert t.lost(ages) == 0
    poses, ages = t.read(1.6)  # no news for 0.6 s: torso lost, still where it was last seen
    np.testing.assert_allclose(poses[:3], [0.9, 0.1, 0.4])
    assert t.lost(ages) == 1


def test_a_late_pose_or_another_frame_is_ignored_and_counted():
    t = TrackedPoses(["torso", "arm"], INITIAL, timeout=0.5, frame="world")
    t.update("torso", 2.0, (1, 1, 1, 0, 0, 0, 1))
    t.update("torso", 1.9, (2, 2, 2, 0, 0, 0, 1))  # measured before the one held
    t.update("arm", 2.0, (3, 3, 3, 0, 0, 0, 1), "camera_optical_frame")
    poses, ages = t.read(2.0)
    np.testing.assert_allclose(poses[:3], [1, 1, 1])
    np.testing.assert_allclose(poses[7:10], INITIAL[7:10])
    assert (t.out_of_order, t.wrong_frame, t.received) == (1, 1, 3)
    assert ages[0] == 0.0 and np.isinf(ages[1])


def test_read_returns_copies_and_bad_input_is_refused():
    t = TrackedPoses(["torso", "arm"], INITIAL, timeout=0.5)
    poses, _ = t.read(0.0)
    poses[:] = 0
    assert t.read(0.0)[0][0] == 0.8
    with pytest.raises(KeyError):
        t.update("leg", 0.0, (0, 0, 0, 0, 0, 0, 1))
    with pytest.raises(ValueError, match="track_timeout"):
        TrackedPoses(["torso"], INITIAL[:7], timeout=0.0)
    with pytest.raises(ValueError, match="expected 14 numbers"):
        TrackedPoses(["torso", "arm"], INITIAL[:7], timeout=1.0)
