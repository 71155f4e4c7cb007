"""`twinfleet sweep`: the argument parser, and the command over `sweep.run`.

`twinfleet.cli` calls `register(subparsers)`; importing this module loads the grid's
parser (PyYAML) and nothing of the checker, so `twinfleet --help` stays light: the
checker, the engines and Pillow load when the command runs. Exit codes: 0 every point
was checked (whatever its verdict; the tables say which hold), 2 bad input (one line
``twinfleet sweep: ...``, nothing run), 130 interrupted (finished points are cached).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from twinfleet.checker.options import SearchChoices, SearchOrder, add_check_arguments
from twinfleet.runtime.contract.kinds import EXIT_BAD_INPUT, EXIT_INTERRUPTED
from twinfleet.sweep.grid import Axis, GridError, Point, parse_axis, parse_grid, point_label

if TYPE_CHECKING:
    from twinfleet.sweep.point import PointResult, SweepSettings
    from twinfleet.sweep.run import Finished

DESCRIPTION = """\
Check a scenario at every combination of parameter values: each point of the grid is one
`twinfleet check` with those overrides, run in parallel worker processes (or as Ray tasks
with --cluster). Each finished point is cached under OUT/points/, so running the same
sweep again (after Ctrl-C, say) runs only the points not finished yet. Writes
OUT/sweep.md, OUT/sweep.csv and OUT/sweep.json (columns: the parameters, verdict, violated
property, states, transitions, time in s, time of first violation in ms of fleet time)
and, with --heatmap X,Y, OUT/heatmap.png; prints the Markdown table on stdout and one
progress line per point on stderr.

