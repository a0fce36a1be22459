"""tools/record_clouds.py end to end on the human world (no ROS): two instants at 80x60, the files and recording.yaml
as the C++ benchmark reads them, the clouds in the optical frame, their poses (the table top where the table is) and
the moving person where its motion puts it at each instant; and what the tool refuses."""

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from moverl_gym.paths import robot_config_file, world_file
from moverl_sim.camera import quaternion_to_rotation
from moverl_sim.robot_config import load_robot_config
from moverl_sim.world import load_world

pytestmark = pytest.mark.live

TOOL = Path(__file__).resolve().parents[1] / "tools" / "record_clouds.py"
TIMES = (0.0, 1.5)  # the person's walk (period 6 s, amplitude 0.15 m along y) is at its +y end at 1.5 s
WIDTH, HEIGHT = 80, 60


def run(*args):
    return subprocess.run([sys.executable, str(TOOL), *map(str, args)], capture_output=True, text=True, timeout=300)


def finite_numbers(values, n=None):
    assert isinstance(values, list) and (n is None or len(values) == n), values
    assert all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in values), values
    return np.asarray(values, dtype=np.float64)


def to_base(points, xyz, quat):
    """Optical-frame points -> the base frame, by a recorded pose."""
    return points.astype(np.float64) @ quaternion_to_rotation(quat).T + np.asarray(xyz)


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    out = tmp_path_factory.mktemp("rec") / "human"
    r = run("--world", "human", "--out", out, "--times", *TIMES, "--size", f"{WIDTH}x{HEIGHT}")
    assert r.returncode == 0, r.stdout + r.stderr
    assert len([line for line in r.stdout.splitlines() if line.startswith("cloud_")]) == 6, r.stdout
    with open(out / "recording.yaml", encoding="utf-8") as f:
        return out, yaml.safe_load(f), r.stdout


def test_header(recording):
    _, doc, _ = recording
    rc = load_robot_config(robot_config_file("panda"))
    assert Path(doc["world"]).is_absolute() and Path(doc["world"]) == world_file("human").resolve()
    assert doc["robot"] == "panda" and doc["base_frame"] == rc["base_link"] == "panda_link0"
    assert doc["joint_names"] == list(rc["joints"])
    # The human world's only static object: the table, a box, in the base frame (the base link is the world origin).
    assert [o["id"] for o in doc["static_objects"]] == ["table"]
    table = doc["static_objects"][0]
    assert table["type"] == "box"
    np.testing.assert_allclose(finite_numbers(table["dimensions"], 3), [1.5, 0.8, 0.03])
    np.testing.assert_allclose(finite_numbers(table["xyz"], 3), [0.35, 0.0, -0.015], atol=1e-12)
    np.testing.assert_allclose(finite_numbers(table["quat"], 4), [0.0, 0.0, 0.0, 1.0], atol=1e-12)


