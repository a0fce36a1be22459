"""RLlib on a multi-node Ray cluster on this machine (rllib_train.py --local-nodes 2): two env runners, one graph each,
on different Ray nodes; then the same run resumed from its checkpoint while one runner's simulator is killed (the env's
recovery relaunches its graph) and the other runner's process is killed (RLlib restarts the runner). Each run must
finish, count what happened, make no contact, and leave no process of the cluster, the runners or the graphs running
(counted in the run's own process tree, never by name across the machine).
"""

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest
import yaml

from moverl_gym.proctree import TreeWatch, alive, cmdline, tree
from moverl_gym.reaper import is_loopback, listening_sockets

pytestmark = pytest.mark.live

SCRIPTS = Path(__file__).resolve().parents[1] / "scripts"
RUN = "rllib_ppo_PandaReachTable-v0_on_s4"
STEPS = 800  # 2 iterations of 400 steps (rllib_ppo.yml: train_batch_size_per_learner)
MORE = 2000  # the resumed run's steps
DEADLINE = 420  # s for one run on a busy 2-core machine (a clean run takes about a minute)


def train(folder: Path, steps: int, *extra, during=None):
    """rllib_train.py on a local cluster of a CPU-less head and 2 nodes, watched; returns (proc, out, err, watch).
    `during(proc, watch)` runs while training is under way (it returns when it is done)."""
    cmd = [
        sys.executable,
        str(SCRIPTS / "rllib_train.py"),
        "--seed",
        "4",
        "-n",
        str(steps),
        "--n-envs",
        "2",
        "--local-nodes",
        "2",
        "--log-folder",
        str(folder),
        "--checkpoint-freq",
        "400",
        *extra,
    ]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    with TreeWatch(proc.pid) as watch:
        try:
            if during is not None:
                during(proc, watch)
            out, err = proc.communicate(timeout=DEADLINE)
        finally:
            if proc.poll() is None:  # past the deadline: SIGTERM stops runners, graphs and cluster, then SIGKILL
                proc.terminate()
                try:
                    proc.communicate(timeout=60)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.communicate()
    return proc, out, err, watch


def progress(folder: Path) -> list[dict]:
    path = folder / RUN / "progress.jsonl"
    return [json.loads(line) for line in path.read_text().splitlines()] if path.exists() else []


def simulators(watch):
    """The simulator processes seen (the node's script re-executes itself with the venv's python: its command line
    names it, its process name may not)."""
    return watch.matching("sim_node __name:=sim ")


def raylets(watch):
    return [p for p in watch.seen.values() if p.name == "raylet"]


def assert_nothing_left(watch):
    left = watch.wait_gone(30)
    assert not left, f"processes of the run still running after it ended: {left}"


def look_at_sockets(folder: Path, sockets: list):
    """While the run trains: every listening socket of the driver's tree (cluster, runners, graphs)."""

    def during(proc, watch):
        deadline = time.monotonic() + DEADLINE
        while time.monotonic() < deadline and proc.poll() is None and not progress(folder):
            time.sleep(0.5)
        sockets.extend(listening_sockets(tree(proc.pid)))

    return during


@pytest.fixture(scope="module")
def clean_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("rllib")
    sockets = []
    proc, out, err, watch = train(folder, STEPS, "--video", "1", during=look_at_sockets(folder, sockets))
    return folder, proc, out, err, watch, sockets


def test_multinode_cluster_runners_on_different_nodes(clean_run):
    folder, proc, out, err, watch, sockets = clean_run
    assert proc.returncode == 0, err[-4000:]
    assert sockets and all(is_loopback(s.address) for s in sockets), [s for s in sockets if not is_loopback(s.address)]
    run = folder / RUN
    nodes = yaml.safe_load((run / "config.yaml").read_text())["runners"]
    assert len(nodes) == 2 and nodes[0]["node_id"] != nodes[1]["node_id"], nodes
    assert len(raylets(watch)) == 3, "a head and two nodes, each its own raylet"
    # One graph per runner, and no throw-away env with a graph of its own anywhere (driver, runners); after training,
    # one more: the env that records --video 1.
    assert len(simulators(watch)) == 3, watch.cmdlines
    assert len(list((run / "videos").glob("*.mp4"))) == 1, "--video 1: one recorded episode"
    last = progress(folder)[-1]
    assert last["env_steps"] >= STEPS and last["envs_created"] == 2
    assert last["contacts"] == 0 and last["contact_substeps"] == 0
    assert last["steps_without_ground_truth"] == 0, "the simulator measured contacts at every step"
    assert last["graph_failures"] == 0 and last["env_runner_restarts"] == 0 and last["healthy_env_runners"] == 2
    assert "ground-truth contacts (physics): 0 contact pairs" in out, out
    assert (run / "checkpoint" / "algorithm_state.pkl").exists()
    # --checkpoint-freq counts env steps (as train.py's): one checkpoint per multiple of 400 passed, named by steps.
    rows = progress(folder)
    saved = sorted(p.name for p in (run / "checkpoints").iterdir())
    expected, passed = [], 0
    for r in rows:
        if r["env_steps"] // 400 > passed:
            passed = r["env_steps"] // 400
            expected.append(f"model_{r['env_steps']}_steps")
    assert saved == sorted(expected) and len(saved) >= 2, (saved, [r["env_steps"] for r in rows])
    assert list(run.glob("events.out.tfevents.*")), "TensorBoard events"
    assert_nothing_left(watch)
    print(f"\n{len(sockets)} listening sockets, all on loopback; last iteration: {last}")


