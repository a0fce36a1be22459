import os
import subprocess
import sys
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from conftest import PANDA_URI, PKG_DIR

from moverl_sim.urdf import UrdfError, resolve_uri, robot_description

pytestmark = pytest.mark.core

SCRIPT = os.path.join(PKG_DIR, "scripts", "robot_description")


def test_resolve_uri_forms(tmp_path):
    import pybullet_data

    data = pybullet_data.getDataPath()
    assert resolve_uri(PANDA_URI) == os.path.join(data, "franka_panda", "panda.urdf")
    assert resolve_uri("/a/b/../c.urdf") == "/a/c.urdf"
    assert resolve_uri("file:///a/b.urdf") == "/a/b.urdf"
    assert resolve_uri("meshes/x.obj", base_dir="/r") == "/r/meshes/x.obj"
    # package://<name>/... with no such ROS package: relative to the URDF folder
    assert (
        resolve_uri("package://meshes_moverl_nonexistent/x.obj", base_dir="/r") == "/r/meshes_moverl_nonexistent/x.obj"
    )
    with pytest.raises(UrdfError, match="unsupported URI scheme"):
        resolve_uri("http://example.com/robot.urdf")
    with pytest.raises(UrdfError, match="no ROS package"):
        resolve_uri("package://meshes_moverl_nonexistent/x.obj")


def test_resolve_ros_package(tmp_path, monkeypatch):
    pytest.importorskip("rospkg", reason="rospkg (python3-rospkg) is needed for package:// lookups")
    pkg = tmp_path / "fake_moverl_pkg"
    pkg.mkdir()
    (pkg / "package.xml").write_text(
        '<?xml version="1.0"?><package format="2"><name>fake_moverl_pkg</name>'
        '<version>0.0.0</version><description>x</description>'
        '<maintainer email="a@b.c">a</maintainer><license>BSD</license></package>'
    )
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path))
    assert resolve_uri("package://fake_moverl_pkg/urdf/r.urdf") == str(pkg / "urdf" / "r.urdf")


def test_robot_description_meshes_absolute_and_existing():
    text = robot_description(PANDA_URI)
    root = ET.fromstring(text)
    assert root.tag == "robot"
    meshes = [m.get("filename") for m in root.iter("mesh")]
    assert len(meshes) >= 10
    for f in meshes:
        assert os.path.isabs(f) and os.path.isfile(f), f
    assert "package://" not in text
    assert {link.get("name") for link in root.iter("link")} >= {"panda_link0", "panda_hand", "panda_link8"}


def test_robot_description_errors(tmp_path):
    with pytest.raises(UrdfError, match="not found"):
        robot_description(str(tmp_path / "missing.urdf"))
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot name='x'><link name='a'>")
    with pytest.raises(UrdfError, match="not valid XML"):
        robot_description(str(bad))
    notrobot = tmp_path / "notrobot.urdf"
    notrobot.write_text("<sdf><model/></sdf>")
    with pytest.raises(UrdfError, match="expected <robot>"):
        robot_description(str(notrobot))
    missing_mesh = tmp_path / "mm.urdf"
    missing_mesh.write_text(
        "<robot name='x'><link name='a'><visual><geometry>"
        "<mesh filename='meshes/none.obj'/></geometry></visual></link></robot>"
    )
    with pytest.raises(UrdfError, match="does not exist"):
        robot_description(str(missing_mesh))


def _run_script(*args):
    env = dict(os.environ)
    env["PYTHONPATH"] = os.path.join(PKG_DIR, "src") + os.pathsep + env.get("PYTHONPATH", "")
    return subprocess.run([sys.executable, SCRIPT] + list(args), capture_output=True, text=True, env=env, timeout=60)


def test_robot_description_script(tmp_path):
    r = _run_script(PANDA_URI)
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("<?xml") and "<robot" in r.stdout and "package://" not in r.stdout
    cfg = os.path.join(os.path.dirname(os.path.dirname(PKG_DIR)), "config", "robots", "panda.yaml")
    r2 = _run_script("--robot-config", cfg)
    assert r2.returncode == 0, r2.stderr
    assert r2.stdout == r.stdout
    r = _run_script(str(tmp_path / "missing.urdf"))
    assert r.returncode == 1 and "not found" in r.stderr and r.stdout == ""
    bad = tmp_path / "bad.urdf"
    bad.write_text("not xml at all <")
    r = _run_script(str(bad))
    assert r.returncode == 1 and "not valid XML" in r.stderr


