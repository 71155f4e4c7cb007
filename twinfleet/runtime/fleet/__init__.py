"""A fleet of node processes: the launcher, the running fleet and its node processes, one
node's process, the live verdict and what a run leaves (its result, run record and merged
event log).

Imports the access wing, the host and what lies below them.
"""

__all__ = [
    "event_merge",
    "fleet_result",
    "launch_options",
    "launcher",
    "live_fleet",
    "live_verdict",
    "node_main",
    "node_process",
    "run_record",
]
