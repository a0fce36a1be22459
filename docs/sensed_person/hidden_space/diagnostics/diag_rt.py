"""Diagnostic (issue 52 audits; private env API, not a tool): the pushing policy as pushing_policy_audit.worker runs
it, logging each step's verdict, map_age and shield message to a JSONL file, and every OctomapStatus the scene
publishes to <out>.status.

    python diag_rt.py <robot config> <world> lockstep|realtime <steps> <out.jsonl>
"""

import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[4] / "src" / "moverl_gym" / "tools"))
import numpy as np
import pushing_policy_audit as ppa
from gymnasium.wrappers import TimeLimit

from moverl_gym.env import MoveRLReachEnv
from moverl_gym.paths import config_file, world_file
from moverl_gym.task import TaskConfig
from moverl_sim.robot_config import load_robot_config
from moverl_sim.settings import simulator_for
from moverl_sim.world import load_world

robot_config, world, mode, steps, out = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4]), sys.argv[5]
rc = load_robot_config(robot_config)
rng = np.random.default_rng(0)
sim = simulator_for(rc, load_world(str(world_file(world))))


def contacts(q):
    sim.reset_robot(q)
    return sim.contacts_now().world_pairs


targets, _ = ppa.pushing_targets(contacts, rc["home"], sim.lower, sim.upper, rng, spread=1.0)
sim.close()
max_steps = TaskConfig.from_yaml(config_file("env.yaml")).max_episode_steps
env = TimeLimit(
    MoveRLReachEnv(
        world=world,
        shield=True,
        graph="launch",
        launch_args={"robot_config": robot_config, "obstacles": "sensed", "mode": mode},
    ),
    max_episode_steps=max_steps,
)
inner = env.unwrapped
import rospy  # noqa: E402 (after the env has initialised rospy)

from moverl_msgs.msg import OctomapStatus  # noqa: E402

status_log = open(out + ".status", "w")


def on_status(m):
    status_log.write(
        json.dumps(
            {
                "wall": round(time.time(), 3),
                "now": round(rospy.get_time(), 3),
                "stamp": round(m.header.stamp.to_sec(), 3),
                "frame": m.sensor_frame,
                "map_time": round(m.map_time, 3),
                "integ": round(m.integration_time, 4),
                "dropped": m.dropped,
                "hidden": m.hidden_cells,
                "turned": m.turned_stale,
                "stale": m.stale_cells,
                "clouds": m.clouds,
                "unheard": list(m.unheard_cameras),
            }
        )
        + "\n"
    )


rospy.Subscriber("/planning_scene/octomap_status", OctomapStatus, on_status, queue_size=100)
policy = ppa.PushingPolicy(targets, inner.scaler.max_delta, rng, noise=0.3, switch=50)
env.reset(seed=0)
t0 = time.perf_counter()
with open(out, "w") as f:
    for i in range(steps):
        a = policy.act(inner.q)
        _, _, term, trunc, info = env.step(a)
        policy.feedback(info["discarded"])
        f.write(
            json.dumps(
                {
                    "i": i,
                    "t": round(time.perf_counter() - t0, 3),
                    "v": info["verdict"],
                    "age": round(info["map_age"], 3),
                    "msg": info["message"][:300],
                }
            )
            + "\n"
        )
        if term or trunc:
            env.reset()
            policy.reset()
            f.write(json.dumps({"i": i, "reset": True, "t": round(time.perf_counter() - t0, 3)}) + "\n")
env.close()
