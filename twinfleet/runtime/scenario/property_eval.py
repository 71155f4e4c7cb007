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
``--max-time``: `time_limit(seconds)` arms one interval timer (SIGALRM, main
thread only); when it expires while an expression is being evaluated, the
evaluation raises `Overtime` (naming the expression), and otherwise it looks
again every 50 ms until evaluation and timer meet. ``range`` is a Python loop
here so that even ``sum(range(10**12))`` reaches a point where the timer can
interrupt it (a C loop over a C iterator never does). Outside `time_limit`
nothing is armed and evaluation costs two attribute writes more than `eval`.
"""

from __future__ import annotations

import ast
import contextlib
import signal
import threading
from collections.abc import Iterator, Mapping, Sequence
from types import CodeType
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
        _CLOCK.inside = True
        try:
            return bool(eval(self.code, env))  # noqa: S307 - checked against the language
        except Overtime:
            raise Overtime(f"{self.where}: {self.source!r}") from None
        finally:
            _CLOCK.inside = False


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


@final
class _Clock:
    """Whether an expression is being evaluated; the alarm looks here."""

    __slots__ = ("inside",)

    def __init__(self) -> None:
        self.inside = False


_CLOCK: Final = _Clock()
_RECHECK_S: Final = 0.05


def _on_alarm(_signum: int, _frame: Any) -> None:
    if _CLOCK.inside:
        raise Overtime("time limit")
    signal.setitimer(signal.ITIMER_REAL, _RECHECK_S)  # look again soon


@contextlib.contextmanager
def time_limit(seconds: float | None) -> Iterator[None]:
    """Interrupt expression evaluation with `Overtime` once `seconds` have passed (module
    docstring). No-op for None or outside the main thread (signals go to the main thread)."""
    if seconds is None or threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGALRM, _on_alarm)
    signal.setitimer(signal.ITIMER_REAL, max(seconds, 1e-3))
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
