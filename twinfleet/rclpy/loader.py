"""How node code that twinfleet loads gets twinfleet's `rclpy` and ROS messages.

While the scenario layer imports a node's module (`importing()`), a meta-path finder
sits first on `sys.meta_path` and answers:

- ``rclpy`` and ``rclpy.<module>`` with `twinfleet.rclpy.api` and its modules;
- ``<package>`` and ``<package>.msg`` / ``.srv`` of the interface packages twinfleet
  generates (std_msgs, geometry_msgs, std_srvs, ...) with `twinfleet.interfaces`;
- the parts of ROS 2 not offered yet (`rclpy.action`, lifecycle nodes, tf2) with one
  `ImportError` line that names them.

When the import is over the finder is removed and those names leave `sys.modules`
again (an entry that was there before, e.g. a real rclpy, is put back), so any other
code of the process, and every other program, keeps the real ROS 2 installation; the
node's module keeps the objects it imported.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import types
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any

from twinfleet.rclpy import wire

_API = "twinfleet.rclpy.api"

#: ROS 2 modules not offered yet, and the line a node importing them gets.
UNSUPPORTED = {
    "rclpy.action": "rclpy.action (actions)",
    "rclpy.lifecycle": "rclpy.lifecycle (lifecycle nodes)",
    "tf2_ros": "tf2_ros (tf2)",
    "tf2_py": "tf2_py (tf2)",
    "tf2_geometry_msgs": "tf2_geometry_msgs (tf2)",
}


class UnsupportedImport(ImportError):
    """Node code imports a part of ROS 2 that twinfleet does not offer yet."""


def _refusal(fullname: str) -> str | None:
    for name, what in UNSUPPORTED.items():
        if fullname == name or fullname.startswith(name + "."):
            return (f"{what} is not supported by twinfleet's rclpy yet "
                    "(docs/rclpy.md lists what is)")
    return None


class _Alias(importlib.abc.Loader):
    """Loads a name as a module that already exists."""

    def __init__(self, module: types.ModuleType) -> None:
        self.module = module

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> types.ModuleType:
        return self.module

    def exec_module(self, module: types.ModuleType) -> None:
        return None


class RosFinder(importlib.abc.MetaPathFinder):
    """The finder of the module docstring."""

    def __init__(self) -> None:
        self.tops: set[str] = set()  # top-level names it answered

    def find_spec(self, fullname: str, path: Sequence[str] | None = None,
                  target: types.ModuleType | None = None) -> importlib.machinery.ModuleSpec | None:
        refusal = _refusal(fullname)
        if refusal is not None:
            raise UnsupportedImport(refusal)
        top = fullname.partition(".")[0]
        if top == "rclpy":
            module = self._api_module(fullname)
        elif wire.is_known_package(top):
            module = self._interface_module(fullname)
        else:
            return None
        self.tops.add(top)
        return importlib.machinery.ModuleSpec(fullname, _Alias(module),
                                              is_package=hasattr(module, "__path__"))

    @staticmethod
    def _api_module(fullname: str) -> types.ModuleType:
        target = _API + fullname[len("rclpy"):]
        try:
            return importlib.import_module(target)
        except ModuleNotFoundError:
            raise UnsupportedImport(f"{fullname} is not offered by twinfleet's rclpy yet "
                                    "(docs/rclpy.md lists what is)") from None

    @staticmethod
    def _interface_module(fullname: str) -> types.ModuleType:
        parts = fullname.split(".")
        if len(parts) == 1:
            package = types.ModuleType(fullname, f"ROS interface package {fullname} (twinfleet)")
            package.__path__ = []
            return package
        if len(parts) == 2 and parts[1] in ("msg", "srv"):
            return wire.load_interface(parts[0], parts[1])
        raise UnsupportedImport(f"{fullname}: twinfleet offers {parts[0]}.msg and "
                                f"{parts[0]}.srv only")


@contextmanager
def importing() -> Iterator[None]:
    """Import node code with twinfleet's rclpy and messages in place (module docstring)."""
    finder = RosFinder()
    saved = {k: v for k, v in list(sys.modules.items()) if _ros_name(k)}
    for name in saved:
        del sys.modules[name]
    sys.meta_path.insert(0, finder)
    try:
        yield
    finally:
        sys.meta_path.remove(finder)
        for name in [k for k in list(sys.modules) if _ros_name(k) or k.partition(".")[0] in finder.tops]:
            del sys.modules[name]
        sys.modules.update(saved)


def _ros_name(name: str) -> bool:
    top = name.partition(".")[0]
    return top == "rclpy" or top in UNSUPPORTED or wire.is_known_package(top)


def is_rclpy_node_class(obj: Any) -> bool:
    """True for a subclass of twinfleet's `rclpy.node.Node`."""
    # Such a class imported the module that defines Node (`rclpy` is an alias of it): if
    # nothing did, no class is one, and a scenario of contract nodes (`check`) need not
    # import the whole rclpy layer to learn that.
    module = sys.modules.get(f"{_API}.node")
    return module is not None and isinstance(obj, type) and issubclass(obj, module.Node)


def contract_class(obj: Any) -> Any:
    """The contract node class for `obj`: its adapter when it is an rclpy node class."""
    if is_rclpy_node_class(obj):
        from twinfleet.rclpy.adapter import adapt
        return adapt(obj)
    return obj
