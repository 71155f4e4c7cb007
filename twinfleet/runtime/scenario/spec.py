"""Scenarios: one description of a fleet for both `launch` and `check`, from YAML or Python.

YAML layout (every key but `nodes` optional)::

    name: c1a                      # also the Zenoh fleet name unless `fleet:` is given
    description: free text
    semantics: ros                 # checker message rules: ros | rebeca
    seed: 1                        # live randomness (ctx.choose)
    scene: mypkg.drawing:MyScene   # how viewers draw the fleet (runtime.contract.scene)
    params:                        # merged into every node whose Params has the field
      period_ms: 100
      layout: ../data/layout.yaml  # a file parameter (file_param): relative to this file
    nodes:
      - name: w1
        class: mypkg.worker:Worker # module:Class, a subclass of twinfleet.Node
        namespace: /w1             # default: root
        priority: 3                # node-instance priority (checker, rebeca semantics)
        respawn: false             # live: restart the process if it dies
        params: {start: [5, 5], goal: [45, 45]}
    properties:                    # see twinfleet/checker/properties.py for the kinds
      - {name: bounded, kind: invariant, expr: "w1.done <= 3"}
    check:                         # checker settings, all optional (twinfleet/checker/faults.py has details)
      max_states: 100000           # also max_depth, max_time_s, search: bfs|dfs|random
      latency: [0, 0]              # delivery delay branches, or {default: [a, b], /topic: [a, b]}
      global_priority: false       # rebeca: node priority of the head message (RMC @globalPriority)
      deadline_ms: 50              # or {default: 100, /topic: 50}: a later delivery is a violation
      queue_bound: 8               # or {default: 8, node: 20}: more pending events = queue overflow
      faults:                      # off unless given
        drop: [/topic_or_service]  # each delivery: delivered | lost
        duplicate: [/topic]        # each delivery: delivered | delivered twice
        crash: {nodes: [r1], max: 1, durable: []}   # crash-and-restart branches
      fairness: none               # weak: a lasso must handle every message it drops (docs/finite-state.md)
    live: {horizon_s: 120, wall_timeout_s: 600, stop_on_error: false, time_scale: 1.0,
           report: "twinfleet.nodes.report:report_for"}  # factory(scenario) -> report, see launcher
    ros2: {domain: 0, router: tcp/127.0.0.1:7447,       # launch runs the ROS 2 bridge too
           inbound: {/goal_pose: /r1/goal}}            # ROS 2 topic -> fleet topic (docs/ros2.md)

`scene:` names a `runtime.contract.scene.Scene` by import name, checked as
node classes are (`runtime.scenario.scenes.load_scene`); a fleet without one
is shown by the viewers as its topics only.

`check:`, `live:` and `ros2:` become `runtime.scenario.config.CheckConfig` /
`LiveConfig` / `Ros2Config`.
`load_scenario` accepts a path or the name of a shipped example
(`resolve_scenario`: ``c1a`` is ``launch/c1a.yaml`` of the installed package).

The same scenario from Python, with class objects, `NodeEntry` values and
config objects (mappings in the YAML shapes work too)::

    Scenario.build("pingpong", [NodeEntry("ping", Ping, {"rounds": 3}), NodeEntry("pong", Pong)],
                   properties=[PropertyConfig("bounded", "invariant", "ping.sent <= 3")],
                   check=CheckConfig(max_states=1000))

Both ways run the same checks: every error names the file (or ``<scenario
NAME>`` for one built in Python), the key and what was expected, and is
raised before anything starts.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import math
import os
import re
import sys
import typing
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, final

import yaml

from twinfleet.runtime.contract.names import InvalidName, normalise_namespace, validate_token
from twinfleet.runtime.contract.node import Node
from twinfleet.runtime.scenario.config import (
    CheckConfig,
    ConfigError,
    LiveConfig,
    Ros2Config,
    check_config,
    live_config,
    ros2_config,
)
from twinfleet.runtime.scenario.examples import shipped_scenarios
from twinfleet.runtime.scenario.params import build_params
from twinfleet.runtime.scenario.property_eval import ExpressionError, parse_expression
from twinfleet.runtime.scenario.scenes import SceneError, load_scene
from twinfleet.runtime.scenario.suggest import did_you_mean

SEMANTICS = ("ros", "rebeca")
PROPERTY_KINDS = ("invariant", "no_failure", "deadlock", "quiescence", "eventually", "within")
MAX_NODES = 100  # default of live.max_nodes: each node is one OS process live
_TOP_KEYS = {"name", "fleet", "description", "semantics", "seed", "params", "nodes",
             "properties", "check", "live", "scene", "ros2"}
_NODE_KEYS = {"name", "class", "namespace", "priority", "respawn", "params"}
_PROPERTY_KEYS = {"name", "kind", "expr", "within_ms"}


class ScenarioError(ValueError):
    """A scenario is invalid; the message names the file, the key and the rule."""


@final
@dataclass(frozen=True)
class NodeEntry:
    """One node of a scenario as written: what `Scenario.build` takes (YAML: a `nodes:` entry).

    Args:
        name: the node's name, unique in the scenario.
        cls: a `Node` subclass, or its ``"module:Class"`` path.
        params: a mapping merged over the scenario's `params` (as YAML does), or an
            instance of ``cls.Params`` used as it is.
        namespace, priority, respawn: as in YAML.
    """

    name: str
    cls: type[Node] | str
    params: Any = None
    namespace: str = ""
    priority: int = 0
    respawn: bool = False

    def as_mapping(self) -> dict[str, Any]:
        """The YAML shape of this entry."""
        entry: dict[str, Any] = {"name": self.name, "class": self.cls,
                                 "namespace": self.namespace, "priority": self.priority,
                                 "respawn": self.respawn}
        if self.params is not None:
            entry["params"] = dict(self.params) if isinstance(self.params, Mapping) else self.params
        return entry


@final
@dataclass(frozen=True)
class NodeConfig:
    """One node of a scenario, with its parameters already built and checked."""

    name: str
    cls: type[Node]
    class_path: str
    namespace: str
    priority: int
    respawn: bool
    params: Any
    raw_params: Mapping[str, Any]

    def instantiate(self) -> Node:
        """A fresh node object for this entry."""
        return self.cls(self.name, self.params, namespace=self.namespace)


@final
@dataclass(frozen=True)
class PropertyConfig:
    """A property named in the scenario."""

    name: str
    kind: str
    expr: str | None = None
    within_ms: int | None = None


@final
@dataclass(frozen=True)
class Scenario:
    """A parsed, validated scenario; `path` is None for one built in Python (`build`)."""

    path: Path | None
    name: str
    fleet: str
    description: str
    semantics: str
    seed: int
    nodes: tuple[NodeConfig, ...]
    properties: tuple[PropertyConfig, ...]
    check: CheckConfig = field(default_factory=CheckConfig)
    live: LiveConfig = field(default_factory=LiveConfig)
    scene: str | None = None  # import name of the fleet's `Scene`, for viewers
    ros2: Ros2Config | None = None  # the ROS 2 bridge `launch` runs beside the fleet

    @property
    def source(self) -> str:
        """Where the scenario came from, as error messages name it."""
        return str(self.path) if self.path is not None else python_source(self.name)

    def node(self, name: str) -> NodeConfig:
        """The node entry called `name`."""
        for cfg in self.nodes:
            if cfg.name == name:
                return cfg
        raise KeyError(name)

    @classmethod
    def build(cls, name: str, nodes: Sequence[NodeEntry | Mapping[str, Any]], *,
              properties: Sequence[PropertyConfig | Mapping[str, Any]] = (),
              check: CheckConfig | Mapping[str, Any] | None = None,
              live: LiveConfig | Mapping[str, Any] | None = None,
              semantics: str = SEMANTICS[0], seed: int = 0,
              params: Mapping[str, Any] | None = None, fleet: str | None = None,
              description: str = "", scene: str | None = None) -> Scenario:
        """A scenario from Python values, checked as a file is (file parameters relative to
        the working directory); the keywords are the YAML keys."""
        doc: dict[str, Any] = {"name": name, "nodes": list(nodes), "properties": list(properties),
                               "semantics": semantics, "seed": seed,
                               "description": description, "check": check, "live": live,
                               "params": dict(params or {})}
        if fleet is not None:
            doc["fleet"] = fleet
        if scene is not None:
            doc["scene"] = scene
        return parse_scenario(doc, None)


def python_source(name: str) -> str:
    """How errors name a scenario built in Python."""
    return f"<scenario {name}>"


def resolve_scenario(spec: str | Path) -> Path:
    """The scenario file `spec` names: an existing file, else a shipped example of that name
    (``c1a`` or ``c1a.yaml``); anything else is a `ScenarioError` listing the shipped names."""
    path = Path(spec)
    if path.exists():
        return path
    shipped = shipped_scenarios()
    name = path.name.removesuffix(".yaml")
    if path.name == str(spec) and name in shipped:
        return shipped[name]
    if not shipped:  # a library caller: only the command line and the testing API add them
        raise ScenarioError(f"{spec}: cannot read scenario file: no such file, and no example "
                            "package is registered to find it by name: pass the file's path, "
                            "or register one first (twinfleet.runtime.scenario.examples."
                            "add_examples; the command line and twinfleet.testing register "
                            "the shipped examples)")
    raise ScenarioError(f"{spec}: cannot read scenario file: no such file, and no shipped "
                        f"example is called {name!r} (shipped: {', '.join(shipped)}; "
                        "`twinfleet examples` describes them)")


def load_scenario(path: str | Path, overrides: Mapping[str, Any] | None = None) -> Scenario:
    """Read and validate a scenario file (or shipped example, `resolve_scenario`);
    `overrides` replace top-level keys (e.g. semantics)."""
    path = resolve_scenario(path)
    try:
        doc = parse_yaml(path.read_text())
    except OSError as exc:
        raise ScenarioError(f"{path}: cannot read scenario file: {exc.strerror}") from None
    except UnicodeDecodeError as exc:
        raise ScenarioError(f"{path}: not a text file ({exc.reason} at byte {exc.start})") from None
    except yaml.YAMLError as exc:
        raise ScenarioError(f"{path}: not valid YAML: {_yaml_problem(exc)}") from None
    except RecursionError:
        raise ScenarioError(f"{path}: YAML nested too deeply to read (a scenario needs a few "
                            "levels)") from None
    if not isinstance(doc, dict):
        raise ScenarioError(f"{path}: expected a mapping at the top level")
    doc = {**doc, **(overrides or {})}
    user_import_path(path.parent)
    return parse_scenario(doc, path)


_C_LOADER_DEPTH = 1_000  # nesting the C parser is given (it crashes at ~30,000)
_BRACKETS = re.compile(r"[][{}]")
_INDENT = re.compile(r"^[ \t]*", re.M)


def parse_yaml(text: str) -> Any:
    """`yaml.safe_load`, with libyaml's parser where PyYAML has it: five times faster on a
    large scenario (10,001 nodes: 3 s against 15 s, before the node cap can refuse it).
    libyaml recurses in C on nesting and crashes the process on deep input, so text nested
    deeper than `_C_LOADER_DEPTH` (brackets or indentation, counted generously) goes to the
    pure-Python parser, whose RecursionError the caller reports."""
    loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
    if loader is not yaml.SafeLoader and _nesting(text) > _C_LOADER_DEPTH:
        loader = yaml.SafeLoader
    return yaml.load(text, Loader=loader)  # both loaders are the safe (plain-data) ones


def _nesting(text: str) -> int:
    """An upper bound of the nesting depth of `text`: open brackets (quotes ignored) or
    the deepest indentation."""
    depth = deepest = 0
    for match in _BRACKETS.finditer(text):
        depth += 1 if match.group() in "[{" else -1
        deepest = max(deepest, depth)
    return max(deepest, max((len(m.group()) for m in _INDENT.finditer(text)), default=0))


def _yaml_problem(exc: yaml.YAMLError) -> str:
    """A YAML error in one line: what and where (PyYAML's own text spans several lines)."""
    mark = getattr(exc, "problem_mark", None)
    where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
    what = getattr(exc, "problem", None) or " ".join(str(exc).split())
    context = getattr(exc, "context", None)
    return f"{what}{where}" + (f" ({context})" if context else "")


def user_import_path(scenario_dir: Path) -> None:
    """Let "module:Class" names find a user's own modules beside the scenario file and in
    the working directory (a console script has neither on `sys.path`). They go last, so
    they never shadow the standard library or installed packages (our nodes are
    `twinfleet.nodes`, so a user package called `nodes` is simply the user's)."""
    for folder in (str(scenario_dir.resolve()), os.getcwd()):
        if folder not in sys.path:
            sys.path.append(folder)


def parse_scenario(doc: Mapping[str, Any], path: Path | None) -> Scenario:
    """Validate a scenario mapping read from `path` (None: built in Python, `Scenario.build`)."""
    err = _Errors(str(path) if path is not None else python_source(doc.get("name", "?")))
    for key in doc:  # a word close to a key is a typo; another, a node parameter put at the
        # top (as old files did)
        if key not in _TOP_KEYS and not did_you_mean(str(key), _TOP_KEYS):
            err.fail(key, f"unknown key; expected one of {', '.join(sorted(_TOP_KEYS))} (a "
                          f"parameter of the nodes goes under params:, as params: {{{key}: ...}})")
    err.unknown_keys(doc, _TOP_KEYS, "")
    name = _get(doc, "name", str, err, default=path.stem if path is not None else ...)
    fleet = _get(doc, "fleet", str, err, default=name.replace("-", "_"))
    try:
        validate_token(fleet, "fleet")
    except InvalidName as exc:
        err.fail("fleet" if "fleet" in doc else "name", str(exc))
    semantics = _choice(doc, "semantics", SEMANTICS, err)
    common = _get(doc, "params", dict, err, default={})
    raw_nodes = doc.get("nodes")
    if not isinstance(raw_nodes, list) or not raw_nodes:
        err.fail("nodes", "expected a non-empty list of nodes")
    _check_node_count(len(raw_nodes), doc.get("live"), err)
    base = path.parent if path is not None else Path()
    nodes = tuple(_node(i, n, common, base, err) for i, n in enumerate(raw_nodes))
    _check_common_params(common, nodes, err)
    names = [n.name for n in nodes]
    for dup in sorted({n for n in names if names.count(n) > 1}):
        err.fail("nodes", f"node name {dup!r} is used twice")
    for i, cfg in enumerate(nodes):
        _finite(cfg.raw_params, f"nodes[{i}] ({cfg.name}).params", err)
        _try_instantiate(i, cfg, err)
    raw_props = doc.get("properties") or []
    if not isinstance(raw_props, list):
        err.fail("properties", f"expected a list of properties, got {raw_props!r:.60}")
    props = tuple(_property(i, p, names, err) for i, p in enumerate(raw_props))
    check = _checked(check_config, err, doc.get("check"))
    _check_node_names(check, names, err)
    live = _checked(live_config, err, doc.get("live"))
    if live.report is not None:
        factory = _import_attr(live.report, err, "live.report", "report factory")
        if not (inspect.isfunction(factory) or inspect.isclass(factory)):
            err.fail("live.report", f"{live.report} is a {type(factory).__name__}, not a "
                                    "report factory (a Python function or class taking the "
                                    "scenario)")
    return Scenario(path=path, name=name, fleet=fleet,
                    description=_get(doc, "description", str, err, default=""),
                    semantics=semantics,
                    seed=_get(doc, "seed", int, err, default=0), nodes=nodes,
                    properties=props, check=check, live=live, scene=_scene(doc, err),
                    ros2=_checked(ros2_config, err, doc["ros2"]) if "ros2" in doc else None)


def _check_common_params(common: Mapping[str, Any], nodes: Sequence[NodeConfig],
                         err: _Errors) -> None:
    """Every key of the common `params:` is a parameter of some node: each node takes only
    the keys its Params declares, so a misspelt one would otherwise reach no node and the
    verdict would silently be that of the default value."""
    declared = {f.name for cfg in nodes for f in dataclasses.fields(cfg.cls.Params)}
    for key in common:
        if key not in declared:
            err.fail(f"params.{key}", "no node of the scenario declares this parameter; "
                     f"expected one of {', '.join(sorted(declared)) or 'none'}"
                     f"{did_you_mean(str(key), declared)}")


def _scene(doc: Mapping[str, Any], err: _Errors) -> str | None:
    """The scene's import name, checked to make a scene (it is built once, cheaply)."""
    name = _get(doc, "scene", str, err, default=None)
    if name is not None:
        try:
            load_scene(name)
        except SceneError as exc:
            err.fail("scene", str(exc))
    return name


def _checked(parse: typing.Callable[..., Any], err: _Errors, *args: Any) -> Any:
    """`parse(*args)`, its `ConfigError` reported as this scenario's error."""
    try:
        return parse(*args)
    except ConfigError as exc:
        err.fail(exc.key, exc.what)


def _check_node_names(check: CheckConfig, names: list[str], err: _Errors) -> None:
    """The node names `check:` mentions (queue bounds, crashes) must be nodes."""
    crash = check.faults.crash
    named = [(f"check.queue_bound.{n}", n) for n in check.queue_bound.named()]
    named += [("check.faults.crash", n) for n in (*crash.nodes, *crash.durable)] if crash else []
    for key, name in named:
        if name not in names:
            err.fail(key, f"{name!r} is not a node of this scenario; expected one of "
                     f"{', '.join(sorted(names))}")


class _Errors:
    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, key: str, what: str) -> typing.NoReturn:
        raise ScenarioError(f"{self.source}: {key}: {what}")

    def unknown_keys(self, doc: Mapping[str, Any], allowed: set[str], prefix: str) -> None:
        for key in doc:
            if key not in allowed:
                self.fail(f"{prefix}{key}", f"unknown key; expected one of "
                          f"{', '.join(sorted(allowed))}{did_you_mean(str(key), allowed)}")


