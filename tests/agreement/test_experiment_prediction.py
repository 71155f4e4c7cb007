"""The experiment's prediction: the agreement test, the stretched timing model, simulations
that end when their outcome is known, the table's columns, and finished cases kept."""

from __future__ import annotations

import csv
import io
import math
import random

import pytest

from tests.checker.smc_systems import Coin4
from twinfleet import testing
from twinfleet.checker.estimate import agreement_p_value, binomial_test, clopper_pearson
from twinfleet.checker.properties import PropertySet
from twinfleet.checker.simulate import Simulator
from twinfleet.checker.system import System
from twinfleet.checker.timing import Histogram, TimingModel
from twinfleet.robots.live import LiveRunResult
from twinfleet.robots.paper import paper_row
from twinfleet.robots.resume import FinishedCase, fingerprint, load_case, save_case
from twinfleet.robots.table import (
    CheckCell,
    LiveSummary,
    Prediction,
    Row,
    columns,
    markdown_header,
    to_csv,
    to_markdown,
)

pytestmark = pytest.mark.offline  # starts no fleet, opens no Zenoh session


def _pmf(j: int, n: int, p: float) -> float:
    return math.comb(n, j) * p ** j * (1 - p) ** (n - j)


@pytest.mark.parametrize(("k", "n", "p"), [(3, 10, 0.6), (0, 5, 0.5), (20, 20, 0.9), (7, 30, 0.1)])
def test_binomial_test_sums_the_outcomes_no_more_likely(k, n, p):
    own = _pmf(k, n, p)
    expected = sum(_pmf(j, n, p) for j in range(n + 1) if _pmf(j, n, p) <= own * (1 + 1e-7))
    assert binomial_test(k, n, p) == pytest.approx(min(1.0, expected), rel=1e-9)
    assert binomial_test(2, 4, 0.5) == pytest.approx(1.0)  # the most likely outcome of a symmetric case
    assert binomial_test(0, 5, 0.0) == 1.0 and binomial_test(1, 5, 0.0) == 0.0


def test_agreement_is_1_inside_the_interval_and_small_far_outside():
    assert agreement_p_value(3, 10, 0.2, 0.5, 0.99) == 1.0
    assert agreement_p_value(20, 20, 0.0, 0.1, 0.99) < 1e-15 + 0.01
    # Near the interval: the best p in it explains the counts fairly well.
    assert agreement_p_value(6, 10, 0.2, 0.5, 0.99) > 0.3


def test_the_agreement_test_rejects_a_true_model_at_most_at_its_level():
    # A derandomized check: the prediction and the live runs come from the same p.
    rng, rejected, trials = random.Random(4), 0, 400
    for _ in range(trials):
        p = rng.choice((0.05, 0.3, 0.5, 0.8))
        sims = sum(rng.random() < p for _ in range(100))
        live = sum(rng.random() < p for _ in range(20))
        low, high = clopper_pearson(sims, 100, 0.99)
        rejected += agreement_p_value(live, 20, low, high, 0.99) <= 0.05
    assert rejected / trials <= 0.05


def test_a_model_is_stretched_to_the_live_time_scale():
    model = TimingModel(Histogram((1, 2, 3), (0.5, 0.25, 0.25), 40), time_scale=1.0)
    fast = model.at_time_scale(2.0)
    assert fast.default.values == (2, 4, 6) and fast.default.weights == (0.5, 0.25, 0.25)
    assert fast.time_scale == 2.0 and fast.default.mean == pytest.approx(2 * model.default.mean)
    assert "stretched from time scale 1 to 2" in fast.sources[-1]
    pooled = model.at_time_scale(0.4).default  # 0.4, 0.8, 1.2 ms round to 0, 1, 1
    assert pooled.values == (0, 1) and pooled.weights == pytest.approx((0.5, 0.5))
    assert model.at_time_scale(1.0) is model
    assert TimingModel().at_time_scale(3.0) == TimingModel()  # scale unknown: as it is


