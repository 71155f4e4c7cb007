"""Re-measure every behavioural figure the docs state, and say whether it is still the same.

    PYTHONPATH=. python3 benchmarks/docs_figures.py [--only TEXT ...] [--list] [--docs DIR]

A behavioural figure is what a deterministic command gives: a verdict, a number of
states or transitions, the time of a violation. The script reads the docs' tables
(README.md, docs/results.md, docs/reduction.md, docs/experiment.md,
docs/discretization.md, docs/performance.md), so an edited figure is what it checks,
runs the command each figure names (`twinfleet check ... --json`, in this process through
`twinfleet.cli.main`, each distinct command once), and prints per figure where it is,
what the doc says, what was measured and whether the two are the same; the last line
is "N of M figures the same" (exit 0 when all are, 1 when one differs, 2 on bad input).

Figures in prose rather than tables are named explicitly below (`PROSE`), each by a
pattern that must match its doc line. Not checked, being no behaviour of the checker:
times in seconds, rates, bytes and ratios (the machine's, not the code's); "no answer
in 60 s" cells; the generated-system rows of docs/reduction.md (sums over systems that
another benchmark draws); the live columns of docs/experiment.md and its table kept
from before issue #16; the fine and coarse rows of docs/discretization.md (scenarios its
study writes, hundreds of thousands of states each); docs/distributed.md's C1a with
0-1 ms of latency (5,985,410 states, minutes); docs/rclpy.md's programs (their own
tests, `tests/rclpy/`, check them).
"""

from __future__ import annotations

import argparse
import atexit
import contextlib
import io
import json
import re
import shutil
import sys
import tempfile
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
for _path in (ROOT, ROOT / "benchmarks"):
    if str(_path) not in sys.path:
        sys.path.insert(0, str(_path))

from twinfleet.cli.main import main as twinfleet  # noqa: E402

DATA = ROOT / "tests" / "data"
NUMBER = r"\d[\d,]*"
_PAIR = re.compile(rf"({NUMBER})\s*/\s*({NUMBER})")
_TIME = re.compile(r"t\s*=\s*(\d[\d,]*(?:\.\d+)?)\s*(ms|s)\b")
_SCRATCH = Path(tempfile.mkdtemp(prefix="docs_figures-"))  # scenarios the script writes
atexit.register(shutil.rmtree, _SCRATCH, ignore_errors=True)


# ------------------------------------------------------------------ what is said, what is run


@dataclass(frozen=True)
class Run:
    """One deterministic command: a `twinfleet check` of a scenario, or (`order="rmc"`) the
    tests' search in RMC's order (`tests/rmc/rmc_order.py`)."""

    scenario: str  # a shipped name or a path
    semantics: str | None = None  # None: the scenario's own
    reduction: str | None = None  # None: the default of the semantics
    order: str = "bfs"


@dataclass(frozen=True)
class Outcome:
    """What a run gave, in the terms the docs use."""

    verdict: str  # "holds" or "violated"
    states: int
    transitions: int
    rmc_transitions: int  # plus one per initial state, as RMC counts
    t_ms: float | None  # the time of the violation


@dataclass(frozen=True)
class Claim:
    """What a doc says of one run; None: not said."""

    verdict: str | None = None
    states: int | None = None
    transitions: int | None = None
    rmc: bool = False  # transitions counted as RMC counts them
    t_ms: float | None = None
    t_unit_ms: float = 1.0  # the stated time's precision: 100 for "t=27.4 s"

    def says(self) -> str:
        """The claim as one short text."""
        return _text(self.verdict, self.states, self.transitions, self.t_ms)

    def measured(self, got: Outcome) -> str:
        """What was measured, showing only what the claim states."""
        transitions = got.rmc_transitions if self.rmc else got.transitions
        t = None if got.t_ms is None else round(got.t_ms / self.t_unit_ms) * self.t_unit_ms
        return _text(got.verdict if self.verdict else None,
                     got.states if self.states is not None else None,
                     transitions if self.transitions is not None else None,
                     t if self.t_ms is not None else None)


