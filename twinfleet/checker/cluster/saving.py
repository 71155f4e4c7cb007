"""What a distributed search's checkpoint records besides its worlds, and reading it back.

The coordinator saves between two levels, when the search is consistent: the visited
keys of every partition, every worker's frontier (`checker.checkpoint`), and the counters
below. Any number of workers continues it, this process included.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from twinfleet.checker.cluster.backend import Traffic
from twinfleet.checker.cluster.level import Expander, Learned, unpack
from twinfleet.checker.cluster.tally import Tally
from twinfleet.checker.reduction import Reduction, ReductionStatistics


def counters(tally: Tally, traffic: Traffic, roots: Mapping[int, tuple[int, ...]],
             distributed_at: int | None, elapsed: float,
             reduction: Reduction | None) -> dict[str, Any]:
    """The counters of a checkpoint (the frontier's width is the saved frontier's own)."""
    counted = dataclasses.asdict(tally)
    del counted["frontier"]
    return {**counted, "distributed_at": distributed_at, "elapsed": elapsed, "roots": roots,
            "traffic": dataclasses.asdict(traffic),
            "publications": None if reduction is None else reduction.learned_state(),
            "reduction": None if reduction is None else reduction.statistics(),
            "relied": [] if reduction is None else sorted(reduction.relied)}


def restored_tally(c: Mapping[str, Any]) -> Tally:
    """The counters `counters` wrote, as a tally (its frontier set once the frontier is in)."""
    return Tally(**{f.name: c[f.name] for f in dataclasses.fields(Tally) if f.name != "frontier"})


def relearn(reduction: Reduction | None, c: Mapping[str, Any]) -> None:
    """Give `reduction` the send relation and the counters a checkpoint recorded."""
    if reduction is None or c.get("publications") is None:
        return
    reduction.relearn(c["publications"])
    reduction.stats = ReductionStatistics(**c["reduction"])
    reduction.visibility.rises = reduction.stats.rises
    reduction.relied = set(c.get("relied", ()))


def take_frontier(expander: Expander, blobs: list[bytes]) -> None:
    """Add a checkpoint's frontier blobs (and the graph they carry) to `expander`."""
    for blob in blobs:
        frontier, graph = unpack(blob)
        expander.frontier += frontier
        if graph is not None and expander.graph is not None:
            expander.graph.extend(graph)


def add_learned_counts(reduction: Reduction | None, learned: list[Learned]) -> None:
    """Add the workers' reduction counters to this process's (the summary's)."""
    if reduction is None:
        return
    stats = reduction.stats
    for found in learned:
        counted = dict(found.counted)
        reduction.visibility.rises += counted.pop("rises", 0)
        for name, value in counted.items():
            setattr(stats, name, getattr(stats, name) + value)
        reduction.relied |= found.relied
