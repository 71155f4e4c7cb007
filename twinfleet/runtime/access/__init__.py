"""How one reaches a running fleet: its credentials, the per-user registry of running
fleets, and connections to it.

Imports the host and what lies below it; the fleet and the tools import it.
"""

__all__ = [
    "connection",
    "errors",
    "fleetauth",
    "registry",
]
