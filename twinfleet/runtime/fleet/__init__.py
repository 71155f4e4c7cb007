"""A fleet of node processes: the launcher, one node's process, credentials, the registry,
connections to a running fleet and the live verdict.

Imports the host and what lies below it.
"""

__all__ = [
    "connection",
    "fleetauth",
    "launcher",
    "live_verdict",
    "node_main",
    "registry",
    "run_record",
]