def test_collision_as_visual_draws_the_collision_shapes(tmp_path):
    """config/sim.yaml robot_visuals: collision: every link with collision shapes is drawn as them (the depth cameras
    see the hulls the scene checks), a link without keeps its visuals, nothing else of the URDF changes."""
    from moverl_sim.urdf import collision_as_visual

    text = robot_description(PANDA_URI)
    extra = '<link name="marker"><visual><geometry><sphere radius="0.01"/></geometry></visual></link>'
    out = ET.fromstring(collision_as_visual(text.replace("</robot>", extra + "</robot>")))
    before = ET.fromstring(text)
    for link in out.findall("link"):
        old = before.find(f"link[@name='{link.get('name')}']")
        if link.get("name") == "marker":
            assert link.find("visual/geometry/sphere") is not None
            continue
        drawn = [ET.tostring(v.find("geometry")) for v in link.findall("visual")]
        assert drawn == [ET.tostring(c.find("geometry")) for c in old.findall("collision")] or not drawn
        assert [ET.tostring(c) for c in link.findall("collision")] == [ET.tostring(c) for c in old.findall("collision")]
        assert link.find("visual/material") is None
    assert [j.attrib for j in out.iter("joint")] == [j.attrib for j in before.iter("joint")]


def test_simulator_draws_what_robot_visuals_says(panda_urdf):
    """The simulator's PyBullet robot shows collision meshes only with robot_visuals collision, its visual meshes with
    visual, simplified copies of them (gone once loaded) with simplified; a wrong value is refused naming all three."""
    import pybullet
    from conftest import make_sim

    for looks in ("collision", "visual", "simplified"):
        sim = make_sim(panda_urdf, None, robot_visuals=looks)
        try:
            files = {d[4].decode() for d in pybullet.getVisualShapeData(sim.robot, physicsClientId=sim.client_id)}
            if looks == "collision":
                assert all("/collision/" in f for f in files), files
            elif looks == "visual":
                assert any("/visual/" in f for f in files), files
            else:
                simplified = [f for f in files if "moverl_robot_" in f]
                assert simplified and not any(os.path.exists(f) for f in simplified), files
        finally:
            sim.close()
    with pytest.raises(ValueError, match="robot_visuals must be 'visual', 'simplified' or 'collision'"):
        make_sim(panda_urdf, None, robot_visuals="hulls")
    with pytest.raises(ValueError, match="simplified_faces"):
        make_sim(panda_urdf, None, robot_visuals="simplified", simplified_faces=None)


def test_simplified_visuals_decimate_every_visual_mesh(tmp_path):
    """robot_visuals simplified: every OBJ or STL visual mesh is written simplified to at most config/sim.yaml's
    simplified_faces triangles, within its original's bounding box grown by 3 mm (blind_zone.py measures the points'
    distance from the collision shapes); collision shapes, primitives and meshes already that small stay; a mesh that
    cannot be read is refused naming it."""
    from moverl_sim import meshes
    from moverl_sim.settings import sim_settings
    from moverl_sim.urdf import simplified_visuals

    faces = sim_settings()["simplified_faces"]
    text = robot_description(PANDA_URI)
    out = ET.fromstring(simplified_visuals(text, str(tmp_path), faces))
    before = ET.fromstring(text)
    for link in out.findall("link"):
        old = before.find(f"link[@name='{link.get('name')}']")
        assert [ET.tostring(c) for c in link.findall("collision")] == [ET.tostring(c) for c in old.findall("collision")]
        for new_mesh, old_mesh in zip(link.iter("mesh"), old.iter("mesh")):
            if new_mesh.get("filename") == old_mesh.get("filename"):
                continue
            v0, f0 = meshes.read_mesh(old_mesh.get("filename"))
            v1, f1 = meshes.read_mesh(new_mesh.get("filename"))
            assert new_mesh.get("filename").startswith(str(tmp_path))
            assert len(f0) > faces and len(f1) <= faces, (old_mesh.get("filename"), len(f0), len(f1))
            assert (v1.min(axis=0) >= v0.min(axis=0) - 0.003).all() and (v1.max(axis=0) <= v0.max(axis=0) + 0.003).all()
    assert len(list(tmp_path.iterdir())) >= 7  # the Panda's seven large visual meshes
    # STL (binary and ASCII) as OBJ: a tetrahedron, as its 4 vertices and 4 faces
    tet = [((0, 0, 0), (1, 0, 0), (0, 1, 0)), ((0, 0, 0), (0, 0, 1), (1, 0, 0)), ((0, 0, 0), (0, 1, 0), (0, 0, 1)),
           ((1, 0, 0), (0, 0, 1), (0, 1, 0))]  # fmt: skip
    import struct

    binary = tmp_path / "tet.stl"
    binary.write_bytes(
        b"\0" * 80 + struct.pack("<I", 4) + b"".join(struct.pack("<12fH", *(0, 0, 0), *sum(t, ()), 0) for t in tet)
    )
    ascii_ = tmp_path / "tet_ascii.stl"
    ascii_.write_text(
        "solid t\n"
        + "".join(
            "facet normal 0 0 0\nouter loop\n" + "".join("vertex %g %g %g\n" % v for v in t) + "endloop\nendfacet\n"
            for t in tet
        )
        + "endsolid t\n"
    )
    for f in (binary, ascii_):
        v, faces = meshes.read_mesh(str(f))
        assert v.shape == (4, 3) and faces.shape == (4, 3)
    broken = tmp_path / "broken.obj"
    broken.write_text("v 0 0 0\nf 1 2 3\n")
    with pytest.raises(ValueError, match="broken.obj"):
        meshes.read_mesh(str(broken))
    with pytest.raises(ValueError, match="only .obj, .stl, .dae"):
        meshes.read_mesh(str(tmp_path / "x.ply"))
    with pytest.raises(ValueError, match="max_faces"):
        meshes.simplified(v, faces, 3)


