"""`twinfleet calibrate`: a timing model fitted from live event logs.

An event log (`twinfleet launch --record-events`, format `twinfleet-events/2`)
holds, for every message a node handled, the sender's fleet ms when it sent
it (``stamp``) and the receiver's fleet ms when its handler ran (``t``): their
difference is the message's delivery latency as the checker counts it (the
wire and the wait in the receiver's queue). Timers and ticks carry ``due``:
``t - due`` is how late they ran. Each channel (topic or service) with at
least `min_samples` latencies gets a histogram of its own; the default
histogram pools every channel. Messages sent in the fleet's first
`startup_ms` fleet ms are fitted apart, into the start-up histogram (they take
several times longer; `checker.timing`). The logs' time scale is recorded, and
must be the same in every file: fleet ms at another scale are another clock.

The deliveries of one publish (same file, sender, topic and sequence number,
handled by several receivers) give `together`: per channel with at least
`TOGETHER_MIN_PUBLISHES` such publishes (and pooled as "default"), the
intraclass correlation of their latencies' normal scores (each latency mapped
through its channel's mid-rank empirical CDF and the inverse normal CDF), the
parameter of the Gaussian copula `checker.sampling` draws them through.

With `levels` K > 1, each event log counts as one run (`launch --runs N
--record-events` writes one per run): the runs, sorted by the mean of their
latencies (start-up ones apart), are cut into K groups of as nearly equal size
as can be, each a `Level` weighted by its share of the runs, with its own default
histogram and one of each channel the model gives a histogram of its own (the
group's latencies on that channel; where the group has none, the pooled one is
kept). K at least the number of runs makes each run a level of its own.

Ties give `messages_first`: of every pair of a timer (or tick) and a message
handled by one node at the timer's due ms, the fraction in which the message ran
first (the node's own event order, ``i``); `checker.simulate` breaks such ties
with it.
"""


from __future__ import annotations

import json
import platform
from bisect import bisect_left, bisect_right
from collections import defaultdict
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from statistics import NormalDist
from typing import Any

from twinfleet.checker.timing import Histogram, Level, TimingError, TimingModel
from twinfleet.runtime.contract.kinds import EventKind
from twinfleet.runtime.core.eventlog import EVENTS_FORMAT

_MESSAGES = {str(EventKind.DELIVERY), str(EventKind.REQUEST), str(EventKind.REPLY)}
_TIMED = {str(EventKind.TIMER), str(EventKind.PERIODIC)}
STARTUP_MS = 20  # fleet ms: at time scale 2, the first scans and path requests of a fleet
STARTUP_MIN_SAMPLES = 5  # fewer start-up latencies than this: no start-up histogram
TOGETHER_MIN_PUBLISHES = 10  # fewer publishes of several deliveries: no correlation fitted
_Publish = tuple[str, object, str, object]  # (file, sender, topic, sequence number)


def machine() -> str:
    """This machine, as a timing model records it."""
    import os

    return f"{platform.system()} {platform.machine()}, {os.cpu_count()} cores, {platform.node()}"


def _records(path: Path) -> Iterable[dict[str, object]]:
    try:
        lines = path.read_text().splitlines()
    except OSError as exc:
        raise TimingError(f"{path}: cannot read event log: {exc}") from None
    for n, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            record = json.loads(line)
        except json.JSONDecodeError:
            raise TimingError(f"{path}:{n}: not a JSON line") from None
        if isinstance(record, dict):
            yield record


@dataclass
class _Samples:
    """What the event logs hold for a model, gathered record by record."""

    startup_ms: int
    latency: defaultdict[str, list[int]] = field(default_factory=lambda: defaultdict(list))
    startup: list[int] = field(default_factory=list)
    lateness: list[int] = field(default_factory=list)
    copies: defaultdict[_Publish, list[int]] = field(default_factory=lambda: defaultdict(list))
    #: per (log and node, ms): (the node's event order, whether a message) of what it ran
    at_ms: defaultdict[tuple[str, int], list[tuple[int, bool]]] = field(
        default_factory=lambda: defaultdict(list))
    scales: set[float] = field(default_factory=set)
    #: per log: per channel the latencies of messages sent after start-up
    runs: defaultdict[str, defaultdict[str, list[int]]] = field(
        default_factory=lambda: defaultdict(lambda: defaultdict(list)))

    def read(self, path: Path) -> None:
        """Add one event log's records."""
        headers = 0
        for line, r in enumerate(_records(path)):
            if r.get("format") == EVENTS_FORMAT:
                headers += 1
                if isinstance(r.get("time_scale"), int | float):
                    self.scales.add(float(r["time_scale"]))  # type: ignore[arg-type]
            elif isinstance(r.get("t"), int):
                self._add(f"{path}", line, r)
        if not headers:
            raise TimingError(f"{path}: not a {EVENTS_FORMAT} event log (no header)")

    def _add(self, log: str, line: int, r: dict[str, object]) -> None:
        kind, t, stamp = r.get("kind"), int(r["t"]), r.get("stamp")  # type: ignore[call-overload]
        if kind in _MESSAGES and isinstance(stamp, int) and r.get("topic"):
            topic = str(r["topic"])
            (self.startup if stamp < self.startup_ms else self.latency[topic]).append(t - stamp)
            if stamp >= self.startup_ms:
                self.runs[log][topic].append(t - stamp)
            if kind == str(EventKind.DELIVERY) and stamp >= self.startup_ms:
                self.copies[(log, r.get("sender"), topic, r.get("seq"))].append(t - stamp)
        elif kind in _TIMED and isinstance(r.get("due"), int):
            self.lateness.append(t - int(r["due"]))  # type: ignore[call-overload]
        if kind in _MESSAGES or (kind in _TIMED and r.get("due") == t):
            order = r.get("i")
            self.at_ms[(f"{log}:{r.get('node')}", t)].append(
                (order if isinstance(order, int) else line, kind in _MESSAGES))


