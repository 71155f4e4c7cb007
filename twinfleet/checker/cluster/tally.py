"""What a distributed search has counted so far: the summary's and the progress line's figures."""

from __future__ import annotations

from dataclasses import dataclass
from typing import final

from twinfleet.checker.cluster.backend import Traffic
from twinfleet.checker.cluster.flow import FlowStatus
from twinfleet.checker.cluster.level import Acceptance, Expansion
from twinfleet.checker.outcome import SearchStatistics, peak_rss_mb


@final
@dataclass
class Tally:
    """The coordinator's counters of one search (a restarted reduced search starts a new one)."""

    states: int = 0
    transitions: int = 0
    initial: int = 0
    depth: int = 0
    frontier: int = 0
    peak_frontier: int = 0
    level: int = 0

    def add_level(self, expansions: list[Expansion], acceptances: list[Acceptance],
                  traffic: Traffic, remote: bool) -> None:
        """Count one level: its transitions, the new worlds each worker kept, the frontier."""
        traffic.levels += 1
        self.level += 1
        traffic.claims += sum(e.claims for e in expansions) if remote else 0
        if len(traffic.new_per_worker) < len(acceptances):
            traffic.new_per_worker = [0] * len(acceptances)
        if remote:
            traffic.handler_runs = [a.handler_runs for a in acceptances]
        self.transitions += sum(e.transitions for e in expansions)
        for i, a in enumerate(acceptances):
            self.states += a.new
            traffic.new_per_worker[i] += a.new
            self.depth = max(self.depth, a.depth)
        self.frontier = sum(a.frontier for a in acceptances)
        self.peak_frontier = max(self.peak_frontier, self.frontier)

    def add_flow(self, statuses: list[FlowStatus], before: tuple[int, int],
                 traffic: Traffic) -> None:
        """Count what the relaxed order's workers did since they took over (at `before`:
        the states and transitions counted then)."""
        self.states = before[0] + sum(s.new for s in statuses)
        self.transitions = before[1] + sum(s.transitions for s in statuses)
        self.depth = max(self.depth, *(s.depth for s in statuses))
        self.frontier = sum(s.queue for s in statuses)
        self.peak_frontier = max(self.peak_frontier, self.frontier)
        traffic.claims = sum(s.claims for s in statuses)
        traffic.new_per_worker = [s.new for s in statuses]
        traffic.stolen = sum(s.gifted for s in statuses)
        traffic.moves = sum(s.gifts for s in statuses)
        traffic.handler_runs = [s.handler_runs for s in statuses]

    def statistics(self, elapsed: float, shard_bytes: list[int],
                   attempt_s: float | None) -> SearchStatistics:
        """The counters as a search's statistics (64-bit keys: the collision bound)."""
        n = self.states
        return SearchStatistics(n, self.transitions, self.initial, self.depth, self.frontier,
                                elapsed, peak_rss_mb(), sum(shard_bytes), 64,
                                min(1.0, n * n / 2.0**65), self.peak_frontier, attempt_s)

    def progress_line(self, where: str, traffic: Traffic, shard_bytes: list[int],
                      elapsed: float) -> str:
        """The progress line (rates over `elapsed`, which includes a resumed search's runs)."""
        per = "/".join(f"{n / max(elapsed, 1e-9):,.0f}" for n in traffic.new_per_worker)
        mem = "/".join(f"{b / 2**20:.0f}" for b in shard_bytes)
        return (f"[check] {where}  states {self.states:,}  "
                f"transitions {self.transitions:,}  states/s per worker {per}  "
                f"depth {self.depth}  frontier {self.frontier:,}  shard memory {mem} MB  "
                f"{elapsed:.0f} s")
