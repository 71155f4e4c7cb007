"""A user's project whose own packages are named like layers of twinfleet (`nodes`,
`runtime`, `checker`), for the tests that run it from another directory: checked,
launched, and under each kind of install (tests/integration/test_user_packages.py,
tests/test_wheel.py).

The project holds a pinger and a listener (`nodes.pinger:Pinger`,
`nodes.listener:Listener`) that import helpers of the user's `runtime` and `checker`
packages. At start each node records, in its state and in a log line, the file of
every top-level module in `sys.modules` named like a sub-package of twinfleet
(`modules`), and the top-level modules loaded from the folder that holds the
`twinfleet` package (a checkout, or site-packages) but from outside it, that no other
installed distribution provides (`strays`: a module of ours that is not under
`twinfleet/`). The scenario's properties say that only the user's files are there:

- `user_classes`: the markers only the user's classes and helpers set;
- `user_modules`: `modules` is exactly the user's three packages, and `strays` is empty;
- `started` / `all_heard`: both nodes did record that, and the listener heard 3 pings.

The invariants also accept the values before the start handlers ran ('' and no
modules): the live monitor judges its first view on `initial_state()` itself, the
checker after the `@on_start` handlers, so an invariant that a start handler makes
true holds in `check` and fails in `launch`. `started` then requires the real values.
"""

from __future__ import annotations

import ast
import os
import re
from pathlib import Path

USER_LAYERS = ("checker", "nodes", "runtime")
PINGER_MARK = "user-pinger user-runtime user-checker"
LISTENER_MARK = "user-listener"

FILES = {
    "nodes/__init__.py": '"""The user\'s own `nodes` package (named like a layer of twinfleet)."""\n',
    "runtime/__init__.py": '"""The user\'s own `runtime` package."""\n',
    "checker/__init__.py": '"""The user\'s own `checker` package."""\n',
    "runtime/counting.py": '''\
"""A helper of the user's `runtime` package."""

MARK = "user-runtime"


def next_count(n: int) -> int:
    return n + 1
''',
    "checker/verdict.py": '''\
"""A helper of the user's `checker` package."""

MARK = "user-checker"


def enough(heard: int, wanted: int) -> bool:
    return heard >= wanted
''',
    "nodes/where.py": '''\
"""Which top-level modules named like a layer of twinfleet this process holds."""

import os
import pkgutil
import sys
from importlib.metadata import packages_distributions

import twinfleet

#: twinfleet's sub-package names (runtime, checker, nodes, ...), read once at import.
LAYERS = tuple(sorted(m.name for m in pkgutil.iter_modules(twinfleet.__path__) if m.ispkg))
HOME = os.path.dirname(os.path.abspath(twinfleet.__file__))
#: Top-level names that installed distributions other than twinfleet provide.
OTHERS = {name for name, dists in packages_distributions().items() if "twinfleet" not in dists}


def _file(module):
    path = getattr(module, "__file__", None)
    return os.path.abspath(path) if path else "<no file>"


def layer_modules():
    """(name, file) of each top-level module in sys.modules named like a twinfleet layer."""
    return tuple((name, _file(sys.modules[name])) for name in LAYERS if name in sys.modules)


def twinfleet_strays():
    """Top-level modules loaded from the folder holding twinfleet/ (a checkout, or
    site-packages), from outside twinfleet/, that no other distribution provides."""
    parent, home = os.path.dirname(HOME) + os.sep, HOME + os.sep
    return tuple(sorted(
        name for name, module in list(sys.modules.items())
        if "." not in name and name not in OTHERS
        and _file(module).startswith(parent) and not _file(module).startswith(home)))
''',
    "nodes/pinger.py": '''\
"""The user's pinger: publishes on /ping every 100 ms, three times."""

from dataclasses import dataclass

from checker.verdict import MARK as CHECKER_MARK
from nodes.where import layer_modules, twinfleet_strays
from runtime.counting import MARK as RUNTIME_MARK
from runtime.counting import next_count

from twinfleet import Context, Node, String, every, on_start


@dataclass
class PingerState:
    sent: int = 0
    marker: str = ""
    modules: tuple = ()
    strays: tuple = ()


class Pinger(Node):
    def initial_state(self) -> PingerState:
        return PingerState()

    @on_start
    def start(self, ctx: Context) -> None:
        self.state.marker = f"user-pinger {RUNTIME_MARK} {CHECKER_MARK}"
        self.state.modules = layer_modules()
        self.state.strays = twinfleet_strays()
        ctx.log("USER-PINGER", modules=self.state.modules, strays=self.state.strays)

    @every(100)
    def ping(self, ctx: Context) -> None:
        if self.state.sent < 3:
            self.state.sent = next_count(self.state.sent)
            ctx.publish("/ping", String(f"ping {self.state.sent}"))
''',
    "nodes/listener.py": '''\
"""The user's listener: counts what it hears on /ping."""

from dataclasses import dataclass

from checker.verdict import enough
from nodes.where import layer_modules, twinfleet_strays
from runtime.counting import next_count

from twinfleet import Context, Node, String, on_start, subscribe


@dataclass
class ListenerState:
    heard: int = 0
    done: bool = False
    marker: str = ""
    modules: tuple = ()
    strays: tuple = ()


class Listener(Node):
    def initial_state(self) -> ListenerState:
        return ListenerState()

    @on_start
    def start(self, ctx: Context) -> None:
        self.state.marker = "user-listener"
        self.state.modules = layer_modules()
        self.state.strays = twinfleet_strays()
        ctx.log("USER-LISTENER", modules=self.state.modules, strays=self.state.strays)

    @subscribe("/ping")
    def on_ping(self, ctx: Context, msg: String) -> None:
        self.state.heard = next_count(self.state.heard)
        self.state.done = enough(self.state.heard, 3)
        ctx.log("USER-HEARD", data=msg.data)
''',
}


