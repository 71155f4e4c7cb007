"""The thin asyncio loop that runs one node's core over a transport, the Zenoh transport, and
the TLS certificates a Zenoh router presents.

Imports the core, the scenario and the contract.
"""

__all__ = [
    "certs",
    "clock",
    "introspect",
    "keys",
    "node_host",
    "readiness",
    "replay_gate",
    "replay_wire",
    "schemas",
    "transport",
    "zenoh_transport",
]
