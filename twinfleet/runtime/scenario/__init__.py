"""Scenarios: one description of a fleet for `launch` and `check`, its settings and properties.

Imports only the contract.
"""

__all__ = [
    "config",
    "examples",
    "lint",
    "params",
    "property_eval",
    "scenario_file",
    "scenes",
    "spec",
]