def _text(verdict: str | None, states: int | None, transitions: int | None,
          t_ms: float | None) -> str:
    parts = [verdict or ""]
    if states is not None:
        parts.append(f"{states:,}" + (f" / {transitions:,}" if transitions is not None else ""))
    if t_ms is not None:
        parts.append(f"t={t_ms:,.0f} ms")
    return ", ".join(p for p in parts if p)


@dataclass(frozen=True)
class Figure:
    """One figure of the docs: where it is, what it is, the run that gives it."""

    where: str  # file:line
    label: str
    run: Run
    claim: Claim


def parse_claim(cell: str, *, rmc: bool) -> Claim | None:
    """A table cell such as ``holds, **18,527 / 43,077**`` or ``collision, 2,832 / 6,262
    (t=9.6 s)``; None when it states no count (a time, "no answer in 60 s", empty)."""
    cell = re.sub("[*¹²³⁴⁵⁶⁷⁸⁹]", "", cell).strip()  # bold and footnote marks
    if not cell or cell.startswith((">", "(")):
        return None
    verdict = _verdict(cell)
    pair = _PAIR.search(cell)
    single = re.fullmatch(NUMBER, cell)
    if pair is None and single is None:
        return None
    states, transitions = ((_int(pair[1]), _int(pair[2])) if pair
                           else (_int(cell), None))
    t_ms, unit = None, 1.0
    if (found := _TIME.search(cell)) is not None:
        value, scale = found[1].replace(",", ""), 1000.0 if found[2] == "s" else 1.0
        unit = scale * 10.0 ** -len(value.partition(".")[2])
        t_ms = float(value) * scale
    return Claim(verdict, states, transitions, rmc, t_ms, unit)


def _verdict(text: str) -> str | None:
    """"holds" or "violated" as the doc words it at the start of `text` (None: not said)."""
    if re.match(r"(holds|satisfied)\b", text, re.I):
        return "holds"
    return "violated" if re.match(r"(collision|violated)\b", text, re.I) else None


def _int(text: str) -> int:
    return int(text.replace(",", ""))


# ------------------------------------------------------------------ the docs' tables


@dataclass(frozen=True)
class Table:
    """A markdown table: its header cells and its rows (line number, cells)."""

    header: tuple[str, ...]
    rows: tuple[tuple[int, tuple[str, ...]], ...]
    before: str = ""  # the last line of text above the table


def tables(path: Path) -> Iterator[Table]:
    """Every table of a markdown file (indented ones included)."""
    block: list[tuple[int, tuple[str, ...]]] = []
    before = ""
    for number, line in enumerate([*path.read_text().splitlines(), ""], 1):
        text = line.strip()
        if text.startswith("|"):
            block.append((number, tuple(c.strip() for c in text.strip("|").split("|"))))
            continue
        if len(block) > 2 and set(block[1][1][0]) <= set("-: "):
            yield Table(block[0][1], tuple(block[2:]), before)
        block = []
        before = text or before


@dataclass(frozen=True)
class Docs:
    """Where the docs are (a checkout's root) and how a line is named."""

    root: Path

    def tables(self, name: str) -> Iterator[Table]:
        """The tables of `name` (relative to the root)."""
        return tables(self.root / name)

    def lines(self, name: str) -> list[str]:
        """The lines of `name`."""
        return (self.root / name).read_text().splitlines()


def scenario(name: str) -> str:
    """A shipped scenario's file (the RMC-order search takes files, not names)."""
    return str(ROOT / "twinfleet" / "launch" / f"{name}.yaml")


