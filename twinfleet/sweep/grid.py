"""The grid of a sweep: `--param NAME=VALUES` words parsed into axes, axes into points.

Pure logic, no I/O. A NAME says what a value sets:

- ``r1.speed``: parameter `speed` of node r1 (as ``twinfleet check c1a r1.speed:=0.4``);
- ``scan_rate_ms``: the scenario's common ``params`` (merged into every node whose
  parameters have that field, unless the node sets it itself);
- ``*.speed``: parameter `speed` of every node whose parameters have that field, over
  what each node sets (expanded into one per-node override per node when the sweep runs);
- ``semantics``: the check's message rules;
- ``check.latency`` (any ``check.KEY``): one key of the scenario's ``check:`` block.

VALUES is a list ``a,b,c`` (each YAML; brackets keep their commas: ``[5, 5],[6, 6]``) or
an inclusive range ``start:stop:step`` of numbers.
"""

from __future__ import annotations

import itertools
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum, unique
from typing import Any, final

import yaml


@unique
class Target(Enum):
    """What a sweep parameter sets."""

    NODE = "node"  # r1.speed: one node's parameter
    COMMON = "common"  # scan_rate_ms: the scenario's common params
    EVERY_NODE = "every node"  # *.speed: every node that has the parameter
    SEMANTICS = "semantics"
    CHECK = "check"  # check.latency: a key of the scenario's check: block


_OPTIONS = {"semantics": Target.SEMANTICS}
_CHOICES = {Target.SEMANTICS: ("ros", "rebeca")}
_NAME = re.compile(r"^(\*\.|check\.|[A-Za-z_][\w/-]*\.)?[A-Za-z_]\w*$")
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_RANGE = re.compile(rf"^({_NUMBER}):({_NUMBER}):({_NUMBER})$")
MAX_POINTS = 10_000  # a typo in a range should not queue a million checks


class GridError(ValueError):
    """A `--param` word that cannot be read (one line naming it)."""


@final
@dataclass(frozen=True)
class Axis:
    """One swept parameter: its name as written, what it sets and its values in order."""

    name: str
    target: Target
    values: tuple[Any, ...]

    @property
    def node(self) -> str | None:
        """The node a NODE axis sets."""
        return self.name.rpartition(".")[0] if self.target is Target.NODE else None

    @property
    def key(self) -> str:
        """The parameter or setting name without its node or ``check.`` prefix."""
        return self.name.rpartition(".")[2]


#: one point of the grid: (axis name, value) for every axis, in the axes' order
Point = tuple[tuple[str, Any], ...]


def parse_axis(text: str) -> Axis:
    """``r1.speed=0.4,0.6`` or ``scan_rate_ms=60:140:20`` → an `Axis`.

    Raises:
        GridError: not NAME=VALUES, a bad name, an empty or malformed value list.
    """
    name, sep, raw = text.partition(":=") if ":=" in text else text.partition("=")
    name = name.strip()
    if not sep or not _NAME.match(name):
        raise GridError(f"--param {text!r}: expected [NODE.|*.|check.]NAME=VALUES, "
                        "e.g. r1.speed=0.4,0.6 or scan_rate_ms=60:140:20")
    target = _target(name)
    values = parse_values(raw, where=f"--param {text!r}")
    allowed = _CHOICES.get(target)
    if allowed is not None and any(v not in allowed for v in values):
        raise GridError(f"--param {text!r}: {name} is one of {', '.join(allowed)}")
    return Axis(name, target, values)


def _target(name: str) -> Target:
    if name in _OPTIONS:
        return _OPTIONS[name]
    if name.startswith("*."):
        return Target.EVERY_NODE
    if name.startswith("check."):
        return Target.CHECK
    return Target.NODE if "." in name else Target.COMMON


def parse_values(raw: str, *, where: str = "values") -> tuple[Any, ...]:
    """A range ``start:stop:step`` (inclusive, numbers) or a comma list of YAML values."""
    raw = raw.strip()
    if not raw:
        raise GridError(f"{where}: no values")
    match = _RANGE.match(raw)
    if match:
        return _range(*(yaml.safe_load(g) for g in match.groups()), where=where)
    values = []
    for piece in _split_top_level(raw):
        try:
            values.append(yaml.safe_load(piece))
        except yaml.YAMLError as exc:
            raise GridError(f"{where}: {piece!r} is not YAML "
                            f"({str(exc).splitlines()[0]})") from None
        if piece.strip() == "":
            raise GridError(f"{where}: an empty value in {raw!r}")
    if len(set(map(repr, values))) != len(values):
        raise GridError(f"{where}: a value is listed twice")
    return tuple(values)


def _range(start: float, stop: float, step: float, *, where: str) -> tuple[Any, ...]:
    if step <= 0 or stop < start:
        raise GridError(f"{where}: a range start:stop:step needs start <= stop and step > 0")
    count = math.floor((stop - start) / step + 1e-9) + 1
    if count > MAX_POINTS:
        raise GridError(f"{where}: {count:,} values (at most {MAX_POINTS:,})")
    whole = all(isinstance(v, int) for v in (start, stop, step))
    # rounding keeps 0.1 steps printable (0.3, not 0.30000000000000004) and cache keys stable
    return tuple(start + i * step if whole else round(start + i * step, 9) for i in range(count))


def _split_top_level(raw: str) -> list[str]:
    """Split on commas outside brackets and quotes."""
    pieces: list[str] = []
    current: list[str] = []
    depth, quote = 0, ""
    for char in raw:
        if quote:
            quote = "" if char == quote else quote
        elif char in "'\"":
            quote = char
        elif char in "[{":
            depth += 1
        elif char in "]}":
            depth -= 1
        elif char == "," and depth == 0:
            pieces.append("".join(current))
            current = []
            continue
        current.append(char)
    pieces.append("".join(current))
    return pieces


def parse_grid(words: Sequence[str]) -> tuple[Axis, ...]:
    """Every `--param` word as an axis; the grid they span must be small enough.

    Raises:
        GridError: a bad word, a name given twice, no words, or too many points.
    """
    if not words:
        raise GridError("give at least one --param NAME=VALUES")
    axes = tuple(parse_axis(w) for w in words)
    names = [a.name for a in axes]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise GridError(f"--param {twice[0]} given twice")
    size = math.prod(len(a.values) for a in axes)
    if size > MAX_POINTS:
        raise GridError(f"the grid has {size:,} points (at most {MAX_POINTS:,})")
    return axes


def points(axes: Sequence[Axis]) -> list[Point]:
    """Every combination of the axes' values, the last axis varying fastest."""
    return [tuple(zip((a.name for a in axes), combo, strict=True))
            for combo in itertools.product(*(a.values for a in axes))]


def point_label(point: Point) -> str:
    """``r1.speed=0.4 scan_rate_ms=100``: a point as one line of words."""
    return " ".join(f"{name}={format_value(value)}" for name, value in point)


def format_value(value: Any) -> str:
    """A value as the user would type it back (YAML flow style, one line)."""
    if isinstance(value, str):
        return value
    return str(yaml.safe_dump(value, default_flow_style=True, width=10_000)).strip().removesuffix(
        "\n...").strip()
