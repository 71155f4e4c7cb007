"""State-growth diagnosis: which node field keeps taking new values, so the search never ends.

A state space is finite only if every node field takes finitely many values. A
retry counter that is never reset, a float heading that drifts, a list that
only grows or a time stamp kept in the state each give every world a new
identity, and the search runs until a limit stops it. `GrowthWatch` names such
fields while the search runs, cheaply:

- It looks at one newly found world in 16 (`SAMPLE_MASK`; the search calls `observe`
  for it with the world it was found from), and only at the nodes whose state
  the step changed: the new and the old state are decoded (`System.decode`)
  and split into *fields* (`_fields`): the attributes of a dataclass (one level
  of nested dataclasses, as ``pose.x``), the keys of a dict or of a sequence of
  ``(name, value)`` pairs (an rclpy node's ``attrs.count``), and for a list,
  tuple, set or dict also its length (``len(log)``); a tuple of plain values
  is also a value (``pose``).
- Per (node, field) a `_Sketch` keeps a K-minimum-values sketch of the values'
  hashes (exact up to `_K` distinct values, an estimate within a few per cent
  beyond, in bounded memory), how often a change along parent -> child went up
  or down, and the most common step.
- `notes` names the fields that still take new values: at least `_MIN_VALUES`
  distinct values, and either only ever moving one way while still finding new
  ones (a counter; in a wide search its values grow with the depth, not with
  the number of states) or having found at least a quarter of their values
  since they had half their samples or fewer (their count keeps growing with
  the state count).
  A bounded field stops finding new values, so it drops out.

The counts are of the sampled worlds: a lower bound of the values the field took.
"""

from __future__ import annotations

import dataclasses
import heapq
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any, Final, final

from twinfleet.checker.transition import Transition
from twinfleet.checker.world import World

SAMPLE_MASK: Final = 15  # the search samples a new world when its id & SAMPLE_MASK == 0 (1 in 16)
_K: Final = 1024  # hashes kept per field: exact counts below, about 3 % error above
_MIN_VALUES: Final = 64  # fewer values is never called growth (C1a's robots reach ~30 cells)
_SPLIT_LIMIT: Final = 4096  # node states whose fields are kept (`GrowthWatch._fields_of`)
_STEPS: Final = 8  # different step sizes remembered per field
_SHOWN: Final = 3  # fields named at most
_MASK: Final = (1 << 64) - 1
_SCALARS: Final = (bool, int, float, str, bytes, type(None))
_SIZED: Final = (list, tuple, dict, set, frozenset, str, bytes)

HINT: Final = "bound it, or check with --max-depth/within (docs/finite-state.md)"


