"""Example scenarios found by name (`twinfleet examples`, ``twinfleet check c1a``).

Examples are package data: a package of scenario files, named to `add_examples` by
the application that ships them (twinfleet's command line and testing API name the
robots' `launch` package; the runtime itself knows no example), so the files'
relative paths work in a checkout and in an installed wheel alike.
`runtime.scenario.spec.resolve_scenario` turns a name into one of these files;
`runtime.scenario.files.copy_example` copies one, with the files it names, into a
directory to edit.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

import yaml


class ExampleError(ValueError):
    """An example cannot be found or copied; the message says why."""


_PACKAGES: list[str] = []  # where examples are found, in the order they were added


def add_examples(package: str) -> None:
    """Let the scenario files of `package` (an importable package of ``*.yaml`` files) be
    loaded by name; adding one twice changes nothing."""
    if package not in _PACKAGES:
        _PACKAGES.append(package)


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
