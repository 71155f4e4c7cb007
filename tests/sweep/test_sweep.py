"""`twinfleet sweep` on the shipped `headon` scenario: two robots in a corridor, which
collide when they meet head-on (r2's goal [5, 1]) and keep apart when r2 turns off to a
side lane ([8, 10]), at either speed of r1. Each point checks in about 0.1 s."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from PIL import Image

import twinfleet.sweep.run as sweep_run
from twinfleet.checker.driver import CheckOptions, check
from twinfleet.checker.parallel import engine_for
from twinfleet.cli import main
from twinfleet.runtime.scenario.spec import resolve_scenario
from twinfleet.sweep.cache import PointCache
from twinfleet.sweep.grid import Target, parse_grid, point_label, points
from twinfleet.sweep.point import PointResult, SweepSettings
from twinfleet.sweep.run import run_sweep

pytestmark = pytest.mark.timeout(60)

HEADON = str(resolve_scenario("headon").resolve())
GRID = ["r2.goal=[5, 1],[8, 10]", "r1.speed=0.3,0.5"]
ARGS = ["sweep", "headon", "--param", GRID[0], "--param", GRID[1], "--workers", "1"]


def _settings(**kwargs: object) -> SweepSettings:
    axes = parse_grid(GRID)
    return SweepSettings(HEADON, tuple((a.name, a.target) for a in axes), **kwargs)  # type: ignore[arg-type]


@pytest.mark.parametrize("workers", [1, 2])
def test_each_row_is_what_a_single_check_of_the_point_answers(workers):
    grid = points(parse_grid(GRID))
    engine = engine_for(workers)
    try:
        results = run_sweep(_settings(), grid, engine)
    finally:
        engine.close()
    assert [r.point for r in results] == grid
    for point, row in zip(grid, results, strict=True):
        words = tuple(f"{name}:={value}" for name, value in point)
        single = check(HEADON, CheckOptions(params=words))
        assert (row.verdict, row.states, row.transitions) == (
            single.status.value, single.statistics.states, single.statistics.transitions)
        assert row.violated == (single.violation and single.violation.property)
        if single.trace is not None:
            assert row.violation_time_ms == single.trace["steps"][-1]["time"]
    assert [r.verdict for r in results] == ["violated", "violated", "holds", "holds"]


def _sweep(capsys: pytest.CaptureFixture[str], out: Path, *extra: str) -> tuple[int, list[str]]:
    code = main([*ARGS, "--out", str(out), *extra])
    lines = capsys.readouterr().err.splitlines()
    return code, [line for line in lines if line.startswith("[sweep] ") and "/4 " in line]


def test_a_second_run_reads_every_point_from_the_cache(tmp_path, capsys):
    code, first = _sweep(capsys, tmp_path)
    assert code == 0 and len(first) == 4 and not any("cached" in line for line in first)
    assert "[sweep] 1/4 r2.goal=[5, 1] r1.speed=0.3: VIOLATED no_collision at 3,400 ms (" \
        in first[0]
    code, second = _sweep(capsys, tmp_path)
    assert code == 0 and len(second) == 4 and all(line.endswith("cached)") for line in second)
    assert (tmp_path / "sweep.md").read_text().count("| holds |") == 2


def test_a_deleted_cache_entry_reruns_exactly_that_point(tmp_path, capsys):
    assert _sweep(capsys, tmp_path)[0] == 0
    entries = sorted((tmp_path / "points").glob("*.json"))
    assert len(entries) == 4
    gone = PointResult.from_json(json.loads(entries[0].read_text()))
    entries[0].unlink()
    _, lines = _sweep(capsys, tmp_path)
    ran = [line for line in lines if not line.endswith("cached)")]
    assert len(ran) == 1 and f" {point_label(gone.point)}: " in ran[0], (ran, gone.point)


def test_a_stopped_sweep_keeps_its_finished_points(tmp_path, monkeypatch):
    calls: list[object] = []
    real = sweep_run.run_point

    def stop_at_third(settings: SweepSettings, point: object, name: str = "") -> PointResult:
        calls.append(point)
        if len(calls) == 3:
            raise KeyboardInterrupt  # Ctrl-C during the third check
        return real(settings, point, name)  # type: ignore[arg-type]

    monkeypatch.setattr(sweep_run, "run_point", stop_at_third)
    grid, cache = points(parse_grid(GRID)), PointCache(tmp_path)
    with pytest.raises(KeyboardInterrupt):
        run_sweep(_settings(), grid, engine_for(1), cache)
    assert len(list(cache.folder.glob("*.json"))) == 2
    calls.clear()
    results = run_sweep(_settings(), grid, engine_for(1), cache)
    assert calls == grid[2:]  # only the two points not finished before
    assert len(results) == 4


def test_the_heatmap_colours_each_cell_by_its_verdict(tmp_path, capsys):
    from twinfleet.sweep.heatmap import COLOURS, cell_centre

    code = main([*ARGS, "--out", str(tmp_path), "--heatmap", "r1.speed,r2.goal", "--quiet"])
    assert code == 0
    rows = json.loads((tmp_path / "sweep.json").read_text())["points"]
    x, y = parse_grid([GRID[1], GRID[0]])
    picture = Image.open(tmp_path / "heatmap.png").convert("RGB")
    seen = set()
    for row in rows:
        params = row["params"]
        column, line = x.values.index(params["r1.speed"]), y.values.index(params["r2.goal"])
        assert picture.getpixel(cell_centre(x, y, column, line)) == COLOURS[row["verdict"]]
        seen.add(row["verdict"])
    assert seen == {"holds", "violated"}
    capsys.readouterr()


def test_a_cell_over_a_third_axis_shows_the_worst_verdict(tmp_path):
    from twinfleet.sweep.heatmap import COLOURS, cell_centre, draw

    x, y, z = parse_grid(["a=1,2", "b=1,2", "c=1,2"])
    verdicts = {(1, 1): ("holds", "holds"), (1, 2): ("holds", "unknown"),
                (2, 1): ("unknown", "violated"), (2, 2): ("error", "holds")}
    results = [PointResult((("a", a), ("b", b), ("c", c)), verdicts[a, b][c - 1], None, 1, 1,
                           0.1, None) for a in (1, 2) for b in (1, 2) for c in (1, 2)]
    picture = Image.open(draw(x, y, results, "worst", tmp_path / "h.png")).convert("RGB")
    want = {(1, 1): "holds", (1, 2): "unknown", (2, 1): "violated", (2, 2): "error"}
    for (a, b), verdict in want.items():
        assert picture.getpixel(cell_centre(x, y, a - 1, b - 1)) == COLOURS[verdict]
    assert z.target is Target.COMMON


def test_a_value_a_node_refuses_is_an_error_row_not_the_end(tmp_path, capsys):
    code = main(["sweep", "headon", "--param", "r1.speed=0.5,3", "--workers", "1", "--out",
                 str(tmp_path)])
    captured = capsys.readouterr()
    assert code == 0
    assert "[sweep] 2/2 r1.speed=3: ERROR: " in captured.err and "scan-rate rule" in captured.err
    assert "2 points: 1 error, 1 violated" in captured.out
    assert "- r1.speed=3: " in captured.out  # the table lists why the point has no verdict


@pytest.mark.parametrize(("extra", "message"), [
    (["--param", "r1.speed"], "twinfleet sweep: --param 'r1.speed': expected"),
    (["--param", "r9.speed=0.3"], "--param r9.speed: the scenario has no node 'r9' (nodes: "),
    (["--param", "r1.sped=0.3"], "r1.sped: node r1 has no parameter 'sped' (it has: start, goal, map, "),
    (["--param", "sped=0.3"], "--param sped: no node of the scenario has parameter 'sped'"),
    (["--param", "*.colour=1,2"], "no node of the scenario has parameter 'colour'"),
    (["--param", "r1.speed=0.3", "--heatmap", "r1.speed,r2.speed"],
     "--heatmap 'r1.speed,r2.speed': 'r2.speed' is not swept"),
    (["r1.speed:=0.4", "--param", "r1.speed=0.3"], "r1.speed is both swept"),
    (["--param", "r1.speed=0.3", "--workers", "0"], "--workers must be at least 1"),
])
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, extra, message):
    code = main(["sweep", "headon", *extra, "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert err.startswith("twinfleet sweep: ") and message in err, err
    assert not (tmp_path / "points").exists()


def test_help_explains_every_flag(capsys):
    with pytest.raises(SystemExit):
        main(["sweep", "--help"])
    text = capsys.readouterr().out
    for flag in ("--param", "--workers", "--cluster", "--out", "--heatmap", "--rerun",
                 "--max-time", "--max-states", "--search", "--reduction", "--quiet"):
        assert flag in text


@pytest.mark.slow
@pytest.mark.ray
def test_ray_tasks_answer_what_local_workers_answer():
    """`--cluster local`: the points as Ray tasks on a cluster started here (about 10 s; Ray
    is in the test extra)."""
    grid = points(parse_grid(GRID))
    engine = engine_for(2, "local")
    try:
        on_ray = run_sweep(_settings(), grid, engine)
    finally:
        engine.close()
    here = run_sweep(_settings(), grid, engine_for(1))
    assert [(r.point, r.verdict, r.states, r.transitions, r.violation_time_ms) for r in on_ray] \
        == [(r.point, r.verdict, r.states, r.transitions, r.violation_time_ms) for r in here]
