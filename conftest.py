"""pytest's side of the test tiers (tests/tiers.py has the rules; pyproject.toml declares the tiers as markers).

* A rostest node (a test_*.py that a .test file runs as its <test>) is not collected: it needs the graph its .test
  file launches, and runs under rostest in that file's tier.
* Every collected test carries exactly one tier, from its module's ``pytestmark``: a test without one is refused
  (pytest exits with a usage error naming it), so ``pytest -m <tier>`` never skips a file without a tier silently.
"""

import importlib.util
import os
import shutil
import sys
import tempfile
from pathlib import Path

import pytest

_spec = importlib.util.spec_from_file_location("moverl_tiers", Path(__file__).parent / "tests" / "tiers.py")
tiers = sys.modules["moverl_tiers"] = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(tiers)

TIERS = tiers.tiers()
collect_ignore = [str(path) for path in tiers.rostest_nodes()]


@pytest.hookimpl(tryfirst=True)  # before -m deselects anything
def pytest_collection_modifyitems(config, items):
    wrong = {}
    for item in items:
        module = getattr(item, "module", None)
        found = sorted({m.name for m in item.iter_markers() if m.name in TIERS})
        if module is None or not hasattr(module, "pytestmark"):
            wrong.setdefault(item.location[0], "no module-level pytestmark")
        elif len(found) != 1:
            wrong.setdefault(item.location[0], f"tiers {found or 'none'} for {item.name}: a test has exactly one")
    if wrong:
        lines = "\n".join(f"  {path}: {why}" for path, why in sorted(wrong.items()))
        raise pytest.UsageError(
            f"test files without exactly one tier ({', '.join(TIERS)}; tests/tiers.py):\n{lines}\n"
            "add `pytestmark = pytest.mark.<tier>` at module level"
        )


_SB3_LOGDIR = None


def pytest_configure(config):
    # Stable-Baselines3 makes a folder SB3-<date> in the system's temp dir for every model that learns without a logger
    # of its own (its configure() reads SB3_LOGDIR first): the tests' models use one folder of this run's, removed at
    # its end, instead of leaving dozens behind per run.
    global _SB3_LOGDIR
    if "SB3_LOGDIR" not in os.environ:
        _SB3_LOGDIR = os.environ["SB3_LOGDIR"] = tempfile.mkdtemp(prefix="moverl_sb3_")


def pytest_unconfigure(config):
    if _SB3_LOGDIR is not None:
        os.environ.pop("SB3_LOGDIR", None)
        shutil.rmtree(_SB3_LOGDIR, ignore_errors=True)