@final
@dataclass(frozen=True, slots=True)
class GrowthNote:
    """A node field that keeps taking new values: `values` distinct ones in the sampled
    worlds (an estimate when `estimated`), `direction` +1 if it only grew along the
    sampled steps, -1 if it only shrank, 0 otherwise, its most common `step`, and for a
    number the smallest and largest value sampled (`span`)."""

    node: str
    field: str
    values: int
    estimated: bool
    direction: int
    step: float | None
    span: tuple[float, float] | None = None

    @property
    def name(self) -> str:
        """``node.field`` (``len(node.field)`` for a length)."""
        if self.field.startswith("len("):
            return f"len({self.node}.{self.field[4:]}"
        return f"{self.node}.{self.field}" if self.field else self.node

    def describe(self) -> str:
        """One line: what grows, how, and what to do about it."""
        how = ""
        if self.direction and self.step is not None:
            how = f" and {'grows' if self.direction > 0 else 'shrinks'} by {abs(self.step):g} a step"
        elif self.direction:
            how = f" and only {'grows' if self.direction > 0 else 'shrinks'}"
        span = "" if self.span is None else f" ({self.span[0]:,.6g} to {self.span[1]:,.6g})"
        return f"{self.name} took {self._many()} values{span}{how}; {HINT}"

    def _many(self) -> str:
        """How many values: a lower bound, since only some worlds are sampled."""
        return f"{'~' if self.estimated else ''}{self.values:,}+"

    def short(self) -> str:
        """A few words for the progress line."""
        step = "" if not self.direction or self.step is None else f", {self.step:+g} a step"
        return f"{self.name} ({self._many()} values{step})"

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready record."""
        return {"node": self.node, "field": self.field, "values": self.values,
                "estimated": self.estimated, "direction": self.direction, "step": self.step,
                "span": None if self.span is None else list(self.span),
                "text": self.describe()}


@final
class _Sketch:
    """Distinct values (K minimum hashes), directions of change and steps of one field."""

    __slots__ = ("_heap", "_kept", "downs", "high", "low", "marks", "samples", "steps", "ups")

    def __init__(self) -> None:
        self._heap: list[int] = []  # the K smallest hashes, negated (a max-heap)
        self._kept: set[int] = set()
        self.low: float | None = None  # the smallest and largest number seen
        self.high: float | None = None
        self.samples = 0
        self.ups = self.downs = 0
        self.steps: dict[float, int] = {}
        self.marks: list[int] = []  # distinct values when `samples` reached 16, 32, 64...

    def add(self, value: Any) -> None:
        self.samples += 1
        if self.samples >= _MIN_VALUES and not self.samples & (self.samples - 1):
            self.marks.append(self.distinct()[0])
        if type(value) in (int, float):
            if self.low is None or value < self.low:
                self.low = value
            if self.high is None or value > self.high:
                self.high = value
        h = hash((value,)) & _MASK
        if h in self._kept:
            return
        heap = self._heap
        if len(heap) < _K:
            heapq.heappush(heap, -h)
            self._kept.add(h)
        elif h < -heap[0]:
            self._kept.discard(-heapq.heappushpop(heap, -h))
            self._kept.add(h)

    def change(self, before: Any, after: Any) -> None:
        if type(before) not in (int, float) or type(after) not in (int, float):
            return
        delta = after - before
        if delta == 0:
            return
        if delta > 0:
            self.ups += 1
        else:
            self.downs += 1
        steps = self.steps
        if delta in steps or len(steps) < _STEPS:
            steps[delta] = steps.get(delta, 0) + 1

    def distinct(self) -> tuple[int, bool]:
        """(distinct values, whether that is an estimate)."""
        heap = self._heap
        if len(heap) < _K:
            return len(heap), False
        return int((_K - 1) * (_MASK + 1) / (-heap[0] + 1)), True

    def growing(self) -> bool:
        values, _ = self.distinct()
        if values < _MIN_VALUES or len(self.marks) < 2:
            return False
        # marks[-1] was taken at more than half the samples so far, marks[-2] at at most half
        new = values - self.marks[-2]
        one_way = (self.ups == 0) != (self.downs == 0)
        return (one_way and new > 0) or 4 * new >= values

    def direction(self) -> int:
        if self.ups and not self.downs:
            return 1
        if self.downs and not self.ups:
            return -1
        return 0


@final
class GrowthWatch:
    """The sketches of every (node, field) seen in sampled new worlds.

    Args:
        names: the node names, in scenario order.
        decode: decodes node `i`'s state bytes (`System.decode`; read-only objects).
    """

    def __init__(self, names: tuple[str, ...], decode: Callable[[int, bytes], Any]) -> None:
        self._names = names
        self._decode = decode
        self._sketches: dict[tuple[int, str], _Sketch] = {}
        # A node state's fields by its bytes: a parent is sampled once per new child, and
        # most node states recur in many worlds (lanes of three robots: 7 % of a search)
        self._split: dict[bytes, dict[str, Any]] = {}
        self.sampled = 0

    def observe(self, parent: World, t: Transition) -> None:
        """A new world `t.world` found from `parent`: sample the nodes the step changed."""
        self.sampled += 1
        for i in t.changed:
            after = self._fields_of(i, t.world.states[i])
            before = self._fields_of(i, parent.states[i])
            sketches = self._sketches
            for name, value in after.items():
                sketch = sketches.get((i, name))
                if sketch is None:
                    sketch = sketches[(i, name)] = _Sketch()
                sketch.add(value)
                old = before.get(name, value)
                if old is not value:
                    sketch.change(old, value)

    def _fields_of(self, i: int, data: bytes) -> dict[str, Any]:
        """The fields of node `i`'s state `data` (cached; read-only)."""
        split = self._split.get(data)
        if split is None:
            if len(self._split) >= _SPLIT_LIMIT:
                self._split.clear()
            split = self._split[data] = dict(_fields(self._decode(i, data)))
        return split

    def notes(self) -> tuple[GrowthNote, ...]:
        """The fields that keep taking new values, most values first (at most three)."""
        found = []
        for (i, name), sketch in self._sketches.items():
            if sketch.growing():
                values, estimated = sketch.distinct()
                steps = sketch.steps
                step = max(steps, key=steps.__getitem__) if steps else None
                span = None if sketch.low is None or sketch.high is None else \
                    (sketch.low, sketch.high)
                found.append(GrowthNote(self._names[i], name, values, estimated,
                                        sketch.direction(), step, span))
        found.sort(key=lambda n: (-n.values, n.node, n.field))
        return tuple(found[:_SHOWN])


_NAMES: dict[type, tuple[str, ...]] = {}  # a dataclass's field names (fields() is slow)


def _fields(state: Any, prefix: str = "", depth: int = 0) -> Iterator[tuple[str, Any]]:
    """(field name, hashable value) pairs of a decoded node state (module docstring)."""
    if dataclasses.is_dataclass(state) and not isinstance(state, type):
        names = _NAMES.get(type(state))
        if names is None:
            names = _NAMES[type(state)] = tuple(f.name for f in dataclasses.fields(state))
        items: Any = ((n, getattr(state, n)) for n in names)
    elif isinstance(state, dict):
        items = ((str(k), v) for k, v in state.items())
    else:
        items = (("", state),)
    for key, value in items:
        name = f"{prefix}.{key}" if prefix and key else prefix or key
        if isinstance(value, _SCALARS):
            yield name, value
        if isinstance(value, _SIZED) and not isinstance(value, (str, bytes)):
            yield f"len({name})", len(value)
            if isinstance(value, tuple) and all(isinstance(v, _SCALARS) for v in value):
                yield name, value
            pairs = named_pairs(value) if depth == 0 and name else None
            if pairs is not None:  # attributes kept by name (an rclpy node's attrs)
                yield from _fields(pairs, name, 1)
        elif depth == 0 and (dataclasses.is_dataclass(value) or isinstance(value, dict)) \
                and not isinstance(value, type) and name:
            yield from _fields(value, name, 1)


def named_pairs(value: Any) -> dict[str, Any] | None:
    """A list or tuple of distinct-named ``(name, value)`` pairs as a map, else None: how a
    state keeps attributes by name (an rclpy node's ``attrs``), read field by field."""
    if not (isinstance(value, (list, tuple)) and value):
        return None
    if not all(isinstance(p, (list, tuple)) and len(p) == 2 and isinstance(p[0], str)
               for p in value):
        return None
    named = {p[0]: p[1] for p in value}
    return named if len(named) == len(value) else None