def rebeca_columns(docs: Docs) -> Iterator[Figure]:
    """The twinfleet column of the paper/RMC/twinfleet tables (results.md, README.md):
    `cX_rebeca` as it is, transitions as RMC counts them."""
    for name, column in (("docs/results.md", "twinfleet `cX_rebeca`"), ("README.md", "twinfleet")):
        for table in docs.tables(name):
            if column not in table.header or table.header[0] != "case":
                continue
            at = table.header.index(column)
            for number, cells in table.rows:
                case = f"{cells[0].lower()}_rebeca"
                if (claim := parse_claim(cells[at], rmc=True)) is not None:
                    yield Figure(f"{name}:{number}", case, Run(case), claim)


def other_rules(docs: Docs) -> Iterator[Figure]:
    """results.md's table of the same cases under the other semantics and profile
    (unreduced: the table predates the reduction, and its counts are the full graph's)."""
    for table in docs.tables("docs/results.md"):
        if "`cX_rebeca`, ros semantics" not in table.header:
            continue
        for number, cells in table.rows:
            for head, cell in zip(table.header[1:], cells[1:], strict=True):
                suffix = "_rebeca" if "cX_rebeca" in head else ""
                semantics = re.findall(r"\b(ros|rebeca)\b", head.rpartition("`")[2])[-1]
                case = f"{cells[0].lower()}{suffix}"
                if (claim := parse_claim(cell, rmc=True)) is not None:
                    yield Figure(f"docs/results.md:{number}", f"{case} {semantics}",
                                 Run(case, semantics, "none"), claim)


def throughput_rows(docs: Docs) -> Iterator[Figure]:
    """results.md's checker-speed table: its states and transitions (unreduced)."""
    for table in docs.tables("docs/results.md"):
        if table.header[:4] != ("scenario", "store", "states", "transitions"):
            continue
        case = ""
        for number, cells in table.rows:
            if (named := re.search(r"`(\w+)\.yaml`", cells[0])) is not None:
                case = named[1]
            semantics = "ros" if ", ros" in cells[0] else None
            claim = Claim(states=_int(cells[2]), transitions=_int(cells[3]))
            yield Figure(f"docs/results.md:{number}", f"{case} {cells[1]}",
                         Run(case, semantics, "none"), claim)


def contract_rows(docs: Docs) -> Iterator[Figure]:
    """performance.md's node-contract table: states / transitions (unreduced)."""
    for table in docs.tables("docs/performance.md"):
        if table.header[:2] != ("scenario", "states / transitions"):
            continue
        for number, cells in table.rows:
            if (claim := parse_claim(cells[1], rmc=False)) is not None:
                yield Figure(f"docs/performance.md:{number}", cells[0],
                             Run(cells[0], None, "none"), claim)


def experiment_rows(docs: Docs) -> Iterator[Figure]:
    """experiment.md's checker columns (both semantics, unreduced: the tables predate the
    reduction), not the table kept from before issue #16."""
    for table in docs.tables("docs/experiment.md"):
        head = table.header
        if "before issue #16" in table.before or head[0] != "case":
            continue
        for number, cells in table.rows:
            for semantics in ("ros", "rebeca"):
                found = _experiment_cell(head, cells, semantics)
                if found is not None:
                    claim, reduction = found
                    yield Figure(f"docs/experiment.md:{number}",
                                 f"{cells[0]} {semantics} {reduction or ''}".strip(),
                                 Run(cells[0], semantics, reduction), claim)


def _experiment_cell(head: Sequence[str], cells: Sequence[str], semantics: str
                     ) -> tuple[Claim, str | None] | None:
    """The claim of one semantics' columns of an experiment.md row, and the reduction it
    was measured with: the tables with transitions predate the reduction (unreduced),
    those with states only are of the default (`por` under `ros`)."""
    if f"{semantics}: states" in head:
        at = head.index(f"{semantics}: states")
        if not head[at + 1].startswith(f"{semantics}: transitions"):
            return Claim(_verdict(cells[at - 1]), _int(cells[at])), None
        text = f"{cells[at - 1]}, {cells[at]} / {cells[at + 1].split('/')[0]}"
        claim = parse_claim(text, rmc=False)
        return None if claim is None else (claim, "none")
    if (column := f"{semantics}: result (states)") in head:
        cell = cells[head.index(column)]
        count = re.search(rf"\(({NUMBER})\)", cell)
        return None if count is None else (Claim(_verdict(cell), _int(count[1])), None)
    if (column := f"twinfleet `{semantics}` semantics") in head:
        claim = parse_claim(cells[head.index(column)], rmc=True)
        return None if claim is None else (claim, "none")
    return None


