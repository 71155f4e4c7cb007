"""Load-time warnings about a scenario's node code: sources of nondeterminism, and names
that nothing answers; and about deprecated keys in its file (`lint_settings`).

Two lints of the code, both read the source (`ast`), run nothing, and give warnings, not
errors (the checker's contract checks, `checker.diagnosis`, are what decide):

- **Imports.** A node module that imports `random`, `time`, `datetime`,
  `threading`, `secrets`, `uuid`, `asyncio`, `socket`, `multiprocessing`, or
  uses `os.urandom` or `numpy.random`, or a node method with a `global` statement, is named with file
  and line: a handler that uses them breaks the node contract (docs/design.md §7, contract breach).
- **Topics and services.** Topics a node publishes (literal names of
  ``ctx.publish``; an f-string is a pattern, ``f"/{robot}/scan"`` matches
  ``/r1/scan``; any other expression could be anything) that no node of the
  scenario subscribes to, topics subscribed that no node publishes, and
  services called that no node serves: ``/entr`` typed for ``/enter`` makes an
  invariant hold by accident. A close name is suggested. Topics published for
  tools outside the fleet (viewers, recorders, ``twinfleet topic echo``) are
  declared on the node class as ``tool_topics = ("status", ...)``, topics fed
  from outside the fleet (a ROS 2 tool through the bridge) as ``external_topics``,
  and fleet-internal topics (``/twinfleet/...``, ``/violations``, ``/_...``) are
  never warned about.
"""

from __future__ import annotations

import ast
import difflib
import fnmatch
import functools
import inspect
import sys
import textwrap
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, final

import yaml

from twinfleet.runtime.contract.names import InvalidName, resolve
from twinfleet.runtime.contract.node import Node, NodeSpec
from twinfleet.runtime.scenario.spec import Scenario, parse_yaml

#: Modules whose import in a node module is worth a warning, with what they offer.
RISKY_MODULES = {
    "random": "randomness (use ctx.choose)", "time": "clocks and sleeping (use ctx.now, "
    "ctx.after)", "datetime": "clocks (use ctx.now)", "threading": "threads",
    "secrets": "randomness (use ctx.choose)", "uuid": "random identifiers",
    "asyncio": "an event loop (handlers are synchronous)", "socket": "I/O",
    "multiprocessing": "processes",
}
_RISKY_ATTRIBUTES = {("os", "urandom"): "os.urandom", ("np", "random"): "numpy.random",
                     ("numpy", "random"): "numpy.random"}
_RISKY_NAMES = frozenset(_RISKY_ATTRIBUTES.values())
_FLEET_TOPICS = ("/twinfleet/*", "/violations", "/_*")


@final
@dataclass(frozen=True, slots=True)
class LintWarning:
    """One warning: where (file:line, or the node) and what."""

    where: str
    message: str

    def __str__(self) -> str:
        return f"warning: {self.where}: {self.message}"


def lint_nodes(classes: Sequence[type[Node]]) -> list[LintWarning]:
    """Import and `global` warnings for the modules defining `classes` (each module once)."""
    seen: set[str] = set()
    out: list[LintWarning] = []
    for cls in classes:
        module = sys.modules.get(cls.__module__)
        path = getattr(module, "__file__", None)
        if path is None or path in seen or not path.endswith(".py"):
            continue
        seen.add(path)
        out += _module_lint(path)
    return out


@functools.cache
def _module_lint(path: str) -> list[LintWarning]:
    """The import and `global` warnings of one source file (read once per process)."""
    tree = _parsed(path)
    return [] if tree is None else list(_module_warnings(tree, path))


@functools.cache
def _parsed(path: str) -> ast.Module | None:
    """One source file's syntax tree (parsed once per process: both lints read it), or None
    if it cannot be read."""
    try:
        return ast.parse(Path(path).read_text(), filename=path)
    except (OSError, SyntaxError, UnicodeDecodeError, SystemError, RecursionError):
        return None


