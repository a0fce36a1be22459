"""The env's deadline thread (ros_backend._Watchdog), without ROS: what fires, what does not, and how soon."""

import threading
import time

import pytest

from moverl_gym.ros_backend import _Watchdog

pytestmark = pytest.mark.core


def test_fires_after_the_deadline_and_reports_it():
    w = _Watchdog()
    fired = threading.Event()
    token = w.arm(0.05, fired.set)
    assert fired.wait(2.0)
    assert w.disarm(token) is True  # the caller learns that its call was cut
    w.close()


def test_a_disarmed_call_never_fires():
    w = _Watchdog()
    fired = threading.Event()
    for _ in range(200):  # many calls well within their deadline, as env steps are
        token = w.arm(0.2, fired.set)
        assert w.disarm(token) is False
    assert not fired.wait(0.5)
    w.close()


def test_an_earlier_deadline_wakes_a_thread_asleep_until_a_later_one():
    w = _Watchdog()
    late = w.arm(30.0, lambda: None)  # the thread now sleeps until 30 s from now
    time.sleep(0.05)
    w.disarm(late)
    fired = threading.Event()
    t0 = time.monotonic()
    w.arm(0.1, fired.set)
    assert fired.wait(5.0)
    assert time.monotonic() - t0 < 5.0
    w.close()


def test_a_later_deadline_while_asleep_until_an_earlier_one_is_kept():
    """Arming without a wake-up: the thread wakes at the old deadline, finds the new one, sleeps again, fires it."""
    w = _Watchdog()
    first = w.arm(0.05, lambda: None)
    w.disarm(first)
    fired = threading.Event()
    w.arm(0.3, fired.set)
    assert not fired.wait(0.15)
    assert fired.wait(5.0)
    w.close()
