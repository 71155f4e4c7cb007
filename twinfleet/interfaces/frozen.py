"""The frozen classes as module attributes: ``twinfleet.interfaces.frozen.geometry_msgs.msg.Twist``.

The node-state snapshot (`runtime.contract.snapshot`) and pickle find a class again by
its module and qualified name. A frozen class is generated (`generate`), so this module
answers its name when asked (PEP 562's module ``__getattr__``): a frozen class's
``__module__`` is this module and its ``__qualname__`` ``geometry_msgs.msg.Twist``
(``std_srvs.srv.SetBool_Request`` for a service's request), which also reads well in
its ``repr``.
"""

from __future__ import annotations

from typing import Any

from twinfleet.interfaces.generate import contract_type


class _Part:
    """``geometry_msgs`` or ``geometry_msgs.msg``: the next name completes the type."""

    def __init__(self, *path: str) -> None:
        self._path = path

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):
            raise AttributeError(name)
        if len(self._path) == 1:
            return _Part(*self._path, name)
        return contract_type("/".join((*self._path, name)))


def __getattr__(package: str) -> Any:
    if package.startswith("_"):
        raise AttributeError(package)
    return _Part(package)
