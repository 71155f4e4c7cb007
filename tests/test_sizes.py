"""Sizes over the whole package `twinfleet/`: every module, function, class and wing small
enough to read whole.

- no module over `MODULE_LINES` lines;
- no function or method over `FUNCTION_LINES` lines, from its ``def`` line through its
  last line (`ast`: ``end_lineno - lineno + 1``; decorators not counted);
- no class over `CLASS_LINES` lines, measured the same way from its ``class`` line;
- no wing of the runtime (`twinfleet/runtime/`) over `WING_LINES` lines, its
  sub-packages included. A wing that only groups sub-packages (`GROUPS`: `tools/` holds
  `monitor/`, `forms/`, `record/` and `view/` and no module but its ``__init__``) is
  measured per sub-package: each is a wing of its own here, as in tests/test_layering.py
  (`TOOLS_RULES`).

Every module under the package is measured, whatever folder it is in (a new folder is
covered the day it appears), and nothing is exempt.

``python -m tests.test_sizes`` prints the longest modules, functions and classes.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "twinfleet"
RUNTIME = PACKAGE / "runtime"
MODULE_LINES = 600
FUNCTION_LINES = 60
CLASS_LINES = 300
WING_LINES = 2_500
GROUPS = ("tools",)
FUNCTIONS = (ast.FunctionDef, ast.AsyncFunctionDef)
CLASSES = (ast.ClassDef,)


def _modules(folder: Path) -> list[Path]:
    return sorted(p for p in folder.rglob("*.py") if "__pycache__" not in p.parts)


def _lines(path: Path) -> int:
    return len(path.read_text().splitlines())


def _name(path: Path) -> str:
    """`path` as the repository names it ("twinfleet/checker/search.py")."""
    return str(path.relative_to(PACKAGE.parent))


def _definitions(kinds: tuple[type, ...], folder: Path = PACKAGE, root: Path = PACKAGE.parent
                 ) -> Iterator[tuple[int, str]]:
    """(length, "file:line name") of every definition of `kinds` under `folder`, files
    named from `root`."""
    for path in _modules(folder):
        where = path.relative_to(root)
        for item in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(item, kinds):
                yield item.end_lineno - item.lineno + 1, f"{where}:{item.lineno} {item.name}"


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
    """The `count` longest definitions of `kinds` in the package, longest first."""
    return sorted(_definitions(kinds), key=lambda row: (-row[0], row[1]))[:count]


def _over(kinds: tuple[type, ...], limit: int) -> list[tuple[int, str]]:
    return [row for row in _definitions(kinds) if row[0] > limit]


def test_the_whole_package_is_measured():
    """Modules outside the runtime count too (the checker, the nodes, the CLI...)."""
    measured = {_name(p) for p in _modules(PACKAGE)}
    assert "twinfleet/checker/search.py" in measured
    assert "twinfleet/cli/__init__.py" in measured
    assert any(name.startswith("twinfleet/runtime/") for name in measured)


def test_no_module_is_over_the_limit():
    over = {_name(p): n for p in _modules(PACKAGE) if (n := _lines(p)) > MODULE_LINES}
    assert over == {}, f"modules over {MODULE_LINES} lines: split them by responsibility"


def test_no_function_is_over_the_limit():
    over = _over(FUNCTIONS, FUNCTION_LINES)
    assert over == [], f"functions over {FUNCTION_LINES} lines: give their steps names"


def test_no_class_is_over_the_limit():
    over = _over(CLASSES, CLASS_LINES)
    assert over == [], f"classes over {CLASS_LINES} lines: split them by responsibility"


def test_the_limits_catch_a_long_definition(tmp_path):
    """The measure counts from the ``def``/``class`` line to the last line of the body."""
    body = "".join(f"    x{i} = {i}\n" for i in range(FUNCTION_LINES))
    (tmp_path / "long.py").write_text(f"@decorated\ndef f():\n{body}\nclass C:\n    y = 1\n")
    rows = {where.rsplit(" ", 1)[-1]: n for n, where in
            _definitions(FUNCTIONS + CLASSES, tmp_path, tmp_path)}
    assert rows == {"f": FUNCTION_LINES + 1, "C": 2}


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


def test_every_runtime_module_but_the_package_markers_is_in_a_wing():
    measured = {p for folder in _wings().values() for p in _modules(folder)}
    markers = {RUNTIME / "__init__.py", *(RUNTIME / group / "__init__.py" for group in GROUPS)}
    assert set(_modules(RUNTIME)) - measured == markers


def _report() -> None:
    modules = sorted(((_lines(p), _name(p)) for p in _modules(PACKAGE)), reverse=True)[:10]
    print(f"the ten longest modules under twinfleet/ (limit {MODULE_LINES}):")
    for length, where in modules:
        print(f"  {length:4d}  {where}")
    for title, kinds, limit in (("functions", FUNCTIONS, FUNCTION_LINES),
                                ("classes", CLASSES, CLASS_LINES)):
        print(f"the ten longest {title} under twinfleet/ (limit {limit}):")
        for length, where in longest(kinds):
            print(f"  {length:4d}  {where}")


if __name__ == "__main__":
    _report()
