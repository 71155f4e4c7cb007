"""Sizes under `twinfleet/runtime/`: every module, function and wing small enough to read whole.

- no module over `MODULE_LINES` lines;
- no function or method over `FUNCTION_LINES` lines, from its ``def`` line through its
  last line (`ast`: ``end_lineno - lineno + 1``; decorators not counted);
- no wing over `WING_LINES` lines, its sub-packages included. A wing that only groups
  sub-packages (`GROUPS`: `tools/` holds `monitor/`, `record/` and `view/` and no module
  but its ``__init__``) is measured per sub-package: each is a wing of its own here, as
  in tests/test_layering.py (`TOOLS_RULES`).

``python -m tests.test_sizes`` prints the ten longest functions and classes.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

RUNTIME = Path(__file__).resolve().parents[1] / "twinfleet" / "runtime"
MODULE_LINES = 600
FUNCTION_LINES = 60
WING_LINES = 2_500
GROUPS = ("tools",)


def _modules(folder: Path) -> list[Path]:
    return sorted(p for p in folder.rglob("*.py") if "__pycache__" not in p.parts)


def _lines(path: Path) -> int:
    return len(path.read_text().splitlines())


def _definitions(kinds: tuple[type, ...]) -> Iterator[tuple[int, str]]:
    """(length, "file:line name") of every definition of `kinds` under the runtime."""
    for path in _modules(RUNTIME):
        for item in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(item, kinds):
                where = f"{path.relative_to(RUNTIME.parents[1])}:{item.lineno} {item.name}"
                yield item.end_lineno - item.lineno + 1, where


def _wings() -> dict[str, Path]:
    """Every wing the size rule measures, by its path under the runtime."""
    wings: dict[str, Path] = {}
    for folder in sorted(p for p in RUNTIME.iterdir() if (p / "__init__.py").exists()):
        parts = [folder]
        if folder.name in GROUPS:
            parts = sorted(p for p in folder.iterdir() if (p / "__init__.py").exists())
        wings.update({str(p.relative_to(RUNTIME)): p for p in parts})
    return wings


def longest(kinds: tuple[type, ...], count: int = 10) -> list[tuple[int, str]]:
    """The `count` longest definitions of `kinds`, longest first."""
    return sorted(_definitions(kinds), key=lambda row: (-row[0], row[1]))[:count]


def test_no_module_is_over_the_limit():
    over = {str(p.relative_to(RUNTIME)): n for p in _modules(RUNTIME)
            if (n := _lines(p)) > MODULE_LINES}
    assert over == {}, f"modules over {MODULE_LINES} lines: split them by responsibility"


def test_no_function_is_over_the_limit():
    functions = (ast.FunctionDef, ast.AsyncFunctionDef)
    over = [row for row in _definitions(functions) if row[0] > FUNCTION_LINES]
    assert over == [], f"functions over {FUNCTION_LINES} lines: give their steps names"


def test_no_wing_is_over_the_limit():
    sizes = {name: sum(_lines(p) for p in _modules(folder)) for name, folder in _wings().items()}
    over = {name: n for name, n in sizes.items() if n > WING_LINES}
    assert over == {}, f"wings over {WING_LINES} lines: {sizes}"


def test_a_group_holds_only_sub_packages():
    """A group's sub-packages are measured one by one, so the group itself may hold no
    module that would escape the count."""
    for group in GROUPS:
        modules = {p.name for p in (RUNTIME / group).glob("*.py")}
        assert modules == {"__init__.py"}, f"{group}/ is a group of wings: {modules}"


def test_every_module_but_the_package_markers_is_measured():
    measured = {p for folder in _wings().values() for p in _modules(folder)}
    markers = {RUNTIME / "__init__.py", *(RUNTIME / group / "__init__.py" for group in GROUPS)}
    assert set(_modules(RUNTIME)) - measured == markers


def _report() -> None:
    for title, kinds in (("functions", (ast.FunctionDef, ast.AsyncFunctionDef)),
                         ("classes", (ast.ClassDef,))):
        print(f"the ten longest {title} under twinfleet/runtime:")
        for length, where in longest(kinds):
            print(f"  {length:4d}  {where}")


if __name__ == "__main__":
    _report()
