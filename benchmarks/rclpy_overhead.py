"""What rclpy costs the checker: one system written twice, checked alternately.

tests/rclpy/programs/turtle_system.py (plain rclpy: Node, timers, a subscription, a
service, a client with a done callback, parameters) and turtle_native.py (the same
behaviour with twinfleet's own node API) are checked with the same properties and a
latency range of [0, LATENCY] ms on every message, so that the state space is
large enough to time. Both must reach the same number of states and transitions; the
script prints each run's search time (wall) and the CPU time of the check (this
process's, which other load on a shared machine disturbs less), the median of each and
their ratios (rclpy over native), and the ratios' spread over the rounds (the runs
alternate, so a load that comes and goes on the machine hits both alike).

    PYTHONPATH=. python benchmarks/rclpy_overhead.py [--goal 8] [--latency 2] [--rounds 5]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PROGRAMS = ROOT / "tests" / "rclpy" / "programs"
sys.path.insert(0, str(ROOT))
sys.path.append(str(PROGRAMS))

from twinfleet import testing  # noqa: E402
from twinfleet.runtime.scenario.spec import Scenario  # noqa: E402


def system(module: str, goal: int, latency: int) -> Scenario:
    """The turtle system of `module` (turtle_system or turtle_native)."""
    return testing.system(
        {"turtle": f"{module}:Turtle",
         "controller": (f"{module}:Controller", {"goal": goal, "step": 1}),
         "monitor": f"{module}:Monitor"},
        [testing.invariant("within_goal", "monitor.farthest <= controller.goal"),
         testing.eventually("two_laps", "controller.laps == 2")],
        name=f"{module}_bench", check={"latency": [0, latency]})


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--goal", type=int, default=8, help="the controller's goal (default 8)")
    parser.add_argument("--latency", type=int, default=2,
                        help="every message's latency range is [0, LATENCY] ms (default 2)")
    parser.add_argument("--rounds", type=int, default=5, help="rounds of both (default 5)")
    args = parser.parse_args()
    systems = {name: system(module, args.goal, args.latency)
               for name, module in (("rclpy", "turtle_system"), ("native", "turtle_native"))}
    times: dict[str, list[float]] = {name: [] for name in systems}
    cpu: dict[str, list[float]] = {name: [] for name in systems}
    counts: dict[str, tuple[int, int]] = {}
    for scenario in systems.values():  # warm-up: imports, interface classes
        testing.check(scenario)
    for r in range(args.rounds):
        for name, scenario in (systems.items() if r % 2 == 0 else reversed(systems.items())):
            started = time.process_time()
            report = testing.check(scenario)
            cpu[name].append(time.process_time() - started)
            assert report.holds, report.explain()
            counts[name] = (report.states, report.transitions)
            times[name].append(report.elapsed_s)
            print(f"round {r + 1} {name:6}: {report.states:,} states, "
                  f"{report.transitions:,} transitions, {report.elapsed_s:.3f} s "
                  f"(CPU {cpu[name][-1]:.3f} s)", flush=True)
    if counts["rclpy"] != counts["native"]:
        print(f"state counts differ: {counts}")
        return 1
    print(f"same counts: {counts['rclpy'][0]:,} states, {counts['rclpy'][1]:,} transitions")
    for what, values in (("search time", times), ("CPU time", cpu)):
        ratios = [a / b for a, b in zip(values["rclpy"], values["native"], strict=True)]
        rclpy, native = statistics.median(values["rclpy"]), statistics.median(values["native"])
        print(f"median {what}: rclpy {rclpy:.3f} s, native {native:.3f} s; ratio "
              f"{rclpy / native:.2f} (per round {min(ratios):.2f}..{max(ratios):.2f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
