"""Tools around a running fleet: monitors (`monitor/`), recordings (`record/`) and viewers
(`view/`).

Imports the fleet and what lies below it.
"""

__all__ = [
    "monitor",
    "record",
    "view",
]