def test_evaluate_reads_the_rllib_checkpoint(clean_run):
    folder, proc, *_ = clean_run
    assert proc.returncode == 0
    with TreeWatch(os.getpid()) as watch:
        ev = subprocess.run(
            [sys.executable, str(SCRIPTS / "evaluate.py"), str(folder / RUN), "--episodes", "1", "--deterministic"],
            capture_output=True,
            text=True,
            timeout=180,
        )
    assert ev.returncode == 0, ev.stderr[-3000:]
    result = json.loads((folder / RUN / "eval.json").read_text())
    assert result["framework"] == "rllib" and result["episodes"] == 1 and result["contacts_total"] == 0
    assert_nothing_left(watch)


def kill_a_simulator_and_a_runner(folder: Path, steps0: int):
    """While the resumed run trains: SIGKILL the simulator of runner 1 (its env recovers), then the process of runner 2
    (RLlib restarts it). Both found through the runners' pids that the run logs, and the process tree below them."""

    def during(proc, watch):
        deadline = time.monotonic() + DEADLINE
        rows = []
        while time.monotonic() < deadline and proc.poll() is None:
            rows = [r for r in progress(folder) if r["env_steps"] > steps0]
            if rows:
                break
            time.sleep(0.5)
        assert rows, "the resumed run did not get under way"
        runners = {r["worker_index"]: r["pid"] for r in rows[-1]["runners"]}
        sims = [p for p in tree(runners[1]) if "sim_node __name:=sim " in cmdline(p.pid)]
        assert len(sims) == 1, tree(runners[1])
        os.kill(sims[0].pid, signal.SIGKILL)
        victim = [p for p in tree(runners[2]) if p.pid == runners[2]][0]
        os.kill(victim.pid, signal.SIGKILL)
        during.killed = (sims[0], victim)

    return during


def test_fault_tolerance_resumed_run_survives_a_dead_simulator_and_a_dead_runner(clean_run):
    folder, proc, *_ = clean_run
    assert proc.returncode == 0
    steps0 = progress(folder)[-1]["env_steps"]
    during = kill_a_simulator_and_a_runner(folder, steps0)
    proc, out, err, watch = train(folder, steps0 + MORE, "--resume", str(folder / RUN / "checkpoint"), during=during)
    assert proc.returncode == 0, err[-4000:]
    sim, runner = during.killed
    assert not alive(sim) and not alive(runner)
    rows = [r for r in progress(folder) if r["env_steps"] > steps0]
    last = rows[-1]
    # Resumed: iterations and lifetime counters continue from the checkpoint.
    assert rows[0]["iteration"] == 3 and last["env_steps"] >= steps0 + MORE
    # The dead simulator: one graph failure, its graph relaunched inside runner 1 (env recovery).
    assert last["graph_failures"] >= 1 and last["graph_restarts"] >= 1, last
    # The dead runner: restarted by RLlib, in a new process with a graph of its own.
    assert last["env_runner_restarts"] >= 1 and last["healthy_env_runners"] == 2, last
    assert {r["worker_index"]: r["pid"] for r in last["runners"]}[2] != runner.pid
    assert last["envs_created"] >= 2 + 2 + 1, "2 envs in the first run, 2 on resume, 1 in the restarted runner"
    # 2 simulators at the start, 1 relaunched by runner 1's env, 1 in the restarted runner 2.
    assert len(simulators(watch)) == 4, watch.cmdlines
    assert last["contacts"] == 0, last
    assert "graph relaunches (env recovery): " in out and "env runner restarts (RLlib): " in out
    assert_nothing_left(watch)
    print(f"\nresumed run, simulator {sim.pid} and runner {runner.pid} killed; last iteration: {last}")


CLUSTER_DRIVER = """
import sys, time, ray
from moverl_gym.rllib import LocalCluster
cluster = LocalCluster([{"num_cpus": 0}, {"num_cpus": 1}, {"num_cpus": 1}])
@ray.remote(num_cpus=1)
class Busy:
    def pid(self):
        import os
        return os.getpid()
actors = [Busy.remote() for _ in range(2)]
print("up", ray.get([a.pid.remote() for a in actors], timeout=120), flush=True)
time.sleep(600)
"""


def readline_within(proc, seconds: float) -> str:
    """The next line of proc's stdout, or "" when none came within seconds."""
    import select

    ready, _, _ = select.select([proc.stdout], [], [], seconds)
    return proc.stdout.readline() if ready else ""


def test_local_cluster_goes_with_its_driver_killed():
    """A driver SIGKILLed with its local cluster up (3 nodes, 2 actors): no process of the cluster is left. (The
    cluster's log folder stays, as a killed driver cannot remove it: here in a temp dir of the test's, short because
    Ray's socket paths below it must fit in 107 bytes.)"""
    short = tempfile.mkdtemp(prefix="mrl_")
    try:
        left = _kill_driver_with_cluster(short)
    finally:
        shutil.rmtree(short, ignore_errors=True)
    assert not left, f"processes of the cluster left after its driver was killed: {left}"


def _kill_driver_with_cluster(tmp: str):
    proc = subprocess.Popen(
        [sys.executable, "-c", CLUSTER_DRIVER],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=dict(os.environ, TMPDIR=tmp),
    )
    with TreeWatch(proc.pid) as watch:
        try:
            line = readline_within(proc, 240)
            assert line.startswith("up"), proc.stderr.read()[-3000:] if proc.poll() is not None else line
            watch.sample()
            assert len(raylets(watch)) == 3
            proc.kill()
            proc.wait(timeout=30)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait(timeout=30)
        return watch.wait_gone(40)
