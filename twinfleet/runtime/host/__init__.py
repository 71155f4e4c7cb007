"""The thin asyncio loop that runs one node's core over a transport, and the Zenoh transport.

Imports the core, the scenario and the contract.
"""

__all__ = [
    "clock",
    "introspect",
    "keys",
    "node_host",
    "readiness",
    "replay_gate",
    "schemas",
    "transport",
    "zenoh_transport",
]
