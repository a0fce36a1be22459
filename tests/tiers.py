#!/usr/bin/env python3
"""Every test file of MoveRL and its tier: the rule tests/run_all.sh selects tests by, and the check that fails when a
test file belongs to no tier (it would never run).

The tiers are the pytest markers declared in pyproject.toml ([tool.pytest.ini_options] markers), in the order run_all.sh
adds them: core (no ROS master: C++ and Python cores), quick (the fastest checks on a live graph, run with the cores by
`./run.sh test --quick`), live (the rest of the live graph: only the full `./run.sh test`, as CI runs it).

A test file, and where its tier comes from:

* pytest file (src/<pkg>/test/**/test_*.py or *_test.py, tests/**/test_*.py): a module-level
  ``pytestmark = pytest.mark.<tier>`` (or a list with exactly one tier mark). The root conftest.py refuses to collect a
  test without exactly one, so ``pytest -m <tier>`` cannot skip a file silently either.
* rostest node: a test_*.py named by the ``type=`` of a ``<test>`` in a .test file. It is no pytest file (the root
  conftest.py keeps pytest from collecting it: it needs the graph its .test file launches) and has no tier of its own:
  it runs in the tier of each .test file that names it.
* rostest file (src/<pkg>/test/**/*.test): ``<arg name="tier" value="<tier>"/>`` among its top-level tags. run_all.sh
  runs every .test file of a tier once, with no arguments (a variant is a .test file of its own that includes another
  with other arguments, e.g. env_live_shield_off.test).
* gtest source (src/<pkg>/test/**/test_*.cpp or *_test.cpp; other .cpp files there are helpers): named by a
  ``catkin_add_gtest(<binary> test/<file>.cpp ...)`` of its package's CMakeLists.txt; tier core. run_all.sh runs
  devel/lib/<pkg>/<binary>, which must have been built.

    python tests/tiers.py check               every test file with its kind and tier; exit 1 naming each without one
    python tests/tiers.py list KIND TIER...   the files of KIND (pytest, rostest, gtest) in the tiers, one a line
                                              (gtest: each binary once; pytest: path, a tab, the docstring's first line)
"""

from __future__ import annotations

import ast
import re
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree

ROOT = Path(__file__).resolve().parents[1]


def tiers() -> list[str]:
    """The declared tiers: pyproject.toml's pytest markers, in their order."""
    with open(ROOT / "pyproject.toml", "rb") as f:
        markers = tomllib.load(f)["tool"]["pytest"]["ini_options"]["markers"]
    return [m.split(":", 1)[0].strip() for m in markers]


@dataclass
class Entry:
    """A test file: its kind and its tier."""

    path: Path  # relative to the repository
    kind: str  # pytest, rostest node, rostest, gtest
    tier: str | None  # None: no tier (the check fails)
    problem: str = ""  # why it has no tier
    title: str = ""  # what run_all.sh prints for its suite
    binary: str = ""  # gtest: its binary, devel/lib/<pkg>/<binary>


def _is_pytest_name(path: Path) -> bool:
    return path.suffix == ".py" and (path.name.startswith("test_") or path.stem.endswith("_test"))


def _test_dirs() -> list[Path]:
    return sorted(ROOT.glob("src/*/test")) + [ROOT / "tests"]


def rostest_nodes() -> dict[Path, list[Path]]:
    """test_*.py files run as rostest nodes -> the .test files that name them (absolute paths)."""
    nodes: dict[Path, list[Path]] = {}
    for test in sorted(ROOT.glob("src/*/test/**/*.test")):
        for tag in ElementTree.parse(test).getroot().iter("test"):
            node = test.parent / tag.get("type", "")
            nodes.setdefault(node.resolve(), []).append(test)
    return nodes


def _pytest_marks(path: Path) -> list[str] | None:
    """The mark names of the module-level pytestmark (None: no such assignment)."""
    tree = ast.parse(path.read_text(), str(path))
    for node in tree.body:
        if isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            if any(isinstance(t, ast.Name) and t.id == "pytestmark" for t in targets):
                values = node.value.elts if isinstance(node.value, (ast.List, ast.Tuple)) else [node.value]
                marks = []
                for v in values:
                    v = v.func if isinstance(v, ast.Call) else v  # pytest.mark.x(...)
                    if isinstance(v, ast.Attribute) and ast.unparse(v.value) == "pytest.mark":
                        marks.append(v.attr)
                return marks
    return None


def _first_sentence(text: str, width: int = 110) -> str:
    """The first sentence of a text, on one line, at most `width` characters."""
    first = re.split(r"(?<=\.)\s", " ".join(text.split()), maxsplit=1)[0].rstrip(".:")
    return first if len(first) <= width else first[: width - 3].rstrip() + "..."


def _title(path: Path) -> str:
    """The first sentence of a Python file's docstring."""
    return _first_sentence(ast.get_docstring(ast.parse(path.read_text())) or "")


