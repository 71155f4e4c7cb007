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
"""


from __future__ import annotations

import json
import platform
from collections import defaultdict
from collections.abc import Iterable, Sequence
from pathlib import Path

from twinfleet.checker.timing import Histogram, TimingError, TimingModel
from twinfleet.runtime.contract.kinds import EventKind
from twinfleet.runtime.core.eventlog import EVENTS_FORMAT

_MESSAGES = {str(EventKind.DELIVERY), str(EventKind.REQUEST), str(EventKind.REPLY)}
_TIMED = {str(EventKind.TIMER), str(EventKind.PERIODIC)}
STARTUP_MS = 20  # fleet ms: at time scale 2, the first scans and path requests of a fleet
STARTUP_MIN_SAMPLES = 5  # fewer start-up latencies than this: no start-up histogram


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


def calibrate(paths: Sequence[str | Path], *, min_samples: int = 30,
              startup_ms: int = STARTUP_MS) -> TimingModel:
    """Fit a `TimingModel` from event logs (module docstring)."""
    if not paths:
        raise TimingError("calibrate: give at least one event log")
    latency: defaultdict[str, list[int]] = defaultdict(list)
    startup: list[int] = []
    lateness: list[int] = []
    scales: set[float] = set()
    for name in paths:
        path = Path(name)
        headers = 0
        for r in _records(path):
            kind = r.get("kind")
            if r.get("format") == EVENTS_FORMAT:
                headers += 1
                if isinstance(r.get("time_scale"), int | float):
                    scales.add(float(r["time_scale"]))  # type: ignore[arg-type]
                continue
            t = r.get("t")
            if not isinstance(t, int):
                continue
            stamp = r.get("stamp")
            if kind in _MESSAGES and isinstance(stamp, int) and r.get("topic"):
                (startup if stamp < startup_ms else latency[str(r["topic"])]).append(t - stamp)
            elif kind in _TIMED and isinstance(r.get("due"), int):
                lateness.append(t - int(r["due"]))  # type: ignore[call-overload]
        if not headers:
            raise TimingError(f"{path}: not a {EVENTS_FORMAT} event log (no header)")
    if len(scales) > 1:
        raise TimingError(f"calibrate: the logs were recorded at different time scales "
                          f"({', '.join(f'{s:g}' for s in sorted(scales))}); fit each apart")
    pooled = [x for samples in latency.values() for x in samples]
    if not pooled and startup:  # every stamped message fell in the start-up window
        raise TimingError(f"calibrate: all {len(startup)} handled messages with a send stamp "
                          f"were sent in the first {startup_ms} fleet ms, which --startup-ms "
                          f"{startup_ms} sets apart as start-up: a protocol that ends that "
                          "early needs a smaller --startup-ms (0: none)")
    if not pooled:
        raise TimingError("calibrate: the logs hold no handled message with a send stamp")
    own = tuple((name, Histogram.fit(samples)) for name, samples in sorted(latency.items())
                if len(samples) >= min_samples)
    start = Histogram.fit(startup) if len(startup) >= STARTUP_MIN_SAMPLES else None
    return TimingModel(Histogram.fit(pooled), own, Histogram.fit(lateness), (),
                       machine(), scales.pop() if scales else None,
                       tuple(str(p) for p in paths), start, startup_ms if start else 0)
