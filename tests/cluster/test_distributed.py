"""The exhaustive search on Ray workers gives the single process's answers, exactly.

One local Ray cluster (loopback, no dashboard) serves the module; the search
uses a Ray already initialised as it is (`checker.cluster.engine.session`).
For 1, 2 and 3 workers, on shipped scenarios and on generated systems, with
and without the partial-order reduction: the same verdict; when every
property holds the same states, transitions and RMC-style counts; when one
is violated a trace of the same length (a strict BFS) that replays; in a relaxed order
(no `--search bfs`, unreduced) the same states and transitions, and a trace at least
as long that replays. `min_width=1` moves every search to the cluster at once,
so the distributed path is what is compared; each result says so.
"""

from __future__ import annotations

import os
import re
import time
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from tests.checker.helpers import replay_confirms
from tests.checker.program_systems import systems, write_scenario
from twinfleet.checker import CheckOptions, CheckResult, check
from twinfleet.checker.cluster import ClusterError, engine_module
from twinfleet.checker.cluster.spec import SystemSpec
from twinfleet.cli import main as cli

pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]

@pytest.fixture(scope="module", autouse=True)
def engine() -> Any:
    """The engine module, with a local Ray cluster of 3 workers on 127.0.0.1 for the module
    (the search uses a Ray already initialised as it is)."""
    engine = engine_module()
    with engine.session(3, None):
        yield engine


def safety_copy(name: str, where: Path, **check: Any) -> Path:
    """A copy of a shipped scenario with its safety properties only (the tests of the
    lasso search on the gathered graph are below), with `check:` options added."""
    cli(["examples", "--copy", name, str(where)])
    path = where / f"{name}.yaml"
    doc = yaml.safe_load(path.read_text())
    doc["properties"] = [p for p in doc["properties"] if p["kind"] != "eventually"]
    if check:
        doc.setdefault("check", {}).update(check)
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def distributed(path: Path, workers: int, *, beyond_start: bool = True, relaxed: bool = False,
                **options: Any) -> CheckResult:
    """The search on `workers` Ray workers from its first level (a search that ends among
    its initial worlds, `beyond_start` False, never needs them); unreduced unless
    `reduction` is given, then from the first world (`reduce_from` 0: a reduction that waits
    keeps the search here, `checker.late_start`); a strict BFS (`--search bfs`) unless
    `relaxed`."""
    options.setdefault("reduction", "none")
    options.setdefault("reduce_from", 0)
    if not relaxed:
        options.setdefault("search", "bfs")
    result = check(path, CheckOptions(workers=workers, cluster="this", min_width=1, **options))
    order = "relaxed order" if relaxed else "strict BFS"
    want = f"{order} on {workers} Ray worker(s)" if beyond_start else "ran in one process"
    assert result.engine is not None and result.engine.startswith(want), result.engine
    return result


def assert_same_answer(one: CheckResult, many: CheckResult, *, relaxed: bool = False) -> None:
    """Holds: the same counts; violated: the same property and trace length (in a relaxed
    order: a trace at least as long, maybe of another property), replayable."""
    assert many.status == one.status, (one.reason, many.reason)
    if one.violation is None:
        assert (many.statistics.states, many.statistics.transitions, many.rmc_transitions) == \
            (one.statistics.states, one.statistics.transitions, one.rmc_transitions)
        if relaxed:  # a world's depth: the length of the path it was found on
            assert many.statistics.depth >= one.statistics.depth
        else:
            assert many.statistics.depth == one.statistics.depth
    else:
        assert many.violation is not None
        if not relaxed:  # in another order another violated property can come first
            assert many.violation.property == one.violation.property
        if one.trace is not None:
            assert many.trace is not None
            if relaxed:
                assert len(many.trace["steps"]) >= len(one.trace["steps"])
            else:
                assert len(many.trace["steps"]) == len(one.trace["steps"])
            assert replay_confirms(many)


_RESTARTS = re.compile(r"(\d+) restarts?; (learned ahead by [^;]*; )?")


