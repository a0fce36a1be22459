"""The tier rules (tests/tiers.py, conftest.py) on a repository made up for the test: each kind of test file gets its
tier from where the rules say, and a file in no tier (or two) is named, by the check and by pytest itself. No ROS."""

import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from moverl_gym.paths import load_script

pytestmark = pytest.mark.core

ROOT = Path(__file__).resolve().parents[1]
tiers = load_script(ROOT / "tests" / "tiers.py", "moverl_tiers_under_test", register=True)

PYPROJECT = """
[tool.pytest.ini_options]
markers = ["core: no graph", "quick: fast live", "live: the rest"]
addopts = "--strict-markers"
"""


def write(root: Path, rel: str, text: str) -> Path:
    path = root / rel
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(textwrap.dedent(text).lstrip())
    return path


@pytest.fixture
def repo(tmp_path, monkeypatch):
    """A repository with one test file of each kind, each in a tier."""
    write(tmp_path, "pyproject.toml", PYPROJECT)
    write(tmp_path, "src/pkg/CMakeLists.txt", "project(pkg)\ncatkin_add_gtest(${PROJECT_NAME}_test test/test_a.cpp)\n")
    write(tmp_path, "src/pkg/test/test_a.cpp", "// gtest\n")
    write(tmp_path, "devel/lib/pkg/pkg_test", "")
    write(tmp_path, "src/pkg/test/test_core.py", '"""Core."""\nimport pytest\n\npytestmark = pytest.mark.core\n')
    write(
        tmp_path,
        "src/pkg/test/test_fast_live.py",
        '"""Fast. More."""\nimport pytest\npytestmark = [pytest.mark.quick]\n',
    )
    write(
        tmp_path,
        "src/pkg/test/a.test",
        """
        <!-- A graph. Of one node. -->
        <launch>
          <arg name="tier" value="live"/>
          <test test-name="a" pkg="pkg" type="test_node.py"/>
        </launch>
        """,
    )
    write(tmp_path, "src/pkg/test/test_node.py", "import rostest\n")  # a rostest node: no pytestmark
    write(tmp_path, "src/pkg/test/helpers.py", "X = 1\n")  # not a test file
    write(tmp_path, "src/pkg/test/peer.cpp", "// a helper executable, not a test file\n")
    monkeypatch.setattr(tiers, "ROOT", tmp_path)
    return tmp_path


def by_path(entries) -> dict:
    return {str(e.path): e for e in entries}


def test_each_kind_gets_its_tier_from_its_rule(repo, capsys):
    entries = by_path(tiers.collect())
    assert tiers.tiers() == ["core", "quick", "live"]
    assert {p: (e.kind, e.tier) for p, e in entries.items()} == {
        "src/pkg/test/test_a.cpp": ("gtest", "core"),
        "src/pkg/test/test_core.py": ("pytest", "core"),
        "src/pkg/test/test_fast_live.py": ("pytest", "quick"),
        "src/pkg/test/a.test": ("rostest", "live"),
        "src/pkg/test/test_node.py": ("rostest node", "(a.test)"),
    }
    assert entries["src/pkg/test/test_a.cpp"].binary == "devel/lib/pkg/pkg_test"
    assert entries["src/pkg/test/a.test"].title == "rostest a: A graph"
    assert entries["src/pkg/test/test_fast_live.py"].title == "pytest test_fast_live: Fast"
    assert tiers.check(tiers.collect()) == 0
    assert tiers.main(["list", "pytest", "quick", "live"]) == 0
    assert capsys.readouterr().out.splitlines()[-1] == "src/pkg/test/test_fast_live.py\tpytest test_fast_live: Fast"


@pytest.mark.parametrize(
    "rel,text,problem",
    [
        ("src/pkg/test/test_new.py", "def test_x():\n    pass\n", "no module-level pytestmark"),
        ("src/pkg/test/test_new.py", "import pytest\npytestmark = pytest.mark.slow\n", "no tier in module-level"),
        ("tests/test_new.py", "import pytest\npytestmark = [pytest.mark.core, pytest.mark.live]\n", "2 tiers"),
        ("src/pkg/test/test_node.py", "import pytest\npytestmark = pytest.mark.live\n", "a rostest node (of a.test)"),
        ("src/pkg/test/b.test", "<launch><arg name='tier' value='nightly'/></launch>\n", "no tier in <arg"),
        ("src/pkg/test/c.test", "<launch/>\n", "no tier in <arg"),
        ("src/pkg/test/test_b.cpp", "// not built by any catkin_add_gtest\n", "named by no catkin_add_gtest"),
    ],
)
def test_a_file_in_no_tier_fails_the_check(repo, rel, text, problem, capsys):
    write(repo, rel, text)
    assert tiers.check(tiers.collect()) == 1
    out = capsys.readouterr().out
    assert f"NOT IN A TIER (it would never run): {rel}: " in out and problem in out, out


def test_a_gtest_built_from_two_sources_is_listed_once(repo, capsys):
    write(
        repo,
        "src/pkg/CMakeLists.txt",
        "project(pkg)\ncatkin_add_gtest(${PROJECT_NAME}_test test/test_a.cpp test/b_test.cpp)\n",
    )
    write(repo, "src/pkg/test/b_test.cpp", "// gtest\n")
    entries = by_path(tiers.collect())
    assert entries["src/pkg/test/b_test.cpp"].binary == entries["src/pkg/test/test_a.cpp"].binary
    capsys.readouterr()
    assert tiers.main(["list", "gtest", "core"]) == 0
    assert capsys.readouterr().out.splitlines() == ["devel/lib/pkg/pkg_test"]


def test_an_unbuilt_gtest_fails_the_check(repo, capsys):
    (repo / "devel/lib/pkg/pkg_test").unlink()
    assert tiers.check(tiers.collect()) == 1
    assert "devel/lib/pkg/pkg_test is not built" in capsys.readouterr().out


def test_pytest_refuses_a_file_without_a_tier_and_never_collects_a_rostest_node(repo):
    shutil.copy(ROOT / "conftest.py", repo / "conftest.py")
    write(repo, "tests/tiers.py", (ROOT / "tests" / "tiers.py").read_text())
    write(repo, "src/pkg/test/test_node.py", "def test_needs_a_graph():\n    raise AssertionError('collected')\n")

    def pytest_(*args):
        cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *args]
        return subprocess.run(cmd, cwd=repo, capture_output=True, text=True, timeout=120)

    write(repo, "src/pkg/test/test_core.py", "import pytest\npytestmark = pytest.mark.core\ndef test_x():\n    pass\n")
    r = pytest_("-m", "core", "src")
    assert r.returncode == 0 and "1 passed" in r.stdout, r.stdout + r.stderr  # the rostest node is not collected
    write(repo, "src/pkg/test/test_orphan.py", "def test_y():\n    pass\n")
    r = pytest_("-m", "core", "src")  # -m core would deselect it silently: refused instead
    assert r.returncode == 4 and "src/pkg/test/test_orphan.py: no module-level pytestmark" in r.stderr, r.stderr
