"""Assertions, connections and a rollout shared by the live (rostest) tests of the shield and the env."""

import threading

import numpy as np


class GroundTruthContacts:
    """Every contact the simulator saw, from its ~contacts reports (one per finished motion, and while idle): the
    ground truth when the shield's driver reports none (the standard FollowJointTrajectory interface)."""

    def __init__(self, topic="/sim/contacts"):
        import rospy

        from moverl_msgs.msg import ContactReport

        self._lock = threading.Lock()
        self.pairs = {}  # (a, b) -> deepest penetration (m)
        self.substeps_in_contact = 0
        self.moving = self.resting = 0  # who moved: contact pairs per report while the robot moved / rested
        self.reports = 0
        self._sub = rospy.Subscriber(topic, ContactReport, self._on_report, queue_size=100)

    def _on_report(self, msg):
        with self._lock:
            self.reports += 1
            self.substeps_in_contact += msg.substeps_in_contact
            self.moving += msg.moving_contacts
            self.resting += msg.resting_contacts
            for p in msg.pairs:
                self.pairs[(p.a, p.b)] = max(self.pairs.get((p.a, p.b), 0.0), p.depth)

    def snapshot(self):
        """(number of distinct pairs, substeps in contact, reports) so far."""
        with self._lock:
            return len(self.pairs), self.substeps_in_contact, self.reports

    def close(self):
        self._sub.unregister()


class LiveAssertions:
    """Mixin for unittest.TestCase classes that step the live shield or env."""

    @classmethod
    def connect_shield_pair(cls, node_name, *services):
        """Make this process a node and connect to /shield and to the unchecked /shield_off of the same graph
        (cls.step, cls.reset, cls.step_off, cls.reset_off, persistent) and to the scene's check_state, after waiting
        for them and for the extra services named."""
        import rospy

        from moverl_msgs.srv import CheckState, ResetRobot, ShieldStep

        rospy.init_node(node_name, anonymous=True, disable_signals=True)
        for name in (
            "/shield/step",
            "/shield/reset",
            "/shield_off/step",
            "/shield_off/reset",
            "/planning_scene/check_state",
        ) + services:
            rospy.wait_for_service(name, timeout=60)
        cls.step = rospy.ServiceProxy("/shield/step", ShieldStep, persistent=True)
        cls.reset = rospy.ServiceProxy("/shield/reset", ResetRobot, persistent=True)
        cls.step_off = rospy.ServiceProxy("/shield_off/step", ShieldStep, persistent=True)
        cls.reset_off = rospy.ServiceProxy("/shield_off/reset", ResetRobot, persistent=True)
        cls.check_state = rospy.ServiceProxy("/planning_scene/check_state", CheckState)

    def place(self, q, reset=None):
        """Reset the robot to q through the shield (or the given reset proxy); returns the response."""
        res = (reset or self.reset)(positions=q)
        self.assertTrue(res.success, res.message)
        return res

    def assert_no_contacts(self, res, substeps=True):
        """The simulator measured contacts for the step and found none."""
        self.assertTrue(res.contacts.available)
        self.assertEqual(res.contacts.world_contacts + res.contacts.self_contacts, 0, res.contacts.pairs)
        if substeps:
            self.assertEqual(res.contacts.substeps_in_contact, 0)

    def random_rollout_without_contact(self, env, steps, near):
        """Random actions for `steps` env steps, asserting zero contacts at every step; episodes alternate
        between the start `near` (next to the obstacles) and a random start. Returns the verdict counts."""
        counts, episode = {}, 0
        for _ in range(steps):
            _, _, term, trunc, info = env.step(env.action_space.sample())
            self.assertEqual(info["contacts"], 0, info)
            counts[info["verdict"]] = counts.get(info["verdict"], 0) + 1
            if term or trunc:
                episode += 1
                env.reset(options={"start": near} if episode % 2 == 0 else None)
        return counts


def seeded_traces(env, seed: int = 7, steps: int = 25) -> list:
    """Two rollouts of the same fixed actions from reset(seed=seed); asserts they are identical (seed determinism,
    moving obstacles included) and returns the first one's observations."""
    n = env.action_space.shape[0]
    actions = np.random.default_rng(1).uniform(-1, 1, (steps, n)).astype(np.float32)
    traces = []
    for _ in range(2):
        obs, _ = env.reset(seed=seed)
        trace = [obs]
        for a in actions:
            trace.append(env.step(a)[0])
        traces.append(trace)
    for a, b in zip(*traces):
        np.testing.assert_array_equal(a, b)
    return traces[0]


class Tool:
    """A robot (config name) in a PyBullet of this process, without obstacles: inverse kinematics of the end effector
    (pointing down), and the lowest point of the tool (the links below the end-effector link)."""

    DOWN = (1.0, 0.0, 0.0, 0.0)  # the end-effector frame's z axis pointing down (x, y, z, w)

    def __init__(self, robot: str):
        from moverl_gym.paths import robot_config_file
        from moverl_sim.robot_config import load_robot_config
        from moverl_sim.settings import simulator_for
        from moverl_sim.world import World

        rc = load_robot_config(robot_config_file(robot))
        self.sim = simulator_for(rc, World(name="empty"))
        p, robot = self.sim.client, self.sim.robot
        index = {p.getJointInfo(robot, j)[12].decode(): j for j in range(p.getNumJoints(robot))}
        self.ee = index[rc["ee_link"]]
        parents = {j: p.getJointInfo(robot, j)[16] for j in range(p.getNumJoints(robot))}

        def below_ee(j):
            while j >= 0:
                if j == self.ee:
                    return True
                j = parents[j]
            return False

        self.tool = [j for j in parents if below_ee(j)]
        self.movable = [j for j in range(p.getNumJoints(robot)) if p.getJointInfo(robot, j)[2] != 4]  # not fixed
        self.home = np.array(rc["home"], dtype=float)

    def lowest(self, q):
        """The tool's lowest point (m, z) in configuration q."""
        self.sim.reset_robot(list(q))
        return min(self.sim.client.getAABB(self.sim.robot, j)[0][2] for j in self.tool)

    def ee_xyz(self, q):
        self.sim.reset_robot(list(q))
        return np.array(self.sim.client.getLinkState(self.sim.robot, self.ee, computeForwardKinematics=True)[4])

    def ik(self, xyz, seed):
        """Joint angles that put the end effector at xyz, pointing down (from seed)."""
        p, robot = self.sim.client, self.sim.robot
        q = np.asarray(seed, dtype=float)
        for _ in range(5):  # refine from the last answer
            self.sim.reset_robot(list(q))
            sol = p.calculateInverseKinematics(robot, self.ee, list(xyz), self.DOWN, maxNumIterations=200)
            by_joint = dict(zip(self.movable, sol))
            q = np.clip([by_joint[j] for j in self.sim.joint_indices], self.sim.lower, self.sim.upper)
        return q

    def close(self):
        self.sim.close()
