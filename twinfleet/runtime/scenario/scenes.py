"""Scenes by import name: how a scenario, a viewer or a recording names the fleet's `Scene`.

``module:Name`` names a class (or any callable) whose call with no arguments
makes a `runtime.contract.scene.Scene`, resolved as node classes are: the
module must be importable where the name is loaded (the scenario's folder and
the working directory are on the path once a scenario file is loaded).
"""

from __future__ import annotations

import importlib
from typing import Any

from twinfleet.runtime.contract.scene import Scene


class SceneError(ValueError):
    """A scene name does not name a scene; the text says why."""


def load_scene(name: str) -> Scene:
    """A new scene of the kind `name` (``module:Name``) names.

    Raises:
        SceneError: the name is malformed, does not import, or its call fails or does not
            make a scene.
    """
    make = _imported(name)
    if not callable(make):
        raise SceneError(f"{name} is a {type(make).__name__}, not a scene class")
    try:
        scene = make()
    except Exception as exc:  # the user's constructor: say what it raised
        raise SceneError(f"{name}() raised {type(exc).__name__}: {exc}") from None
    if not isinstance(scene, Scene):
        raise SceneError(f"{name}() made a {type(scene).__name__}, not a scene (one with "
                         "columns, drawings and state_drawings)")
    return scene


def _imported(name: str) -> Any:
    module_name, _, attr = name.partition(":")
    if not module_name or not attr:
        raise SceneError(f"expected 'module:Scene', got {name!r}")
    try:
        return getattr(importlib.import_module(module_name), attr)
    except (ImportError, AttributeError) as exc:
        raise SceneError(f"unknown scene {name!r} ({exc})") from None
    except RecursionError:
        raise SceneError(f"importing {module_name!r} for scene {name!r} recursed too "
                         "deeply") from None
    except Exception as exc:  # the module itself raised while it was imported
        raise SceneError(f"importing {module_name!r} for scene {name!r} raised "
                         f"{type(exc).__name__}: {exc}") from None
