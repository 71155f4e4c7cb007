"""Timing models: how long messages take and how late timers fire, as measured live.

A `TimingModel` holds, in fleet milliseconds, an empirical distribution
(`Histogram`) of delivery latency per topic or service (and a default for the
rest), one of the latency of messages sent while the fleet starts, one of
timer lateness, an optional loss probability per topic, and where it came
from (the machine, the time scale of the runs, how many samples).

Start-up: the first messages of a live fleet (sent in its first few fleet
ms: the first scans, the first service requests and their replies) take far
longer than later ones (20-90 fleet ms at time scale 2 against about 7: new
routes, processes still warming up), and their spread sets every robot's
phase for the rest of the run. A message sent before `startup_ms` draws its
latency from `startup`, whatever its channel.

Deliveries of one publish: a topic's subscribers receive one message at
nearly the same moment (one send, one wake-up of the sender's session), so
their latencies are far from independent (a two-phase commit's decision, three
receivers: median spread 2 ms against 4 for independent draws from the same
histogram). `together` holds, per channel (and "default" for the rest), the
correlation of the normal scores of one publish's delivery latencies; a
simulation draws them through a Gaussian copula with that correlation, so
each delivery keeps its channel's histogram and the copies of one publish move
together.

Ties at one millisecond: the checker's clock has whole ms, so a node may have a
message and a timer due at the same ms. Live, the message is almost always
handled first (two-phase commit, 43 such ties: 40 message first): its logged
ms is the floor of its arrival, while a timer is released only when the
event loop's wake-up for it fires (`epoll` waits whole ms, rounded up), and a
message that arrives in the meantime is served before it. `messages_first`
(fitted by `calibrate`, None: unknown) is the probability that a simulation
runs one of the node's messages rather than one of its timers when both are
enabled at one ms (`checker.simulate`); with None the choice is uniform.
`twinfleet calibrate` fits one from live event logs
(`twinfleet.agreement.calibrate`); a model for loopback ships with the package
(`default_timing`).

Load levels: a machine's load changes between runs more than within one, so the
latencies of one live run are alike (all slow, or all quick), and a mixture of
per-run distributions is not the pooled histogram drawn independently: a
protocol whose outcome turns on a few deliveries being late together breaks in
slow runs far more often than the pooled draws say. `levels` (fitted by
`calibrate --levels K`: the runs sorted by their mean latency and cut into K
groups) holds, per group, its share of the runs and its own latency
histograms; a simulation first draws its level by those shares, then draws
every latency from that level (`at_level`). A model without levels draws from
the pooled histograms, as before.

Two uses. `twinfleet check --timing FILE` takes the model's *bounds* as the
exhaustive search's latency ranges (every value a branch, as `check.latency`
is) and timer lateness (as `check.timer_lateness`, when the model's reaches
above 0 ms); `twinfleet check --statistical` draws each latency from the model's
*weights* (`checker.sampling`). Latencies are whole fleet ms, as the checker's
clock is: a live latency of t - stamp ms (both whole fleet ms) is counted as is.

File format (YAML, ``format: twinfleet-timing/1``)::

    format: twinfleet-timing/1
    machine: "Linux x86_64, 2 cores"     # where it was measured
    time_scale: 1.0                      # fleet ms per wall ms of the runs
    sources: [c1a.events.jsonl]
    latency:
      default: {values: [0, 1, 2], weights: [0.80, 0.15, 0.05], samples: 9000}
      /poses: {values: [0, 1], weights: [0.9, 0.1], samples: 4000}
    timer_lateness: {values: [0, 1], weights: [0.95, 0.05], samples: 2000}
    startup: {window_ms: 20, values: [20, 48], weights: [0.5, 0.5], samples: 24}  # optional
    together: {default: 0.6, /decision: 0.87}  # optional: one publish's copies, correlation
    ties: {messages_first: 0.93, samples: 43}  # optional: a message and a timer at one ms
    levels:                              # optional: load levels, each its share of the runs
      - {weight: 0.5, runs: 20, mean_ms: 2.1, latency: {default: {values: [1, 2], ...}}}
      - {weight: 0.5, runs: 20, mean_ms: 3.4, latency: {default: {values: [2, 5], ...}}}
    loss: {/poses: 0.0}                  # optional

`values` are distinct whole ms in increasing order, `weights` their
probabilities (they must sum to 1 within 1e-3; they are renormalised).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Final, final

import yaml

TIMING_FORMAT: Final = "twinfleet-timing/1"
DEFAULT_MODEL: Final = "loopback.timing.yaml"
Range = tuple[int, int]


class TimingError(ValueError):
    """A timing model file is unreadable or malformed (one line, naming the file and key)."""


@final
@dataclass(frozen=True, slots=True)
class Histogram:
    """An empirical distribution over whole milliseconds.

    Attributes:
        values: distinct values in increasing order (>= 0).
        weights: the probability of each value (summing to 1).
        samples: how many measurements it was fitted from (0: written by hand).
    """

    values: tuple[int, ...] = (0,)
    weights: tuple[float, ...] = (1.0,)
    samples: int = 0

    def __post_init__(self) -> None:
        if not self.values or len(self.values) != len(self.weights):
            raise ValueError("values and weights must be non-empty and of equal length")
        if any(v < 0 for v in self.values) or list(self.values) != sorted(set(self.values)):
            raise ValueError("values must be distinct whole ms >= 0 in increasing order")
        if any(w < 0 for w in self.weights) or abs(sum(self.weights) - 1.0) > 1e-6:
            raise ValueError(f"weights must be >= 0 and sum to 1 (sum {sum(self.weights):.6f})")

    @classmethod
    def fit(cls, samples: Iterable[int]) -> Histogram:
        """The empirical distribution of `samples` (negative values count as 0)."""
        counts = Counter(max(0, int(s)) for s in samples)
        total = sum(counts.values())
        if not total:
            return cls()
        values = tuple(sorted(counts))
        return cls(values, tuple(counts[v] / total for v in values), total)

    @property
    def bounds(self) -> tuple[int, int]:
        """(smallest, largest) value."""
        return self.values[0], self.values[-1]

    @property
    def mean(self) -> float:
        """The expected value in ms."""
        return math.fsum(v * w for v, w in zip(self.values, self.weights, strict=True))

    def weights_over(self, low: int, n: int) -> tuple[float, ...]:
        """The weight of each of `low`, ..., `low + n - 1`, renormalised over that range
        (uniform when the model gives the range no weight)."""
        own = dict(zip(self.values, self.weights, strict=True))
        out = [own.get(low + k, 0.0) for k in range(n)]
        total = math.fsum(out)
        return tuple(w / total for w in out) if total > 0 else (1.0 / n,) * n

    def quantile(self, q: float) -> int:
        """The smallest value whose cumulative weight reaches `q`."""
        acc = 0.0
        for v, w in zip(self.values, self.weights, strict=True):
            acc += w
            if acc >= q - 1e-12:
                return v
        return self.values[-1]

    def scaled(self, factor: float) -> Histogram:
        """The same distribution with every value multiplied by `factor` (rounded to whole
        ms; values that round together pool their weight)."""
        pooled: dict[int, float] = {}
        for v, w in zip(self.values, self.weights, strict=True):
            key = max(0, round(v * factor))
            pooled[key] = pooled.get(key, 0.0) + w
        values = tuple(sorted(pooled))
        return Histogram(values, tuple(pooled[v] for v in values), self.samples)

    def to_yaml(self) -> dict[str, Any]:
        """The mapping the file format writes."""
        return {"values": list(self.values), "weights": [round(w, 6) for w in self.weights],
                "samples": self.samples}


@final
@dataclass(frozen=True, slots=True)
class Level:
    """One load level of a model: a group of runs alike in latency (module docstring).

    Attributes:
        weight: the share of the runs in this level (the probability a simulation draws it).
        default: latency of a channel with no histogram of its own, in these runs.
        latency: (topic or service, histogram) pairs, sorted by name; a channel of the
            model missing here is drawn from the model's own histogram of it.
        runs: how many runs it was fitted from; mean_ms: their mean latency.
    """

    weight: float
    default: Histogram
    latency: tuple[tuple[str, Histogram], ...] = ()
    runs: int = 0
    mean_ms: float = 0.0

    def scaled(self, factor: float) -> Level:
        """The level with every histogram stretched by `factor` (`Histogram.scaled`)."""
        return Level(self.weight, self.default.scaled(factor),
                     tuple((n, h.scaled(factor)) for n, h in self.latency), self.runs,
                     self.mean_ms * factor)

    def to_yaml(self) -> dict[str, Any]:
        """The mapping the file format writes."""
        return {"weight": round(self.weight, 6), "runs": self.runs,
                "mean_ms": round(self.mean_ms, 3),
                "latency": {"default": self.default.to_yaml(),
                            **{name: h.to_yaml() for name, h in self.latency}}}


@final
@dataclass(frozen=True, slots=True)
class TimingModel:
    """Delivery latency per channel, timer lateness and loss (module docstring).

    Attributes:
        default: latency of a channel with no histogram of its own.
        latency: (topic or service, histogram) pairs, sorted by name.
        timer_lateness: how late timers (`ctx.after`, `@every`) fire.
        loss: (topic, probability) pairs, sorted by name.
        startup: latency of a message sent before `startup_ms` (None: as any other).
        startup_ms: the length of the start-up window, fleet ms.
        together: (channel or "default", correlation in [0, 1)) pairs, sorted by name: how
            the latencies of one publish's deliveries move together (module docstring).
        messages_first: the probability that a node's message runs before its timer due
            at the same ms (None: unknown, a uniform choice); tie_samples: the ties it was
            fitted from.
        levels: load levels (module docstring; empty: the pooled histograms only).
        machine: where it was measured.
        time_scale: the time scale of the runs it was fitted from (None: not measured).
        sources: the event logs it was fitted from.
        origin: where a model not fitted from logs comes from (`from_ranges`).
    """

    default: Histogram = Histogram()
    latency: tuple[tuple[str, Histogram], ...] = ()
    timer_lateness: Histogram = Histogram()
    loss: tuple[tuple[str, float], ...] = ()
    machine: str = ""
    time_scale: float | None = None
    sources: tuple[str, ...] = ()
    startup: Histogram | None = None
    startup_ms: int = 0
    origin: str = ""
    together: tuple[tuple[str, float], ...] = ()
    messages_first: float | None = None
    tie_samples: int = 0
    levels: tuple[Level, ...] = ()

    def __post_init__(self) -> None:
        if self.levels and abs(math.fsum(lv.weight for lv in self.levels) - 1.0) > 1e-6:
            raise ValueError("the levels' weights must sum to 1")

    @classmethod
    def from_ranges(cls, default: Range | None, channels: tuple[tuple[str, Range | None], ...],
                    origin: str) -> TimingModel:
        """A model drawing each latency uniformly from a checker's latency ranges (None: no
        latency), timers on time: a scenario's `check.latency` as a distribution."""
        return cls(_uniform(default), tuple((name, _uniform(span)) for name, span in channels),
                   origin=origin)

    def assumed(self, source: str) -> AssumedTiming:
        """The timing this model assumes, as every summary states it."""
        return AssumedTiming(self.default.bounds, tuple((n, h.bounds) for n, h in self.latency),
                             self.timer_lateness.bounds, source)

    def together_of(self, channel: str) -> float:
        """The correlation of the latencies of one publish's deliveries on `channel`."""
        found = dict(self.together)
        return found.get(channel, found.get("default", 0.0))

    def at_level(self, index: int) -> TimingModel:
        """The model of level `index` alone: its histograms in place of the pooled ones
        (a channel it lacks keeps the pooled histogram), no levels."""
        level = self.levels[index]
        own = dict(self.latency) | dict(level.latency)
        return replace(self, default=level.default, latency=tuple(sorted(own.items())),
                       levels=())

    def starting(self, sent: int | None) -> bool:
        """Whether a message sent at fleet ms `sent` draws the start-up latency."""
        return self.startup is not None and sent is not None and sent < self.startup_ms

    def latency_of(self, channel: str, sent: int | None = None) -> Histogram:
        """The latency distribution of messages on `channel` (sent at fleet ms `sent`)."""
        if self.starting(sent):
            assert self.startup is not None
            return self.startup
        return dict(self.latency).get(channel, self.default)

    def ranges(self, channels: Iterable[str]) -> tuple[tuple[int, int] | None,
                                                      tuple[tuple[str, tuple[int, int]], ...]]:
        """The model's bounds as a checker's latency ranges: (default range or None for
        none, per-channel ranges of those of `channels` that have their own histogram)."""
        low, high = self.default.bounds
        if self.startup is not None:
            low, high = min(low, self.startup.bounds[0]), max(high, self.startup.bounds[1])
        default = None if high == 0 else (low, high)
        known = set(channels)
        return default, tuple((name, h.bounds) for name, h in self.latency if name in known)

    def at_time_scale(self, time_scale: float) -> TimingModel:
        """The model for runs at `time_scale`: a wall delay of d ms is d * K fleet ms at time
        scale K, so every histogram is stretched by `time_scale / self.time_scale` (a model
        of unknown scale is taken as it is)."""
        if self.time_scale is None or self.time_scale == time_scale:
            return self
        f = time_scale / self.time_scale
        return TimingModel(self.default.scaled(f), tuple((n, h.scaled(f)) for n, h in self.latency),
                           self.timer_lateness.scaled(f), self.loss, self.machine, time_scale,
                           (*self.sources, f"stretched from time scale {self.time_scale:g} "
                                           f"to {time_scale:g}"),
                           None if self.startup is None else self.startup.scaled(f),
                           round(self.startup_ms * f), self.origin, together=self.together,
                           messages_first=self.messages_first, tie_samples=self.tie_samples,
                           levels=tuple(lv.scaled(f) for lv in self.levels))

    def describe(self) -> str:
        """One line: default latency bounds and mean, channels, lateness, machine, scale."""
        low, high = self.default.bounds
        if self.origin:
            return (f"latency {low}-{high} ms, each value equally likely "
                    f"({len(self.latency)} channel(s) of their own), timers on time: "
                    f"{self.origin}")
        scale = "unknown" if self.time_scale is None else f"{self.time_scale:g}"
        start = "" if self.startup is None else (
            f", {self.startup.bounds[0]}-{self.startup.bounds[1]} ms when sent in the first "
            f"{self.startup_ms} ms")
        shared = "" if not self.together else (
            f"; one publish's deliveries correlated {max(r for _, r in self.together):.2f} "
            f"at most")
        if self.messages_first is not None:
            shared += f"; a message before a timer at one ms {self.messages_first:.2f}"
        if self.levels:
            shared += (f"; {len(self.levels)} load levels by run, mean "
                       + "/".join(f"{lv.mean_ms:.1f}" for lv in self.levels) + " ms, weights "
                       + "/".join(f"{lv.weight:.2f}" for lv in self.levels))
        return (f"latency {low}-{high} ms (mean {self.default.mean:.2f} ms; "
                f"{len(self.latency)} channel(s) of their own{start}{shared}), timer lateness "
                f"{self.timer_lateness.bounds[0]}-{self.timer_lateness.bounds[1]} ms; "
                f"measured on {self.machine or 'an unknown machine'} at time scale {scale}")

    def to_yaml(self) -> dict[str, Any]:
        """The mapping the file format writes."""
        doc: dict[str, Any] = {
            "format": TIMING_FORMAT, "machine": self.machine, "time_scale": self.time_scale,
            "unit": "fleet ms", "sources": list(self.sources),
            "latency": {"default": self.default.to_yaml(),
                        **{name: h.to_yaml() for name, h in self.latency}},
            "timer_lateness": self.timer_lateness.to_yaml()}
        if self.startup is not None:
            doc["startup"] = {"window_ms": self.startup_ms, **self.startup.to_yaml()}
        if self.loss:
            doc["loss"] = dict(self.loss)
        if self.together:
            doc["together"] = dict(self.together)
        if self.messages_first is not None:
            doc["ties"] = {"messages_first": self.messages_first, "samples": self.tie_samples}
        if self.levels:
            doc["levels"] = [lv.to_yaml() for lv in self.levels]
        return doc


