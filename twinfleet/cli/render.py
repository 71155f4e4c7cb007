"""`twinfleet render` draws a scenario or a checker trace.

A trace of a fleet with a map (a scenario with a `scene:`) is drawn on its map
as today; any trace, and a mapless one always, can be drawn as a
message-sequence chart (`--chart`: lifelines, messages, state changes, the
violation), to PNG or SVG. `register(subparsers)` adds the command to the
`twinfleet` command line (`twinfleet.cli`).
"""

from __future__ import annotations

import argparse
import sys
from typing import Any


def register(sub: argparse._SubParsersAction) -> None:
    """Add `render` to the `twinfleet` command line."""
    p = sub.add_parser("render", help="draw a scenario or a checker trace (map or sequence chart)",
                       description="Draw a scenario's start (fleets with a map) or a trace "
                       "written by `twinfleet check`: on its map when the scenario has one, "
                       "else as a message-sequence chart. Exit 0, or 2 on bad input.")
    p.add_argument("source", help="scenario YAML, or a trace JSON written by `twinfleet check`")
    p.add_argument("-o", "--output", required=True, metavar="FILE",
                   help="FILE.png: one picture (a trace's last step, with the violation marked, "
                        "or the chart); FILE.gif: one frame per step that changed the picture; "
                        "FILE.svg: the sequence chart as SVG")
    p.add_argument("--chart", action="store_true",
                   help="draw a trace as a message-sequence chart even when its scenario has "
                        "a map (one lifeline per node, messages with their times, the fields "
                        "each step changed, the violated property in red)")
    p.add_argument("--steps", metavar="A..B", default=None, type=_steps,
                   help="with a chart: draw steps A to B only (1-based, inclusive; messages "
                        "sent before A start at the top, those handled after B end at the "
                        "foot); default: every step, a trace longer than 60 steps in pages "
                        "FILE-1.png, FILE-2.png, ...")
    p.add_argument("--scan-of", metavar="NODE", default=None,
                   help="draw the scan rays of this node, where the scenario's renderer draws "
                        "scans (the robots' example: a robot, e.g. r1)")
    p.add_argument("--every-step", action="store_true",
                   help="for a GIF of a trace, one frame per step even when nothing moved")
    p.add_argument("--cell-px", type=int, default=12, metavar="N",
                   help="pixels per grid cell (default: %(default)s)")
    p.set_defaults(func=cmd_render)


def cmd_render(args: argparse.Namespace) -> int:
    """`twinfleet render`: a scenario's start or a trace, on its map or as a chart."""
    from twinfleet.runtime.scenario.examples import renderer_for
    from twinfleet.runtime.scenario.overrides import load_with_params
    from twinfleet.runtime.scenario.spec import ScenarioError, load_scenario

    source = args.source
    try:
        if source.endswith(".json"):
            from twinfleet.runtime.contract.tracefile import TraceError, load_trace

            try:
                trace = load_trace(source)
            except TraceError as exc:
                raise ValueError(str(exc)) from None
            scenario = load_with_params(trace["scenario"], trace.get("params") or ())
            no_map = _no_picture(scenario)
            if args.chart or args.steps or no_map or args.output.endswith(".svg"):
                if no_map and not args.chart:
                    print(f"drawn as a sequence chart: {no_map}")
                return _chart(trace, args.output, args.steps)
        else:
            trace, scenario = None, load_scenario(source)
            no_map = _no_picture(scenario)
            if no_map:
                raise ValueError(f"{source}: nothing to draw: {no_map}; a trace of it "
                                 "(`twinfleet check SCENARIO --trace-out T.json`) is drawn as "
                                 "a sequence chart (`twinfleet render T.json -o chart.png`)")
        options = {"scan_of": args.scan_of, "every_step": args.every_step,
                   "cell_px": args.cell_px}
        frames = renderer_for(scenario).draw(scenario, trace, args.output, options=options)
    except (ScenarioError, ValueError, KeyError, OSError) as exc:
        print(f"twinfleet render: {exc}", file=sys.stderr)
        return 2
    except (TypeError, AttributeError) as exc:  # well-formed trace, states of another system
        print(f"twinfleet render: {source}: the trace does not fit its scenario's nodes ({exc})",
              file=sys.stderr)
        return 2
    print(f"wrote {args.output} ({frames} frame{'s' if frames > 1 else ''})")
    return 0


def _steps(text: str) -> tuple[int, int]:
    """``A..B`` as (A, B), 1 <= A <= B."""
    first, sep, last = text.partition("..")
    if not (sep and first.isdigit() and last.isdigit() and 1 <= int(first) <= int(last)):
        raise argparse.ArgumentTypeError(f"expected A..B with 1 <= A <= B (e.g. 40..80), "
                                         f"got {text!r}")
    return int(first), int(last)


def _no_picture(scenario: Any) -> str | None:
    """Why no registered renderer draws a scenario, in its user's words (None: one does)."""
    from twinfleet.runtime.scenario.examples import renderer_for

    if scenario.scene is None:
        return "the scenario names no scene (`scene:`), so there is no map to draw its fleet on"
    try:
        renderer_for(scenario)
    except ValueError as exc:
        return str(exc)
    return None


def walk_json(trace: dict[str, Any]) -> dict[str, Any]:
    """A trace re-executed and described step by step, as plain JSON values."""
    from twinfleet.checker.driver import system_for_trace
    from twinfleet.checker.trace_show import walk

    system, _ = system_for_trace(trace)
    return walk(system, trace).to_json()


def _chart(trace: dict[str, Any], output: str, window: tuple[int, int] | None) -> int:
    from twinfleet.checker.trace import NondeterminismError
    from twinfleet.runtime.tools.view.sequence_chart import save_chart

    if not output.endswith((".png", ".svg")):
        raise ValueError(f"{output}: a sequence chart is written as .png or .svg")
    try:
        steps = walk_json(trace)
    except NondeterminismError as exc:
        raise ValueError(f"the trace does not replay: {exc}") from None
    total = len(steps["steps"])
    if window is not None and window[1] > total:
        raise ValueError(f"--steps {window[0]}..{window[1]}: the trace has {total} steps")
    written = save_chart(steps, output, window)
    shown = f", steps {window[0]}..{window[1]}" if window else ""
    pages = f" in {len(written)} pages: {written[0]} ... {written[-1]}" if len(written) > 1 else ""
    print(f"wrote {output if len(written) == 1 else written[0].parent} (sequence chart, "
          f"{total} steps{shown}, {len(steps['nodes'])} lifelines){pages}")
    return 0