def _one_tier(found: list[str], declared: list[str], where: str) -> tuple[str | None, str]:
    named = [t for t in found if t in declared]
    if len(named) == 1:
        return named[0], ""
    if not named:
        return None, f"no tier in {where} (tiers: {', '.join(declared)})"
    return None, f"{len(named)} tiers in {where} ({', '.join(named)}): a file has one"


def _gtests() -> dict[Path, tuple[str, str]]:
    """gtest source -> (package, binary), from every catkin_add_gtest of the packages' CMakeLists.txt."""
    out = {}
    for cmake in sorted(ROOT.glob("src/*/CMakeLists.txt")):
        text = cmake.read_text()
        project = re.search(r"^\s*project\(\s*(\w+)", text, re.M).group(1)
        for binary, sources in re.findall(r"catkin_add_gtest\(\s*(\S+)\s+([^)]*)\)", text):
            binary = binary.replace("${PROJECT_NAME}", project)
            for src in sources.split():
                out[(cmake.parent / src).resolve()] = (project, binary)
    return out


def collect() -> list[Entry]:
    """Every test file of the repository with its kind and tier."""
    declared = tiers()
    nodes = rostest_nodes()
    gtests = _gtests()
    files: list[Entry] = []
    for d in _test_dirs():
        for path in sorted(p for p in d.rglob("*") if p.is_file()):
            rel = path.relative_to(ROOT)
            if "fixtures" in rel.parts:
                continue
            if path.suffix == ".test":
                args = {a.get("name"): a.get("value") for a in ElementTree.parse(path).getroot().findall("arg")}
                tier, problem = _one_tier([args["tier"]] if args.get("tier") else [], declared, '<arg name="tier">')
                comment = re.search(r"<!--(.*?)-->", path.read_text(), re.S)  # the file's first comment: what it tests
                title = f"rostest {path.stem}" + (f": {_first_sentence(comment.group(1))}" if comment else "")
                files.append(Entry(rel, "rostest", tier, problem, title=title))
            elif path.suffix == ".cpp" and (path.name.startswith("test_") or path.stem.endswith("_test")):
                if path.resolve() in gtests:
                    pkg, binary = gtests[path.resolve()]
                    built = (ROOT / "devel" / "lib" / pkg / binary).is_file()
                    problem = "" if built else f"devel/lib/{pkg}/{binary} is not built (./catkin_ws_setup.sh)"
                    tier = "core" if built else None
                    files.append(Entry(rel, "gtest", tier, problem, f"gtest {binary}", f"devel/lib/{pkg}/{binary}"))
                else:
                    files.append(Entry(rel, "gtest", None, "named by no catkin_add_gtest of its package"))
            elif _is_pytest_name(path):
                marks = _pytest_marks(path)
                if path.resolve() in nodes:
                    by = ", ".join(t.name for t in nodes[path.resolve()])
                    if marks:
                        problem = f"a rostest node (of {by}) with a pytestmark: its tier is its .test file's"
                        files.append(Entry(rel, "rostest node", None, problem))
                    else:
                        files.append(Entry(rel, "rostest node", f"({by})"))
                    continue
                tier, problem = _one_tier(marks or [], declared, "module-level pytestmark")
                if marks is None:
                    problem = f"no module-level pytestmark (pytestmark = pytest.mark.<{'|'.join(declared)}>)"
                title = f"pytest {path.stem}: {_title(path)}" if tier and tier != "core" else f"pytest {path.stem}"
                files.append(Entry(rel, "pytest", tier, problem, title=title))
    return files


def check(files: list[Entry]) -> int:
    width = max(len(str(f.path)) for f in files)
    for f in files:
        print(f"{str(f.path):<{width}}  {f.kind:<12}  {f.tier or 'NONE: ' + f.problem}")
    orphans = [f for f in files if f.tier is None]
    counts = {t: sum(f.tier == t for f in files) for t in tiers()}
    nodes = sum(f.kind == "rostest node" for f in files)
    print(f"{len(files)} test files: " + ", ".join(f"{n} {t}" for t, n in counts.items()) + f", {nodes} rostest nodes")
    for f in orphans:
        print(f"NOT IN A TIER (it would never run): {f.path}: {f.problem}")
    return 1 if orphans else 0


def main(argv: list[str]) -> int:
    if argv[:1] == ["check"] and len(argv) == 1:
        return check(collect())
    if argv[:1] == ["list"] and len(argv) >= 3 and argv[1] in ("pytest", "rostest", "gtest"):
        unknown = set(argv[2:]) - set(tiers())
        if unknown:
            print(f"tiers.py: unknown tier {sorted(unknown)} (tiers: {', '.join(tiers())})", file=sys.stderr)
            return 2
        lines = [
            f.binary if f.kind == "gtest" else f"{f.path}\t{f.title}"
            for f in collect()
            if f.kind == argv[1] and f.tier in argv[2:]
        ]
        for line in dict.fromkeys(lines):  # once each: a gtest binary built from two sources runs once
            print(line)
        return 0
    print(__doc__.split("\n\n")[-1].rstrip(), file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
