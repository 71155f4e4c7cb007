"""Example scenarios found by name (`twinfleet examples`, ``twinfleet check c1a``).

Examples are package data: a package of scenario files, named to `add_examples` by
the application that ships them (twinfleet's command line and testing API name the
robots' `launch` package; the runtime itself knows no example), so the files'
relative paths work in a checkout and in an installed wheel alike.
`runtime.scenario.spec.resolve_scenario` turns a name into one of these files;
`copy_example` copies one (and the files its nodes' path parameters name) into a
directory to edit.
"""

from __future__ import annotations

import re
import shutil
from importlib import resources
from pathlib import Path

import yaml

_KEY_LINE = r"^(?P<head>{key}:[ \t]*)(?P<q>['\"]?)(?P<value>[^'\"#\n]*?)(?P=q)[ \t]*$"


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


def copy_example(name: str, directory: str | Path) -> list[tuple[Path, bool]]:
    """Copy shipped scenario `name` and the map it names into `directory`.

    The copy's `map:` names the copied map (a file beside it). Returns every file
    with True if it was written, False if an existing copy of a map was kept.
    Raises `ExampleError` for an unknown name or when the scenario file exists.
    """
    shipped = shipped_scenarios()
    if name not in shipped:
        raise ExampleError(f"{name}: no shipped example of that name (shipped: "
                           f"{', '.join(shipped)})")
    source, target_dir = shipped[name], Path(directory)
    target = target_dir / source.name
    if target.exists():
        raise ExampleError(f"{target} exists; not overwritten")
    target_dir.mkdir(parents=True, exist_ok=True)
    text, written = source.read_text(), []
    map_rel = _key_value(text, "map")
    if map_rel is not None:
        map_source = (source.parent / map_rel).resolve()
        written += _copy_map(map_source, target_dir)
        text = _set_key_value(text, "map", map_source.name)
    target.write_text(text)
    return [(target, True), *written]


def _copy_map(map_source: Path, target_dir: Path) -> list[tuple[Path, bool]]:
    """Copy a map YAML and the image it names; keep copies already there (one map often
    serves several scenarios)."""
    text = map_source.read_text()
    files: list[tuple[Path, str | None]] = [(map_source, text)]
    image_rel = _key_value(text, "image")
    if image_rel is not None:
        image = (map_source.parent / image_rel).resolve()
        if Path(image_rel).parent != Path():  # not beside the map yet: point at the copy
            text = _set_key_value(text, "image", image.name)
        files = [(map_source, text), (image, None)]
    done = []
    for path, content in files:
        target = target_dir / path.name
        if target.exists():
            done.append((target, False))
        elif content is None:
            shutil.copyfile(path, target)
            done.append((target, True))
        else:
            target.write_text(content)
            done.append((target, True))
    return done


def _key_value(text: str, key: str) -> str | None:
    match = re.search(_KEY_LINE.format(key=key), text, re.MULTILINE)
    return match.group("value") if match else None


def _set_key_value(text: str, key: str, value: str) -> str:
    """Replace a top-level `key: value` line, keeping the rest of the file (and its comments)."""
    return re.sub(_KEY_LINE.format(key=key), lambda m: f"{m.group('head')}{value}", text,
                  count=1, flags=re.MULTILINE)
