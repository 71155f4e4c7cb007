"""Node parameters that name files: `file_param` marks a field of a node's `Params`.

A scenario gives such a parameter as a path; a relative one is read relative to the
scenario file's folder (for a scenario built in Python, the working directory), so a
scenario and the files it names move together. `twinfleet examples --copy` copies the
files, and the live launcher sizes its payload limit by them.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Final

#: the dataclass field metadata key that marks a file parameter
FILE_PARAM: Final = "file"


def file_param(*, default: str | None = None, required: bool = True) -> Any:
    """A `Params` field whose value is a file path (``map: str = file_param()``).

    Args:
        default: the path when the scenario gives none (with ``required=False``).
        required: the scenario must give one (no default).
    """
    if required:
        return dataclasses.field(metadata={FILE_PARAM: True})
    return dataclasses.field(default=default, metadata={FILE_PARAM: True})


def file_fields(params_cls: type) -> tuple[str, ...]:
    """The names of the file parameters of a `Params` dataclass, in field order."""
    return tuple(f.name for f in dataclasses.fields(params_cls) if f.metadata.get(FILE_PARAM))