def test_clouds(recording):
    out, doc, _ = recording
    world = load_world(world_file("human"))
    home = load_robot_config(robot_config_file("panda"))["home"]
    clouds = doc["clouds"]
    assert [(c["t"], c["camera"]) for c in clouds] == [(t, cam.id) for t in TIMES for cam in world.cameras]
    assert [c["file"] for c in clouds] == [f"cloud_{i:04d}.f32" for i in range(len(clouds))]
    assert sorted(p.name for p in out.iterdir()) == sorted([c["file"] for c in clouds] + ["recording.yaml"])
    table = doc["static_objects"][0]
    rt = quaternion_to_rotation(table["quat"])
    half = np.asarray(table["dimensions"]) / 2.0
    torso = world.object("human_torso")  # a vertical cylinder [height, radius]
    on_torso = {}  # (instant, where the torso is checked) -> points on its side, all cameras
    for c in clouds:
        assert set(c) == {"file", "camera", "t", "width", "height", "xyz", "quat", "joints"}
        assert (c["width"], c["height"]) == (WIDTH, HEIGHT)
        xyz, quat = finite_numbers(c["xyz"], 3), finite_numbers(c["quat"], 4)
        assert abs(np.linalg.norm(quat) - 1.0) < 1e-9
        np.testing.assert_allclose(finite_numbers(c["joints"], len(home)), home, atol=1e-12)
        path = out / c["file"]
        assert path.stat().st_size == WIDTH * HEIGHT * 3 * 4
        pts = np.fromfile(path, dtype="<f4").reshape(HEIGHT * WIDTH, 3)
        far = world.camera(c["camera"]).far
        # The optical frame: every pixel in front of the camera, no farther than the far plane (no return: z = far).
        assert np.isfinite(pts).all() and (pts[:, 2] > 0.0).all() and (pts[:, 2] <= far + 1e-4).all()
        hit = pts[:, 2] < far - 1e-3
        assert 0.1 * len(pts) < hit.sum() < len(pts), c
        # Pixel rays: row-major, u to the right (x grows along a row), v down (y grows down the rows).
        grid = pts.reshape(HEIGHT, WIDTH, 3) / pts.reshape(HEIGHT, WIDTH, 3)[:, :, 2:]
        assert (np.diff(grid[:, :, 0], axis=1) > 0).all() and (np.diff(grid[:, :, 1], axis=0) > 0).all()
        # The recorded pose is right: a good share of the points lands on the table top (within 3 mm of its plane,
        # inside its outline).
        local = (to_base(pts[hit], xyz, quat) - np.asarray(table["xyz"])) @ rt
        inside = (np.abs(local[:, 0]) <= half[0]) & (np.abs(local[:, 1]) <= half[1])
        top = inside & (np.abs(local[:, 2] - half[2]) < 3e-3)
        assert top.sum() > 0.05 * len(pts), (c, int(top.sum()))
        # The person is where its motion puts it at t (not where it stands at 0).
        p = to_base(pts[hit], xyz, quat)
        for where in (c["t"], 0.0):
            x, y, z = torso.position_at(where)
            r = np.hypot(p[:, 0] - x, p[:, 1] - y)
            side = (np.abs(r - torso.size[1]) < 3e-3) & (np.abs(p[:, 2] - z) < 0.25)
            on_torso[(c["t"], where)] = on_torso.get((c["t"], where), 0) + int(side.sum())
    assert on_torso[(0.0, 0.0)] > 50
    assert on_torso[(1.5, 1.5)] > 50 and on_torso[(1.5, 0.0)] < on_torso[(1.5, 1.5)] / 5, on_torso


def test_output(recording):
    _, _, stdout = recording
    assert "6 clouds (3 cameras x 2 instants)" in stdout


def test_arm_swing(recording, tmp_path):
    """--arm-swing: each cloud is rendered with the arm where the swing puts it at its instant (the joints recorded are
    home_j + A sin(2 pi t / (2 + 0.5 j) + j), within the limits), and the cameras see it there: the clouds differ from
    the arm at home's at the same instants, by the robot's pixels only (the rest of the room is the same)."""
    home_dir, home_doc, _ = recording
    out = tmp_path / "swing"
    swing = 0.3
    r = run("--world", "human", "--out", out, "--times", *TIMES, "--size", f"{WIDTH}x{HEIGHT}", "--arm-swing", swing)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "swinging 0.3 rad about home" in r.stdout, r.stdout
    doc = yaml.safe_load((out / "recording.yaml").read_text())
    home = load_robot_config(robot_config_file("panda"))["home"]
    changed = 0
    for c, h in zip(doc["clouds"], home_doc["clouds"]):
        want = [q + swing * math.sin(2.0 * math.pi * c["t"] / (2.0 + 0.5 * j) + j) for j, q in enumerate(home)]
        np.testing.assert_allclose(finite_numbers(c["joints"], len(home)), want, atol=1e-9)
        pts = np.fromfile(out / c["file"], dtype="<f4")
        differ = np.any(pts.reshape(-1, 3) != np.fromfile(home_dir / h["file"], dtype="<f4").reshape(-1, 3), axis=1)
        assert differ.sum() < 0.5 * len(differ), c  # the arm's pixels, not the room
        changed += int(differ.sum())
    assert changed > 50, changed