def discretization_rows(docs: Docs) -> Iterator[Figure]:
    """discretization.md's "paper" rows (C1a as shipped; the fine and coarse settings are
    scenarios `twinfleet.robots.discretization` writes, not measured here)."""
    for table in docs.tables("docs/discretization.md"):
        if table.header[:2] != ("setting", "profile / semantics"):
            continue
        for number, cells in table.rows:
            if cells[0] != "paper":
                continue
            semantics = cells[1].split("/")[-1].strip()
            case = "c1a_rebeca" if cells[1].startswith("rebeca") else "c1a"
            claim = parse_claim(f"{cells[2]}, {cells[3]} / {cells[4]}", rmc=False)
            if claim is not None:
                yield Figure(f"docs/discretization.md:{number}", f"{case} {semantics}",
                             Run(case, semantics, "none"), claim)


#: results.md's "More variants" rows by the start of their first cell: base case, scan
#: period (ms) and the robots' (speed, max wait, priority), as tests/rmc/test_variants.py
#: builds them
VARIANTS: dict[str, tuple[str, int, str | None]] = {
    "the model's HEAD `main`": ("c1a", 100, "HEAD_MAIN"),
    "C1b at scan 140": ("c1b", 140, None),
    "C2a at scan 100": ("c2a", 100, None),
    "C2c at scan 100": ("c2c", 100, None),
}


def variant_rows(docs: Docs) -> Iterator[Figure]:
    """results.md's RMC variants: the twinfleet column; "in RMC's order" is the tests'
    search in RMC's order, else a breadth-first check."""
    from tests.rmc import test_variants

    for table in docs.tables("docs/results.md"):
        if table.header[:1] != ("variant",):
            continue
        for number, cells in table.rows:
            known = [v for start, v in VARIANTS.items() if cells[0].startswith(start)]
            if not known or (claim := parse_claim(cells[-1], rmc=True)) is None:
                print(f"docs/results.md:{number}: a variant this script cannot build: "
                      f"{cells[0]}", file=sys.stderr)
                continue
            base, scan, robots = known[0]
            folder = _SCRATCH / f"variant{number}"
            folder.mkdir(exist_ok=True)
            path = test_variants.variant(folder, base, scan,
                                         getattr(test_variants, robots) if robots else None)
            order = "rmc" if "RMC's order" in cells[-1] else "bfs"
            yield Figure(f"docs/results.md:{number}", f"{base} scan {scan} variant ({order})",
                         Run(str(path), order=order), claim)


def _reduction_scenario(first: str, kind: str) -> str | None:
    """The scenario of a row of a reduction.md table (`kind`: the table's first header)."""
    from checker_scaling import crossing_scenario, lanes_scenario

    word = first.split(" (")[0].strip()
    if kind == "N":
        return str(lanes_scenario(_SCRATCH, int(word), "ros"))
    if kind == "robots":
        return str(crossing_scenario(_SCRATCH, int(word), 1, "ros"))
    named = {"station": DATA / "station" / "station.yaml",
             "settled": DATA / "station" / "settled.yaml",
             "two-phase commit": DATA / "two_phase" / "two_phase.yaml",
             "two-phase commit, 2 participants": DATA / "two_phase" / "two_phase_small.yaml"}
    if word in named:
        return str(named[word])
    return word.lower() if re.fullmatch(r"c[12][abc]|headon", word, re.I) else None


