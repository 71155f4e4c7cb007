"""`twinfleet render` draws a scenario or a checker trace (the robot case study's pictures).

`register(subparsers)` adds it to the `twinfleet` command line (`twinfleet.cli`).
"""

from __future__ import annotations

import argparse
import sys


def register(sub: argparse._SubParsersAction) -> None:
    """Add `render` to the `twinfleet` command line."""
    p = sub.add_parser("render", help="draw a scenario (start, goals, first plans) or a checker trace")
    p.add_argument("source", help="scenario YAML, or a trace JSON written by `twinfleet check`")
    p.add_argument("-o", "--output", required=True, metavar="FILE",
                   help="FILE.png: one picture (a trace's last step, with the collision circled); "
                        "FILE.gif: one frame per step in which a robot moved")
    p.add_argument("--scan-of", metavar="ROBOT", default=None,
                   help="draw the scan rays of this robot (e.g. r1)")
    p.add_argument("--every-step", action="store_true",
                   help="for a GIF of a trace, one frame per step even when nothing moved")
    p.add_argument("--cell-px", type=int, default=12, metavar="N",
                   help="pixels per grid cell (default: %(default)s)")
    p.set_defaults(func=cmd_render)


def cmd_render(args: argparse.Namespace) -> int:
    """`twinfleet render`: draw a scenario's start or a checker trace to PNG/GIF."""
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
        else:
            trace, scenario = None, load_scenario(source)
        from twinfleet.nodes.render import save_pictures, scenario_view, trace_views

        views = (trace_views(scenario, trace, scan_of=args.scan_of, every_step=args.every_step)
                 if trace else [scenario_view(scenario, scan_of=args.scan_of)])
        frames = save_pictures(views, args.output, cell_px=args.cell_px)
    except (ScenarioError, ValueError, KeyError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except (TypeError, AttributeError) as exc:  # well-formed trace, states of another system
        print(f"error: {source}: the trace does not fit its scenario's nodes ({exc})", file=sys.stderr)
        return 2
    print(f"wrote {args.output} ({frames} frame{'s' if frames > 1 else ''})")
    return 0
