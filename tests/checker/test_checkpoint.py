"""Checkpoints: a stopped or killed search resumes to exactly the uninterrupted result."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.checker.helpers import node, replay_confirms, scenario
from tests.support import child_env
from twinfleet.checker import checkpoint, commands
from twinfleet.checker.checkpoint import CheckpointError
from twinfleet.checker.driver import CheckOptions, check

pytestmark = pytest.mark.timeout(120)

ROOT = Path(__file__).resolve().parents[2]
C1A = ROOT / "twinfleet" / "launch" / "c1a.yaml"
C1A_REBECA = ROOT / "twinfleet" / "launch" / "c1a_rebeca.yaml"
DOOR = [node("opener", "Opener"), node("locker", "Locker"), node("door", "Door")]


def _counts(result):
    s = result.statistics
    return (result.status, result.reason, s.states, s.transitions, s.depth, s.initial_states)


@pytest.mark.parametrize(("path", "search", "stop_at"), [
    # with edges for the `eventually` property, checked after resuming; the reduction (on by
    # default under ros: 6,176 of C1a's 41,608 states) resumes with the send relation it learned
    (C1A, "bfs", 3_000),
    (C1A_REBECA, "dfs", 7_000),
])
@pytest.mark.slow
def test_resume_after_a_state_limit_matches_an_uninterrupted_search(tmp_path, path, search,
                                                                    stop_at):
    whole = check(path, CheckOptions(search=search))
    assert whole.status == "holds"
    ckpt = str(tmp_path / "run.ckpt")
    first = check(path, CheckOptions(search=search, max_states=stop_at, checkpoint=ckpt))
    assert first.status == "unknown"
    assert first.statistics.states == stop_at
    assert first.checkpoint == ckpt
    resumed = check(None, CheckOptions(resume=ckpt))
    assert resumed.search == search
    assert resumed.resumed_from == ckpt
    assert _counts(resumed) == _counts(whole)


@pytest.mark.slow
def test_resume_twice_and_from_a_periodic_checkpoint_of_a_killed_run(tmp_path, monkeypatch):
    whole = check(C1A_REBECA, CheckOptions())
    ckpt = tmp_path / "periodic.ckpt"
    killed = tmp_path / "killed.ckpt"
    save = checkpoint.save

    def save_and_grab(path, meta, store, frontier, counters):
        save(path, meta, store, frontier, counters)
        if len(store) > 4_000 and not killed.exists():  # what a killed process leaves behind
            shutil.copy(path, killed)

    monkeypatch.setattr(checkpoint, "save", save_and_grab)
    check(C1A_REBECA, CheckOptions(checkpoint=str(ckpt), checkpoint_every_s=0.05))
    assert killed.exists()
    # Resume the copy with a limit (it keeps writing to the same file), then again to the end.
    part = check(None, CheckOptions(resume=str(killed), max_states=12_000))
    assert part.status == "unknown"
    assert part.statistics.states == 12_000
    resumed = check(None, CheckOptions(resume=str(killed)))
    assert _counts(resumed) == _counts(whole)


def test_resumed_search_finds_the_same_violation_and_trace(tmp_path):
    path = scenario(tmp_path, DOOR, name="race")
    whole = check(path, CheckOptions(trace_out=str(tmp_path / "a.json")))
    ckpt = str(tmp_path / "race.ckpt")
    first = check(path, CheckOptions(max_states=3, checkpoint=ckpt))
    assert first.status == "unknown"
    resumed = check(path, CheckOptions(resume=ckpt, trace_out=str(tmp_path / "b.json")))
    assert _counts(resumed) == _counts(whole)
    assert resumed.trace["steps"] == whole.trace["steps"]
    assert replay_confirms(resumed)


def test_ctrl_c_saves_a_checkpoint_that_resumes(tmp_path):
    path = scenario(tmp_path, [node("a", "WaiterA", inbox="/go_a", outbox="/go_b", first=True),
                               node("b", "WaiterB", inbox="/go_b", outbox="/go_a"),
                               node("p", "Picker", second=[0, 100])], name="mix",
                    properties=[{"name": "f", "kind": "eventually",
                                 "expr": "a.stage == 'done' and b.stage == 'done'"}])
    whole = check(path, CheckOptions(reduction="none"))  # the Search below is unreduced
    calls = []

    def interrupt(stats):
        calls.append(stats.states)
        if len(calls) == 3:
            raise KeyboardInterrupt

    ckpt = str(tmp_path / "int.ckpt")
    from twinfleet.checker import PropertySet, Search, System
    from twinfleet.checker.driver import load

    scen = load(path)
    props = PropertySet.from_scenario(scen)
    search = Search(System(scen, properties=props), props, progress=interrupt, progress_interval=0,
                    checkpoint=ckpt, checkpoint_meta={})
    outcome = search.run("bfs")
    assert outcome.reason == "interrupted (Ctrl-C)"
    assert outcome.checkpoint == ckpt
    assert outcome.statistics.states < whole.statistics.states
    # The meta-less checkpoint was written by the API; resume it through the API too.
    from twinfleet.checker.checkpoint import load as load_checkpoint

    again = Search(System(scen, properties=props), props)
    again.restore(load_checkpoint(ckpt))
    done = again.run("bfs").statistics
    assert (done.states, done.transitions, done.depth) == (
        whole.statistics.states, whole.statistics.transitions, whole.statistics.depth)


def test_cli_checkpoint_and_resume(tmp_path, capsys):
    path = scenario(tmp_path, [node("c", "Counter", modulo=0, cap=300)], name="cap")
    ckpt = tmp_path / "cap.ckpt"
    assert commands.main([str(path), "--max-states", "100", "--checkpoint", str(ckpt),
                          "--quiet"]) == 2
    out = capsys.readouterr().out
    assert f"twinfleet check --resume {ckpt}" in out
    assert commands.main(["--resume", str(ckpt), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert (res["verdict"], res["states"], res["transitions"]) == ("holds", 301, 301)
    assert res["resumed_from"] == str(ckpt)
    # A changed scenario, a different semantics, a non-checkpoint: exit 2 with a message.
    assert commands.main(["--resume", str(ckpt), "--semantics", "rebeca"]) == 2
    assert "cannot resume with rebeca" in capsys.readouterr().err
    path.write_text(path.read_text() + "\n# edited\n")
    assert commands.main(["--resume", str(ckpt)]) == 2
    assert "changed since the checkpoint was written" in capsys.readouterr().err
    assert commands.main(["--resume", str(path)]) == 2
    assert "cannot read checkpoint" in capsys.readouterr().err
    assert commands.main(["check"]) == 2
    assert "give a scenario file" in capsys.readouterr().err


def test_checkpoint_errors_are_bad_input(tmp_path):
    with pytest.raises(CheckpointError, match="no such checkpoint"):
        check(None, CheckOptions(resume=str(tmp_path / "missing.ckpt")))


_USER_NODES = '''
from dataclasses import dataclass

from twinfleet import Context, Node, every, message, subscribe


@message("tally/Note")
class Note:
    total: int


@dataclass
class TallyState:
    total: int = 0
    ticks: int = 0
    heard: int = 0


class Tally(Node):
    def initial_state(self) -> TallyState:
        return TallyState()

    @every(5)
    def tick(self, ctx: Context) -> None:
        if self.state.ticks < 6:
            self.state.ticks += 1
            self.state.total += ctx.choose([0, 1, 2])
            ctx.publish("/notes", Note(self.state.total))

    @subscribe("/notes")
    def on_note(self, ctx: Context, msg: Note) -> None:
        self.state.heard += 1
'''


@pytest.mark.slow
def test_a_checkpoint_of_the_users_own_nodes_resumes_from_another_folder(tmp_path):
    # The saved frontier holds messages of the user's classes: a resume that names only
    # the checkpoint must find their module beside the scenario, as the first run did.
    home, elsewhere = tmp_path / "project", tmp_path / "elsewhere"
    home.mkdir()
    elsewhere.mkdir()
    (home / "tally.py").write_text(_USER_NODES)
    path = home / "tally.yaml"
    path.write_text("name: tally\nnodes:\n  - {name: t1, class: 'tally:Tally'}\n"
                    "  - {name: t2, class: 'tally:Tally'}\n"
                    "properties:\n  - {name: small, kind: invariant, expr: 't1.total < 99'}\n")
    ckpt = tmp_path / "tally.ckpt"

    def run(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, "-m", "twinfleet", "check", *args, "--json"],
                              cwd=elsewhere, env=child_env(), capture_output=True, text=True,
                              timeout=120, check=False)

    first = run(str(path), "--checkpoint", str(ckpt), "--max-states", "100")
    assert first.returncode == 2 and ckpt.is_file(), first.stderr
    resumed = run("--resume", str(ckpt))
    assert resumed.returncode == 0, resumed.stderr
    whole = check(path, CheckOptions())
    counts = json.loads(resumed.stdout)
    assert (counts["states"], counts["transitions"]) == (whole.statistics.states,
                                                         whole.statistics.transitions)
