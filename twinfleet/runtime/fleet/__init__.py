"""A fleet of node processes: the launcher, the running fleet and its node processes, one
node's process, credentials, the registry, connections to a running fleet, the live
verdict and what a run leaves (its result, run record and merged event log).

Imports the host and what lies below it.
"""

__all__ = [
    "connection",
    "event_merge",
    "fleet_result",
    "fleetauth",
    "launcher",
    "live_fleet",
    "live_verdict",
    "node_main",
    "node_process",
    "registry",
    "run_record",
]
