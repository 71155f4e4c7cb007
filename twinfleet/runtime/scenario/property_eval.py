"""Property expressions: a small, safe language over node states, shared by both drivers.

A scenario's ``expr`` is parsed once, at load, with `ast` and checked against
the language below; anything else is refused with an `ExpressionError` that
says what and where (``properties[2].expr``), before anything runs. The
language:

- names: the scenario's node names (each bound to that node's state object),
  ``nodes`` (name → state), ``now`` (the time in ms), names bound by a
  comprehension, and the pure functions of `SAFE_FUNCTIONS`;
- state fields (``r1.done``), subscripts and slices (``nodes['r1']``, ``xs[1:]``);
- constants, tuples, lists, sets and dicts, arithmetic, comparisons, ``and``/
  ``or``/``not``, ``x if c else y``, list/set/dict comprehensions and generator
  expressions;
- calls of `SAFE_FUNCTIONS` and of the container methods of `SAFE_METHODS`
  (``nodes.items()``, ``r1.targets.count(c)``) only, with the keywords ``key``
  (itself one of the functions), ``default``, ``start`` and ``reverse``.

Refused: attributes and names that start with ``_`` (``__class__``,
``__import__``), the frame and code attributes of generators, imports, lambdas,
``:=``, f-strings, and calls of anything else (other methods included). The
expression is evaluated with `SAFE_FUNCTIONS` as its only builtins.

Time. A property that runs too long must not outlast the checker's
``--max-time``: `time_limit(seconds)` sets a deadline for the calling thread;
while an expression is evaluated under a deadline, a trace function
(``sys.settrace``, which acts on the calling thread only) looks at the clock at
every call, generator resume and loop iteration of the expression's frames, and
raises `Overtime` (naming the expression) once the deadline has passed; an
expression evaluated after the deadline stops at its first step. No signal is
involved, so this works the same in any thread (a worker thread, a notebook,
pytest-xdist). ``range`` is a Python generator here so that even
``sum(range(10**12))`` resumes a traced frame at every step (a C loop over a C
iterator never would). Outside `time_limit` nothing is traced and evaluation
costs one attribute read more than `eval`; a tracer already installed (a
debugger, coverage) is set aside during the evaluation and put back after.
"""

from __future__ import annotations

import ast
import contextlib
import sys
import threading
import time
from collections.abc import Iterator, Mapping, Sequence
from types import CodeType, FrameType
from typing import Any, Final, final


class ExpressionError(ValueError):
    """A property expression is not in the language (module docstring)."""


class Overtime(Exception):
    """An expression was still being evaluated when the `time_limit` expired."""


def _range(*args: int) -> Iterator[int]:
    # A Python loop, unlike the builtin: a time limit can interrupt the consumer.
    for i in range(*args):  # noqa: UP028 - `yield from` would be a C loop again
        yield i


#: The functions an expression may call: pure, and total on plain data.
SAFE_FUNCTIONS: Final[Mapping[str, Any]] = {
    "abs": abs, "all": all, "any": any, "bool": bool, "dict": dict, "enumerate": enumerate,
    "float": float, "frozenset": frozenset, "int": int, "len": len, "list": list, "max": max,
    "min": min, "range": _range, "reversed": reversed, "round": round, "set": set,
    "sorted": sorted, "str": str, "sum": sum, "tuple": tuple, "zip": zip,
}
_KEYWORDS: Final = frozenset({"key", "default", "start", "reverse"})
#: Methods an expression may call: the pure readers of dicts, tuples, lists and strings.
SAFE_METHODS: Final = frozenset({"keys", "values", "items", "get", "count", "index"})
#: Attributes that lead from a generator to frames, code and other modules' globals.
_INTROSPECTION: Final = frozenset({"gi_frame", "gi_code", "gi_yieldfrom", "cr_frame", "cr_code",
                                   "ag_frame", "ag_code", "tb_frame", "tb_next", "f_back",
                                   "f_globals", "f_locals", "f_builtins", "f_code"})
_ALLOWED_NODES: Final = (
    ast.Expression, ast.BoolOp, ast.BinOp, ast.UnaryOp, ast.Compare, ast.IfExp, ast.Call,
    ast.keyword, ast.Name, ast.Attribute, ast.Subscript, ast.Slice, ast.Constant, ast.Tuple,
    ast.List, ast.Set, ast.Dict, ast.ListComp, ast.SetComp, ast.DictComp, ast.GeneratorExp,
    ast.comprehension, ast.Starred, ast.expr_context, ast.boolop, ast.operator, ast.unaryop,
    ast.cmpop,
)
_HELP: Final = ("a property reads node states: node names and their fields, nodes, now, "
                "arithmetic, comparisons, and/or/not, comprehensions and calls of "
                + ", ".join(sorted(SAFE_FUNCTIONS)) + " and of the methods "
                + ", ".join(sorted(SAFE_METHODS)))


@final
class Expression:
    """A checked, compiled property expression.

    Attributes:
        source: the expression as written.
        where: where it was written (for messages), e.g. ``c1a.yaml:properties[0]``.
        names: the free names it reads (node names, ``nodes``, ``now``).
    """

    __slots__ = ("code", "names", "source", "where")

    def __init__(self, source: str, code: CodeType, names: frozenset[str], where: str) -> None:
        self.source, self.code, self.names, self.where = source, code, names, where

    def evaluate(self, env: dict[str, Any]) -> bool:
        """The truth of the expression with the free names bound in `env` (changed: it
        gains ``__builtins__``).

        Raises:
            Overtime: the `time_limit` expired during the evaluation.
            Exception: whatever the expression raised (a missing field, a type error).
        """
        env["__builtins__"] = SAFE_FUNCTIONS
        deadline = _DEADLINE.at
        if deadline is None:
            return bool(eval(self.code, env))  # noqa: S307 - checked against the language
        previous = sys.gettrace()
        sys.settrace(_Watchdog(deadline))
        try:
            return bool(eval(self.code, env))  # noqa: S307 - checked against the language
        except Overtime:
            raise Overtime(f"{self.where}: {self.source!r}") from None
        finally:
            sys.settrace(previous)


