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
                   help="FILE.png: one picture (a trace's last step, with the collision circled, "
                        "or the chart); FILE.gif: one frame per step in which a robot moved; "
                        "FILE.svg: the sequence chart as SVG")
    p.add_argument("--chart", action="store_true",
                   help="draw a trace as a message-sequence chart even when its scenario has "
                        "a map (one lifeline per node, messages with their times, the fields "
                        "each step changed, the violated property in red)")
    p.add_argument("--scan-of", metavar="ROBOT", default=None,
                   help="draw the scan rays of this robot (e.g. r1)")
    p.add_argument("--every-step", action="store_true",
                   help="for a GIF of a trace, one frame per step even when nothing moved")
    p.add_argument("--cell-px", type=int, default=12, metavar="N",
                   help="pixels per grid cell (default: %(default)s)")
    p.set_defaults(func=cmd_render)


def cmd_render(args: argparse.Namespace) -> int:
    """`twinfleet render`: a scenario's start or a trace, on its map or as a chart."""
    from twinfleet.runtime.scenario.spec import ScenarioError, load_scenario

    source = args.source
    try:
        if source.endswith(".json"):
            from twinfleet.runtime.contract.tracefile import TraceError, load_trace

            try:
                trace = load_trace(source)
            except TraceError as exc:
                raise ValueError(str(exc)) from None
            scenario = load_scenario(trace["scenario"], {"profile": trace.get("profile") or "fixed"})
            if args.chart or scenario.scene is None or args.output.endswith(".svg"):
                return _chart(trace, args.output)
        else:
            trace, scenario = None, load_scenario(source)
        from twinfleet.nodes.render import save_pictures, scenario_view, trace_views

        views = (trace_views(scenario, trace, scan_of=args.scan_of, every_step=args.every_step)
                 if trace else [scenario_view(scenario, scan_of=args.scan_of)])
        frames = save_pictures(views, args.output, cell_px=args.cell_px)
    except (ScenarioError, ValueError, KeyError, OSError) as exc:
        print(f"twinfleet render: {exc}", file=sys.stderr)
        return 2
    except (TypeError, AttributeError) as exc:  # well-formed trace, states of another system
        print(f"twinfleet render: {source}: the trace does not fit its scenario's nodes ({exc})",
              file=sys.stderr)
        return 2
    print(f"wrote {args.output} ({frames} frame{'s' if frames > 1 else ''})")
    return 0


def walk_json(trace: dict[str, Any]) -> dict[str, Any]:
    """A trace re-executed and described step by step, as plain JSON values."""
    from twinfleet.checker.driver import system_for_trace
    from twinfleet.checker.trace_show import walk

    system, _ = system_for_trace(trace)
    return walk(system, trace).to_json()


def _chart(trace: dict[str, Any], output: str) -> int:
    from twinfleet.checker.trace import NondeterminismError
    from twinfleet.runtime.tools.view.sequence_chart import save_chart

    if not output.endswith((".png", ".svg")):
        raise ValueError(f"{output}: a sequence chart is written as .png or .svg")
    try:
        steps = walk_json(trace)
    except NondeterminismError as exc:
        raise ValueError(f"the trace does not replay: {exc}") from None
    save_chart(steps, output)
    print(f"wrote {output} (sequence chart, {len(steps['steps'])} steps, "
          f"{len(steps['nodes'])} lifelines)")
    return 0