def syntax_nodes(tree: ast.AST) -> list[ast.AST]:
    """Every node of `tree` in `ast.walk`'s order (breadth first, fields in order), as a
    list grown while it is read: `ast.walk`'s generators were a third of the lint."""
    out = [tree]
    for node in out:
        for name in node._fields:
            value = getattr(node, name, None)
            if isinstance(value, list):
                out += [v for v in value if isinstance(v, ast.AST)]
            elif isinstance(value, ast.AST):
                out.append(value)
    return out


def _module_warnings(tree: ast.Module, path: str) -> Iterator[LintWarning]:
    for item in syntax_nodes(tree):
        names: list[str] = []
        if isinstance(item, ast.Import):
            names = [alias.name for alias in item.names]
        elif isinstance(item, ast.ImportFrom) and item.module and item.level == 0:
            names = [item.module] + [f"{item.module}.{a.name}" for a in item.names]
        elif isinstance(item, ast.Attribute) and isinstance(item.value, ast.Name) and \
                (item.value.id, item.attr) in _RISKY_ATTRIBUTES:
            names = [_RISKY_ATTRIBUTES[item.value.id, item.attr]]
        elif isinstance(item, ast.Global):
            yield LintWarning(f"{path}:{item.lineno}", f"`global {', '.join(item.names)}`: "
                              "a node that keeps state in module variables breaks the node "
                              "contract (keep it in self.state)")
        for name in names:
            top = name.split(".")[0]
            if name in _RISKY_NAMES or (top in RISKY_MODULES and name == top):
                assert isinstance(item, ast.stmt | ast.expr)  # an import or an attribute
                what = RISKY_MODULES.get(top, "randomness (use ctx.choose)")
                yield LintWarning(f"{path}:{item.lineno}",
                                  f"imports {name}: {what}; a handler that uses it breaks the "
                                  "node contract")
                break


# ------------------------------------------------------------------ topics


def lint_topics(nodes: Sequence[tuple[str, str, type[Node]]]) -> list[LintWarning]:
    """Topic and service warnings for nodes given as (name, namespace, class)."""
    subscribed: dict[str, str] = {}
    served: set[str] = set()
    published: list[tuple[str, str, str]] = []  # (pattern, node, where)
    called: list[tuple[str, str, str]] = []
    for name, namespace, cls in nodes:
        spec = NodeSpec.of(cls)
        for h in spec.handlers:
            full = _resolved(h.name, namespace, name) if h.kind in ("subscribe", "service") \
                else None
            if full and h.kind == "subscribe":
                subscribed.setdefault(full, name)
            elif full:
                served.add(full)
        for topic in [*spec.publications, *getattr(cls, "tool_topics", ())]:
            published.append((_resolved(topic, namespace, name) or topic, name, "declared"))
        # A class is hashable: mypy reads Node.__hash__ (an instance method) as the class's.
        for kind, pattern, where in _uses(cls):
            full = pattern if "*" in pattern else _resolved(pattern, namespace, name)
            target = published if kind == "publish" else called
            target.append((full or pattern, name, where))
    tools = {_resolved(t, ns, n) for n, ns, cls in nodes for t in getattr(cls, "tool_topics", ())}
    out = _once_per_line([w for topic, node, where in published
                          if where != "declared" and topic not in tools
                          for w in _unheard(topic, node, where, subscribed)])
    external = {_resolved(t, ns, n) for n, ns, cls in nodes
                for t in getattr(cls, "external_topics", ())}  # fed from outside the fleet
    for topic, node in subscribed.items():
        if not any(fnmatch.fnmatchcase(topic, p) for p, _, _ in published) and \
                not _fleet_topic(topic) and topic not in external:
            out.append(LintWarning(f"node {node}", f"subscribes to {topic} but no node "
                                   f"publishes on it{_close(topic, [p for p, _, _ in published])}"))
    for service, node, where in called:
        if "*" not in service and service not in served:
            out.append(LintWarning(where, f"node {node} calls service {service} but no node "
                                   f"serves it{_close(service, served)}"))
    return out


