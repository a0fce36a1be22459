"""Ground truth unchanged (issue 26): the contacts counted at every physics substep, replayed from what the simulator
node received on a live graph with the shield off, are those recorded with the code before the speed work (each
fixture's simulator_commit): the same pairs (link and object names) at the same substeps, depths within 1e-9 m, the same
moving / resting flag. No roscore: the recordings (fixtures/ground_truth/*.json.gz, made by
src/moverl_gym/tools/record_ground_truth.py, which checked them against the live graph's reports step by step) are
replayed through a Simulator in this process.

Runs: random actions in the table, human and case worlds; the pushing policy in the case world (its 5 mm walls) and
in the human world (the walking person, a moving multibody).
"""

import os

import pytest
from conftest import REPO_DIR

from moverl_sim.ground_truth import compare, load, replay_by_substep

pytestmark = pytest.mark.core

FIXTURES = os.path.join(os.path.dirname(os.path.abspath(__file__)), "fixtures", "ground_truth")
RUNS = sorted(f[: -len(".json.gz")] for f in os.listdir(FIXTURES) if f.endswith(".json.gz"))
DEPTH_TOL = 1e-9  # m


def make_sim(record):
    """The simulator the node builds for the recording's robot and world (its start-up configuration included)."""
    from moverl_sim.robot_config import load_robot_config
    from moverl_sim.settings import simulator_for
    from moverl_sim.world import load_world

    rc = load_robot_config(os.path.join(REPO_DIR, "config", "robots", record["robot"] + ".yaml"))
    sim = simulator_for(rc, load_world(os.path.join(REPO_DIR, "worlds", record["world"] + ".yaml")))
    sim.reset_robot(rc["home"])
    return sim


def test_every_run_is_recorded():
    assert {"table_random", "human_random", "case_random", "case_pushing"} <= set(RUNS), RUNS


@pytest.fixture(scope="module", params=RUNS)
def record(request):
    return load(os.path.join(FIXTURES, request.param + ".json.gz"))


def test_recording_has_contacts_with_the_world(record):
    """A recording without contacts would compare nothing: each has contacts with the world (the random runs also
    self contacts; the pushing runs touch the case's walls and the walking person)."""
    kinds = {row[1] for row in record["trace"]}
    assert "world" in kinds and (record["policy"] != "random" or "self" in kinds), (record["name"], kinds)


def test_substep_replay_matches_the_recording(record):
    sim = make_sim(record)
    try:
        trace, counts = replay_by_substep(sim, record["events"])
    finally:
        sim.close()
    diff = compare(record["trace"], trace, DEPTH_TOL)
    assert not diff, "%s: %d of %d pair-substeps differ, first: %s" % (
        record["name"],
        len(diff),
        len(record["trace"]),
        diff[:5],
    )
    assert [list(c) for c in counts] == [list(c) for c in record["live_counts"]]
