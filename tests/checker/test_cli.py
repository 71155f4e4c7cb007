"""The check/replay commands: exit codes, JSON output, bad input, the demo scenario."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.checker.helpers import node, scenario
from twinfleet.checker import commands
from twinfleet.cli import build_parser

pytestmark = pytest.mark.timeout(60)

ROOT = Path(__file__).resolve().parents[2]
DOOR = [node("opener", "Opener"), node("locker", "Locker"), node("door", "Door")]


def test_check_exit_codes_and_json(tmp_path, capsys):
    ok = scenario(tmp_path, [node("ping", "Ping"), node("pong", "Pong")], name="ok")
    assert commands.main([str(ok), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert (out["verdict"], out["states"], out["transitions"], out["rmc_transitions"]) == (
        "holds", 7, 6, 7)
    assert out["exit_code"] == 0
    assert out["peak_memory_mb"] > 0

    bad = scenario(tmp_path, DOOR, name="race")
    trace = tmp_path / "race.json"
    assert commands.main(["check", str(bad), "--trace-out", str(trace), "--quiet"]) == 1
    text = capsys.readouterr().out
    assert "VIOLATED no_failure" in text
    assert f"twinfleet replay {trace}" in text
    assert commands.main(["replay", str(trace)]) == 1
    assert "replay confirmed" in capsys.readouterr().out

    inf = scenario(tmp_path, [node("c", "Counter", modulo=0)], name="inf")
    assert commands.main([str(inf), "--max-states", "20", "--quiet"]) == 2
    assert "exit 2: no answer (max-states 20" in capsys.readouterr().out


def test_bad_scenario_exit_2_without_traceback(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("nodes:\n  - {name: x, class: 'no.such:Thing'}\n")
    assert commands.main([str(bad)]) == 2
    err = capsys.readouterr().err
    assert "nodes[0].class" in err
    assert "Traceback" not in err
    missing = tmp_path / "missing.yaml"
    assert commands.main([str(missing)]) == 2
    assert "cannot read scenario file" in capsys.readouterr().err
    wrong = scenario(tmp_path, [node("c", "Counter")], name="wrong", properties=[
        {"name": "p", "kind": "invariant", "expr": "c.nonexistent > 0"}])
    assert commands.main([str(wrong)]) == 2
    assert "has no field 'nonexistent'" in capsys.readouterr().err
    not_trace = tmp_path / "x.json"
    not_trace.write_text("{}")
    assert commands.main(["replay", str(not_trace)]) == 2


def _commands(parser: argparse.ArgumentParser, words: tuple[str, ...] = ()):
    """Every (sub)command parser of the `twinfleet` command line, with its words."""
    yield words, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _commands(sub, (*words, name))


def test_every_flag_of_every_command_has_help():
    commands_seen = set()
    for words, parser in _commands(build_parser()):
        commands_seen.add(" ".join(words))
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                continue
            assert action.help, f"twinfleet {' '.join(words)} " \
                f"{action.option_strings or action.dest} has no help"
    assert {"check", "replay", "launch", "validate", "render", "topic echo"} <= commands_seen


def test_each_command_module_adds_the_commands_the_cli_names_for_it():
    # `check` builds its own module's parser only (`COMMAND_MODULES`), so the table must
    # name every command its module adds, in --help's order.
    import importlib

    from twinfleet.cli.main import COMMAND_MODULES, named_command

    everything: list[str] = []
    for module, names in COMMAND_MODULES:
        sub = argparse.ArgumentParser().add_subparsers()
        importlib.import_module(module).register(sub)
        assert tuple(sub.choices) == names
        everything += names
    assert list(build_parser()._subparsers._group_actions[0].choices) == everything  # type: ignore[union-attr]
    assert list(build_parser("check")._subparsers._group_actions[0].choices) == \
        ["check", "trace"]  # type: ignore[union-attr]
    assert named_command(["--debug", "check", "c1a"]) == "check"
    assert named_command(["--version"]) is None and named_command(["chek"]) is None


def test_check_imports_no_other_command_module():
    code = ("import sys\nfrom twinfleet.cli.main import build_parser, named_command\n"
            "build_parser(named_command(['check', 'c1a'])).parse_args(['check', 'c1a'])\n"
            "print(sorted(m for m in sys.modules if m.endswith('commands')))")
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=ROOT, timeout=60, env=env, check=True).stdout
    assert out.strip() == "['twinfleet.checker.commands']"


def test_python_m_checker_subprocess_and_cross_process_replay(tmp_path):
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin", "PYTHONHASHSEED": "12345"}
    path = scenario(tmp_path, [node("ping", "Ping"), node("pong", "Pong")], name="pp")
    proc = subprocess.run([sys.executable, "-m", "twinfleet.checker", str(path), "--json"],
                          capture_output=True, text=True, cwd=ROOT, timeout=60, env=env)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["states"] == 7
    # A trace written by this process replays in another one with another hash seed.
    race = scenario(tmp_path, DOOR, name="race")
    trace = tmp_path / "race.trace.json"
    assert commands.main([str(race), "--quiet", "--trace-out", str(trace)]) == 1
    proc = subprocess.run([sys.executable, "-m", "twinfleet.checker", "replay", str(trace)],
                          capture_output=True, text=True, cwd=ROOT, timeout=60, env=env)
    assert proc.returncode == 1, proc.stderr
    assert proc.stdout.startswith("replay confirmed: no_failure violated after 3 steps")


def test_demo_scenario_checks_with_a_limit(tmp_path, capsys):
    demo = ROOT / "twinfleet" / "launch" / "demo.yaml"
    code = commands.main([str(demo), "--max-states", "3000", "--json",
                          "--trace-out", str(tmp_path / "demo.json")])
    out = json.loads(capsys.readouterr().out)
    # The talker counts for ever: no finite answer, but no violation in 3000 states.
    assert code == 2
    assert out["verdict"] == "unknown"
    assert out["states"] == 3000
    assert out["violation"] is None
    code = commands.main([str(demo), "--max-depth", "40", "--json", "--semantics", "rebeca"])
    out = json.loads(capsys.readouterr().out)
    assert code == 2
    assert out["semantics"] == "rebeca"
    assert "max-depth 40" in out["reason"]


def test_a_user_package_beside_the_scenario_is_found_from_any_directory(tmp_path):
    # A user's own `nodes` package next to the scenario file: found by the console script
    # (whose sys.path has neither the scenario's folder nor the working directory), and
    # `@handler` works bare, like `@on_start`.
    project = tmp_path / "project"
    (project / "nodes").mkdir(parents=True)
    (project / "nodes" / "__init__.py").write_text("")
    (project / "nodes" / "pair.py").write_text(
        "from dataclasses import dataclass\n"
        "from twinfleet import Context, Node, handler, on_start\n\n"
        "@dataclass\nclass S:\n    fired: int = 0\n\n"
        "class Once(Node):\n"
        "    def initial_state(self):\n        return S()\n\n"
        "    @on_start\n    def start(self, ctx: Context) -> None:\n"
        "        ctx.after(10, self.fire)\n\n"
        "    @handler\n    def fire(self, ctx: Context) -> None:\n"
        "        self.state.fired += 1\n")
    (project / "once.yaml").write_text(
        "name: once\nnodes:\n  - {name: a, class: 'nodes.pair:Once'}\n"
        "properties:\n  - {name: fires_once, kind: invariant, expr: 'a.fired <= 1'}\n")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    code = ("import sys; sys.path = [p for p in sys.path if p not in ('', '.')]; "
            "from twinfleet.cli import main; sys.exit(main(sys.argv[1:]))")
    proc = subprocess.run([sys.executable, "-c", code, "check", str(project / "once.yaml"),
                           "--json"], capture_output=True, text=True, cwd=elsewhere, timeout=60)
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout)
    assert (result["verdict"], result["states"]) == ("holds", 2)


def test_check_imports_no_loop_package_metadata_or_rclpy_layer(tmp_path):
    # `twinfleet check` waits for every module it imports: asyncio (the live commands),
    # importlib.metadata (--version) and the rclpy layer (rclpy nodes) are imported only
    # by what uses them.
    path = scenario(tmp_path, [node("ping", "Ping"), node("pong", "Pong")], name="pp")
    unwanted = ["asyncio", "importlib.metadata", "twinfleet.runtime.fleet.fleet_result",
                "twinfleet.rclpy.api"]
    code = (f"import sys; from twinfleet.cli.main import main; code = main(['check', "
            f"{str(path)!r}, '--quiet']); print(code, sorted(set({unwanted!r}) & set(sys.modules)))")
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=tmp_path, timeout=60, env=env)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.splitlines()[-1] == "0 []"
    version = subprocess.run([sys.executable, "-m", "twinfleet", "--version"],
                             capture_output=True, text=True, cwd=ROOT, timeout=60, env=env)
    assert version.returncode == 0 and version.stdout.startswith("twinfleet "), version.stderr
