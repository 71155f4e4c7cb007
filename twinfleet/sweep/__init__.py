"""`twinfleet sweep`: one check per point of a grid of parameter values.

`grid` parses ``--param NAME=VALUES`` into axes and points; `point` runs the check of one
point (the same `checker.driver.check` a single `twinfleet check` runs); `run` spreads
the points over the checker's engines (`checker.parallel.engine_for`: local processes or
Ray tasks) and caches each finished one (`cache`); `tables` and `heatmap` write the
results. `commands` is the command line. The package imports neither Zenoh nor asyncio,
and Ray only through the checker's engine.
"""

from __future__ import annotations

__all__ = ["cache", "commands", "grid", "heatmap", "point", "run", "tables"]