def assert_same_reduction(one: CheckResult, many: CheckResult) -> None:
    """The same reduction summary: worlds reduced, worlds expanded fully, what was learned.
    A search in one process walks its reduced graph on before it restarts, to learn deeper
    sends at once (`Reduction.walk_on`); the distributed search does not, so it may restart
    more often: its restarts are at least as many, the rest of the summary the same."""
    assert one.reduction is not None and many.reduction is not None
    counted = [int(m.group(1)) if (m := _RESTARTS.search(r)) else 0
               for r in (one.reduction, many.reduction)]
    assert counted[1] >= counted[0], (one.reduction, many.reduction)
    assert _RESTARTS.sub("", many.reduction) == _RESTARTS.sub("", one.reduction)


@pytest.mark.parametrize("reduction", ["none", "por"])
@pytest.mark.parametrize("workers", [1, 3])  # 2 workers: the wide searches and C2c below
def test_a_violated_shipped_case_has_a_trace_as_short(tmp_path: Path, workers: int,
                                                      reduction: str) -> None:
    path = safety_copy("headon", tmp_path)
    one = check(path, CheckOptions(reduction=reduction, reduce_from=0))
    many = distributed(path, workers, reduction=reduction)
    assert one.violation is not None and one.trace is not None
    assert_same_answer(one, many)


def test_a_search_smaller_than_the_reductions_wait_stays_here_and_says_why(tmp_path: Path
                                                                           ) -> None:
    # --min-width 1 asks for the workers from the first level, but por decides on a sample
    # of the frontier in this process once 1,000 worlds are stored: head-on ends before.
    path = safety_copy("headon", tmp_path)
    one = check(path, CheckOptions())
    many = check(path, CheckOptions(workers=2, cluster="this", min_width=1))
    assert_same_answer(one, many)
    assert many.engine == ("ran in one process: por waits until 1,000 worlds are stored to "
                           "decide, on a sample of the frontier here, whether to reduce, and "
                           "this search stored fewer")


def test_a_wide_holding_search_has_the_same_counts(tmp_path: Path) -> None:
    # headon with latencies of 0-1 ms and a horizon: a graph whose levels are hundreds of
    # worlds wide, so workers share work (frontier worlds move between them).
    path = safety_copy("headon", tmp_path, latency={"default": [0, 1]})
    one = check(path, CheckOptions(reduction="none", max_depth=40))
    for workers in (2, 3):
        many = distributed(path, workers, max_depth=40)
        assert_same_answer(one, many)
        assert "worlds moved" in (many.engine or "")
    assert one.statistics.states > 1_000


def test_a_wide_reduced_search_has_the_same_counts_and_restarts(tmp_path: Path) -> None:
    # The reduction learns its send relation on every worker; what they learn at a level
    # is merged and the search starts again, as in one process at the end of that level.
    path = safety_copy("headon", tmp_path, latency={"default": [0, 1]})
    one = check(path, CheckOptions(max_depth=80, reduce_from=0))
    assert one.reduction_statistics is not None and one.reduction_statistics["restarts"] >= 1
    for workers in (2, 3):
        many = distributed(path, workers, max_depth=80, reduction="por")
        assert_same_answer(one, many)
        assert_same_reduction(one, many)


def test_a_violated_paper_case_with_two_workers(tmp_path: Path) -> None:
    path = safety_copy("c2c", tmp_path)
    assert_same_answer(check(path, CheckOptions(reduction="none")), distributed(path, 2))


@pytest.mark.parametrize("workers", [1, 3])
def test_a_relaxed_order_keeps_the_counts_of_a_holding_case(tmp_path: Path, workers: int) -> None:
    # C1a unreduced: 41,608 states on a narrow graph (a few worlds a level), its eventually
    # property decided on the graph the workers gathered
    cli(["examples", "--copy", "c1a", str(tmp_path)])
    path = tmp_path / "c1a.yaml"
    one = check(path, CheckOptions(reduction="none"))
    many = distributed(path, workers, relaxed=True)
    assert_same_answer(one, many, relaxed=True)
    assert "lasso search on the graph gathered" in (many.engine or "")


@pytest.mark.parametrize("workers", [2, 3])
def test_a_relaxed_order_finds_a_violation_that_replays(tmp_path: Path, workers: int) -> None:
    path = safety_copy("c2c", tmp_path)
    one = check(path, CheckOptions(reduction="none"))
    assert_same_answer(one, distributed(path, workers, relaxed=True), relaxed=True)