def parse_expression(source: str, node_names: Sequence[str], where: str) -> Expression:
    """Check `source` against the language and compile it.

    Args:
        source: the expression.
        node_names: the scenario's node names (free names it may read).
        where: where it was written, for messages and the code object.

    Raises:
        ExpressionError: a syntax error, or something outside the language (one line).
    """
    try:
        tree = ast.parse(source.strip(), mode="eval")
    except SyntaxError as exc:
        raise ExpressionError(f"not a Python expression: {exc.msg}") from None
    bound = {t.id for c in ast.walk(tree) if isinstance(c, ast.comprehension)
             for t in ast.walk(c.target) if isinstance(t, ast.Name)}
    states = {*node_names, "nodes", "now"}  # a node's name shadows a function's
    readable = {*states, *SAFE_FUNCTIONS, *bound}
    free: set[str] = set()
    nodes = list(ast.walk(tree))
    # Foreign constructs first, then names and attributes, then calls: the more telling
    # reason wins (`__import__('os').system(...)` is refused for its `__import__`).
    for node in sorted(nodes, key=_check_order):
        _check_node(node, readable, node_names)
        if isinstance(node, ast.Name) and node.id in states and node.id not in bound:
            free.add(node.id)
    return Expression(source, compile(tree, where, "eval"), frozenset(free), where)


def _check_order(node: ast.AST) -> int:
    if not isinstance(node, _ALLOWED_NODES):
        return 0
    return 1 if isinstance(node, ast.Name | ast.Attribute) else 2


def _check_node(node: ast.AST, readable: set[str], node_names: Sequence[str]) -> None:
    if not isinstance(node, _ALLOWED_NODES):
        raise ExpressionError(f"{_describe(node)} is not allowed ({_HELP})")
    if isinstance(node, ast.Name):
        if node.id.startswith("_") and node.id != "_":  # `_` alone: a throw-away loop name
            raise ExpressionError(f"the name {node.id!r} is not allowed (names starting with "
                                  "'_' are refused, but for `_` itself)")
        if node.id not in readable:
            raise ExpressionError(f"unknown name {node.id!r} (nodes: {', '.join(node_names)}; "
                                  f"{_HELP})")
    elif isinstance(node, ast.Attribute) and (node.attr.startswith("_")
                                              or node.attr in _INTROSPECTION):
        raise ExpressionError(f"the attribute {node.attr!r} is not allowed (attributes "
                              "starting with '_' and frame or code attributes are refused)")
    elif isinstance(node, ast.Call):
        _check_call(node)


def _check_call(call: ast.Call) -> None:
    func = call.func
    if isinstance(func, ast.Attribute) and func.attr in SAFE_METHODS:
        name = func.attr
    elif isinstance(func, ast.Name) and func.id in SAFE_FUNCTIONS:
        name = func.id
    else:
        what = ast.unparse(func)
        raise ExpressionError(f"calling {what!r} is not allowed ({_HELP})")
    for kw in call.keywords:
        if kw.arg is None or kw.arg not in _KEYWORDS:
            raise ExpressionError(f"the keyword {kw.arg or '**'!r} of {name}() is not allowed "
                                  f"(allowed: {', '.join(sorted(_KEYWORDS))})")
        if kw.arg == "key" and not (isinstance(kw.value, ast.Name)
                                    and kw.value.id in SAFE_FUNCTIONS):
            raise ExpressionError(f"{name}(key=...) must name one of the allowed functions, "
                                  f"got {ast.unparse(kw.value)!r}")


def _describe(node: ast.AST) -> str:
    text = {ast.Lambda: "a lambda", ast.NamedExpr: "':='", ast.JoinedStr: "an f-string",
            ast.Await: "await", ast.Yield: "yield", ast.YieldFrom: "yield"}.get(type(node))
    return text or f"{type(node).__name__} ({ast.unparse(node)!r:.60})"


# ---------------------------------------------------------------------- time limit


class _Deadline(threading.local):
    """The calling thread's `time_limit` deadline (`time.monotonic` seconds), or None."""

    at: float | None = None


_DEADLINE: Final = _Deadline()


@final
class _Watchdog:
    """The trace function of one evaluation: raises `Overtime` at the first step past
    `deadline` (a call, a generator resume, a line or a loop's jump back)."""

    __slots__ = ("deadline",)

    def __init__(self, deadline: float) -> None:
        self.deadline = deadline

    def __call__(self, _frame: FrameType, _event: str, _arg: Any) -> _Watchdog:
        if time.monotonic() > self.deadline:
            raise Overtime("time limit")
        return self


@contextlib.contextmanager
def time_limit(seconds: float | None) -> Iterator[None]:
    """Make expression evaluation in this thread raise `Overtime` once `seconds` have passed
    (module docstring). No-op for None; nests (the earlier deadline wins)."""
    if seconds is None:
        yield
        return
    outer = _DEADLINE.at
    mine = time.monotonic() + max(seconds, 1e-3)
    _DEADLINE.at = mine if outer is None else min(outer, mine)
    try:
        yield
    finally:
        _DEADLINE.at = outer
