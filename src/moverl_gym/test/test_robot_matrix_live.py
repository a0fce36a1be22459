"""Every shipped robot in every scenario, against the live graph with the shield on (each case launches its own graph
on a free port): Gymnasium's and SB3's check_env, seed determinism (the walking person included), and a random policy
with zero ground-truth contacts. Robots come from config/robots/*.yaml; nothing here names one."""

import gymnasium as gym
import numpy as np
import pytest
from live_helpers import seeded_traces

import moverl_gym  # noqa: F401
from moverl_gym.registration import ROBOTS, SCENARIOS, env_id

pytestmark = pytest.mark.live

RANDOM_STEPS = 500
CASES = [(robot, scenario) for robot in ROBOTS.values() for scenario in SCENARIOS]


@pytest.mark.parametrize("robot, scenario", CASES)
def test_check_env_determinism_and_random_policy_without_contact(robot, scenario):
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make(env_id(robot, scenario))
    try:
        u = env.unwrapped
        assert env.action_space.shape == (u.limits.size,)
        check_env(u, skip_render_check=True)
        sb3_check_env(u, warn=True)
        seeded_traces(env)
        env.reset(seed=3)
        env.action_space.seed(3)
        verdicts, contacts = {}, 0
        for _ in range(RANDOM_STEPS):
            obs, _, term, trunc, info = env.step(env.action_space.sample())
            assert env.observation_space.contains(obs)
            verdicts[info["verdict"]] = verdicts.get(info["verdict"], 0) + 1
            contacts += info["contacts"]
            if term or trunc:
                env.reset()
        print(f"\n{env_id(robot, scenario)}: {RANDOM_STEPS} random steps, verdicts {verdicts}, {contacts} contacts")
        assert contacts == 0, verdicts
    finally:
        env.close()


@pytest.mark.parametrize("robot", sorted(ROBOTS.values()))
def test_planning_across_the_whole_span_of_wide_joints(robot):
    """Joints that turn more than a full turn (limits of +-2 pi): the planner plans in the joint limits as given, no
    wrap-around, from one end of their span to the other (the base joint when a robot has none)."""
    import rospy

    from moverl_msgs.srv import CheckPath, PlanPath

    env = gym.make(env_id(robot, "Case"))
    try:
        u = env.unwrapped
        lo, hi = u.limits.lower, u.limits.upper
        wide = [j for j in range(u.limits.size) if hi[j] - lo[j] > 2 * np.pi] or [0]
        start, goal = np.array(u._backend.home, dtype=float), np.array(u._backend.home, dtype=float)
        start[wide], goal[wide] = hi[wide] - 0.2, lo[wide] + 0.2
        assert u._backend.check_state(start) and u._backend.check_state(goal)
        plan = rospy.ServiceProxy("/planning_scene/plan", PlanPath)(
            start=list(start), goal=list(goal), planner="", time_limit=2.0
        )
        assert plan.outcome == PlanPath._response_class.SUCCESS, plan.message
        points = np.array([p.positions for p in plan.path.points])
        assert np.all(points >= lo - 1e-9) and np.all(points <= hi + 1e-9)
        np.testing.assert_allclose(points[0], start)
        np.testing.assert_allclose(points[-1], goal)
        check = rospy.ServiceProxy("/planning_scene/check_path", CheckPath)
        for a, b in zip(points[:-1], points[1:]):
            assert check(start=list(a), goal=list(b)).outcome == CheckPath._response_class.VALID
        span = points[:, wide].max(axis=0) - points[:, wide].min(axis=0)
        assert np.all(span >= (hi[wide] - lo[wide]) - 0.5), span  # crossed the span, not a wrap to a near angle
    finally:
        env.close()