def _get(doc: Mapping[str, Any], key: str, typ: type, err: _Errors, *, default: Any = ...,
         where: str = "") -> Any:
    if key not in doc:
        if default is ...:
            err.fail(where + key, f"missing; expected a {typ.__name__}")
        return default
    value = doc[key]
    if not isinstance(value, typ) or (typ is int and isinstance(value, bool)):
        err.fail(where + key, f"expected a {typ.__name__}, got {value!r}")
    return value


def _choice(doc: Mapping[str, Any], key: str, options: tuple[str, ...], err: _Errors) -> str:
    value = _get(doc, key, str, err, default=options[0])
    if value not in options:
        err.fail(key, f"expected one of {', '.join(options)}, got {value!r}")
    return value


def _node(i: int, raw: Any, common: Mapping[str, Any], base: Path, err: _Errors) -> NodeConfig:
    where = f"nodes[{i}]."
    if isinstance(raw, NodeEntry):
        raw = raw.as_mapping()
    if not isinstance(raw, dict):
        err.fail(f"nodes[{i}]", "expected a mapping with name, class and params")
    err.unknown_keys(raw, _NODE_KEYS, where)
    name = _get(raw, "name", str, err, where=where)
    try:
        validate_token(name, "node name")
        namespace = normalise_namespace(_get(raw, "namespace", str, err, default="", where=where))
    except InvalidName as exc:
        err.fail(where + "name", str(exc))
    if "class" not in raw:
        err.fail(where + "class", "missing; expected 'module:Class' or a Node subclass")
    cls, class_path = _node_class(raw["class"], err, where + "class")
    given = raw.get("params")
    if given is not None and not isinstance(given, dict) and isinstance(given, cls.Params):
        params, raw_params = given, {f.name: getattr(given, f.name)
                                     for f in dataclasses.fields(given)}
    else:
        raw_params = _get(raw, "params", dict, err, default={}, where=where)
        params = _checked(build_params, err, cls.Params, raw_params, common, base,
                          where + "params")
    return NodeConfig(name=name, cls=cls, class_path=class_path, namespace=namespace,
                      priority=_get(raw, "priority", int, err, default=0, where=where),
                      respawn=_get(raw, "respawn", bool, err, default=False, where=where),
                      params=params, raw_params=dict(raw_params))


