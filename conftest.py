"""pytest's side of the test tiers (tests/tiers.py has the rules; pyproject.toml declares the tiers as markers).

* A rostest node (a test_*.py that a .test file runs as its <test>) is not collected: it needs the graph its .test
  file launches, and runs under rostest in that file's tier.
* Every collected test carries exactly one tier, from its module's ``pytestmark``: a test without one is refused
  (pytest exits with a usage error naming it), so ``pytest -m <tier>`` never skips a file without a tier silently.
"""

import importlib.util
import sys
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