def reduction_rows(docs: Docs) -> Iterator[Figure]:
    """reduction.md §8: unreduced and `por` states (and transitions) per row: lanes,
    crossing fleets, the paper cases, the "does it pay" scenarios (not the generated
    rows: sums over systems another benchmark draws)."""
    for table in docs.tables("docs/reduction.md"):
        head = table.header
        columns = [(i, mode) for i, h in enumerate(head)
                   for mode in ("none", "por") if h in (f"{mode} states", "unreduced states")
                   and (mode == "por") == h.startswith("por")]
        if not columns:
            continue
        for number, cells in table.rows:
            path = _reduction_scenario(cells[0], head[0])
            if path is None:
                continue
            verdict = re.search(r"\((holds|collision)\)", cells[0])
            for at, mode in columns:
                text = cells[at] + (f" / {cells[at + 1]}" if head[at + 1:at + 2] == (
                    "transitions",) and cells[at + 1] else "")
                if (claim := parse_claim(text, rmc=False)) is None:
                    continue
                if verdict is not None:
                    claim = Claim("holds" if verdict[1] == "holds" else "violated",
                                  claim.states, claim.transitions)
                yield Figure(f"docs/reduction.md:{number}", f"{Path(path).stem} {mode}",
                             Run(path, "ros" if head[0] in ("N", "robots") else None, mode), claim)


#: Figures in prose: the doc, a pattern its line must match (its groups: the figures),
#: what the figure is, and the run that gives it. Named groups: s (states), t
#: (transitions), r (transitions as RMC counts them).
PROSE: tuple[tuple[str, str, str, Callable[[], Run]], ...] = (
    ("README.md", r"`twinfleet check c1a`: (?P<s>[\d,]+) states", "c1a (por)", lambda: Run("c1a")),
    ("README.md", r"C1a (?P<s>[\d,]+) → [\d,]+ states", "c1a none",
     lambda: Run("c1a", reduction="none")),
    ("README.md", r"C1a [\d,]+ → (?P<s>[\d,]+) states", "c1a (por)", lambda: Run("c1a")),
    ("README.md", r"16 robots: (?P<s>[\d,]+) states", "16 lanes (por)",
     lambda: Run(str(_reduction_scenario("16", "N")), "ros")),
    ("docs/reduction.md", r"\(C1a (?P<s>[\d,]+) / (?P<t>[\d,]+) …\)", "c1a_rebeca",
     lambda: Run("c1a_rebeca")),
    ("docs/results.md", r"gives \*\*(?P<s>[\d,]+) / (?P<r>[\d,]+)\*\* for C2c",
     "c2c_rebeca (RMC's order)", lambda: Run(scenario("c2c_rebeca"), order="rmc")),
    ("docs/results.md", r"again\s*$", "c2a_rebeca (RMC's order)",
     lambda: Run(scenario("c2a_rebeca"), order="rmc")),
    ("docs/results.md", r"^(?P<s>[\d,]+) / (?P<r>[\d,]+) and [\d,]+ / [\d,]+ for C2a and C2b",
     "c2a_rebeca (RMC's order)", lambda: Run(scenario("c2a_rebeca"), order="rmc")),
    ("docs/results.md", r"^[\d,]+ / [\d,]+ and (?P<s>[\d,]+) / (?P<r>[\d,]+) for C2a and C2b",
     "c2b_rebeca (RMC's order)", lambda: Run(scenario("c2b_rebeca"), order="rmc")),
    ("docs/results.md", r"\((?P<s>[\d,]+) / (?P<r>[\d,]+) for C1a either way\)",
     "c1a_rebeca (RMC's order)", lambda: Run(scenario("c1a_rebeca"), order="rmc")),
)


