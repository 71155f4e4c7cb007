"""One node's event handling with no I/O, no clock and no asyncio (sans-IO), and its observers.

Imports only the contract.
"""

__all__ = [
    "choosers",
    "due",
    "events",
    "eventlog",
    "guard",
    "node_core",
    "outbox",
    "state_report",
]