def _once_per_line(warnings: list[LintWarning]) -> list[LintWarning]:
    """One warning per source line (five robots of one class: one warning, "and 4 more")."""
    by_line: dict[str, list[LintWarning]] = {}
    for w in warnings:
        by_line.setdefault(w.where, []).append(w)
    return [ws[0] if len(ws) == 1 else
            LintWarning(ws[0].where, f"{ws[0].message} (and {len(ws) - 1} more nodes alike)")
            for ws in by_line.values()]


def _unheard(topic: str, node: str, where: str, subscribed: dict[str, str]
             ) -> Iterator[LintWarning]:
    if _fleet_topic(topic) or any(fnmatch.fnmatchcase(s, topic) for s in subscribed):
        return
    if "*" in topic:
        return  # a pattern that matches nothing known may still match at run time
    yield LintWarning(where, f"node {node} publishes on {topic} but no node subscribes to "
                      f"it{_close(topic, subscribed)} (a topic for tools only: list it in "
                      "the class's tool_topics)")


def _fleet_topic(topic: str) -> bool:
    return any(fnmatch.fnmatchcase(topic, p) for p in _FLEET_TOPICS)


def _close(name: str, known: Iterable[str]) -> str:
    match = difflib.get_close_matches(name, [k for k in known if "*" not in k], n=1, cutoff=0.8)
    return f" (did you mean {match[0]}?)" if match else ""


def _resolved(name: str | None, namespace: str, node: str) -> str | None:
    if not name:
        return None
    try:
        return resolve(name, namespace, node)
    except InvalidName:
        return None


@functools.cache
def _calls(cls: type[Node]) -> list[tuple[ast.Call, str]]:
    """Each ``x.publish/call/after(...)`` call with arguments in the methods `cls` has (its
    own or inherited, overridden ones left out), with its file:line."""
    found: list[tuple[ast.Call, str]] = []
    for _, fn in inspect.getmembers(cls, inspect.isfunction):
        if fn.__module__.startswith("twinfleet.runtime"):
            continue
        located = _function_tree(fn)
        if located is None:
            continue
        tree, file, offset = located
        for item in syntax_nodes(tree):
            if isinstance(item, ast.Call) and isinstance(item.func, ast.Attribute) and \
                    item.func.attr in ("publish", "call", "after") and item.args:
                found.append((item, f"{file}:{offset + item.lineno}"))
    return found


def _function_tree(fn: Any) -> tuple[ast.AST, str, int] | None:
    """The syntax tree of function `fn`, its file, and what turns the tree's line numbers
    into the file's; None if its source cannot be read. Found in its module's tree (parsed
    once per file) by the line its code starts at: reading each method's own lines
    tokenised them in Python, most of what the lint of a node class cost."""
    try:
        file = inspect.getsourcefile(fn) or "?"
        code = fn.__code__
        found = _functions(file).get((code.co_firstlineno, code.co_name))
        if found is not None:
            return found, file, 0
        lines, first = inspect.getsourcelines(fn)
        return ast.parse(textwrap.dedent("".join(lines))), file, first - 1
    except (OSError, TypeError, SyntaxError, SystemError, RecursionError):
        return None  # SystemError: CPython 3.11's parser, called deep in a stack (a lint
        # that cannot read a method says nothing about it)


@functools.cache
def _functions(file: str) -> dict[tuple[int, str], ast.FunctionDef | ast.AsyncFunctionDef]:
    """The functions of one source file's module and class bodies by (the line their code
    starts at: the first decorator's, as `co_firstlineno` counts it; their name)."""
    tree = _parsed(file)
    out: dict[tuple[int, str], ast.FunctionDef | ast.AsyncFunctionDef] = {}
    bodies = [] if tree is None else [tree.body]
    while bodies:
        for item in bodies.pop():
            if isinstance(item, ast.FunctionDef | ast.AsyncFunctionDef):
                first = min([item.lineno, *(d.lineno for d in item.decorator_list)])
                out.setdefault((first, item.name), item)
            elif isinstance(item, ast.ClassDef):
                bodies.append(item.body)
    return out


