"""How to launch a fleet: `LaunchOptions`, every setting of `launcher.run_fleet` but the
scenario, the output stream and the driver, as one frozen value.

None means "the scenario's": `time_scale`, the run's limits and `seed` come from its
`live:` section and `seed:` unless given, and `until_settled`/`until_violation` from
``live.stop``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import final

from twinfleet.runtime.access import fleetauth

#: wall seconds every node has to become alive (imports, session, liveliness) before a run
#: ends as not started; the timeout counts from the epoch, after that
STARTUP_S = 60.0


@final
@dataclass(frozen=True)
class LaunchOptions:
    """Settings of one launch (`launcher.run_fleet`).

    Attributes:
        time_scale, seed: fleet speed-up and seed (default: the scenario's).
        timeout_s: wall seconds the run lasts from the fleet's epoch, instead of the
            scenario's `live.wall_timeout_s` and ``live.horizon_s`` (`launcher.wall_limit`).
        connect, listen: join this router; else the embedded one's endpoint.
        handle_signals: end on SIGINT/SIGTERM (main thread only).
        run_record: write the run as JSON lines to this file (`runtime.fleet.run_record`).
        record_events: write every dispatched event to this file (`launcher`).
        node_args: extra arguments for every node process (`runtime.fleet.node_main`).
        params: parameter overrides ``[NODE.]NAME=VALUE`` (`runtime.host.introspect`); the
            scenario must already be loaded with them (`overrides.load_with_params`).
        judge: judge the properties live (`runtime.fleet.live_verdict`: the result's
            `verdict`); False: no state reports (exits and the report decide).
        auth: with `connect`, the joined fleet's key and logins (default: the registry's).
        bridge: take external input under a bridge key (`core.guard`); the driver runs it.
        startup_s: wall seconds for every node to become alive; a run not up by then is
            INCONCLUSIVE, never a node's failure.
        accept_recorded: the nodes take recorded input ``twinfleet play --into-fleet``
            signs (the verdict says so); otherwise they drop it.
        until_settled, until_violation: end once every eventually property held, at the
            first violation (default: ``live.stop``).
    """

    time_scale: float | None = None
    timeout_s: float | None = None
    seed: int | None = None
    connect: str | None = None
    listen: str | None = None
    handle_signals: bool = True
    run_record: str | None = None
    record_events: str | None = None
    node_args: Sequence[str] = ()
    params: Sequence[str] = ()
    judge: bool = True
    auth: fleetauth.MonitorAuth | None = None
    bridge: bool = False
    startup_s: float = STARTUP_S
    accept_recorded: bool = False
    until_settled: bool | None = None
    until_violation: bool | None = None
