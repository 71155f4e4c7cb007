"""The fleet registry: owner-only entries, stale ones dropped by pid, one-line answers."""

from __future__ import annotations

import json
import os
import stat
import subprocess
import sys

import pytest

from twinfleet.runtime.access import registry
from twinfleet.runtime.access.registry import RegistryError, find_fleet, register, running_fleets


@pytest.fixture
def home(tmp_path, monkeypatch):
    monkeypatch.setenv(registry.DIR_ENV, str(tmp_path / "reg"))
    return tmp_path / "reg"


def test_an_entry_is_owner_only_and_found(home):
    path = register("c1a", "tcp/127.0.0.1:4711", scenario="launch/c1a.yaml",
                    params={"overrides": ["r1.speed=0.4"]}, extra={"later": "credentials"})
    assert stat.S_IMODE(home.stat().st_mode) == 0o700
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    entry = find_fleet()
    assert (entry.fleet, entry.endpoint, entry.pid) == ("c1a", "tcp/127.0.0.1:4711", os.getpid())
    assert entry.params == {"overrides": ["r1.speed=0.4"]} and entry.extra["later"] == "credentials"
    registry.unregister(path)
    assert running_fleets() == []


def test_none_several_and_a_wrong_name_are_one_line_each(home):
    with pytest.raises(RegistryError, match="no twinfleet fleet is running.*twinfleet launch"):
        find_fleet()
    register("c1a", "tcp/127.0.0.1:1")
    register("demo", "tcp/127.0.0.1:2")
    with pytest.raises(RegistryError, match=r"2 fleets are running: .*choose one with --fleet NAME"):
        find_fleet()
    assert find_fleet("demo").endpoint == "tcp/127.0.0.1:2"
    with pytest.raises(RegistryError, match="no fleet named 'c1b' is running; running: c1a"):
        find_fleet("c1b")
    for name in ("c1b", "*"):
        with pytest.raises(RegistryError) as caught:
            find_fleet(name)
        assert "\n" not in str(caught.value)


def test_an_entry_whose_process_is_gone_is_stale_and_removed(home):
    done = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)
    dead = int(done.stdout)
    register("live", "tcp/127.0.0.1:1")
    stale = home / f"ghost-{dead}.json"
    stale.write_text(json.dumps({"format": registry.FORMAT, "fleet": "ghost",
                                 "endpoint": "tcp/127.0.0.1:9", "pid": dead}))
    recycled = home / "reused-1.json"  # a live pid, but not the process that registered
    recycled.write_text(json.dumps({"format": registry.FORMAT, "fleet": "reused",
                                    "endpoint": "tcp/127.0.0.1:8", "pid": os.getpid(),
                                    "started": -1}))
    assert [e.fleet for e in running_fleets()] == ["live"]
    assert not stale.exists() and not recycled.exists()


def test_a_directory_others_can_write_is_refused(home):
    home.mkdir(mode=0o700)
    os.chmod(home, 0o777)
    with pytest.raises(RegistryError, match="others may read or write it"):
        running_fleets()
    register("c1a", "tcp/127.0.0.1:1")  # the launcher, owning it, takes it back to 0700
    assert stat.S_IMODE(home.stat().st_mode) == 0o700


def test_wait_says_once_that_it_waits_and_gives_up_after_its_timeout(home, capsys):
    from twinfleet.cli import main

    for words in (["topic", "hz", "/chatter"], ["foxglove"], ["record", "-o", "x.mcap"]):
        assert main([*words, "--wait", "--wait-timeout", "0.3"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err[0] == "waiting for a fleet to be launched on this machine (up to 0.3 s)", err
        assert len(err) == 2 and "no fleet was launched on this machine within 0.3 s" in err[1]


def test_wait_finds_a_fleet_registered_while_it_waits(home):
    import threading

    from twinfleet.runtime.access.connection import connection
    from twinfleet.runtime.access.registry import unregister

    args = type("Args", (), {"connect": None, "fleet": "demo", "credentials": None,
                             "wait": True, "wait_timeout": 10.0})()
    paths = []
    later = threading.Timer(0.3, lambda: paths.append(register("demo", "tcp/127.0.0.1:9")))
    later.start()
    try:
        conn = connection(args)
    finally:
        later.join()
        for path in paths:
            unregister(path)
    assert (conn.fleet, conn.endpoint, conn.found) == ("demo", "tcp/127.0.0.1:9", "registry")
