"""Every verdict and outcome code written outside a message definition equals the definition.

The .srv / .action files are the one source of the codes. Python reads them from the generated classes; the C++ enums
are checked against the generated headers by static_asserts (shield_node.cpp, planning_scene_node.cpp: the build fails
when one differs). This test checks what remains: the tables Python builds from the classes, the codes moverl_sim.follow
states for control_msgs, the verdict names the C++ shield publishes (ShieldEvent.verdict_name), and the .srv files
themselves against the classes generated from them (a stale build)."""

import re
from pathlib import Path

import pytest

from control_msgs.msg import FollowJointTrajectoryResult
from moverl_gym import env
from moverl_msgs.srv import ShieldStepResponse
from moverl_sim import follow

pytestmark = pytest.mark.core

REPO = Path(__file__).resolve().parents[3]


def srv_constants(name: str) -> dict:
    """The constants of the response part of src/moverl_msgs/srv/<name>.srv, as written there."""
    text = (REPO / "src" / "moverl_msgs" / "srv" / f"{name}.srv").read_text().split("---", 1)[1]
    return {m.group(1): int(m.group(2)) for m in re.finditer(r"^\s*u?int\d+\s+([A-Z_]+)\s*=\s*(-?\d+)", text, re.M)}


@pytest.mark.parametrize(
    "name", ["ShieldStep", "ValidateMotion", "CheckState", "CheckPath", "PlanPath", "ExecuteTrajectory"]
)
def test_generated_classes_match_the_srv_files(name):
    import moverl_msgs.srv as srv

    cls = getattr(srv, f"{name}Response")
    written = srv_constants(name)
    assert written, name
    assert {k: getattr(cls, k) for k in written} == written


def test_env_verdict_table_is_the_message():
    assert env.VERDICTS == {v: k.lower() for k, v in srv_constants("ShieldStep").items()}
    assert env.ABORTED == ShieldStepResponse.ABORTED
    assert set(env.FAILURES) | env.DISCARDED | {env.ABORTED} <= set(env.VERDICTS)
    # Every DISCARDED_* verdict of the message is counted in the training logs, under its own name.
    discarded = sorted((v, k.lower()) for k, v in srv_constants("ShieldStep").items() if k.startswith("DISCARDED_"))
    assert env.DISCARDED_COUNTERS == tuple(name for _, name in discarded)
    assert env.DRIVER_ERRORS == {
        getattr(FollowJointTrajectoryResult, n): n
        for n in dir(FollowJointTrajectoryResult)
        if n.isupper() and getattr(FollowJointTrajectoryResult, n) != 0
    }


def test_follow_codes_are_control_msgs():
    for name in (
        "SUCCESSFUL",
        "INVALID_GOAL",
        "INVALID_JOINTS",
        "OLD_HEADER_TIMESTAMP",
        "PATH_TOLERANCE_VIOLATED",
        "GOAL_TOLERANCE_VIOLATED",
    ):
        assert getattr(follow, name) == getattr(FollowJointTrajectoryResult, name), name


def test_the_shields_verdict_names_are_the_message_constants():
    """shield_core.cpp's verdictName() (published as ShieldEvent.verdict_name) names each verdict as the env does."""
    source = (REPO / "src" / "moverl_shield" / "src" / "shield_core.cpp").read_text()
    body = source[source.index("std::string verdictName") : source.index("bool isDiscarded")]
    cpp = dict(re.findall(r"case Verdict::k(\w+):\s*return \"(\w+)\";", body))
    assert sorted(cpp.values()) == sorted(k.lower() for k in srv_constants("ShieldStep"))
