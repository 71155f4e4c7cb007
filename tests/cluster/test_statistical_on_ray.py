"""Statistical checking on Ray tasks answers what it answers in this process.

`check --statistical --cluster local --workers 2` sends the simulations to a
Ray cluster the command starts (`checker.cluster.engine.RayEngine`); with the
same seed, the estimates and each simulation's outcome are those of one
process.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.checker.test_statistical import _scenario
from twinfleet.checker.statistical import StatisticalOptions, check_statistical

pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]


def test_simulations_on_ray_tasks_give_the_estimates_of_one_process(tmp_path: Path) -> None:
    path = _scenario(tmp_path)
    timing = str(tmp_path / "timing.yaml")
    here, on_ray = (check_statistical(path, StatisticalOptions(
        simulations=120, seed=11, workers=workers, cluster=cluster, timing=timing,
        traces_out=str(tmp_path / f"out-{cluster}"))) for workers, cluster in
        ((1, None), (2, "local")))
    assert on_ray.estimates() == here.estimates()
    assert [s.violated for s in on_ray.simulations] == [s.violated for s in here.simulations]
    assert len(on_ray.simulations) == 120
