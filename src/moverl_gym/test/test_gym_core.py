"""Unit tests of moverl_gym's ROS-free core (no roscore needed)."""

from pathlib import Path

import numpy as np
import pytest

from moverl_gym import ENV_IDS
from moverl_gym.graph import free_port, master_alive
from moverl_gym.paths import config_file, world_file
from moverl_gym.robot import ActionScaler, JointLimits, chain_reach
from moverl_gym.task import ReachTask, TaskConfig
from moverl_gym.training import load_hyperparams

pytestmark = pytest.mark.core

URDF = """<robot name="r">
  <link name="a"/><link name="b"/><link name="c"/>
  <joint name="j1" type="revolute"><parent link="a"/><child link="b"/>
    <limit lower="-1.0" upper="2.0" velocity="2.0" effort="1"/></joint>
  <joint name="j2" type="revolute"><parent link="b"/><child link="c"/>
    <limit lower="-3.0" upper="0.0" velocity="1.0" effort="1"/></joint>
</robot>"""


def test_limits_come_from_the_urdf():
    lim = JointLimits.from_urdf(URDF, ["j2", "j1"])
    np.testing.assert_array_equal(lim.lower, [-3.0, -1.0])
    np.testing.assert_array_equal(lim.upper, [0.0, 2.0])
    np.testing.assert_array_equal(lim.velocity, [1.0, 2.0])


def test_transmissions_do_not_hide_the_joints():
    """ros_control URDFs name every joint again inside a <transmission>: only the <robot>'s own joints count."""
    tr = '<transmission name="t1"><joint name="j1"><hardwareInterface>x</hardwareInterface></joint></transmission>'
    lim = JointLimits.from_urdf(URDF.replace("</robot>", tr + "</robot>"), ["j1"])
    np.testing.assert_array_equal(lim.upper, [2.0])


def test_chain_reach_bounds_the_tip():
    urdf = URDF.replace(
        '<parent link="b"/><child link="c"/>', '<parent link="b"/><child link="c"/><origin xyz="0.3 0.4 0"/>'
    )
    assert chain_reach(urdf, "c") == pytest.approx(0.5)
    assert chain_reach(urdf, "a") == 0.0
    with pytest.raises(ValueError, match="'nope' is not in the URDF"):
        chain_reach(urdf, "nope")


@pytest.mark.parametrize(
    "urdf,joints,match",
    [
        ("<robot", ["j1"], "not valid XML"),
        (URDF, ["nope"], "'nope' is not in the URDF"),
        (URDF.replace('velocity="1.0"', 'velocity="0"'), ["j2"], "unusable limits"),
    ],
)
def test_bad_urdf_gives_clear_errors(urdf, joints, match):
    with pytest.raises(ValueError, match=match):
        JointLimits.from_urdf(urdf, joints)


def test_action_scaling_bounds_delta_and_clips_to_limits():
    lim = JointLimits.from_urdf(URDF, ["j1", "j2"])
    s = ActionScaler(lim, dt=0.05)
    q = np.array([0.0, -1.0])
    np.testing.assert_allclose(s.command(q, [1.0, -1.0]), [0.1, -1.05])
    np.testing.assert_allclose(s.command(q, [0.5, 0.0]), [0.05, -1.0])
    # out-of-range actions are clipped to [-1, 1], targets to the joint limits
    np.testing.assert_allclose(s.command(np.array([1.99, -0.01]), [5.0, 1.0]), [2.0, 0.0])


@pytest.mark.parametrize(
    "action,match", [([0.0], "shape"), ([np.nan, 0.0], "NaN"), ([np.inf, 0.0], "NaN or inf"), ([[0.0, 0.0]], "shape")]
)
def test_bad_actions_are_rejected(action, match):
    s = ActionScaler(JointLimits.from_urdf(URDF, ["j1", "j2"]), dt=0.05)
    with pytest.raises(ValueError, match=match):
        s.command(np.zeros(2), action)


def test_reward_follows_the_paper():
    cfg = TaskConfig.from_yaml(
        config_file("env.yaml"),
        kappa=10.0,
        goal_reward=10.0,
        step_penalty=-0.2,
        safety_penalty=-1.0,
        goal_tolerance=0.1,
    )
    task = ReachTask(cfg, [0.4, 0.2, 0.2])
    assert task.distance([0.4, 0.2, 0.5]) == pytest.approx(0.3)
    assert task.reward(0.5, 0.4, discarded=False) == pytest.approx(10 * 0.1 - 0.2)
    assert task.reward(0.15, 0.05, discarded=False) == pytest.approx(10 * 0.1 + 10.0)
    assert task.reward(0.5, 0.5, discarded=True) == pytest.approx(-0.2 - 1.0)
    assert task.is_success(0.099) and not task.is_success(0.1)
    with pytest.raises(ValueError):
        ReachTask(cfg, [0.0, np.nan, 0.0])


def test_task_config_reads_the_yaml_and_rejects_unknown_keys(tmp_path: Path):
    cfg = TaskConfig.from_yaml(config_file("env.yaml"))
    assert cfg.dt == 0.05 and cfg.max_episode_steps == 100 and cfg.safety_penalty == -1.0
    assert TaskConfig.from_yaml(config_file("env.yaml"), kappa=3).kappa == 3.0
    bad = tmp_path / "env.yaml"
    bad.write_text("dt: 0.05\nkapa: 10\n")
    with pytest.raises(ValueError, match="kapa"):
        TaskConfig.from_yaml(bad)
    bad.write_text("dt: 0.05\nkappa: 10\n")  # a key left out has no default elsewhere
    with pytest.raises(ValueError, match="missing task settings.*goal_reward"):
        TaskConfig.from_yaml(bad)


def test_env_ids_are_registered():
    import gymnasium as gym

    assert "MoveRL/PandaReachTable-v0" in ENV_IDS and "MoveRL/PandaReachTableEE-v0" in ENV_IDS
    for env_id in ENV_IDS:
        spec = gym.spec(env_id)
        assert spec.max_episode_steps is None  # the env truncates after config.max_episode_steps itself
        assert world_file(spec.kwargs["world"]).exists()


def test_hyperparams_follow_the_paper():
    hp = load_hyperparams("ppo", "MoveRL/PandaReachTable-v0")
    assert hp["learning_rate"] == 5e-4 and hp["n_steps"] == 100 and hp["batch_size"] == 100
    with pytest.raises(ValueError, match="no hyper-parameter file"):
        load_hyperparams("nope", "x")


def test_no_master_on_a_free_port():
    assert not master_alive(f"http://127.0.0.1:{free_port()}", timeout=0.5)
