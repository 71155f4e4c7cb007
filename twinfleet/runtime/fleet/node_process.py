"""One OS process per node: started, its output copied, signalled and stopped.

A `NodeProcess` starts ``python -P -m twinfleet.runtime.fleet.node_main ...`` with
`asyncio.create_subprocess_exec` (never a fork after a Zenoh session is open, never
`multiprocessing`), with the fleet's secrets in its environment, and copies every output
line with a ``[node]`` prefix, keeping the last few for the report when the node dies. The
child asks Linux for PR_SET_PDEATHSIG (`node_main.die_with_parent`), so none outlives a
SIGKILLed launcher. `stop_all` escalates SIGINT → SIGTERM → SIGKILL.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from typing import TextIO, final

from twinfleet.runtime.fleet.node_main import PARENT_ENV
from twinfleet.runtime.scenario.spec import NodeConfig

#: `-P`: the working directory does not go first on a node process's `sys.path`, so user
#: modules resolve exactly as `twinfleet check` resolves them (`scenario.spec.user_import_path`).
NODE_PROCESS_FLAGS = ("-P",)
_LAST_LINES = 15
_GRACE_S = (3.0, 2.0)  # after SIGINT, after SIGTERM; then SIGKILL
_KILL_WAIT_S = 5.0  # after SIGKILL, for the exit to be reaped


@final
class NodeProcess:
    """One supervised node process and its output pump."""

    def __init__(self, cfg: NodeConfig, argv: list[str], out: TextIO,
                 secrets: Mapping[str, str] | None = None) -> None:
        self.cfg, self.argv, self.out = cfg, argv, out
        self.secrets = dict(secrets or {})
        self.proc: asyncio.subprocess.Process | None = None
        self.last_lines: deque[str] = deque(maxlen=_LAST_LINES)
        self.restarts = 0
        self.exit_code: int | None = None
        self._pump: asyncio.Task[None] | None = None

    async def start(self) -> None:
        """Start (or start again) the process, in a session of its own."""
        env = dict(os.environ)
        env["PYTHONUNBUFFERED"] = "1"
        env[PARENT_ENV] = str(os.getpid())
        env.update(self.secrets)  # the environment: other users cannot read it, unlike argv
        self.exit_code = None
        self.proc = await asyncio.create_subprocess_exec(
            *self.argv, stdin=asyncio.subprocess.DEVNULL, stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.STDOUT, env=env, start_new_session=True)
        self._pump = asyncio.create_task(self._copy_output(self.proc))

    async def _copy_output(self, proc: asyncio.subprocess.Process) -> None:
        assert proc.stdout is not None
        async for raw in proc.stdout:
            line = raw.decode(errors="replace").rstrip("\n")
            self.last_lines.append(line)
            emit(self.out, f"[{self.cfg.name}] {line}")

    async def wait(self) -> int:
        """Wait for the process to exit and its output to be copied; return the exit code."""
        assert self.proc is not None
        code = await self.proc.wait()
        if self._pump is not None:
            await asyncio.wait([self._pump], timeout=2.0)
        self.exit_code = code
        return code

    def running(self) -> bool:
        """True while the process runs."""
        return self.proc is not None and self.proc.returncode is None

    def signal(self, sig: int) -> None:
        """Send `sig` if the process still runs."""
        if self.running():
            assert self.proc is not None
            with contextlib.suppress(ProcessLookupError):
                self.proc.send_signal(sig)

    def final_code(self) -> int | None:
        """The exit code once stopped (None: it never started or could not be reaped)."""
        if self.exit_code is None and self.proc is not None:
            self.exit_code = self.proc.returncode
        return self.exit_code


async def stop_all(procs: Sequence[NodeProcess], log: Callable[[str], None]) -> None:
    """Stop every process: SIGINT, then SIGTERM, then SIGKILL, each after a grace period;
    `log` names the processes that needed more than SIGINT."""
    for sig, grace in ((signal.SIGINT, _GRACE_S[0]), (signal.SIGTERM, _GRACE_S[1]),
                       (signal.SIGKILL, _KILL_WAIT_S)):
        alive = [p for p in procs if p.running()]
        if not alive:
            break
        if sig != signal.SIGINT:
            log(f"sending {signal.Signals(sig).name} to " + ", ".join(p.cfg.name for p in alive))
        for p in alive:
            p.signal(sig)
        await asyncio.wait([asyncio.ensure_future(p.wait()) for p in alive], timeout=grace)


def emit(out: TextIO, line: str) -> None:
    """Write one output line and flush it (the lines of several processes interleave)."""
    out.write(line + "\n")
    out.flush()
