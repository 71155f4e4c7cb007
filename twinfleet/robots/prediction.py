"""The experiment's prediction: P(a live run passes), from simulations under a timing model.

`predict` runs `twinfleet check --statistical` on a scenario with the `ros`
message rules (Zenoh's per-sender FIFO, what the live fleet has), the timing
model stretched to the live runs' time scale (`TimingModel.at_time_scale`: a
wall delay of d ms is d * K fleet ms at scale K), the live runs' horizon, and
each simulation ending once its outcome is known, as a live run does
(`until_decided`). A simulation passes when it violates no property: no
collision, every robot arrived within the horizon, no handler failure (and
any other property of the scenario — a robot past its failure limit gives up
and does not arrive, which a live run counts as a failure too).

`Prediction.agreement_p` (in `robots.table`) holds the live k/N against
the predicted interval (`checker.estimate.agreement_p_value`): 1 when k/N
lies inside it, small when the counts and the prediction disagree.
"""

from __future__ import annotations

import time
from pathlib import Path

from twinfleet.checker.options import Semantics
from twinfleet.checker.statistical import StatisticalOptions, check_statistical
from twinfleet.checker.timing import load_timing, save_timing
from twinfleet.robots.table import Prediction


def predict(scenario: str | Path, *, timing: str | None, time_scale: float, simulations: int,
            seed: int | None, horizon_s: float, confidence: float, workers: int,
            out: Path) -> Prediction:
    """Estimate P(pass) of a live run of `scenario` (module docstring). The model used is
    written to `out/timing.yaml`, violating traces to `out/traces/`."""
    model = load_timing(timing).at_time_scale(time_scale)
    used = out / "timing.yaml"
    save_timing(model, used)
    start = time.perf_counter()
    result = check_statistical(scenario, StatisticalOptions(
        simulations=simulations, seed=seed, horizon_ms=int(horizon_s * 1000),
        confidence=confidence, workers=workers, timing=str(used),
        traces_out=str(out / "traces"), max_traces=1, verify=False,
        semantics=Semantics.ROS, until_decided=True))
    elapsed = time.perf_counter() - start
    fails = result.estimates()[-1]  # "any property"
    n = fails.n
    return Prediction(n - fails.violations, n, 1.0 - fails.high, 1.0 - fails.low, confidence,
                      elapsed, result.traces[0] if result.traces else None)
