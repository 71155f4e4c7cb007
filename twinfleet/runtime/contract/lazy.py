"""Public names of a package imported from their modules on first use (PEP 562).

A package that re-exports names of heavy modules its importers mostly do not need
(every command imports `twinfleet.interfaces` and `twinfleet.robots` for a name or two)
gives them a module `__getattr__` made here: the first read of a name imports its
module, and the package keeps the value, so later reads are plain attribute reads.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Mapping
from typing import Any


def lazy_names(package: str, homes: Mapping[str, str]) -> Callable[[str], Any]:
    """The `__getattr__` of `package` that finds each name of `homes` in the module
    ``package.<home>`` it maps to, on first use."""

    def __getattr__(name: str) -> Any:
        home = homes.get(name)
        if home is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f"{package}.{home}"), name)
        setattr(sys.modules[package], name, value)
        return value

    return __getattr__