def calibrate(paths: Sequence[str | Path], *, min_samples: int = 30,
              startup_ms: int = STARTUP_MS, levels: int = 1) -> TimingModel:
    """Fit a `TimingModel` from event logs (module docstring); `levels` > 1: that many
    load levels, each log one run."""
    if not paths:
        raise TimingError("calibrate: give at least one event log")
    if levels < 1:
        raise TimingError(f"calibrate: levels: expected a whole number >= 1, got {levels}")
    got = _Samples(startup_ms)
    for name in paths:
        got.read(Path(name))
    if len(got.scales) > 1:
        raise TimingError(f"calibrate: the logs were recorded at different time scales "
                          f"({', '.join(f'{s:g}' for s in sorted(got.scales))}); fit each apart")
    pooled = [x for samples in got.latency.values() for x in samples]
    if not pooled and got.startup:  # every stamped message fell in the start-up window
        raise TimingError(f"calibrate: all {len(got.startup)} handled messages with a send "
                          f"stamp were sent in the first {startup_ms} fleet ms, which "
                          f"--startup-ms {startup_ms} sets apart as start-up: a protocol that "
                          "ends that early needs a smaller --startup-ms (0: none)")
    if not pooled:
        raise TimingError("calibrate: the logs hold no handled message with a send stamp")
    own = tuple((name, Histogram.fit(samples)) for name, samples in sorted(got.latency.items())
                if len(samples) >= min_samples)
    start = Histogram.fit(got.startup) if len(got.startup) >= STARTUP_MIN_SAMPLES else None
    return TimingModel(Histogram.fit(pooled), own, Histogram.fit(got.lateness), (),
                       machine(), got.scales.pop() if got.scales else None,
                       tuple(str(p) for p in paths), start, startup_ms if start else 0,
                       together=_together(got.latency, got.copies),
                       levels=_levels(got.runs, levels, [name for name, _ in own]),
                       **_ties(got.at_ms.values()))


def _levels(runs: Mapping[str, Mapping[str, list[int]]], k: int, channels: list[str]
            ) -> tuple[Level, ...]:
    """`k` load levels of the `runs` (module docstring; k <= 1: none)."""
    measured = [lats for lats in runs.values() if any(lats.values())]
    if k <= 1 or len(measured) < 2:
        return ()
    k = min(k, len(measured))

    def mean(lats: Mapping[str, list[int]]) -> float:
        every = [x for xs in lats.values() for x in xs]
        return sum(every) / len(every)

    ordered = sorted(measured, key=mean)
    out = []
    for g in range(k):
        group = ordered[g * len(ordered) // k:(g + 1) * len(ordered) // k]
        every = [x for lats in group for xs in lats.values() for x in xs]
        own = tuple((name, Histogram.fit(found)) for name in channels
                    if (found := [x for lats in group for x in lats.get(name, ())]))
        out.append(Level(len(group) / len(ordered), Histogram.fit(every), own, len(group),
                         round(sum(every) / len(every), 3)))
    return tuple(out)


def _ties(moments: Iterable[list[tuple[int, bool]]]) -> dict[str, Any]:
    """`messages_first`: the fraction of message-before-timer among a node's message/timer
    pairs of one ms, and `tie_samples`: how many pairs (neither when there were none)."""
    first = pairs = 0
    for handled in moments:
        for order, message in handled:
            if message:
                timers = [o for o, m in handled if not m]
                pairs += len(timers)
                first += sum(1 for o in timers if order < o)
    return {"messages_first": round(first / pairs, 3), "tie_samples": pairs} if pairs else {}


def _together(latency: dict[str, list[int]], copies: dict[_Publish, list[int]]
              ) -> tuple[tuple[str, float], ...]:
    """Per channel (and "default", pooled) the correlation of one publish's delivery
    latencies (module docstring); channels with too few such publishes are left out."""
    normal = NormalDist()
    ordered = {name: sorted(samples) for name, samples in latency.items()}

    def score(channel: str, x: int) -> float:
        xs = ordered[channel]
        below, upto = bisect_left(xs, x), bisect_right(xs, x)
        return normal.inv_cdf((below + upto) / (2 * len(xs)))  # x is one of xs: in (0, 1)

    sums: defaultdict[str, list[float]] = defaultdict(lambda: [0.0, 0.0, 0.0])
    for (_, _, channel, _), lats in copies.items():
        if len(lats) < 2:
            continue
        z = [score(channel, x) for x in lats]
        cross = sum(a * b for i, a in enumerate(z) for b in z[i + 1:])
        square = sum(a * a for a in z) * (len(z) - 1) / 2  # as many terms as `cross`
        for key in (channel, "default"):
            acc = sums[key]
            acc[0], acc[1], acc[2] = acc[0] + cross, acc[1] + square, acc[2] + 1
    return tuple(sorted((key, round(min(0.99, max(0.0, cross / square)), 3))
                        for key, (cross, square, n) in sums.items()
                        if n >= TOGETHER_MIN_PUBLISHES and square > 0))