NAME is NODE.PARAM (one node's parameter, r1.speed), PARAM (the scenario's common params,
scan_rate_ms), *.PARAM (that parameter of every node that has it), semantics, or
check.KEY (a key of the scenario's check: block). VALUES is a list a,b,c (YAML values) or
an inclusive range start:stop:step.

  twinfleet sweep c2a --param '*.speed=0.3,0.5' --param scan_rate_ms=60:140:40
  twinfleet sweep c2a '*.allow_unsafe_speed:=true' --param '*.speed=0.3:0.9:0.2' \\
      --param scan_rate_ms=60:140:40 --heatmap '*.speed,scan_rate_ms' --workers 2"""


def register(subparsers: Any) -> None:
    """Add the `sweep` subcommand to an argparse subparsers object."""
    p = subparsers.add_parser("sweep", help="check a scenario over a grid of parameter values",
                              description=DESCRIPTION,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scenario", help="scenario YAML file, or the name of a shipped example")
    p.add_argument("fixed", nargs="*", metavar="NAME:=VALUE",
                   help="overrides every point shares, not swept and not in the tables "
                        "(same NAMEs as --param; e.g. '*.allow_unsafe_speed:=true')")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUES",
                   help="a swept parameter and its values, a,b,c or start:stop:step "
                        "(repeatable; the grid is every combination, the last --param "
                        "varying fastest)")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="points checked at once: local worker processes, or Ray tasks with "
                        "--cluster (default: the number of CPUs; 1: one after another in "
                        "this process)")
    p.add_argument("--cluster", default=None, metavar="ADDRESS",
                   help="run the points as Ray tasks on the cluster at ADDRESS ('local': "
                        "start one here); needs the cluster extra")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="where the tables, the heatmap, the cache of finished points and "
                        "the traces of violations go (default: out/sweep-SCENARIO)")
    p.add_argument("--rerun", action="store_true",
                   help="check every point again, ignoring (and replacing) cached results")
    p.add_argument("--heatmap", default=None, metavar="X,Y",
                   help="draw OUT/heatmap.png: X across, Y up, each cell coloured by "
                        "verdict (holds green, violated red, unknown grey; with more axes, a "
                        "cell shows the worst verdict over the other axes)")
    add_check_arguments(p, searches=(SearchOrder.BFS, SearchOrder.DFS))  # as `check`'s
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    p.set_defaults(func=sweep_command)


def sweep_command(args: argparse.Namespace) -> int:
    """Run `sweep` for parsed arguments; return the exit code."""
    try:
        axes, settings, out = _prepare(args)
    except (GridError, ValueError) as exc:
        print(f"twinfleet sweep: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    from twinfleet.checker.commands import bad_input_errors

    try:
        _validate(settings)
        results = _run(args, axes, settings, out)
    except bad_input_errors() as exc:
        print(f"twinfleet sweep: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:  # Ctrl-C or SIGTERM: each finished point had its line
        print(f"twinfleet sweep: interrupted; the finished points are cached under "
              f"{out / 'points'}: the same command checks only the others", file=sys.stderr)
        return EXIT_INTERRUPTED
    _write(args, axes, settings, results, out)
    return 0


def _prepare(args: argparse.Namespace) -> tuple[tuple[Axis, ...], SweepSettings, Path]:
    """The grid, the settings every point shares and the output folder, from the words."""
    from twinfleet.runtime.scenario.spec import resolve_scenario
    from twinfleet.sweep.point import SweepSettings

    axes = parse_grid(args.param)
    fixed = tuple(parse_axis(_fixed_word(w)) for w in args.fixed)
    for axis in fixed:
        if axis.name in {a.name for a in axes}:
            raise GridError(f"{axis.name} is both swept (--param) and fixed ({axis.name}:=)")
    if args.heatmap is not None:
        from twinfleet.sweep.heatmap import pick_axes

        pick_axes(axes, args.heatmap)  # a bad name is bad input before anything runs
    for flag in ("workers", "max_states", "max_depth"):
        value = getattr(args, flag)
        if value is not None and value < 1:
            raise GridError(f"--{flag.replace('_', '-')} must be at least 1, got {value}")
    scenario = resolve_scenario(args.scenario)
    out = Path(args.out or Path("out") / f"sweep-{scenario.stem}")
    settings = SweepSettings(
        str(scenario.resolve()), tuple((a.name, a.target) for a in (*axes, *fixed)),
        fixed=tuple((a.name, a.values[0]) for a in fixed), check=SearchChoices.of(args),
        trace_dir=str(out / "traces"))
    return axes, settings, out


def _fixed_word(word: str) -> str:
    """A fixed override ``NAME:=VALUE`` as a one-value axis word."""
    if ":=" not in word:
        raise GridError(f"unexpected argument {word!r}: fixed overrides look like "
                        "r1.speed:=0.4, swept ones --param r1.speed=0.4,0.6")
    name, _, value = word.partition(":=")
    if "," in value and not value.strip().startswith(("[", "{")):
        raise GridError(f"{word!r}: a fixed override has one value (sweep values with --param)")
    return f"{name}={value}"


def _validate(settings: SweepSettings) -> None:
    """Every node and parameter an axis names exists, so that a misspelt name is one line
    before anything runs, not an error in every row. (A value a node refuses, such as an
    unsafe speed, is the verdict ``error`` of its points only.)

    Raises:
        ScenarioError: the scenario, or a node or parameter an axis names, does not exist.
    """
    import dataclasses

    from twinfleet.runtime.scenario.overrides import scenario_common
    from twinfleet.runtime.scenario.spec import ScenarioError, load_scenario
    from twinfleet.runtime.scenario.suggest import did_you_mean
    from twinfleet.sweep.grid import Target

    scenario = load_scenario(settings.scenario)
    fields = {cfg.name: [f.name for f in dataclasses.fields(cfg.cls.Params)]
              for cfg in scenario.nodes}
    common = set(scenario_common(settings.scenario))
    for name, target in settings.targets:
        node, _, key = name.rpartition(".")
        if target is Target.NODE and node not in fields:
            raise ScenarioError(f"{settings.scenario}: --param {name}: the scenario has no node "
                                f"{node!r} (nodes: {', '.join(fields)})"
                                f"{did_you_mean(node, fields)}")
        if target is Target.NODE and key not in fields[node]:
            raise ScenarioError(f"{settings.scenario}: --param {name}: node {node} has no "
                                f"parameter {key!r} (it has: {', '.join(fields[node])})"
                                f"{did_you_mean(key, fields[node])}")
        known = {f for names in fields.values() for f in names}
        if target in (Target.COMMON, Target.EVERY_NODE) and key not in known | (
                common if target is Target.COMMON else set()):
            raise ScenarioError(f"{settings.scenario}: --param {name}: no node of the scenario "
                                f"has parameter {key!r}{did_you_mean(key, known)}")


def _run(args: argparse.Namespace, axes: tuple[Axis, ...], settings: SweepSettings,
         out: Path) -> list[PointResult]:
    """Every point's result, from the cache or checked on the engine the flags choose."""
    from twinfleet.checker.parallel import engine_for
    from twinfleet.sweep.cache import PointCache
    from twinfleet.sweep.grid import points
    from twinfleet.sweep.run import run_sweep

    grid = points(axes)
    workers = min(args.workers or os.cpu_count() or 1, len(grid))
    cache = PointCache(out)
    if args.rerun:
        cache.clear()
    engine = engine_for(workers, args.cluster)
    try:
        return run_sweep(settings, grid, engine, cache, None if args.quiet else _progress)
    finally:
        engine.close()


def progress_line(finished: Finished) -> str:
    """``[sweep] 3/24 r1.speed=0.4 scan_rate_ms=100: HOLDS (5,516 states, 2.1 s)``."""
    r = finished.result
    head = f"[sweep] {finished.done}/{finished.total} {point_label(r.point)}: "
    if r.verdict == "error":
        return head + f"ERROR: {r.reason}"
    verdict = r.verdict.upper()
    if r.violated is not None:
        verdict += f" {r.violated}"
        if r.violation_time_ms is not None:
            verdict += f" at {r.violation_time_ms:,} ms"
    how = "cached" if finished.cached else f"{r.time_s:.1f} s"
    return head + f"{verdict} ({r.states:,} states, {how})"


def _progress(finished: Finished) -> None:
    print(progress_line(finished), file=sys.stderr, flush=True)


def _write(args: argparse.Namespace, axes: tuple[Axis, ...], settings: SweepSettings,
           results: list[PointResult], out: Path) -> None:
    """The three tables (and the heatmap) under `out`; the Markdown table on stdout."""
    from twinfleet.sweep import tables

    title = f"twinfleet sweep {args.scenario}"
    if settings.fixed:
        title += " " + " ".join(f"{n}:={v}" for n, v in _labels(settings.fixed))
    text = tables.markdown(title, axes, results)
    out.mkdir(parents=True, exist_ok=True)
    (out / "sweep.md").write_text(text)
    (out / "sweep.csv").write_text(tables.csv_text(axes, results))
    (out / "sweep.json").write_text(tables.json_text(settings.scenario, axes, results,
                                                     _settings_record(settings)))
    written = [out / "sweep.md", out / "sweep.csv", out / "sweep.json"]
    if args.heatmap is not None:
        from twinfleet.sweep.heatmap import draw, pick_axes

        x, y = pick_axes(axes, args.heatmap)
        written.append(draw(x, y, results, title, out / "heatmap.png"))
    print(text, end="")
    if not args.quiet:
        print("[sweep] wrote " + ", ".join(map(str, written)), file=sys.stderr)


def _labels(point: Point) -> list[tuple[str, str]]:
    from twinfleet.sweep.grid import format_value

    return [(name, format_value(value)) for name, value in point]


def _settings_record(settings: SweepSettings) -> dict[str, Any]:
    """What every point shared, for the JSON table."""
    choices = settings.check
    return {"fixed": dict(settings.fixed), "search": choices.search,
            "reduction": choices.reduction, "max_states": choices.max_states,
            "max_time_s": choices.max_time_s, "max_depth": choices.max_depth,
            "contract_checks": choices.verify}