def test_a_simulation_until_decided_ends_at_its_outcome():
    scenario = testing.system({"c": Coin4}, [testing.invariant("ok", "c.pick != 3"),
                                             testing.eventually("picked", "c.pick >= 0")])
    props = PropertySet.from_scenario(scenario)
    system = System(scenario, properties=props)
    model = TimingModel()
    sim = Simulator(system, props, model, seed=1, horizon_ms=1000, max_steps=100,
                    until_decided=True)
    runs = [sim.run(i) for i in range(40)]
    assert {r.ended for r in runs} == {"decided"}
    assert {r.violated for r in runs} == {(), ("ok",)}
    whole = Simulator(system, props, model, seed=1, horizon_ms=1000, max_steps=100)
    assert [r.violated for r in runs] == [whole.run(i).violated for i in range(40)]


def _prediction() -> Prediction:
    low, high = clopper_pearson(37, 100, 0.99)
    return Prediction(37, 100, low, high, 0.99, 12.5, "out/traces/c2a.sim0.trace.json")


def _row() -> Row:
    row = Row("c2a", "launch/c2a.yaml", "fixed", 140, (("r1", 0.9, 1500),),
              paper=paper_row("c2a"), prediction=_prediction())
    row.checks["ros"] = CheckCell("ros", "violated", "no_collision", 3074, 6602, 6603, 1.0,
                                  "t.json")
    row.live = LiveSummary(5, 2.0)
    for k in range(5):
        row.live.add(passed=k < 2, collision=k >= 2, all_arrived=k < 2, node_failed=False,
                     wall_s=20.0)
    return row


def test_the_table_shows_the_prediction_beside_the_live_counts():
    row = _row()
    head = markdown_header(("ros",))
    cells = to_markdown([row], ("ros",)).splitlines()[2].split(" | ")
    at = head.index("predicted P(pass) [interval]")
    assert cells[at] == "0.37 [0.25, 0.50] (100 sim.)"
    assert cells[at + 1] == "2/5 passed, 3/5 failed" and cells[at + 2] == "1"
    (record,) = csv.DictReader(io.StringIO(to_csv([row], ("ros",))))
    assert list(record) == columns(("ros",))
    assert record["predicted_pass"] == "0.3700" and record["predicted_simulations"] == "100"
    assert record["agreement_p"] == "1"
    row.live = LiveSummary(20, 2.0)
    for _ in range(20):
        row.live.add(passed=True, collision=False, all_arrived=True, node_failed=False,
                     wall_s=1.0)
    assert row.agreement_p is not None and row.agreement_p < 0.02  # 20/20 against 0.25-0.50


def test_a_finished_case_is_kept_under_its_fingerprint(tmp_path):
    scenario = tmp_path / "c2a.yaml"
    scenario.write_text("name: c2a\n")
    key = fingerprint(scenario, {"runs": 5})
    run = LiveRunResult(3, 2.0, "collision", 9.5, (), [("r1", "r2", 4100)], {"r1": False},
                        {"r1": 10}, {"r1": None}, ("r2",))
    done = FinishedCase(_row(), [run], {"r1": 5000}, [("c2a", 3, "node r1: exit code -9")])
    save_case(tmp_path, key, done)
    back = load_case(tmp_path, "c2a", key)
    assert back is not None
    assert back.row == done.row and back.runs == [run] and back.retried == done.retried
    assert back.predicted_arrival_ms == {"r1": 5000}
    assert load_case(tmp_path, "c2a", fingerprint(scenario, {"runs": 6})) is None
    scenario.write_text("name: c2a\nseed: 2\n")
    assert load_case(tmp_path, "c2a", fingerprint(scenario, {"runs": 5})) is None
    assert load_case(tmp_path, "c1a", key) is None
    (tmp_path / "cases" / "c2a.json").write_text("{not json")
    assert load_case(tmp_path, "c2a", key) is None