def _uses(cls: type[Node]) -> list[tuple[str, str, str]]:
    """(kind, name, file:line) of each `ctx.publish`/`ctx.call` of `cls` (`_calls`), with
    literal or f-string names."""
    # A class is hashable: mypy reads Node.__hash__ (an instance method) as the class's.
    return [(call.func.attr, _pattern(call.args[0]), where)  # type: ignore[attr-defined]
            for call, where in _calls(cls)  # type: ignore[arg-type]
            if call.func.attr != "after"]  # type: ignore[attr-defined]


def code_uses(cls: type[Node]) -> tuple[list[str], list[str]]:
    """What a class's code names plainly, for `twinfleet node info`: the services it calls
    (a literal name, or ``params.NAME`` for ``ctx.call(self.params.NAME, ...)``) and the
    handlers it schedules (``ctx.after(delay, self.handler)``), each sorted."""
    handlers = {h.method for h in NodeSpec.of(cls).handlers}
    clients: set[str] = set()
    after: set[str] = set()
    for call, _ in _calls(cls):  # type: ignore[arg-type]
        kind = call.func.attr  # type: ignore[attr-defined]
        if kind == "call":
            name = _pattern(call.args[0])
            param = _self_attribute(call.args[0], "params")
            clients.add(f"params.{param}" if name == "*" and param else name)
        elif kind == "after" and len(call.args) > 1:
            target = _self_attribute(call.args[1])
            if target in handlers:
                after.add(target)
    clients.discard("*")
    return sorted(clients), sorted(after)


def _self_attribute(arg: ast.expr, through: str | None = None) -> str | None:
    """X of ``self.X`` (or of ``self.<through>.X``), else None."""
    base = arg.value if isinstance(arg, ast.Attribute) else None
    if through is not None:
        if not (isinstance(base, ast.Attribute) and base.attr == through):
            return None
        base = base.value
    if isinstance(base, ast.Name) and base.id == "self" and isinstance(arg, ast.Attribute):
        return arg.attr
    return None


def _pattern(arg: ast.expr) -> str:
    """A name as written: a literal, an f-string as a glob (`*` per field), else `*`."""
    if isinstance(arg, ast.Constant) and isinstance(arg.value, str):
        return arg.value
    if isinstance(arg, ast.JoinedStr):
        return "".join(v.value if isinstance(v, ast.Constant) and isinstance(v.value, str) else "*"
                       for v in arg.values)
    return "*"


def lint_scenario(scenario: Scenario) -> list[LintWarning]:
    """Every load-time warning for a scenario: its nodes, and old keys in its file."""
    nodes = [(cfg.name, cfg.namespace, cfg.cls) for cfg in scenario.nodes]
    classes = list(dict.fromkeys(cls for _, _, cls in nodes))
    return lint_settings(scenario.path) + lint_nodes(classes) + lint_topics(nodes)


def lint_settings(path: Path | None) -> list[LintWarning]:
    """A scenario file's deprecated keys, each with what it was taken as (the loader has
    already moved it: `LiveConfig`)."""
    if path is None or path.suffix not in (".yaml", ".yml"):
        return []
    try:
        doc = parse_yaml(path.read_text())
    except (OSError, yaml.YAMLError, RecursionError):
        return []
    live = doc.get("live") if isinstance(doc, dict) else None
    if not isinstance(live, dict) or "timeout_s" not in live:
        return []
    return [LintWarning(str(path), "live.timeout_s is deprecated: taken as "
                        "live.wall_timeout_s (wall seconds a launch runs once its fleet is "
                        "up); for fleet seconds (at any time scale; the statistical "
                        "checker's horizon) write live.horizon_s")]