GEOMETRY_FIXTURES = os.path.join(
    os.path.dirname(__file__), "..", "..", "moverl_planning_scene", "test", "fixtures", "geometry", "meshes"
)


def _canonical(faces):
    """Triangles as a sorted list, each rotated to start at its smallest index (its winding kept)."""
    return sorted(tuple(np.roll(t, -int(np.argmin(t)))) for t in faces.tolist())


def test_a_collada_mesh_is_read_in_metres_where_its_nodes_place_it():
    """COLLADA as PyBullet reads it: the triangles of the visual scene's geometries, moved by their nodes' transforms
    (nested: the child's, then the parent's) and scaled by the file's <unit> (millimetres here). blob.stl is the same
    blob in metres, where no node placed it: the same points, the same triangles, the same winding."""
    from moverl_sim import meshes

    ref, ref_faces = meshes.read_mesh(os.path.join(GEOMETRY_FIXTURES, "blob.stl"))
    rotation = np.array([[0.877583, -0.479426, 0.0], [0.479426, 0.877583, 0.0], [0.0, 0.0, 1.0]])
    for name, child_mm in (("blob.dae", [0, 0, 0]), ("blob_nested.dae", [0, 15, -10])):
        v, faces = meshes.read_mesh(os.path.join(GEOMETRY_FIXTURES, name))
        want = (ref + 0.001 * np.array(child_mm)) @ rotation.T + 0.001 * np.array([10, -5, 20])
        distance = np.linalg.norm(v[:, None, :] - want[None, :, :], axis=2)
        assert distance.min(axis=1).max() < 1e-6, name  # float32 STL against 4 decimals of millimetres
        assert len(v) == len(want)
        assert _canonical(distance.argmin(axis=1)[faces]) == _canonical(ref_faces), name


def test_a_collada_visual_is_simplified_and_one_it_cannot_read_is_left_to_pybullet(tmp_path):
    """simplified_visuals decimates a COLLADA visual as it does an OBJ (written in metres: the OBJ has no unit), and
    leaves a COLLADA file it cannot read as it is (here one without a visual scene): PyBullet reads COLLADA itself."""
    from moverl_sim import meshes
    from moverl_sim.urdf import simplified_visuals

    blob = os.path.abspath(os.path.join(GEOMETRY_FIXTURES, "blob.dae"))
    with open(blob, encoding="utf-8") as fh:
        text = fh.read()
    no_scene = tmp_path / "no_scene.dae"
    no_scene.write_text(text[: text.index("<scene>")] + "</COLLADA>\n")
    with pytest.raises(ValueError, match="no visual scene"):
        meshes.read_mesh(str(no_scene))
    urdf = '<robot name="r">%s</robot>' % "".join(
        f'<link name="l{k}"><visual><geometry><mesh filename="{path}"/></geometry></visual></link>'
        for k, path in enumerate((blob, str(no_scene)))
    )
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    names = [m.get("filename") for m in ET.fromstring(simplified_visuals(urdf, str(out_dir), 50)).iter("mesh")]
    assert names[0].startswith(str(out_dir)) and names[0].endswith(".obj")
    assert names[1] == str(no_scene)
    v0, _ = meshes.read_mesh(blob)
    v1, f1 = meshes.read_mesh(names[0])
    assert len(f1) <= 50
    assert (v1.min(axis=0) >= v0.min(axis=0) - 0.003).all() and (v1.max(axis=0) <= v0.max(axis=0) + 0.003).all()


def test_simulator_refuses_a_visual_mesh_it_cannot_simplify(tmp_path, monkeypatch):
    """robot_visuals simplified with a broken visual mesh: a ValueError naming the mesh (the node's clear error), and
    no scratch folder left behind. The scratch folders go to a temp dir of this test's own: the suite's parallel
    workers make theirs in the shared one at the same time."""
    import tempfile

    from moverl_sim.core import Simulator
    from moverl_sim.settings import sim_settings

    (tmp_path / "bad.obj").write_text("v 0 0 0\nf 1 2 3\n")
    urdf = tmp_path / "r.urdf"
    urdf.write_text(
        '<robot name="r"><link name="a"><visual><geometry><mesh filename="bad.obj"/></geometry></visual></link></robot>'
    )
    scratch_root = tmp_path / "tmp"
    scratch_root.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch_root))
    with pytest.raises(ValueError, match="bad.obj cannot be simplified"):
        Simulator(str(urdf), [], "a", None, None, **{**sim_settings(), "robot_visuals": "simplified"})
    assert list(scratch_root.iterdir()) == []
