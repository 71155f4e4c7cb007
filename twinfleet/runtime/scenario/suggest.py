"""`did_you_mean`: the closest known name to a misspelt one, for one-line errors."""

from __future__ import annotations

import difflib
from collections.abc import Iterable


def did_you_mean(word: str, known: Iterable[str]) -> str:
    """``"; did you mean 'speed'?"`` for the known name closest to `word`, else ``""``.

    Every error about an unknown name (a scenario key, a parameter, a node, an
    override) ends with it, so that a typo is one glance from its fix.
    """
    close = difflib.get_close_matches(word, sorted(set(known)), n=1, cutoff=0.6)
    return f"; did you mean {close[0]!r}?" if close else ""
