"""Import layering, checked on the source with `ast` (STYLE.md, "Layout").

- checker/ imports nothing from zenoh or asyncio, nor agreement;
- nodes/ and runtime/ (except runtime/cli.py) never import checker;
- agreement/ (the layer over both) may import checker and runtime; nothing below imports it;
- nodes/ never imports random, time, asyncio, threading, socket or zenoh;
- `import checker` in a fresh interpreter does not load zenoh.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.timeout(60)

ROOT = Path(__file__).resolve().parents[1]


def _imports(path: Path) -> set[str]:
    """Top-level names of every module imported anywhere in the file (incl. inside functions)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    found: set[str] = set()
    for item in ast.walk(tree):
        if isinstance(item, ast.Import):
            found.update(alias.name.split(".")[0] for alias in item.names)
        elif isinstance(item, ast.ImportFrom) and item.level == 0 and item.module:
            found.add(item.module.split(".")[0])
        elif (isinstance(item, ast.Call) and isinstance(item.func, ast.Name | ast.Attribute)
              and getattr(item.func, "attr", getattr(item.func, "id", "")) in (
                  "import_module", "__import__")
              and item.args and isinstance(item.args[0], ast.Constant)
              and isinstance(item.args[0].value, str)):
            found.add(item.args[0].value.split(".")[0])
    return found


def _dotted_imports(path: Path) -> set[str]:
    """Full dotted names of every module imported with `import a.b` or `from a.b import c`."""
    found: set[str] = set()
    for item in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(item, ast.Import):
            found.update(alias.name for alias in item.names)
        elif isinstance(item, ast.ImportFrom) and item.level == 0 and item.module:
            found.add(item.module)
            found.update(f"{item.module}.{alias.name}" for alias in item.names)
    return found


def _modules(package: str) -> list[Path]:
    return sorted((ROOT / package).rglob("*.py"))


def _offences(package: str, banned: set[str], skip: set[str] = frozenset()) -> list[str]:
    bad = []
    for path in _modules(package):
        rel = path.relative_to(ROOT).as_posix()
        if rel in skip:
            continue
        hits = sorted(_imports(path) & banned)
        if hits:
            bad.append(f"{rel} imports {', '.join(hits)}")
    return bad


def test_checker_imports_no_transport():
    assert _modules("checker"), "checker/ has no modules"
    assert _offences("checker", {"zenoh", "asyncio"}) == []


def test_runtime_and_nodes_do_not_import_checker():
    assert _offences("runtime", {"checker"}, skip={"runtime/cli.py"}) == []
    assert _offences("nodes", {"checker"}) == []


def test_only_the_cli_imports_agreement():
    assert _offences("checker", {"agreement"}) == []
    live = {"runtime.launcher", "runtime.host", "runtime.zenoh_transport", "runtime.node_main",
            "runtime.cli", "runtime.clock"}
    bad = [f"{path.relative_to(ROOT).as_posix()} imports {sorted(hits)}"
           for path in _modules("checker") if (hits := _dotted_imports(path) & live)]
    assert bad == []
    assert _offences("nodes", {"agreement"}) == []
    assert _offences("runtime", {"agreement"}, skip={"runtime/cli.py"}) == []


def test_nodes_import_no_sources_of_nondeterminism():
    banned = {"random", "time", "asyncio", "threading", "socket", "zenoh"}
    assert _offences("nodes", banned) == []


def test_import_checker_does_not_load_zenoh():
    code = ("import sys, checker, checker.commands; "
            "print('zenoh' in sys.modules, 'asyncio' in sys.modules)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=ROOT, timeout=60, env={"PYTHONPATH": str(ROOT),
                                                     "PATH": "/usr/bin:/bin"})
    assert proc.returncode == 0, proc.stderr
    zenoh_loaded, _asyncio_loaded = proc.stdout.split()
    assert zenoh_loaded == "False"


def test_the_checker_detects_what_it_should(tmp_path):
    # The scanner itself: a banned import inside a function is found.
    sample = tmp_path / "m.py"
    sample.write_text("def f():\n    import zenoh.ext\n    from time import monotonic\n")
    assert _imports(sample) == {"zenoh", "time"}
