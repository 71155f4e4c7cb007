"""Import layering and import circles, checked on the source with `ast` (docs/design.md §1).

Every source file belongs to one layer, read from its folder under `twinfleet/`:

- `runtime/<wing>/` for each wing of the runtime (`contract`, `scenario`, `core`, `host`,
  `access`, `fleet`, `tools`);
- `checker/`, `sweep/` (many checks over a grid of parameters, on the checker's engines),
  `agreement/`, `nodes/` (the robots and the demo: node code only), `robots/` (the robot
  case study's experiment, on everything below the command line), `ros2/` (the ROS 2 bridge, beside the runtime: it
  speaks rmw_zenoh's protocol through the runtime's tools, and only it imports the ROS
  field's libraries, `ROS_LIBRARIES`, so the default install needs none of them);
- `interfaces/` (ROS 2 message and service types from their definitions, above the
  contract; it may import rosbags, whose parser and Jazzy store hold the definitions);
- `twinfleet/__init__.py` (the node API, which re-exports the contract);
- the command line (`twinfleet/cli/`, `twinfleet/__main__.py`) and the testing API
  (`twinfleet/testing.py`) on top.

An import is seen wherever it is written: `import` statements (inside functions too),
`importlib.import_module("...")` / `__import__("...")`, and any string constant that names a
module of ours (`"twinfleet.nodes.msgs"`, `"twinfleet.nodes.scene:RobotScene"`), which code
resolves at run time; a prefix a name is compared with (`.startswith("twinfleet.runtime")`)
is not an import.

`RULES` names the layers each layer may import, with no exemptions; `PURE` the third-party
modules a layer must not import (checked on the source here, and on what a fresh interpreter
loads in `test_pure_layers_load_no_io`). No two source files import each other, directly or
through others.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

from twinfleet.checker.fairness import cyclic_components

pytestmark = pytest.mark.timeout(60)

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "twinfleet"
WINGS = ("contract", "scenario", "core", "host", "access", "fleet", "tools")
_BELOW_HOST = {"host", "core", "scenario", "contract"}
RULES: dict[str, set[str]] = {
    "api": {"contract"},
    "contract": set(),
    "scenario": {"contract", "rclpy"},
    "core": {"contract"},
    "host": {"core", "scenario", "contract"},
    "access": _BELOW_HOST,
    "fleet": {"access", *_BELOW_HOST},
    "tools": {"fleet", "access", *_BELOW_HOST},
    "checker": {"api", "contract", "scenario"},
    "sweep": {"api", "contract", "scenario", "checker"},
    "nodes": {"api", "contract"},
    "agreement": {"api", "access", "fleet", "tools", *_BELOW_HOST, "checker"},
    # the robot case study's experiment: an application of everything below the command line
    "robots": {"api", "access", "fleet", "tools", *_BELOW_HOST, "checker", "agreement", "nodes",
               "launch"},  # ... and its own example scenarios
    "interfaces": {"contract"},
    "rclpy": {"contract", "interfaces"},
    "ros2": {"api", "access", "fleet", "tools", *_BELOW_HOST, "interfaces"},
    "runtime": set(),  # runtime/__init__.py: names its wings, imports none
    "maps": set(), "launch": set(),  # package data: shipped maps and scenarios
    "top": {"api", "access", "fleet", "tools", *_BELOW_HOST, "checker", "agreement", "nodes", "ros2",
            "sweep", "interfaces", "rclpy", "robots", "top"},
}
#: `tools/` groups four wings of its own (tests/test_sizes.py measures each alone): the
#: monitors and the forms (JSON and Foxglove forms of the fleet's data) lie below the
#: recordings and the viewers, which share what they share through those two and never
#: import each other.
TOOLS_RULES: dict[str, set[str]] = {
    "monitor": set(),
    "forms": set(),
    "record": {"monitor", "forms"},
    "view": {"monitor", "forms"},
}
IO = {"asyncio", "zenoh", "aiohttp", "mcap", "foxglove"}
#: the ROS field's libraries (the `ros2` extra): imported by the `ros2` layer only, and rosbags
#: (the definitions of ROS 2 messages) by the `interfaces` layer too
ROS_LIBRARIES = {"rosbags", "mcap_ros2", "zenoh_ros2_sdk", "rclpy"}
ROS_IMPORTERS = {"ros2": ROS_LIBRARIES, "interfaces": {"rosbags"}}
PURE: dict[str, set[str]] = {
    "contract": IO, "scenario": IO, "core": IO, "checker": IO, "rclpy": IO,
    "sweep": IO | {"ray"},  # Ray only through checker.parallel.engine_for
    "nodes": {"random", "time", "asyncio", "threading", "socket", "zenoh"},
}


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


SOURCES = {_module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def _layer(module: str) -> str:
    parts = module.split(".")[1:]
    if not parts:
        return "api"
    if parts[0] == "runtime":
        if len(parts) == 1:
            return "runtime"
        return parts[1]
    if parts[0] in ("cli", "__main__", "testing"):
        return "top"
    return parts[0]


def _imported(path: Path) -> set[str]:
    """Every module an import in the file names, inside functions too (dotted, absolute).

    `from a import b` names `a.b` when that is a source module, else `a`.
    """
    found: set[str] = set()
    tree = ast.parse(path.read_text(), filename=str(path))
    compared = _prefix_tests(tree)
    for item in ast.walk(tree):
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
        elif isinstance(item, ast.Constant) and isinstance(item.value, str) \
                and id(item) not in compared:
            found.update(_named_modules(item.value))
    return found


def _prefix_tests(tree: ast.AST) -> set[int]:
    """The string constants a name is compared with (``m.__module__.startswith("pkg")``):
    they name a package to tell code apart by, not one to import."""
    return {id(arg) for item in ast.walk(tree) if isinstance(item, ast.Call)
            and isinstance(item.func, ast.Attribute) and item.func.attr == "startswith"
            for arg in item.args}


def _named_modules(text: str) -> set[str]:
    """Modules of ours a string names as code would resolve it ("pkg.mod" or "pkg.mod:Name").

    Only a whole string counts: prose in a docstring that mentions a module is not an import.
    """
    name = text.strip().split(":", 1)[0]
    if not name.startswith("twinfleet.") or not all(p.isidentifier() for p in name.split(".")):
        return set()
    while name and name not in SOURCES:
        name = name.rpartition(".")[0]
    return {name} if name.count(".") else set()


def test_every_source_file_has_a_layer():
    layers = {_layer(m) for m in SOURCES}
    assert layers == set(RULES)


def test_the_runtime_root_holds_only_its_wings():
    root = PACKAGE / "runtime"
    files = {p.name for p in root.iterdir() if p.name != "__pycache__"}
    assert files == {"__init__.py", *WINGS}


def test_wings_and_packages_name_their_public_modules():
    for folder in [PACKAGE / "runtime", *(PACKAGE / "runtime").glob("*/"),
                   *(PACKAGE / "runtime" / "tools").glob("*/")]:
        if folder.name == "__pycache__" or not folder.is_dir() or folder.name == "static":
            continue
        tree = ast.parse((folder / "__init__.py").read_text())
        names = [n for n in tree.body if isinstance(n, ast.Assign)
                 and any(getattr(t, "id", "") == "__all__" for t in n.targets)]
        assert names, f"{folder} has no __all__"


@pytest.mark.parametrize("layer", sorted(RULES))
def test_layer_imports_only_what_lies_below_it(layer):
    bad = []
    for module, path in SOURCES.items():
        if _layer(module) != layer:
            continue
        for name in sorted(_imported(path)):
            top = name.split(".")[0]
            if top == "twinfleet":
                target = name if name in SOURCES else name.rsplit(".", 1)[0]
                other = _layer(target) if target in SOURCES else None
                if other is not None and other != layer and other not in RULES[layer]:
                    bad.append(f"{path.relative_to(ROOT)} imports {name} ({other})")
            elif top in ROS_LIBRARIES and top not in ROS_IMPORTERS.get(layer, ()):
                bad.append(f"{path.relative_to(ROOT)} imports {name}: only twinfleet.ros2 may")
            elif top in PURE.get(layer, ()):
                bad.append(f"{path.relative_to(ROOT)} imports {name}")
            elif top in ("runtime", "checker", "nodes", "agreement"):
                bad.append(f"{path.relative_to(ROOT)} imports {name}: use twinfleet.{name}")
    assert bad == []


def _tools_wing(module: str) -> str | None:
    parts = module.split(".")
    return parts[3] if parts[1:3] == ["runtime", "tools"] and len(parts) > 3 else None


def test_tools_wings_import_only_what_their_rule_allows():
    folders = {p.name for p in (PACKAGE / "runtime" / "tools").iterdir()
               if (p / "__init__.py").exists()}
    assert folders == set(TOOLS_RULES)
    bad = []
    for module, path in SOURCES.items():
        wing = _tools_wing(module)
        if wing is None:
            continue
        for name in sorted(_imported(path)):
            other = _tools_wing(name)
            if other is not None and other != wing and other not in TOOLS_RULES[wing]:
                bad.append(f"{path.relative_to(ROOT)} imports {name} ({other})")
    assert bad == []


def test_pure_layers_load_no_io():
    """Importing every module of the contract, scenario, core and checker loads no I/O library."""
    pure = sorted(m for m in SOURCES if _layer(m) in ("contract", "scenario", "core", "checker")
                  and not m.endswith("__main__") and m != RAY_MODULE)
    code = ("import importlib, sys\n"
            f"for m in {pure!r}: importlib.import_module(m)\n"
            f"print(sorted(b for b in {sorted(IO)!r} if b in sys.modules))")
    proc = subprocess.run([sys.executable, "-P", "-c", code], capture_output=True, text=True,
                          cwd=ROOT.parent, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "[]", proc.stdout


def test_the_layer_test_catches_a_wrong_import(tmp_path):
    sample = tmp_path / "m.py"
    sample.write_text("from twinfleet.runtime.host.clock import FleetClock\n")
    assert "twinfleet.runtime.host.clock" in _imported(sample)
    assert _layer("twinfleet.runtime.host.clock") not in RULES["core"]


def test_no_import_circles():
    graph = {m: {n for n in _imported(p) if n in SOURCES and n != m} for m, p in SOURCES.items()}
    circles = _strongly_connected(graph)
    assert circles == [], "import circles: " + "; ".join(" -> ".join(c) for c in circles)


def _strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """The import circles: components of more than one module (no module imports itself)."""
    return [sorted(c) for c in cyclic_components(sorted(graph), lambda m: sorted(graph[m]))]


def test_circle_finder_finds_circles():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": set()}
    assert _strongly_connected(graph) == [["a", "b", "c"]]


def test_help_loads_neither_zenoh_nor_the_checker():
    """`twinfleet --help` loads the checker's argument parser, not its search."""
    code = ("import sys, contextlib, io\n"
            "from twinfleet.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
            "    main(['--help'])\n"
            "parsers = {'twinfleet.checker.commands', 'twinfleet.checker.options'}\n"
            "print('zenoh' in sys.modules,\n"
            "      any(m.startswith('twinfleet.checker.') and m not in parsers for m in sys.modules))")
    proc = subprocess.run([sys.executable, "-P", "-c", code], capture_output=True, text=True,
                          cwd=ROOT.parent, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["False", "False"]


def test_the_scanner_sees_modules_named_in_strings(tmp_path):
    sample = tmp_path / "m.py"
    sample.write_text('SCENE = "twinfleet.nodes.scene:RobotScene"\n'
                      'MSGS = "twinfleet.nodes.msgs"\n'
                      'PROSE = "see twinfleet.nodes.msgs for the types"\n'
                      'OURS = type(1).__module__.startswith("twinfleet.runtime")\n')
    assert _imported(sample) == {"twinfleet.nodes.scene", "twinfleet.nodes.msgs"}
    assert "nodes" not in RULES["host"]


def test_the_scanner_sees_imports_inside_functions(tmp_path):
    sample = tmp_path / "m.py"
    sample.write_text("def f():\n    import zenoh.ext\n    from time import monotonic\n")
    assert _imported(sample) == {"zenoh.ext", "time"}


#: the one module of the checker that may import Ray (the distributed search's engine)
RAY_MODULE = "twinfleet.checker.cluster.engine"


def test_only_the_cluster_engine_imports_ray():
    bad = [f"{path.relative_to(ROOT)} imports {name}"
           for module, path in SOURCES.items() if module != RAY_MODULE
           for name in sorted(_imported(path)) if name.split(".")[0] == "ray"]
    assert bad == []
    assert "ray" in {n.split(".")[0] for n in _imported(SOURCES[RAY_MODULE])}
