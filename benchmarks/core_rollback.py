"""Cost of live rollback: NodeCore handler runs with and without the state copy.

A handler that raises leaves `self.state` as before it ran, live as in the
checker (twinfleet/runtime/core/node_core.py, 6): the core keeps the snapshot of the state after
the last handler that went well, one `pickle.dumps` per handler.
This measures what that costs per message, in one process, no I/O: a sample
goes in through the core's receiver, `run_next` runs the handler. Modes,
interleaved over `--runs` rounds in the same run:

* ``rollback`` — the shipped `NodeCore`;
* ``baseline`` — the same core with the copy taken out (what it did before).

States: a small counter node, and the C1a map server's and a robot's own
initial states (real node classes, their handler replaced by a counter bump,
so the figure is the per-message floor a larger state raises). Prints one JSON
line per measurement, then a summary of medians with the ratio to baseline.

    python benchmarks/core_rollback.py [--count 20000] [--runs 5]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from twinfleet import Context, Node, subscribe  # noqa: E402
from twinfleet.runtime.contract.dispatch import HandlerError  # noqa: E402
from twinfleet.runtime.contract.messages import String, encode  # noqa: E402
from twinfleet.runtime.core.node_core import NodeCore  # noqa: E402
from twinfleet.runtime.scenario.spec import load_scenario  # noqa: E402


class Sink(Node):
    """Counts /in messages in whatever state `make` gives it."""

    make: Any = int

    def initial_state(self) -> Any:
        return type(self).make()

    @subscribe("/in")
    def on_in(self, ctx: Context, msg: String) -> None:
        self.state = self.state  # a handler that goes well; its state is copied anyway


class NoRollback(NodeCore):
    """The core without the per-handler copy (the behaviour before rollback)."""

    def _keep_or_roll_back(self, method: str, error: HandlerError | None,
                           ctx: Context) -> HandlerError | None:
        return error


def states() -> dict[str, Any]:
    scenario = load_scenario("c1a")
    found = {"counter": int}
    for cfg in scenario.nodes[:2]:
        state = cfg.instantiate().state
        found[cfg.name] = lambda state=state: state
    return found


def measure(core_class: type[NodeCore], make: Any, count: int) -> float:
    """Messages per second through receive + run_next."""
    sink = type("S", (Sink,), {"make": staticmethod(make)})("sink")
    core = core_class(sink, seed=1)
    core.start(0)
    receive = core.receiver("on_in")
    payloads = [encode(String("x"), stamp_ms=0, seq=i + 1, sender="p") for i in range(count)]
    core._saved = b""  # type: ignore[attr-defined]  # both modes skip the first copy
    started = time.perf_counter()
    for i, payload in enumerate(payloads):
        receive(payload, i)
        core.run_next(i)
    return count / (time.perf_counter() - started)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--count", type=int, default=20_000, help="messages per measurement")
    p.add_argument("--runs", type=int, default=5, help="interleaved rounds per mode and state")
    args = p.parse_args()
    rates: dict[tuple[str, str], list[float]] = {}
    for _ in range(args.runs):
        for name, make in states().items():
            for mode, cls in (("baseline", NoRollback), ("rollback", NodeCore)):
                rate = measure(cls, make, args.count)
                rates.setdefault((name, mode), []).append(rate)
                print(json.dumps({"state": name, "mode": mode, "msgs_per_s": round(rate)}))
    summary = {}
    for name in states():
        base = statistics.median(rates[(name, "baseline")])
        roll = statistics.median(rates[(name, "rollback")])
        summary[name] = {"baseline_msgs_per_s": round(base), "rollback_msgs_per_s": round(roll),
                         "rollback_vs_baseline": round(roll / base, 3),
                         "us_per_msg_added": round(1e6 / roll - 1e6 / base, 2)}
    print(json.dumps({"summary": summary}, indent=1))


if __name__ == "__main__":
    main()
