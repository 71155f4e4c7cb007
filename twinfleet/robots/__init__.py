"""The robot case study on twinfleet's public API: the paper's experiment.

The robots themselves are node code (`twinfleet.nodes`: the robot and map server nodes,
their messages, maps and scene; the scenarios under `twinfleet/launch`). What lies here
measures them, on the checker, the agreement layer and the live fleet, as any
application could: `run_experiment` (the paper's Table 4/5 for any scenarios: checker
verdicts and counts per semantics plus N live runs), `live_run` (one live fleet with
arrival times and early stop), `predicted_arrivals` (the checker's logical arrival
times on one path), the discretization study, and `robots.commands.register` for the
`twinfleet experiment` command. Nothing below the command line imports this package.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from twinfleet.nodes.pictures import FleetPictures
from twinfleet.runtime.contract.lazy import lazy_names

if TYPE_CHECKING:
    from twinfleet.robots.paper import PAPER, PaperRow, paper_row
    from twinfleet.robots.table import CheckCell, LiveSummary, Row

#: The live time scale the experiment uses unless told otherwise: the fastest scale at
#: which every measured live run stayed on the checker's path
#: (`benchmarks/agreement_timescale.py`, docs/experiment.md).
DEFAULT_TIME_SCALE = 2.0

#: the package of the robots' example scenarios (package data, beside their maps), which the
#: command line and the testing API add to the names scenarios resolve (`add_examples`)
EXAMPLES = "twinfleet.launch"
#: their picture renderer (`twinfleet render`), registered with them: ``add_examples(EXAMPLES,
#: PICTURES)``
PICTURES = FleetPictures()

# The paper's figures and the table's rows, imported on first use: every command imports
# the package for `EXAMPLES` and `PICTURES`, and only the experiment needs those.
_HOMES = {**dict.fromkeys(("PAPER", "PaperRow", "paper_row"), "paper"),
          **dict.fromkeys(("CheckCell", "LiveSummary", "Row"), "table")}

__getattr__ = lazy_names(__name__, _HOMES)

__all__ = ["DEFAULT_TIME_SCALE", "EXAMPLES", "PAPER", "PICTURES", "CheckCell", "LiveSummary",
           "PaperRow", "Row", "paper_row"]