def _finite(value: Any, key: str, err: _Errors) -> None:
    """Refuse inf and NaN anywhere in a node's parameters (no node means them)."""
    if isinstance(value, float) and not math.isfinite(value):
        err.fail(key, f"expected a finite number, got {value}")
    elif isinstance(value, Mapping):
        for k, v in value.items():
            _finite(v, f"{key}.{k}", err)
    elif isinstance(value, list | tuple):
        for j, v in enumerate(value):
            _finite(v, f"{key}[{j}]", err)


def _check_node_count(count: int, live: Any, err: _Errors) -> None:
    """Refuse more nodes than `live.max_nodes` (each is an OS process live) before any is
    validated: 10,000 entries fail at once instead of after a minute of checks."""
    cap = live.get("max_nodes", MAX_NODES) if isinstance(live, Mapping) else MAX_NODES
    if type(cap) is not int or cap < 1:
        err.fail("live.max_nodes", f"expected a whole number >= 1, got {cap!r}")
    if count > cap:
        err.fail("nodes", f"{count} nodes, more than live.max_nodes = {cap} (each node is one "
                          "process when launched); raise live.max_nodes if the machine can "
                          "take them")


def _try_instantiate(i: int, cfg: NodeConfig, err: _Errors) -> None:
    """Build the node once so that bad parameters fail before anything starts."""
    try:
        cfg.instantiate()
    except (ValueError, TypeError, OSError, ArithmeticError) as exc:
        err.fail(f"nodes[{i}] ({cfg.name})", str(exc) or type(exc).__name__)


