"""Scenarios: one description of a fleet for `launch` and `check`, its settings and properties.

Imports only the contract.
"""

__all__ = [
    "config",
    "examples",
    "files",
    "lint",
    "overrides",
    "params",
    "property_eval",
    "property_fields",
    "scenario_file",
    "scenes",
    "spec",
]
