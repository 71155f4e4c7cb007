"""The checker's named choices, light enough for argument parsers: message semantics, reductions.

Importing this module loads nothing else of the checker, so `twinfleet --help` and the
commands' parsers can offer the choices without loading the search.
"""

from __future__ import annotations

from enum import StrEnum, unique
from typing import Final


@unique
class Semantics(StrEnum):
    """The checker's message semantics, named in a scenario's `semantics:` key.

    Not to be confused with a robot *profile* (`profile: fixed|rebeca`, the nodes'
    behaviour): `Semantics.REBECA` is RMC's message rules, whatever the nodes do.
    """

    ROS = "ros"  # per-sender FIFO, as Zenoh delivers
    REBECA = "rebeca"  # the Timed Rebeca model checker's rules (Rules 3 and 4)


POR: Final = "por"  # the partial-order reduction (docs/reduction.md)
NONE: Final = "none"  # every interleaving
REDUCTIONS: Final = (POR, NONE)