def _import_attr(path: str, err: _Errors, key: str, what: str = "name") -> Any:
    module_name, _, attr = path.partition(":")
    if not attr:
        err.fail(key, f"expected 'module:{what.split()[-1].capitalize()}', got {path!r}")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        err.fail(key, f"unknown {what} {path!r} ({exc})")
    except ImportError as exc:  # the module exists; an import of its own was refused
        err.fail(key, f"cannot load {what} {path!r}: importing {module_name!r} failed: {exc}")
    except RecursionError:
        err.fail(key, f"importing {module_name!r} for {what} {path!r} recursed too deeply")
    except Exception as exc:  # the module itself raised while it was imported
        err.fail(key, f"importing {module_name!r} for {what} {path!r} raised "
                      f"{type(exc).__name__}: {exc}")
    try:
        return getattr(module, attr)
    except AttributeError as exc:
        names = [f"{module_name}:{n}" for n in vars(module) if not n.startswith("_")]
        err.fail(key, f"unknown {what} {path!r} ({exc}){did_you_mean(path, names)}")


def _node_class(value: Any, err: _Errors, key: str) -> tuple[type[Node], str]:
    """The node class an entry names ("module:Class" or the class itself) and its path."""
    from twinfleet.rclpy.loader import contract_class, importing

    if isinstance(value, str):
        with importing():  # node code's `import rclpy` and ROS messages: docs/rclpy.md
            cls, path = _import_attr(value, err, key, "node class"), value
    elif isinstance(value, type):
        cls, path = value, f"{value.__module__}:{value.__qualname__}"
    else:
        err.fail(key, f"expected 'module:Class' or a Node subclass, got {value!r}")
    try:
        cls = contract_class(cls)  # an rclpy Node subclass becomes its contract adapter
    except Exception as exc:  # its __init__ ran once to learn its entities, and raised
        err.fail(key, f"{path!r}: building the rclpy node raised {type(exc).__name__}: {exc}")
    if not (isinstance(cls, type) and issubclass(cls, Node)):
        err.fail(key, f"{path!r} is not a subclass of twinfleet.Node")
    return cls, path


