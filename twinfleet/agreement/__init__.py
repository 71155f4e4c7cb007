"""twinfleet's agreement layer: the live runtime and the checker, side by side.

The checker's verdicts are statements about the very node code the live fleet
runs; this package measures how well they predict live runs. It is the only
package allowed to import both `checker` and the live parts of `runtime`
(`tests/test_layering.py`); `checker` never imports it.

Entry points: `run_experiment` (the paper's Table 4/5 for any scenarios:
checker verdicts and counts per semantics plus N live runs), `live_run` (one
live fleet with arrival times and early stop), `predicted_arrivals` (the
checker's logical arrival times on one path), the discretization helpers,
and `agreement.commands.register` for the `twinfleet experiment` command.
"""

from twinfleet.agreement.paper import PAPER, PaperRow, paper_row
from twinfleet.agreement.table import CheckCell, LiveSummary, Row

#: The live time scale the experiment uses unless told otherwise: the fastest scale at
#: which every measured live run stayed on the checker's path
#: (`benchmarks/agreement_timescale.py`, docs/experiment.md).
DEFAULT_TIME_SCALE = 2.0

__all__ = ["DEFAULT_TIME_SCALE", "PAPER", "CheckCell", "LiveSummary", "PaperRow", "Row",
           "paper_row"]
