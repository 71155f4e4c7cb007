"""Every environment variable twinfleet reads is named in one module and described in the docs."""

from __future__ import annotations

import ast
import re
from pathlib import Path

from twinfleet.runtime.contract.environment import EnvVar

ROOT = Path(__file__).resolve().parents[1]
HOME = ROOT / "twinfleet" / "runtime" / "contract" / "environment.py"


def _reads_a_named_variable(node: ast.AST) -> bool:
    """`os.getenv(...)`, `os.environ.get("NAME")` or a load of `os.environ["NAME"]`."""
    def environ(n: ast.AST) -> bool:
        return (isinstance(n, ast.Attribute) and n.attr == "environ"
                and isinstance(n.value, ast.Name) and n.value.id == "os")
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
        if node.func.attr == "getenv":
            return True
        return (node.func.attr == "get" and environ(node.func.value) and bool(node.args)
                and isinstance(node.args[0], ast.Constant))
    return (isinstance(node, ast.Subscript) and environ(node.value)
            and isinstance(node.ctx, ast.Load) and isinstance(node.slice, ast.Constant))


def test_only_the_environment_module_reads_or_spells_a_variable() -> None:
    bad = []
    for path in sorted((ROOT / "twinfleet").rglob("*.py")):
        if path == HOME:
            continue
        text = path.read_text()
        bad += [f"{path.relative_to(ROOT)}:{n.lineno}" for n in ast.walk(ast.parse(text))
                if _reads_a_named_variable(n)]
        bad += [f"{path.relative_to(ROOT)}: spells {name}"
                for name in sorted(set(re.findall(r'"(TWINFLEET_[A-Z_]+)"', text)))]
    assert bad == []


def test_the_docs_describe_every_variable_and_no_other() -> None:
    page = (ROOT / "docs" / "environment.md").read_text()
    documented = set(re.findall(r"^\| `([A-Za-z_]+)` \|", page, re.M))
    assert documented == {var.value for var in EnvVar}


def test_the_scan_sees_a_read(tmp_path: Path) -> None:
    code = 'import os\nA = os.environ.get("X")\nB = os.environ["Y"]\nC = os.getenv("Z")\n'
    assert sum(_reads_a_named_variable(n) for n in ast.walk(ast.parse(code))) == 3