def prose(docs: Docs) -> Iterator[Figure]:
    """The `PROSE` figures; a pattern that no longer matches its doc is an error (exit 2)."""
    for name, pattern, label, run in PROSE:
        if "?P<" not in pattern:
            continue  # a marker only: the sentence goes on on the next line
        found = [(n, m) for n, line in enumerate(docs.lines(name), 1)
                 if (m := re.search(pattern, line)) is not None]
        if len(found) != 1:
            raise SystemExit(f"{name}: {len(found)} lines match {pattern!r} (expected one): "
                             "the prose changed, update PROSE in benchmarks/docs_figures.py")
        number, match = found[0]
        groups = {k: _int(v) for k, v in match.groupdict().items()}
        transitions = groups.get("t", groups.get("r"))
        yield Figure(f"{name}:{number}", label, run(),
                     Claim(states=groups["s"], transitions=transitions, rmc="r" in groups))


SOURCES: tuple[Callable[[Docs], Iterator[Figure]], ...] = (
    rebeca_columns, other_rules, variant_rows, throughput_rows, reduction_rows,
    contract_rows, experiment_rows, discretization_rows, prose)


# ------------------------------------------------------------------ measuring


class RunError(RuntimeError):
    """A figure's command gave no verdict (the line says which command)."""


@cache
def outcome(run: Run) -> Outcome:
    """What `run` gives (each distinct run once)."""
    if run.order == "rmc":
        from tests.rmc import adapter, rmc_order

        system, world = adapter.build(run.scenario)
        counts = rmc_order.search(system, world, rmc_order.collision_or_livelock)
        return Outcome("violated" if counts.violated else "holds", counts.states,
                       counts.transitions - 1, counts.transitions, None)
    argv = ["check", run.scenario, "--json", "--trace-out", str(_SCRATCH / "trace.json")]
    argv += ["--semantics", run.semantics] if run.semantics else []
    argv += ["--reduction", run.reduction] if run.reduction else []
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        code = twinfleet(argv)
    if code not in (0, 1):
        raise RunError(f"twinfleet {' '.join(argv)}: exit {code}, no verdict")
    doc: dict[str, Any] = json.loads(out.getvalue())
    message = (doc.get("violation") or {}).get("message", "")
    at = re.search(r"at t=(\d+) ms", message)
    return Outcome("holds" if doc["verdict"] == "holds" else "violated", doc["states"],
                   doc["transitions"], doc["rmc_transitions"],
                   float(at[1]) if at else None)


def figures(docs: Docs, only: Sequence[str] | None) -> list[Figure]:
    """Every figure the sources find; with `only`, those whose place or label contains
    one of its texts."""
    found = [f for source in SOURCES for f in source(docs)]
    return [f for f in found
            if only is None or any(text in f.where or text in f.label for text in only)]


def compare(found: Sequence[Figure]) -> int:
    """Measure and print each figure; the number that are the same."""
    same = 0
    for k, figure in enumerate(found, 1):
        print(f"[{k}/{len(found)}] {figure.run.scenario}", file=sys.stderr, flush=True)
        says = figure.claim.says()
        try:
            measured = figure.claim.measured(outcome(figure.run))
        except RunError as exc:
            measured = f"no verdict ({exc})"
        same += says == measured
        print(f"{figure.where:<24} {figure.label:<30} doc says {says:<30} measured "
              f"{measured:<30} {'same' if says == measured else 'DIFFERS'}", flush=True)
    return same


def main(argv: Sequence[str] | None = None) -> int:
    """Command line (module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", metavar="TEXT", action="append",
                        help="only the figures whose place (file:line) or label contains TEXT "
                             "(repeatable: any of them)")
    parser.add_argument("--list", action="store_true",
                        help="list the figures found in the docs without measuring them")
    parser.add_argument("--docs", type=Path, default=ROOT, metavar="DIR",
                        help="the checkout whose README.md and docs/ are read (default: this one)")
    args = parser.parse_args(argv)
    found = figures(Docs(args.docs), args.only)
    if args.list:
        for figure in found:
            print(f"{figure.where:<24} {figure.label:<30} {figure.claim.says()}")
        return 0
    same = compare(found)
    print(f"{same} of {len(found)} figures the same")
    return 0 if same == len(found) else 1


if __name__ == "__main__":
    sys.exit(main())
