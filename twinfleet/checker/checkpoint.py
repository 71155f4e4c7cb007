"""Checkpoint files: a long search saved to disk and resumed later.

A checkpoint is two pickles in one file: a header (``"format":
"twinfleet-checkpoint/3"`` and `meta`: what the search was run on: the scenario
file, its SHA-256, semantics, parameters, search order, state mode...), then the
visited-state store, the frontier (worlds waiting to be expanded, with their ids
and depths) and the counters. The header comes first because the rest holds node
states of the user's own classes: `load` puts the scenario's folder on the import
path, as loading the scenario does, before it reads them. (/2, one pickle of all
of it, is still read; event kinds have been `EventKind` values since /2.)
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
from twinfleet.runtime.scenario.spec import user_import_path

FORMAT = "twinfleet-checkpoint/3"
_ONE_PICKLE = "twinfleet-checkpoint/2"  # header and body in one pickle, still read


class CheckpointError(ValueError):
    """A checkpoint file is unreadable, of another format, or does not fit the scenario."""


def save(path: str | Path, meta: Mapping[str, Any], store: Any, frontier: list[Any],
         counters: Mapping[str, Any]) -> None:
    """Write a checkpoint atomically (temporary file, then rename)."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".tmp")
    with open(tmp, "wb") as f:
        pickle.dump({"format": FORMAT, "meta": dict(meta)}, f, protocol=pickle.HIGHEST_PROTOCOL)
        pickle.dump({"store": store, "frontier": frontier, "counters": dict(counters)}, f,
                    protocol=pickle.HIGHEST_PROTOCOL)
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
            if isinstance(doc, dict) and doc.get("format") == FORMAT:
                scenario = doc["meta"].get("scenario")
                if scenario is not None:  # the node states below may be of its modules
                    user_import_path(Path(scenario).parent)
                doc.update(pickle.load(f))
    except FileNotFoundError:
        raise CheckpointError(f"{path}: no such checkpoint file") from None
    except Exception as exc:  # pickle raises many kinds for a damaged file
        raise CheckpointError(f"{path}: cannot read checkpoint: {type(exc).__name__}: {exc}") \
            from None
    if not isinstance(doc, dict) or doc.get("format") not in (FORMAT, _ONE_PICKLE):
        raise CheckpointError(f"{path}: not a {FORMAT} file")
    return doc