@settings(max_examples=12, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(doc=systems(), workers=st.sampled_from([1, 2, 3]))
def test_generated_systems_in_a_relaxed_order(tmp_path: Path, doc: dict[str, Any],
                                              workers: int) -> None:
    path = write_scenario(doc, tmp_path / "generated.yaml")
    one = check(path, CheckOptions(reduction="none", max_states=1_000))
    assume(one.status.value != "unknown")
    many = distributed(path, workers, relaxed=True, max_states=50_000,  # found later, maybe
                       beyond_start=one.statistics.depth > 0)
    assert_same_answer(one, many, relaxed=True)


@settings(max_examples=20, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(doc=systems(), workers=st.sampled_from([1, 2, 3]),
       reduction=st.sampled_from(["none", "por"]))
def test_generated_systems(tmp_path: Path, doc: dict[str, Any], workers: int,
                           reduction: str) -> None:
    # eventually properties stay: the lasso search runs on the gathered graph
    path = write_scenario(doc, tmp_path / "generated.yaml")
    one = check(path, CheckOptions(reduction=reduction, max_states=1_000, reduce_from=0))
    assume(one.status.value != "unknown")  # a search cut by a limit proves nothing
    many = distributed(path, workers, max_states=1_000, reduction=reduction,
                       beyond_start=one.statistics.depth > 0)
    assert_same_answer(one, many)
    if one.violation is None:
        assert_same_reduction(one, many)


@pytest.mark.parametrize("backend", ["RayBackend", "RayFlow"])
def test_a_worker_with_other_node_sources_refuses_to_start(tmp_path: Path, engine: Any,
                                                           backend: str) -> None:
    path = safety_copy("headon", tmp_path)
    spec = SystemSpec(str(path), None, None, (), ())
    expected = {"scenario": "0" * 64, "rules": "", "node sources": ""}
    starting = getattr(engine, backend)(spec, expected, 2)  # returns before the workers start

    def wait() -> None:
        while not starting.ready():
            time.sleep(0.02)

    with pytest.raises(ClusterError, match="its scenario differ"):
        wait()


def test_random_walks_say_they_stay_in_one_process(tmp_path: Path) -> None:
    cli(["examples", "--copy", "headon", str(tmp_path)])
    walks = check(tmp_path / "headon.yaml", CheckOptions(workers=2, cluster="this",
                                                         search="random", walks=5))
    assert "random walks run in one process" in (walks.engine or ""), walks.engine


_LOOPBACK = {"0100007F", "0000000000000000FFFF00000100007F", "00000000000000000000000001000000"}


def _listening_of(pids: set[int]) -> list[str]:
    """The local addresses (hex, as /proc/net shows them) of the TCP sockets `pids` listen on."""
    inodes = set()
    for pid in pids:
        for fd in Path(f"/proc/{pid}/fd").glob("*"):
            try:
                target = fd.readlink().as_posix()
            except OSError:
                continue
            if target.startswith("socket:["):
                inodes.add(target[8:-1])
    found = []
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        for line in Path(table).read_text().splitlines()[1:]:
            fields = line.split()
            if fields[3] == "0A" and fields[9] in inodes:  # LISTEN
                found.append(fields[1].split(":")[0])
    return found


def test_the_local_cluster_runs_its_workers_at_this_process_priority() -> None:
    import ray

    @ray.remote(num_cpus=0)
    def niceness() -> int:
        return os.getpriority(os.PRIO_PROCESS, 0)

    assert ray.get(niceness.remote(), timeout=120) == os.getpriority(os.PRIO_PROCESS, 0)


def test_the_local_cluster_listens_on_loopback_only() -> None:
    ray_pids = set()
    for entry in Path("/proc").glob("[0-9]*"):
        try:
            cmdline = (entry / "cmdline").read_bytes()
        except OSError:
            continue
        if b"ray::" in cmdline or b"raylet" in cmdline or b"gcs_server" in cmdline:
            ray_pids.add(int(entry.name))
    addresses = _listening_of(ray_pids)
    assert addresses, "no listening socket found in Ray's processes"
    assert set(addresses) <= _LOOPBACK, addresses
