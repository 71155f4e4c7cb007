"""Checkpoint files: a long search saved to disk and resumed later.

A checkpoint is a pickle (``"format": "twinfleet-checkpoint/2"``; /2: event kinds
are `EventKind` values) of the
visited-state store, the frontier (worlds waiting to be expanded, with their
ids and depths), the counters and `meta`: what the search was run on (the
scenario file, its SHA-256, semantics, profile, search order, state mode...).
It is written to a temporary file and renamed, so a crash while writing
leaves the previous checkpoint intact. Only load checkpoints you wrote: a
pickle can run code when it is read.

Node code is not recorded: resuming after changing node classes gives a
search of neither version. The scenario file is checked by its hash.
"""

from __future__ import annotations

import os
import pickle
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from twinfleet.runtime.contract.tracefile import file_sha256  # noqa: F401 (the checker's name for it)

FORMAT = "twinfleet-checkpoint/2"


class CheckpointError(ValueError):
    """A checkpoint file is unreadable, of another format, or does not fit the scenario."""


def save(path: str | Path, meta: Mapping[str, Any], store: Any, frontier: list[Any],
         counters: Mapping[str, Any]) -> None:
    """Write a checkpoint atomically (temporary file, then rename)."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".tmp")
    doc = {"format": FORMAT, "meta": dict(meta), "store": store, "frontier": frontier,
           "counters": dict(counters)}
    with open(tmp, "wb") as f:
        pickle.dump(doc, f, protocol=pickle.HIGHEST_PROTOCOL)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, out)


def load(path: str | Path) -> dict[str, Any]:
    """Read a checkpoint written by `save`.

    Raises:
        CheckpointError: the file cannot be read or is not a checkpoint.
    """
    try:
        with open(path, "rb") as f:
            doc = pickle.load(f)
    except FileNotFoundError:
        raise CheckpointError(f"{path}: no such checkpoint file") from None
    except Exception as exc:  # pickle raises many kinds for a damaged file
        raise CheckpointError(f"{path}: cannot read checkpoint: {type(exc).__name__}: {exc}") \
            from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise CheckpointError(f"{path}: not a {FORMAT} file")
    return doc
