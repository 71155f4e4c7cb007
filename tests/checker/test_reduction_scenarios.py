"""Every shipped scenario under both semantics: the verdict with the partial-order
reduction equals the verdict without (docs/reduction.md).

Slow (about two minutes on the 2-core VM): each scenario is searched twice. Under
`rebeca` the paper cases set node-instance priorities (Rule 4), which the
reduction does not cover: there it must say it turned itself off, and a
second, identical search would prove nothing. `demo` is left out: its talker counts
for ever, so its state space is infinite and neither search has a verdict to compare.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from twinfleet.checker.driver import CheckOptions, check

LAUNCH = Path(__file__).resolve().parents[2] / "twinfleet" / "launch"
INFINITE = {"demo"}  # no verdict either way (see the module docstring)
SCENARIOS = sorted(p for p in LAUNCH.glob("*.yaml") if p.stem not in INFINITE)

pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]


@pytest.mark.parametrize("semantics", ["ros", "rebeca"])
@pytest.mark.parametrize("path", SCENARIOS, ids=[p.stem for p in SCENARIOS])
def test_reduced_verdict_equals_unreduced(tmp_path, path, semantics):
    def run(reduction, **limits):
        return check(path, CheckOptions(semantics=semantics, reduction=reduction,
                                        trace_out=str(tmp_path / f"{reduction}.json"),
                                        reduce_from=0, **limits))

    # whether the reduction runs is decided before the search: one state tells
    planned = run("por", max_states=1).reduction
    if planned.startswith("none"):
        assert semantics == "rebeca"
        assert planned == "none (node-instance priorities under rebeca (Rule 4))"
        return
    reduced = run("por")
    full = run("none")
    assert reduced.status == full.status, (reduced.summary(), full.summary())
    if full.status == "holds":
        assert reduced.statistics.states <= full.statistics.states
    else:
        assert reduced.violation is not None and full.violation is not None
