"""The paper's own figures: Tables 4 and 5 of Trinh et al. (docs/robots.md §8).

One `PaperRow` per case, keyed by scenario name (`c1a` … `c2c`); the
`_rebeca` variants of the launch files (same case, the model's profile and
RMC's message rules) map to the same row. States and transitions are what
RMC reported for the Timed Rebeca model; "simulations" are the paper's five
manual RViz runs per case.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import final


@final
@dataclass(frozen=True, slots=True)
class PaperRow:
    """One row of the paper's Table 4 (working cases) or Table 5 (non-working).

    Attributes:
        case: the paper's name, e.g. "C1a".
        table: 4 or 5.
        scan_ms: laser scan period in ms.
        robots: per robot r1..r5, (speed m/s, max wait ms).
        result: the paper's analysis result, "satisfied" or "collision".
        states: RMC's state count.
        transitions: RMC's transition count.
        passed: simulations that passed, out of `runs`.
        runs: simulations run (5 in the paper).
    """

    case: str
    table: int
    scan_ms: int
    robots: tuple[tuple[float, int], ...]
    result: str
    states: int
    transitions: int
    passed: int
    runs: int = 5

    @property
    def simulations(self) -> str:
        """The paper's simulation column in our wording: "k/N passed, m/N failed"."""
        n = self.runs
        return f"{self.passed}/{n} passed, {n - self.passed}/{n} failed"


def _five(*pairs: tuple[float, int]) -> tuple[tuple[float, int], ...]:
    assert len(pairs) == 5
    return pairs


_ROWS = (
    PaperRow("C1a", 4, 100, _five((.5, 1500), (.7, 2000), (.8, 2500), (.5, 3000), (.3, 1500)),
             "satisfied", 19264, 43814, 5),
    PaperRow("C1b", 4, 100, _five((.3, 1500), (.3, 2000), (.3, 2500), (.3, 3000), (.7, 1500)),
             "satisfied", 20554, 46868, 5),
    PaperRow("C1c", 4, 100, _five((.4, 1500), (.5, 2000), (.7, 2500), (.8, 3000), (.9, 1500)),
             "satisfied", 15747, 35642, 5),
    PaperRow("C2a", 5, 140, _five((.9, 1500), (.9, 2000), (.9, 2500), (.9, 3000), (.9, 1500)),
             "collision", 3074, 6602, 2),
    PaperRow("C2b", 5, 100, _five((.5, 1500), (.5, 1500), (.5, 1500), (.5, 1500), (.5, 1500)),
             "collision", 6816, 15293, 3),
    PaperRow("C2c", 5, 140, _five((.9, 1500), (.8, 2000), (.7, 2500), (.6, 3000), (1.0, 1500)),
             "collision", 1740, 3727, 0),
)

#: Scenario name → the paper's row; `c1a` and `c1a_rebeca` share a row.
PAPER: dict[str, PaperRow] = {
    **{row.case.lower(): row for row in _ROWS},
    **{f"{row.case.lower()}_rebeca": row for row in _ROWS},
}


def paper_row(scenario_name: str) -> PaperRow | None:
    """The paper's row for a scenario name (`c2a`, `c2a_rebeca`), or None for other scenarios."""
    return PAPER.get(scenario_name.lower())
