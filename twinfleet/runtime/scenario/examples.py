"""Example scenarios found by name (`twinfleet examples`, ``twinfleet check c1a``).

Examples are package data: a package of scenario files, named to `add_examples` by
the application that ships them (twinfleet's command line and testing API name the
robots' `launch` package; the runtime itself knows no example), so the files'
relative paths work in a checkout and in an installed wheel alike.
`runtime.scenario.spec.resolve_scenario` turns a name into one of these files;
`runtime.scenario.files.copy_example` copies one, with the files it names, into a
directory to edit.

An example package may also bring a picture renderer (`Pictures`) for its scenarios:
`twinfleet render` asks the registered renderers, in the order they were added, and
draws with the first that can draw the scenario. The registry is the application's
wiring, like its command line's subcommands: it is set once at start-up, only grows,
and adding the same package again changes nothing, so it holds no state of a run.
"""

from __future__ import annotations

from collections.abc import Mapping
from importlib import resources
from pathlib import Path
from typing import Any, Protocol

import yaml


class ExampleError(ValueError):
    """An example cannot be found or copied; the message says why."""


class Pictures(Protocol):
    """Draws the scenarios of an example package and traces of them as pictures."""

    def cannot_draw(self, scenario: Any) -> str | None:
        """Why this renderer cannot draw `scenario` (a loaded scenario), in its user's
        words; None when it can."""

    def draw(self, scenario: Any, trace: Mapping[str, Any] | None, output: str, *,
             options: Mapping[str, Any]) -> int:
        """Write `output` (a picture of `scenario`'s start, or of `trace`'s steps); return
        the number of frames. `options`: the renderer's own flags by name (unknown ones
        are ignored); ValueError on bad input."""


_PACKAGES: list[str] = []  # where examples are found, in the order they were added
_PICTURES: list[Pictures] = []  # the packages' renderers, in the same order


def add_examples(package: str, pictures: Pictures | None = None) -> None:
    """Let the scenario files of `package` (an importable package of ``*.yaml`` files) be
    loaded by name, and `pictures` draw scenarios (`renderer_for`); adding one twice
    changes nothing."""
    if package not in _PACKAGES:
        _PACKAGES.append(package)
    if pictures is not None and pictures not in _PICTURES:
        _PICTURES.append(pictures)


def renderer_for(scenario: Any) -> Pictures:
    """The first registered renderer that can draw `scenario`; ValueError saying why none
    can (one line)."""
    reasons = []
    for pictures in _PICTURES:
        if (why := pictures.cannot_draw(scenario)) is None:
            return pictures
        reasons.append(why)
    if not reasons:
        raise ValueError(f"no example package registered a renderer, so {scenario.name} "
                         "cannot be drawn on a picture")
    raise ValueError("; ".join(reasons))


def shipped_scenarios() -> dict[str, Path]:
    """Every example scenario by name (file stem), sorted; a name in two packages is the
    first package's."""
    found: dict[str, Path] = {}
    for package in _PACKAGES:
        for path in Path(str(resources.files(package))).glob("*.yaml"):
            found.setdefault(path.stem, path)
    return dict(sorted(found.items()))


def describe(path: Path) -> str:
    """A scenario file's `description:` (empty when it has none or cannot be read)."""
    try:
        doc = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError):
        return ""
    return str(doc.get("description", "")) if isinstance(doc, dict) else ""
