"""The frozen classes as module attributes: ``twinfleet.interfaces.frozen.geometry_msgs.msg.Twist``.

The node-state snapshot (`runtime.contract.snapshot`) and pickle find a class again by
its module and qualified name. A frozen class is generated (`generate`), so this module
answers its name when asked (PEP 562's module ``__getattr__``): a frozen class's
``__module__`` is this module and its ``__qualname__`` ``geometry_msgs.msg.Twist``
(``std_srvs.srv.SetBool_Request`` for a service's request), which also reads well in
its ``repr``.

It lies below `generate`, which hands it the function that makes the classes
(`answer_with`) when it is imported: importing this module imports its package first,
and the package imports `generate`, so the function is there before any name is asked.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

_contract_type: Callable[[str], type] | None = None


def answer_with(contract_type: Callable[[str], type]) -> None:
    """Answer ``pkg.msg.Name`` with ``contract_type("pkg/msg/Name")`` (`generate` calls it)."""
    global _contract_type
    _contract_type = contract_type


class _Part:
    """``geometry_msgs`` or ``geometry_msgs.msg``: the next name completes the type."""

    def __init__(self, *path: str) -> None:
        self._path = path

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):
            raise AttributeError(name)
        if len(self._path) == 1:
            return _Part(*self._path, name)
        assert _contract_type is not None, "twinfleet.interfaces.generate is not loaded"
        return _contract_type("/".join((*self._path, name)))


def __getattr__(package: str) -> Any:
    if package.startswith("_"):
        raise AttributeError(package)
    return _Part(package)