def _uniform(span: Range | None) -> Histogram:
    low, high = span or (0, 0)
    n = high - low + 1
    return Histogram(tuple(range(low, high + 1)), (1.0 / n,) * n)


def _span(span: Range | None) -> str:
    low, high = span or (0, 0)
    return f"{low} ms" if low == high else f"{low}-{high} ms"


@final
@dataclass(frozen=True, slots=True)
class AssumedTiming:
    """The timing a verdict assumed: the latency range of every channel (`default`) and of
    those with their own (`channels`), timer lateness, and where the figures come from.
    Every summary states it: a HOLDS under no latency is no HOLDS under 5 ms."""

    default: Range | None
    channels: tuple[tuple[str, Range | None], ...] = ()
    lateness: Range = (0, 0)
    source: str = ""

    def line(self) -> str:
        """``latency 0-2 ms (/vote 1-3 ms), timers 0 ms late; from ...``."""
        own = ", ".join(f"{name} {_span(span)}" for name, span in self.channels)
        return (f"latency {_span(self.default)}" + (f" ({own})" if own else "")
                + f", timers {_span(self.lateness)} late; from {self.source}")

    def to_json(self) -> dict[str, Any]:
        """The JSON record: ranges as [min, max] lists."""
        return {"latency": {"default": list(self.default or (0, 0)),
                            **{name: list(span or (0, 0)) for name, span in self.channels}},
                "timer_lateness": list(self.lateness), "source": self.source}


