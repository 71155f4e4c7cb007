"""Recordings: fleet topics to MCAP and back, `bag info` and the Foxglove export.
"""

__all__ = [
    "bag",
    "mcap_export",
    "recorder",
]
