"""The rules the partial-order reduction was reviewed for are the rules that run.

The reduction's closure (`twinfleet/checker/closure.py`, argued in docs/reduction.md §4–§6)
treats events of different nodes as independent because of what the checker's enabling and
effect rules do. A new rule (KEEP_LAST dropping pending deliveries, a new kind of fault) may
make events dependent that the closure treats as independent, so a change to the code of
those rules fails here until the closure has been reviewed for it. Only code counts: a
comment, a docstring or a blank line does not change the fingerprint.

The checker itself never reads its source (an install may have none); this test is where
the check lives.
"""

from __future__ import annotations

import hashlib
import inspect
import io
import textwrap
import tokenize
from collections.abc import Callable
from typing import Any

from twinfleet.checker import runner, semantics, system

#: The code that decides what is enabled and what a transition does to the pending events.
RULE_FUNCTIONS: tuple[Callable[..., Any], ...] = (
    semantics.Rules.enabled, semantics.Rules._across_nodes, semantics.Rules.add,
    semantics.Rules.remove, semantics.Rules.delivery, semantics.Rules.copies,
    semantics.Rules.crashable, semantics.Rules.droppable, semantics.Rules.tick_after,
    semantics._earliest_sent, semantics._lowest,
    runner.Runner._effects, runner._reply, runner._token, system.System._apply,
    system.System._apply_run, system.System._apply_crash,
)

#: The fingerprint of `RULE_FUNCTIONS` as the closure was last reviewed for them: Rule 6
#: (KEEP_LAST drops, BEST_EFFORT losses), calls with no server (their CallError typed with a
#: CallFailure: the same two branches), a latency branch that tells a sampler the send time
#: (its branches and due times unchanged), the keys of the messages a drop branch lost,
#: recorded for weak fairness (no event changed), a latency site that also names the
#: publish a delivery copies plus event keys computed as the event is made (for
#: simulations: the same branches, due times and keys as before), and Rule 7, a late
#: `@every` tick's next due time as a branch of the tick's own run (a variant of it,
#: creating only the node's own timer, always after the instant: docs/reduction.md §6);
#: then three rewrites for speed that keep every value: an event alone at t* is enabled
#: at once (a group of one was picked as it is), a sent message's FIFO clamp and rank
#: come from one pass over its channel-mates (the latest due time among them, the count
#: at the clamped due time), and one fault option with nothing lossy is one copy at once.
#: Then deferred replies: a request's handler that deferred (reply None) sends no reply,
#: and a `Reply` effect of any handler sends the reply event the request's handler would
#: have (`_reply`, for both): a zero-latency send at the instant to the caller, which the
#: learned send relation sees like any other (an edge from the replying handler).
#: Then a fourth rewrite for speed that keeps every value (tests/checker/test_rule_rewrites.py
#: runs the code it replaced beside it): Rules 2 and 4 from one pass over the events at t*
#: (each node's lowest handler priority, then Rule 4 narrows the nodes: the same events, as
#: every node it keeps has an event of its lowest priority; with no two nodes of one
#: instance priority, `_lowest`, which keeps one node, is that pair's minimum), and a run
#: event's step in `_apply_run`, whose pending events under `rebeca` are slices (there
#: `remove` and `add` only drop and append, changing no event).
PINNED = "61baa6023ce4ee8f"

_SKIPPED = (tokenize.NL, tokenize.COMMENT)
_STATEMENT_START = (tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT)


def code_only(source: str) -> str:
    """`source` without comments, docstrings (and other bare string statements), blank
    lines and trailing spaces: what runs, not what explains it."""
    lines = source.splitlines()
    for (row, col), (end_row, end_col) in _explanations(source):
        for r in range(row, end_row + 1):
            start = col if r == row else 0
            stop = end_col if r == end_row else len(lines[r - 1])
            text = lines[r - 1]
            lines[r - 1] = text[:start] + " " * (stop - start) + text[stop:]
    return "\n".join(line.rstrip() for line in lines if line.strip())


def _explanations(source: str) -> list[tuple[tuple[int, int], tuple[int, int]]]:
    """Where the comments and the bare string statements of `source` are (tokenize spans)."""
    tokens = list(tokenize.generate_tokens(io.StringIO(source).readline))
    spans = [(t.start, t.end) for t in tokens if t.type == tokenize.COMMENT]
    code = [t for t in tokens if t.type not in _SKIPPED]
    for before, token, after in zip(code, code[1:], code[2:], strict=False):
        if (token.type == tokenize.STRING and before.type in _STATEMENT_START
                and after.type == tokenize.NEWLINE):
            spans.append((token.start, token.end))
    return spans


def rules_fingerprint() -> str:
    """16 hex digits of SHA-256 over the name and code of every rule function."""
    digest = hashlib.sha256()
    for fn in RULE_FUNCTIONS:
        digest.update(fn.__qualname__.encode() + b"\0")
        digest.update(code_only(textwrap.dedent(inspect.getsource(fn))).encode() + b"\0")
    return digest.hexdigest()[:16]


def test_the_rules_the_reduction_was_reviewed_for_are_the_rules_that_run():
    actual = rules_fingerprint()
    assert actual == PINNED, (
        "The checker's enabling or effect rules changed (one of RULE_FUNCTIONS in "
        f"{__file__}). The partial-order reduction may now treat dependent events as "
        "independent. Review docs/reduction.md (§4-§6) and the closure's rules "
        "(twinfleet/checker/closure.py, Closure) for the change, adapt them if needed, "
        f"then set PINNED = {actual!r} in this file.")


def test_comments_and_docstrings_do_not_count():
    plain = "def f(x):\n    return x + 1\n"
    explained = ('def f(x):\n    """Add one."""\n\n    # why: the next one\n'
                 '    return x + 1  # the successor\n')
    assert code_only(explained) == code_only(plain)
    assert code_only(plain.replace("+ 1", "+ 2")) != code_only(plain)


def test_a_string_that_is_an_argument_counts():
    assert code_only('def f():\n    g(\n        "a"\n    )\n') != code_only(
        'def f():\n    g(\n        "b"\n    )\n')
