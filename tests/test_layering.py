"""Import layering and import circles, checked on the source with `ast` (DESIGN.md §1).

Every source file belongs to one layer, named by its folder; each layer may import
only the layers listed under it in `ALLOWED`, with no exemptions:

- `twinfleet/__init__.py` (the node API) re-exports the contract of `runtime/`;
- `runtime/` (contract + live driver) imports no other layer, and its contract modules
  (`CONTRACT`) import only each other;
- `checker/` imports the contract modules of `runtime/` and nothing of zenoh or asyncio;
- `nodes/` (the case study) imports the node API and the runtime's contract modules, and
  no source of nondeterminism (random, time, asyncio, threading, socket, zenoh);
- `agreement/` (the layer over both drivers) imports runtime, checker and nodes;
- the command line (`twinfleet/cli.py`, `twinfleet/__main__.py`) and the testing API
  (`twinfleet/testing.py`) sit on top, side by side.

No two source files import each other, directly or through others.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.timeout(60)

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = {"runtime": "runtime", "checker": "checker", "nodes": "nodes", "agreement": "agreement"}
#: runtime/ modules that import neither Zenoh nor asyncio: the checker and the nodes may use them.
CONTRACT = {"config", "context", "dispatch", "examples", "kinds", "lint", "messages", "names", "node",
            "params", "property_eval", "scenario", "snapshot", "tracefile"}
ALLOWED = {
    "api": {"api", "runtime-contract"},
    "runtime-contract": {"runtime-contract"},
    "runtime": {"runtime", "runtime-contract"},
    "checker": {"checker", "runtime-contract", "api"},
    "nodes": {"nodes", "runtime-contract", "api"},
    "agreement": {"agreement", "checker", "nodes", "runtime", "runtime-contract", "api"},
    "cli": {"cli", "agreement", "checker", "nodes", "runtime", "runtime-contract", "api"},
    "testing": {"testing", "agreement", "checker", "nodes", "runtime", "runtime-contract", "api"},
}
BANNED_THIRD_PARTY = {
    "checker": {"zenoh", "asyncio"},
    "nodes": {"random", "time", "asyncio", "threading", "socket", "zenoh"},
}


def _module_name(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[0] in FOLDERS:
        parts = ["twinfleet", *parts]
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _sources() -> dict[str, Path]:
    files = [p for folder in (*FOLDERS, "twinfleet") for p in (ROOT / folder).rglob("*.py")]
    return {_module_name(p): p for p in sorted(files)}


SOURCES = _sources()


def _layer(module: str) -> str:
    parts = module.split(".")
    if len(parts) == 1:
        return "api"
    if parts[1] in ("cli", "__main__"):
        return "cli"
    if parts[1] == "testing":  # twinfleet.testing: checks and fleets in pytest, on top too
        return "testing"
    if parts[1] == "runtime" and len(parts) > 2 and parts[2] in CONTRACT:
        return "runtime-contract"
    return parts[1]


def _imported(path: Path) -> set[str]:
    """Every module an import in the file names, inside functions too (dotted, absolute).

    `from a import b` names `a.b` when that is a source module, else `a`.
    """
    found: set[str] = set()
    for item in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(item, ast.Import):
            found.update(alias.name for alias in item.names)
        elif isinstance(item, ast.ImportFrom) and item.module:
            assert item.level == 0, f"{path}: relative import"
            subs = {f"{item.module}.{alias.name}" for alias in item.names}
            found.update(subs & SOURCES.keys() or {item.module})
            if not subs <= SOURCES.keys() and subs & SOURCES.keys():
                found.add(item.module)
        elif (isinstance(item, ast.Call) and isinstance(item.func, ast.Name | ast.Attribute)
              and getattr(item.func, "attr", getattr(item.func, "id", "")) in (
                  "import_module", "__import__")
              and item.args and isinstance(item.args[0], ast.Constant)
              and isinstance(item.args[0].value, str)):
            found.add(item.args[0].value)
    return found


def test_every_source_file_has_a_layer():
    assert {_layer(m) for m in SOURCES} == set(ALLOWED)


@pytest.mark.parametrize("layer", sorted(ALLOWED))
def test_layer_imports_only_what_lies_below_it(layer):
    bad = []
    for module, path in SOURCES.items():
        if _layer(module) != layer:
            continue
        for name in sorted(_imported(path)):
            top = name.split(".")[0]
            if top == "twinfleet":
                target = name if name in SOURCES else name.rsplit(".", 1)[0]
                if target in SOURCES and _layer(target) not in ALLOWED[layer]:
                    bad.append(f"{path.relative_to(ROOT)} imports {name} ({_layer(target)})")
            elif top in BANNED_THIRD_PARTY.get(layer, ()):
                bad.append(f"{path.relative_to(ROOT)} imports {name}")
            elif top in FOLDERS:
                bad.append(f"{path.relative_to(ROOT)} imports {name}: use twinfleet.{name}")
    assert bad == []




def test_no_import_circles():
    graph = {m: {n for n in _imported(p) if n in SOURCES and n != m} for m, p in SOURCES.items()}
    circles = _strongly_connected(graph)
    assert circles == [], "import circles: " + "; ".join(" -> ".join(c) for c in circles)


def _strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's algorithm, iteratively: the components with more than one module."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return found


def test_circle_finder_finds_circles():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": set()}
    assert _strongly_connected(graph) == [["a", "b", "c"]]


def test_import_of_the_checker_and_the_api_loads_no_zenoh():
    code = ("import sys, twinfleet, twinfleet.checker, twinfleet.checker.commands, "
            "twinfleet.nodes.robot; print('zenoh' in sys.modules, 'asyncio' in sys.modules)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=ROOT, timeout=60)
    assert proc.returncode == 0, proc.stderr
    zenoh_loaded, _asyncio_loaded = proc.stdout.split()
    assert zenoh_loaded == "False"


def test_the_scanner_sees_imports_inside_functions(tmp_path):
    sample = tmp_path / "m.py"
    sample.write_text("def f():\n    import zenoh.ext\n    from time import monotonic\n")
    assert _imported(sample) == {"zenoh.ext", "time"}
