"""The robots' picture renderer for `twinfleet render` (`runtime.scenario.examples.Pictures`).

It draws a fleet on its map: a scenario's starts, goals and first plans, or a trace's
steps (`nodes.render`, imported only when something is drawn: it needs Pillow).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any


class FleetPictures:
    """Draws scenarios whose map server serves robots; options: ``scan_of`` (a robot whose
    scan rays are drawn), ``every_step`` (a GIF frame per step), ``cell_px``."""

    def cannot_draw(self, scenario: Any) -> str | None:
        """Why `scenario` has no fleet on a map to draw (None: it has)."""
        if not any(hasattr(c.params, "robots") for c in scenario.nodes):
            return (f"no node of {scenario.name} serves a map with robots on it (the robot "
                    "scene draws a map server and its robots)")
        return None

    def draw(self, scenario: Any, trace: Mapping[str, Any] | None, output: str, *,
             options: Mapping[str, Any]) -> int:
        """Write the start (no trace) or the trace's steps to `output` (.png or .gif)."""
        from twinfleet.nodes.render import save_pictures, scenario_view, trace_views

        scan_of = options.get("scan_of")
        views = (trace_views(scenario, trace, scan_of=scan_of,
                             every_step=bool(options.get("every_step")))
                 if trace is not None else [scenario_view(scenario, scan_of=scan_of)])
        return save_pictures(views, output, cell_px=int(options.get("cell_px") or 12))

