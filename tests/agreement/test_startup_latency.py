"""A fleet's first messages take longer: the timing model keeps their latency apart.

`calibrate` fits messages sent in the first `startup_ms` fleet ms into a
histogram of their own (the others' histograms do not see them), the file
keeps it, a model stretched to another time scale stretches it and its
window, and a simulation draws a message's latency from it when the message
is sent inside the window.
"""

from __future__ import annotations

import json
import random
from pathlib import Path

import pytest

from twinfleet.agreement.calibrate import calibrate
from twinfleet.checker.choices import LatencySite
from twinfleet.checker.sampling import SamplingChooser
from twinfleet.checker.timing import Histogram, TimingModel, load_timing, save_timing
from twinfleet.runtime.core.eventlog import EVENTS_FORMAT

pytestmark = pytest.mark.offline  # starts no fleet, opens no Zenoh session


def _log(path: Path) -> Path:
    lines = [{"format": EVENTS_FORMAT, "kind": "header", "node": "sink", "time_scale": 2.0}]
    for stamp in range(0, 2000, 2):
        lines.append({"node": "sink", "kind": "delivery", "topic": "/x", "stamp": stamp,
                      "t": stamp + (50 if stamp < 20 else 5)})
    path.write_text("\n".join(json.dumps(x) for x in lines) + "\n")
    return path


def test_calibrate_fits_the_start_up_apart_and_the_file_keeps_it(tmp_path: Path) -> None:
    model = calibrate([_log(tmp_path / "sink.events.jsonl")])
    assert model.startup is not None and model.startup.values == (50,)
    assert model.startup.samples == 10  # stamps 0, 2, ..., 18
    assert model.startup_ms == 20 and model.latency_of("/x").values == (5,)
    assert model.latency_of("/x", sent=10).values == (50,)
    save_timing(model, tmp_path / "timing.yaml")
    back = load_timing(tmp_path / "timing.yaml")
    assert back.startup == model.startup and back.startup_ms == 20
    faster = back.at_time_scale(4.0)
    assert faster.startup is not None and faster.startup.values == (100,)
    assert faster.startup_ms == 40
    assert calibrate([tmp_path / "sink.events.jsonl"], startup_ms=0).startup is None


def test_a_message_sent_in_the_window_draws_the_start_up_latency() -> None:
    model = TimingModel(Histogram((5,), (1.0,), 100), startup=Histogram((50,), (1.0,), 10),
                        startup_ms=20)
    chooser = SamplingChooser(random.Random(1), model)
    assert chooser.branch(60, LatencySite("/x", 0, sent=10)) == 50
    assert chooser.branch(60, LatencySite("/x", 0, sent=20)) == 5
    assert chooser.branch(60, LatencySite("/x", 0)) == 5


def test_calibrate_names_startup_ms_when_the_window_took_every_message(tmp_path: Path,
                                                                       capsys) -> None:
    from twinfleet.cli import main

    log = tmp_path / "fast.events.jsonl"  # a protocol over within 20 fleet ms
    lines = [{"format": EVENTS_FORMAT, "kind": "header", "node": "sink", "time_scale": 1.0}]
    lines += [{"node": "sink", "kind": "delivery", "topic": "/x", "stamp": s, "t": s + 2}
              for s in range(0, 16, 2)]
    log.write_text("\n".join(json.dumps(x) for x in lines) + "\n")
    assert main(["calibrate", str(log), "-o", str(tmp_path / "t.yaml")]) == 2
    err = capsys.readouterr().err
    assert "all 8 handled messages with a send stamp were sent in the first 20 fleet ms" in err
    assert "--startup-ms" in err
    assert main(["calibrate", str(log), "-o", str(tmp_path / "t.yaml"), "--startup-ms", "0"]) == 0
