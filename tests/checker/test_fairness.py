"""Weak fairness (`check --fairness weak`, `check.fairness`): a retry loop over a lossy
channel holds under it, a real livelock does not, and without it both have a lasso."""

from __future__ import annotations

import json

import pytest

from tests.checker.helpers import replay_confirms, run, scenario
from twinfleet.checker.commands import main

pytestmark = pytest.mark.timeout(120)

L = "tests.checker.liveness_models:"
DONE = [{"name": "done", "kind": "eventually", "expr": "sender.done"}]


def _retry(tmp_path, *, wanted=1, name="retry", **check):
    nodes = [{"name": "sender", "class": L + "Retrier"},
             {"name": "receiver", "class": L + "Acker", "params": {"wanted": wanted}}]
    return scenario(tmp_path, nodes, properties=DONE, name=name,
                    faults={"drop": ["/req"]}, **check)


def _calls(tmp_path):
    nodes = [{"name": "sender", "class": L + "CallRetrier"}, {"name": "adder", "class": L + "Adder"}]
    return scenario(tmp_path, nodes, properties=DONE, name="calls",
                    faults={"drop": ["/add_two"]})


def test_retry_loop_is_a_lasso_without_fairness(tmp_path):
    result = run(_retry(tmp_path))
    assert result.status == "violated"
    assert result.violation.shape == "lasso"
    assert result.fairness == "none"
    assert any("fairness none" in p for p in result.properties)
    # the cycle is the retry whose /req is lost every time
    assert any("dropped" in f for s in result.trace["steps"] for f in s.get("faults", []))
    assert replay_confirms(result)


def test_retry_loop_holds_under_weak_fairness(tmp_path):
    result = run(_retry(tmp_path), fairness="weak")
    assert result.status == "holds", result.reason
    assert any("fairness weak" in p for p in result.properties)
    assert result.to_json()["fairness"] == "weak"


def test_scenario_key_asks_for_weak_fairness(tmp_path):
    assert run(_retry(tmp_path, fairness="weak")).status == "holds"
    # the option wins over the scenario
    assert run(_retry(tmp_path, fairness="weak"), fairness="none").status == "violated"


def test_lost_service_requests_hold_under_weak_fairness(tmp_path):
    path = _calls(tmp_path)
    plain = run(path)
    assert plain.status == "violated" and plain.violation.shape == "lasso"
    assert run(path, fairness="weak").status == "holds"


def test_keep_last_drops_count_as_drops(tmp_path):
    # KEEP_LAST (depth 1) may throw /m 1 away every period while /m 2 waits behind it
    nodes = [{"name": "pub", "class": L + "Pair"}, {"name": "sub", "class": L + "KeepLast"}]
    path = scenario(tmp_path, nodes, name="keeplast", properties=[
        {"name": "first", "kind": "eventually", "expr": "sub.got_first"}])
    plain = run(path)
    assert plain.status == "violated" and plain.violation.shape == "lasso"
    assert any("KEEP_LAST" in f for s in plain.trace["steps"] for f in s.get("faults", []))
    assert run(path, fairness="weak").status == "holds"


def test_real_livelock_is_violated_under_weak_fairness(tmp_path):
    # the receiver handles every /req it gets but never acks one: a fair cycle
    result = run(_retry(tmp_path, wanted=2, name="livelock"), fairness="weak")
    assert result.status == "violated"
    assert result.violation.shape == "lasso"
    assert "weak fairness" in result.violation.message
    steps = result.trace["steps"]
    start = result.trace["cycle_start"]
    cycle = steps[start:]
    # the cycle hands the request to the receiver at least once
    assert any(s["node"] == "receiver" for s in cycle)
    assert replay_confirms(result)


def test_cli_flag_and_summary(tmp_path, capsys):
    path = _retry(tmp_path)
    argv = ["check", str(path), "--reduction", "none", "--quiet",
            "--trace-out", str(tmp_path / "t.json")]
    assert main(argv) == 1
    assert "fairness none" in capsys.readouterr().out
    assert main([*argv, "--fairness", "weak", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["fairness"] == "weak"
    with pytest.raises(SystemExit) as exc:
        main([*argv, "--fairness", "strong"])
    assert exc.value.code == 2


def test_bad_scenario_value_is_refused(tmp_path):
    from twinfleet.runtime.scenario.spec import ScenarioError

    with pytest.raises(ScenarioError, match="check.fairness: expected one of none, weak"):
        run(_retry(tmp_path, fairness="sometimes"))


def _edge(source, target, dropped=(), handled=()):
    from twinfleet.checker.fairness import _Edge
    from twinfleet.checker.transition import Step

    return _Edge(source, target, Step(None, (source, target)), frozenset(dropped),
                 frozenset(handled))


def test_starved_steps_are_removed_and_the_rest_searched_again():
    from twinfleet.checker.fairness import _cycle, _fair_part

    # 0 -> 0 loses m for ever; 0 -> 1 -> 0 loses n but handles it on 1 -> 0: only the
    # second loop is fair, and the walk built from 0 handles everything it drops
    edges = [_edge(0, 0, dropped={b"m"}), _edge(0, 1, dropped={b"n"}),
             _edge(1, 0, handled={b"n"})]
    fair = _fair_part(edges)
    assert fair is not None and edges[0] not in fair
    walk = _cycle(0, fair)
    assert [(e.source, e.target) for e in walk] == [(0, 1), (1, 0)]
    # nothing handles m anywhere: no fair cycle
    assert _fair_part([_edge(0, 0, dropped={b"m"}), _edge(0, 1, dropped={b"m"}),
                       _edge(1, 0)]) is None


def test_the_cycle_takes_a_detour_to_handle_what_it_drops():
    from twinfleet.checker.fairness import _cycle

    # the cheapest loop 0 -> 1 -> 0 drops m; only 2 -> 0 handles it
    edges = [_edge(0, 1, dropped={b"m"}), _edge(1, 0), _edge(1, 2), _edge(2, 0, handled={b"m"})]
    walk = _cycle(0, edges)
    assert walk[0].source == 0 and walk[-1].target == 0
    assert all(a.target == b.source for a, b in zip(walk, walk[1:], strict=False))
    assert any(b"m" in e.handled for e in walk)


def test_the_check_options_of_every_command_carry_fairness():
    # check, sweep and experiment declare their options in one function
    import argparse

    from twinfleet.checker.options import SearchChoices, add_check_arguments
    from twinfleet.runtime.scenario.config import Fairness

    parser = argparse.ArgumentParser()
    add_check_arguments(parser)
    weak = SearchChoices.of(parser.parse_args(["--fairness", "weak"]))
    assert weak.fairness is Fairness.WEAK and weak.fields()["fairness"] is Fairness.WEAK
    # not given: not in the fields, so a sweep's cache keys of earlier runs stay the same
    assert "fairness" not in SearchChoices.of(parser.parse_args([])).fields()
