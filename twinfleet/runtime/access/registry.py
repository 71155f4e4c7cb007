"""The fleet registry: how a monitor finds the fleets running on this machine without --connect.

Every `twinfleet launch` (and `twinfleet play` when it is its own router)
writes one entry per fleet into a per-user runtime directory and removes it
when the run ends:

    $TWINFLEET_RUNTIME_DIR, else $XDG_RUNTIME_DIR/twinfleet, else <tmp>/twinfleet-<uid>
        <fleet>-<pid>.json      one running fleet (mode 0600, in a 0700 directory)

An entry is a JSON object (`FleetEntry`): ``format`` (``twinfleet-fleet/1``),
``fleet``, ``endpoint`` (the Zenoh router the fleet's nodes use), ``pid`` and
``started`` (the process start tick from /proc, so a recycled pid is not taken
for the launcher), ``scenario`` (its path), ``kind`` (``launch`` or ``play``),
``params`` (the launch-time parameter overrides), ``time`` (when it was
registered) and ``extra`` (a free mapping: later fields, e.g. per-fleet
credentials, go there without a format change; readers ignore what they do
not know). The directory and the files
are owner-only because entries may hold secrets later; a directory that
another user owns, or that others can write, is refused.

A monitor started without --connect reads the registry (`find_fleet`): an
entry whose process is gone is stale and removed; with one fleet left it is
used, with none or several the error says so in one line (and how to start a
fleet, or which --fleet to choose). Fleets on other machines are still
reached with --connect.
"""

from __future__ import annotations

import contextlib
import json
import os
import stat
import tempfile
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from twinfleet.runtime.contract.environment import EnvVar, env_value

FORMAT = "twinfleet-fleet/1"
DIR_ENV = EnvVar.RUNTIME_DIR


class RegistryError(ValueError):
    """The registry cannot be used, or does not name exactly one fleet; the text says why."""


@dataclass(frozen=True)
class FleetEntry:
    """One running fleet, as registered by its launcher."""

    fleet: str
    endpoint: str
    pid: int
    started: int | None = None
    scenario: str = ""
    kind: str = "launch"
    params: Mapping[str, Any] = field(default_factory=dict)
    extra: Mapping[str, Any] = field(default_factory=dict)
    time: float = 0.0
    path: Path | None = None

    def describe(self) -> str:
        """``c1a (tcp/127.0.0.1:4711, pid 123)``."""
        return f"{self.fleet} ({self.endpoint}, pid {self.pid})"


def registry_dir(env: Mapping[str, str] | None = None) -> Path:
    """The per-user directory of fleet entries (not created)."""
    own, xdg = env_value(EnvVar.RUNTIME_DIR, env), env_value(EnvVar.XDG_RUNTIME_DIR, env)
    if own:
        return Path(own)
    if xdg:
        return Path(xdg) / "twinfleet"
    return Path(tempfile.gettempdir()) / f"twinfleet-{os.getuid()}"


def _checked_dir(create: bool) -> Path | None:
    """The registry directory, made owner-only; None if it does not exist and `create` is off."""
    path = registry_dir()
    if create:
        path.mkdir(mode=0o700, parents=True, exist_ok=True)
    try:
        info = path.lstat()
    except FileNotFoundError:
        return None
    if not stat.S_ISDIR(info.st_mode) or info.st_uid != os.getuid():
        raise RegistryError(f"fleet registry {path}: not a directory owned by you; "
                            f"remove it or set {DIR_ENV}")
    if info.st_mode & 0o077:
        if not create:
            raise RegistryError(f"fleet registry {path}: others may read or write it "
                                f"(mode {stat.S_IMODE(info.st_mode):o}); run chmod 700 {path}")
        os.chmod(path, 0o700)
    return path