def expected_modules(project: Path) -> dict[str, str]:
    """What `modules` must be: the user's three packages, from the project folder."""
    return {name: os.path.join(project.resolve(), name, "__init__.py") for name in USER_LAYERS}


def write_project(project: Path) -> Path:
    """Write the project into `project` (created); return the path of its scenario pp.yaml.

    Beside pp.yaml, reveal.yaml runs the same nodes with an invariant that the third
    ping breaks, so that `check` writes a trace holding the states (and paths) it saw.
    """
    for rel, text in FILES.items():
        (project / rel).parent.mkdir(parents=True, exist_ok=True)
        (project / rel).write_text(text)
    want = expected_modules(project)
    marks = f"pinger.marker == {PINGER_MARK!r} and listener.marker == {LISTENER_MARK!r}"
    recorded = f"all(dict(n.modules) == {want!r} for n in nodes.values())"
    nodes = ('  - {name: pinger, class: "nodes.pinger:Pinger"}\n'
             '  - {name: listener, class: "nodes.listener:Listener"}\n')
    properties = (
        f'  - {{name: user_classes, kind: invariant, expr: "pinger.marker in (\'\', {PINGER_MARK!r})'
        f' and listener.marker in (\'\', {LISTENER_MARK!r})"}}\n'
        f'  - {{name: user_modules, kind: invariant, expr: "all(dict(n.modules) in ({{}}, {want!r})'
        ' and len(n.strays) == 0 for n in nodes.values())"}\n'
        f'  - {{name: started, kind: eventually, expr: "{marks} and {recorded}"}}\n')
    (project / "reveal.yaml").write_text(
        f"name: reveal\nnodes:\n{nodes}properties:\n{properties}"
        '  - {name: third_ping, kind: invariant, expr: "not listener.done"}\n')
    scenario = project / "pp.yaml"
    scenario.write_text(f"name: pp\nnodes:\n{nodes}properties:\n{properties}"
                        '  - {name: all_heard, kind: eventually, expr: "listener.done"}\n')
    return scenario


START_LINE = re.compile(r"^\[(pinger|listener)\] t=\d+ USER-(?:PINGER|LISTENER) "
                        r"modules=(\(.*\)) strays=(\(.*\))$", re.M)


def logged_modules(output: str) -> dict[str, tuple[dict[str, str], tuple[str, ...]]]:
    """node → (modules, strays) from the start lines of a `twinfleet launch` output."""
    return {m[1]: (dict(ast.literal_eval(m[2])), ast.literal_eval(m[3]))
            for m in START_LINE.finditer(output)}