def save_timing(model: TimingModel, path: str | Path) -> None:
    """Write `model` as YAML, creating parent directories."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(yaml.safe_dump(model.to_yaml(), sort_keys=False, width=100,
                                  default_flow_style=None))


def load_timing(path: str | Path | None) -> TimingModel:
    """Read a timing model file; None reads the loopback model shipped with the package."""
    if path is None:
        text = Path(__file__).with_name(DEFAULT_MODEL).read_text()  # package data beside us
        return parse_timing(yaml.safe_load(text), DEFAULT_MODEL)
    try:
        doc = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise TimingError(f"{path}: cannot read timing model: {exc}") from None
    return parse_timing(doc, str(path))


def default_timing() -> TimingModel:
    """The loopback timing model that ships with the package."""
    return load_timing(None)


def parse_timing(doc: Any, where: str) -> TimingModel:
    """A `TimingModel` from the decoded YAML of file `where` (errors name the key)."""
    if not isinstance(doc, Mapping) or doc.get("format") != TIMING_FORMAT:
        raise TimingError(f"{where}: not a {TIMING_FORMAT} file")
    latency = doc.get("latency") or {}
    if not isinstance(latency, Mapping):
        raise TimingError(f"{where}: latency: expected a mapping of channel to histogram")
    default, per = _latencies(latency, where, "latency")
    lateness = _histogram(doc.get("timer_lateness", {"values": [0], "weights": [1]}), where,
                          "timer_lateness")
    loss = doc.get("loss") or {}
    if not isinstance(loss, Mapping) or not all(
            isinstance(p, int | float) and 0 <= p <= 1 for p in loss.values()):
        raise TimingError(f"{where}: loss: expected a mapping of topic to a probability")
    scale = doc.get("time_scale")
    if scale is not None and not (isinstance(scale, int | float) and scale > 0):
        raise TimingError(f"{where}: time_scale: expected a positive number, got {scale!r}")
    startup, window = _startup(doc.get("startup"), where)
    together = doc.get("together") or {}
    if not isinstance(together, Mapping) or not all(
            isinstance(r, int | float) and 0 <= r < 1 for r in together.values()):
        raise TimingError(f"{where}: together: expected a mapping of channel to a "
                          "correlation in [0, 1)")
    return TimingModel(default, per, lateness,
                       tuple(sorted((str(k), float(v)) for k, v in loss.items())),
                       str(doc.get("machine") or ""), None if scale is None else float(scale),
                       tuple(str(s) for s in doc.get("sources") or ()), startup, window,
                       together=tuple(sorted((str(k), float(v)) for k, v in together.items())),
                       levels=_levels(doc.get("levels"), where), **_ties(doc.get("ties"), where))


def _latencies(latency: Mapping[Any, Any], where: str, key: str
               ) -> tuple[Histogram, tuple[tuple[str, Histogram], ...]]:
    """The default histogram and the per-channel ones of a `latency:` mapping at `key`."""
    per = tuple(sorted((str(k), _histogram(v, where, f"{key}.{k}"))
                       for k, v in latency.items() if k != "default"))
    return _histogram(latency.get("default", {"values": [0], "weights": [1]}), where,
                      f"{key}.default"), per


def _levels(value: Any, where: str) -> tuple[Level, ...]:
    """The load levels of a model file (none: no levels), weights renormalised."""
    if value is None:
        return ()
    if not isinstance(value, list) or not all(
            isinstance(lv, Mapping) and isinstance(lv.get("weight"), int | float)
            and lv["weight"] > 0 and isinstance(lv.get("latency"), Mapping) for lv in value):
        raise TimingError(f"{where}: levels: expected a list of {{weight: > 0, latency: "
                          "{default: histogram, ...}}")
    total = math.fsum(float(lv["weight"]) for lv in value)
    out = []
    for k, lv in enumerate(value):
        default, own = _latencies(lv["latency"], where, f"levels[{k}].latency")
        out.append(Level(float(lv["weight"]) / total, default, own, int(lv.get("runs", 0)),
                         float(lv.get("mean_ms", default.mean))))
    return tuple(out)


def _ties(value: Any, where: str) -> dict[str, Any]:
    """`messages_first` and `tie_samples` of a model file's `ties` (none: neither)."""
    if value is None:
        return {}
    first = value.get("messages_first") if isinstance(value, Mapping) else None
    if not isinstance(first, int | float) or not 0 <= first <= 1:
        raise TimingError(f"{where}: ties.messages_first: expected a probability, got {first!r}")
    return {"messages_first": float(first), "tie_samples": int(value.get("samples", 0))}


def _startup(value: Any, where: str) -> tuple[Histogram | None, int]:
    """The start-up histogram and window of a model file (none: (None, 0))."""
    if value is None:
        return None, 0
    window = value.get("window_ms") if isinstance(value, Mapping) else None
    if not isinstance(window, int) or window < 0:
        raise TimingError(f"{where}: startup.window_ms: expected whole fleet ms >= 0, "
                          f"got {window!r}")
    return _histogram(value, where, "startup"), window


def _histogram(value: Any, where: str, key: str) -> Histogram:
    if not isinstance(value, Mapping):
        raise TimingError(f"{where}: {key}: expected {{values: [...], weights: [...]}}")
    try:
        values = tuple(int(v) for v in value["values"])
        weights = tuple(float(w) for w in value["weights"])
        total = sum(weights)
        if abs(total - 1.0) <= 1e-3:  # the file rounds weights to 6 decimals
            weights = tuple(w / total for w in weights)
        return Histogram(values, weights, int(value.get("samples", 0)))
    except (KeyError, TypeError, ValueError) as exc:
        raise TimingError(f"{where}: {key}: {exc}") from None