def process_start(pid: int) -> int | None:
    """The start time of process `pid` in clock ticks since boot (/proc), or None if unknown."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = text.rsplit(")", 1)[-1].split()
    return int(fields[19]) if len(fields) > 19 else None  # field 22 of stat(5)


def _alive(pid: int, started: int | None) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass  # exists, someone else's: the start tick decides
    now = process_start(pid)
    return started is None or now is None or now == started


def register(fleet: str, endpoint: str, *, scenario: str = "", kind: str = "launch",
             params: Mapping[str, Any] | None = None,
             extra: Mapping[str, Any] | None = None) -> Path:
    """Write this process's entry for `fleet`; returns its path (give it to `unregister`)."""
    directory = _checked_dir(create=True)
    assert directory is not None
    pid = os.getpid()
    doc = {"format": FORMAT, "fleet": fleet, "endpoint": endpoint, "pid": pid,
           "started": process_start(pid), "scenario": scenario, "kind": kind,
           "params": dict(params or {}), "extra": dict(extra or {}), "time": time.time()}
    path = directory / f"{fleet}-{pid}.json"
    tmp = directory / f".{fleet}-{pid}.json.tmp"
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as f:
        json.dump(doc, f)
    os.replace(tmp, path)  # readers never see half an entry
    return path


def write_beside(entry: Path, suffix: str, data: bytes) -> Path:
    """Write `data` owner-only beside `entry` as ``<fleet>-<pid>.<suffix>`` (a secret of that
    run, e.g. its router's TLS key); `unregister` removes it with the entry."""
    path = entry.with_name(f"{entry.stem}.{suffix}")
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "wb") as f:
        f.write(data)
    return path


def unregister(path: Path | None) -> None:
    """Remove an entry written by `register`, and what was written beside it (nothing if
    it is already gone)."""
    if path is not None:
        for beside in [path, *path.parent.glob(f"{path.stem}.*")]:
            with contextlib.suppress(FileNotFoundError):
                beside.unlink()


def _read(path: Path) -> FleetEntry | None:
    try:
        doc = json.loads(path.read_text())
        if doc.get("format") != FORMAT:
            return None
        return FleetEntry(fleet=str(doc["fleet"]), endpoint=str(doc["endpoint"]),
                          pid=int(doc["pid"]), started=doc.get("started"),
                          scenario=str(doc.get("scenario", "")), kind=str(doc.get("kind", "launch")),
                          params=doc.get("params") or {}, extra=doc.get("extra") or {},
                          time=float(doc.get("time") or 0.0), path=path)
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None


def running_fleets() -> list[FleetEntry]:
    """Every live entry, oldest first; stale entries (their process is gone) are removed."""
    directory = _checked_dir(create=False)
    if directory is None:
        return []
    entries = []
    for path in sorted(directory.glob("*.json")):
        entry = _read(path)
        if entry is None:
            continue
        if not _alive(entry.pid, entry.started):
            unregister(path)
            continue
        entries.append(entry)
    return sorted(entries, key=lambda e: (e.time, e.fleet))


def find_fleet(fleet: str = "*", entries: Sequence[FleetEntry] | None = None) -> FleetEntry:
    """The one running fleet called `fleet` (``*``: the only one running).

    Raises:
        RegistryError: none runs, or several match; the text names them and what to do.
    """
    entries = running_fleets() if entries is None else list(entries)
    matching = [e for e in entries if fleet in ("*", e.fleet)]
    if len(matching) == 1:
        return matching[0]
    if not matching:
        if not entries:
            raise RegistryError("no twinfleet fleet is running on this machine; start one with "
                                "`twinfleet launch SCENARIO` (e.g. `twinfleet launch demo`), or "
                                "give --connect EP of a router elsewhere")
        raise RegistryError(f"no fleet named {fleet!r} is running; running: "
                            + ", ".join(e.describe() for e in entries))
    names = ", ".join(e.describe() for e in matching)
    if fleet == "*":
        twice = len({e.fleet for e in matching}) < len(matching)
        raise RegistryError(f"{len(matching)} fleets are running: {names}; choose one with "
                            "--fleet NAME" + (" (or --connect EP)" if twice else ""))
    raise RegistryError(f"{len(matching)} fleets named {fleet!r} are running: {names}; choose "
                        "one with --connect EP")
