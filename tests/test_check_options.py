"""No check option is declared twice: `check`, `sweep` and `experiment` take the search
options from one function (`checker.options.add_check_arguments`), and `CheckOptions`
holds enums, not strings (issue 37, acceptance 3)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from twinfleet.checker.driver import CheckOptions
from twinfleet.checker.options import ReductionMode, SearchOrder, Semantics
from twinfleet.cli.main import build_parser
from twinfleet.runtime.scenario.spec import ScenarioError

ROOT = Path(__file__).resolve().parents[1]
FLAGS = ("--max-states", "--max-time", "--max-depth", "--search", "--reduction",
         "--no-contract-checks")


def test_every_check_option_is_declared_once_in_the_sources():
    text = "\n".join(p.read_text() for p in (ROOT / "twinfleet").rglob("*.py"))
    for flag in FLAGS:
        declared = re.findall(rf"add_argument\(\s*\"{flag}\"", text)
        assert len(declared) == 1, (flag, len(declared))


def _actions(command: str) -> dict[str, object]:
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    parser = sub.choices[command]  # type: ignore[attr-defined]
    return {o: a for a in parser._actions for o in a.option_strings}


def test_check_sweep_and_experiment_share_the_declaration():
    check, sweep, experiment = _actions("check"), _actions("sweep"), _actions("experiment")
    for flag in FLAGS[:-3] + FLAGS[-2:]:  # --search offers what the command has (below)
        assert check[flag].help == sweep[flag].help, flag  # type: ignore[attr-defined]
    for flag in ("--max-states", "--max-time"):
        assert check[flag].help == experiment[flag].help, flag  # type: ignore[attr-defined]
    assert tuple(sweep["--search"].choices) == (SearchOrder.BFS, SearchOrder.DFS)  # type: ignore[attr-defined]


def test_the_parsed_options_are_enums():
    args = build_parser().parse_args(["check", "c1a", "--search", "dfs", "--reduction", "none",
                                      "--semantics", "rebeca"])
    assert (args.search, args.reduction, args.semantics) == (
        SearchOrder.DFS, ReductionMode.NONE, Semantics.REBECA)
    options = CheckOptions(search="random", semantics="ros", reduction="por")  # type: ignore[arg-type]
    assert options.search is SearchOrder.RANDOM and options.semantics is Semantics.ROS
    assert options.reduction is ReductionMode.POR
    with pytest.raises(ScenarioError, match="unknown search 'breadth'; expected one of bfs, "
                       "dfs, random"):
        CheckOptions(search="breadth")  # type: ignore[arg-type]


def test_a_word_that_is_no_choice_is_argparses_own_error(capsys):
    for argv, says in ((["check", "c1a", "--search", "bread"],
                        "invalid choice: 'bread' (choose from bfs, dfs, random)"),
                       (["sweep", "c1a", "--search", "random"],
                        "invalid choice: 'random' (choose from bfs, dfs)")):
        with pytest.raises(SystemExit) as exit_:
            build_parser().parse_args(argv)
        assert exit_.value.code == 2 and says in capsys.readouterr().err
