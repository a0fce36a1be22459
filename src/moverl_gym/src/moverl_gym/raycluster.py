"""A local Ray cluster of our own, started in a host process that runs under a moverl_gym reaper.

Why a host process under the reaper, rather than ray.cluster_utils.Cluster in the driver itself: Ray's nodes are
children of whoever starts them, and when the driver is killed Ray's own clean-up (its process reaper kills its
process group) left the nodes' dashboard and runtime-env agents running here (Ray 2.60: re-parented to init, in no
tree and without a readable marker: Ray overwrites its processes' environment area with their process titles).
Under the reaper (PR_SET_CHILD_SUBREAPER) every process of the cluster stays in one tree whatever happens to its
parent, and the reaper stops that tree when the driver closes it or dies in any way (SIGKILL included): SIGINT to the
host (which shuts Ray down cleanly), SIGINT to whatever is left, SIGKILL after the grace period. Env runners and the
ROS graphs their envs launch are in that tree too (each graph also under its own reaper).

Every node listens on 127.0.0.1 with ports the OS picks free, and the cluster keeps its files (sessions, sockets,
logs, the address file that ray.init("auto") reads) in a temp dir of its own ($RAY_TMPDIR): nothing collides with
another Ray on the machine.

Run as `python raycluster.py '<json spec>'` (spec: nodes, temp_dir, address_file, object_store_memory); writes the
cluster's address to address_file once every node is up, then waits for SIGINT/SIGTERM.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import sys
import threading

#: Ray's switch for multi-node clusters on Windows and macOS. Off, Ray takes 127.0.0.1 as the node's own address:
#: ray.init() and node start-up otherwise turn 127.0.0.1 into the host's outward address before they connect, which a
#: cluster listening on loopback does not answer. Nodes started in-process (ray.cluster_utils) are not refused by it.
LOOPBACK_SWITCH = "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"


def main(argv: list[str]) -> int:
    spec = json.loads(argv[1])
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):  # the reaper's SIGINT, or SIGTERM if it died
        signal.signal(sig, lambda *_: stop.set())
    import ray._private.ray_constants as ray_constants
    from ray.cluster_utils import Cluster

    ray_constants.ENABLE_RAY_CLUSTER = os.environ.get(LOOPBACK_SWITCH) != "0"
    common = dict(
        node_ip_address="127.0.0.1",
        temp_dir=spec["temp_dir"],
        include_dashboard=False,
        object_store_memory=spec["object_store_memory"],
        min_worker_port=0,
        max_worker_port=0,
    )
    cluster = Cluster(initialize_head=True, head_node_args={**common, **spec["nodes"][0]})
    try:
        for node in spec["nodes"][1:]:
            cluster.add_node(**{**common, **node})
        cluster.wait_for_nodes(timeout=60)
        tmp = spec["address_file"] + ".tmp"
        with open(tmp, "w") as f:
            f.write(cluster.address)
        os.replace(tmp, spec["address_file"])
        while not stop.wait(0.5):
            pass
    finally:
        cluster.shutdown()
        shutil.rmtree(spec["temp_dir"], ignore_errors=True)  # sessions, sockets, logs (the driver keeps the rest)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
