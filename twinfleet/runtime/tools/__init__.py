"""Tools around a running fleet: monitors (`monitor/`), recordings (`record/`) and viewers
(`view/`).

Imports the fleet and what lies below it. The three are wings of their own, each sized and
layered alone (tests/test_sizes.py, tests/test_layering.py): the monitors lie below the
recordings and the viewers; those two use each other. Nothing but this file lies here
beside them.
"""

__all__ = [
    "monitor",
    "record",
    "view",
]
