"""Tools around a running fleet: monitors (`monitor/`), the viewers' data forms (`forms/`),
recordings (`record/`) and viewers (`view/`).

Imports the fleet and what lies below it. The four are wings of their own, each sized and
layered alone (tests/test_sizes.py, tests/test_layering.py): the monitors and the forms lie
below the recordings and the viewers, which share what they share through those two and
do not import each other. Nothing but this file lies here beside them.
"""

__all__ = [
    "forms",
    "monitor",
    "record",
    "view",
]