def _property(i: int, raw: Any, names: Sequence[str], err: _Errors) -> PropertyConfig:
    where = f"properties[{i}]."
    if isinstance(raw, PropertyConfig):
        raw = {k: v for k, v in dataclasses.asdict(raw).items() if v is not None}
    if not isinstance(raw, dict):
        err.fail(f"properties[{i}]", "expected a mapping with kind (and name, expr, within_ms)")
    err.unknown_keys(raw, _PROPERTY_KEYS, where)
    kind = _get(raw, "kind", str, err, where=where)
    if kind not in PROPERTY_KINDS:
        err.fail(where + "kind", f"expected one of {', '.join(PROPERTY_KINDS)}, got {kind!r}")
    name = _get(raw, "name", str, err, default=f"{kind}_{i}", where=where)
    expr = _get(raw, "expr", str, err, default=None, where=where)
    if kind in ("invariant", "eventually", "within") and expr is None:
        err.fail(where + "expr", f"a {kind} property needs an expression over node states")
    if expr is not None:
        try:  # the safe language of property expressions, checked before anything runs
            parse_expression(expr, names, f"{err.source}:{where}expr")
        except ExpressionError as exc:
            err.fail(where + "expr", f"property {name!r}: {exc}")
    within = _get(raw, "within_ms", int, err, default=None, where=where)
    if kind == "within" and (within is None or within <= 0):
        err.fail(where + "within_ms", "a within property needs within_ms > 0")
    return PropertyConfig(name=name, kind=kind, expr=expr, within_ms=within)