def test_replaces_a_previous_recording(recording, tmp_path):
    out = tmp_path / "again"
    r = run("--world", "human", "--out", out, "--times", 0, 0.5, "--size", "16x12")
    assert r.returncode == 0, r.stdout + r.stderr
    r = run("--world", "human", "--out", out, "--times", 0, "--size", "16x12")
    assert r.returncode == 0, r.stdout + r.stderr
    doc = yaml.safe_load((out / "recording.yaml").read_text())
    assert len(doc["clouds"]) == 3 and sorted(p.name for p in out.iterdir()) == sorted(
        [c["file"] for c in doc["clouds"]] + ["recording.yaml"]
    )


def test_refusals(tmp_path):
    nocam = tmp_path / "nocam.yaml"
    nocam.write_text("name: nocam\nobjects: []\n")
    r = run("--world", nocam, "--out", tmp_path / "a")
    assert r.returncode != 0 and "has no cameras" in r.stderr, r.stderr
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("keep me")
    r = run("--world", "human", "--out", foreign, "--times", 0)
    assert r.returncode != 0 and "other than a previous recording" in r.stderr and "notes.txt" in r.stderr, r.stderr
    assert (foreign / "notes.txt").read_text() == "keep me"
    for args, words in (
        (["--size", "640x"], ["--size", "WIDTHxHEIGHT"]),
        (["--size", "0x480"], ["--size", "positive"]),
        (["--times", "-1"], ["--times", ">= 0"]),
        (["--rate", "0"], ["--rate", "> 0"]),
        (["--times", "0", "--duration", "2"], ["either --times or --duration/--rate"]),
        (["--robot", "nope"], ["--robot", "panda", "xarm6"]),
        (["--world", "nope"], ["--world", "human", "table", "case"]),
        (["--robot-visuals", "mesh"], ["visual", "collision"]),
        (["--arm-swing", "-0.1"], ["--arm-swing", ">= 0"]),
    ):
        r = run("--out", tmp_path / "b", *args)
        assert r.returncode == 2 and all(w in r.stderr for w in words), (args, r.stderr)
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


def test_map_benchmark_reads_the_recording(recording):
    """The simulator's clouds, recorded, through the scene's live pipeline (map_benchmark --recording): both
    integrations run on every cloud, and every cloud fits a pinhole camera (none falls back to ray casting)."""
    out, doc, _ = recording
    r = subprocess.run(
        ["rosrun", "moverl_planning_scene", "map_benchmark", "--recording", str(out)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    assert f"{len(doc['clouds'])} clouds of {WIDTH} x {HEIGHT} px" in r.stdout, r.stdout
    reports = [line for line in r.stdout.splitlines() if "fallbacks to ray casting" in line]
    assert len(reports) == 2 and all(line.endswith("; 0 fallbacks to ray casting") for line in reports), r.stdout
    assert "fell back" not in r.stderr, r.stderr
    bad = subprocess.run(
        ["rosrun", "moverl_planning_scene", "map_benchmark", "--recording", str(out / "missing")],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert bad.returncode == 1 and "recording.yaml" in bad.stderr, bad.stdout + bad.stderr
    # Another cell edge on the same clouds (what a coarser map costs); a value that is no length is refused.
    coarse = subprocess.run(
        ["rosrun", "moverl_planning_scene", "map_benchmark", "--recording", str(out), "--resolution", "0.04"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert coarse.returncode == 0 and "map resolution 0.040 m" in coarse.stdout, coarse.stdout + coarse.stderr
    for value in ("0", "-0.02", "2cm", "nan"):
        r = subprocess.run(
            ["rosrun", "moverl_planning_scene", "map_benchmark", "--recording", str(out), "--resolution", value],
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert r.returncode == 2 and "--resolution takes" in r.stderr, (value, r.stderr)
