"""The files a scenario names through its nodes' file parameters (`contract.params.file_param`).

A file parameter is read relative to the scenario file, so a scenario and its files move
together: `examples.copy_example` copies them with it, and the launcher sizes the fleet's
payload limit by them. A YAML file may name files of its own by a relative path (a map
names its image): `companions` finds those, without knowing what the file means.
"""

from __future__ import annotations

import re
import shutil
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml

from twinfleet.runtime.contract.params import file_fields
from twinfleet.runtime.scenario.examples import ExampleError, shipped_scenarios
from twinfleet.runtime.scenario.spec import Scenario, load_scenario

_YAML = (".yaml", ".yml")
_KEY_LINE = r"^(?P<head>[ \t]*{key}:[ \t]*)(?P<q>['\"]?)(?P<value>[^'\"#\n]*?)(?P=q)[ \t]*$"


def scenario_files(scenario: Scenario) -> dict[str, Path]:
    """Every file a node's file parameter names, by parameter name (the first node's when
    two name different files with one parameter), in node order."""
    found: dict[str, Path] = {}
    for cfg in scenario.nodes:
        for name in file_fields(type(cfg.params)):
            value = getattr(cfg.params, name)
            if isinstance(value, str):
                found.setdefault(name, Path(value))
    return found


def with_absolute_files(doc: Mapping[str, Any], scenario: Scenario) -> dict[str, Any]:
    """`doc`, the YAML mapping `scenario` was read from, with every file parameter it gives
    (common or a node's own) as the absolute path the scenario read: a copy of it written
    anywhere reads the same files."""
    out = dict(doc)
    files = scenario_files(scenario)
    if isinstance(out.get("params"), Mapping):
        out["params"] = {k: str(files[k]) if k in files else v for k, v in out["params"].items()}
    nodes = []
    for entry, cfg in zip(out.get("nodes") or [], scenario.nodes, strict=False):
        own = entry.get("params") if isinstance(entry, Mapping) else None
        if isinstance(own, Mapping):
            fields = set(file_fields(type(cfg.params)))
            entry = {**entry, "params": {k: getattr(cfg.params, k) if k in fields else v
                                         for k, v in own.items()}}
        nodes.append(entry)
    out["nodes"] = nodes
    return out


def companions(path: Path) -> dict[str, Path]:
    """The files a YAML file names by a relative path, by the top-level key naming each
    (nothing for a file that is not YAML or cannot be read)."""
    if path.suffix not in _YAML:
        return {}
    try:
        doc = yaml.safe_load(path.read_text())
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        return {}
    if not isinstance(doc, Mapping):
        return {}
    return {str(k): (path.parent / v).resolve() for k, v in doc.items()
            if isinstance(v, str) and v and not Path(v).is_absolute()
            and (path.parent / v).is_file()}


def largest_file_bytes(scenario: Scenario) -> int:
    """The size of the largest file the scenario's nodes read (their companions included):
    what a node may send whole, such as a map's grid (0 when they read none)."""
    sizes = [0]
    for path in scenario_files(scenario).values():
        for one in (path, *companions(path).values()):
            try:
                sizes.append(one.stat().st_size)
            except OSError:
                continue
    return max(sizes)


def copy_example(name: str, directory: str | Path) -> list[tuple[Path, bool]]:
    """Copy example scenario `name` and the files its nodes' file parameters name (and
    their `companions`) into `directory`.

    The copy's file parameters name the copied files (beside it). Returns every file
    with True if it was written, False if an existing copy was kept (one map often
    serves several scenarios). Raises `ExampleError` for an unknown name or when the
    scenario file exists.
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
    for key, path in scenario_files(load_scenario(source)).items():
        if _key_value(text, key) is not None:
            written += _copy_file(path, target_dir)
            text = _set_key_value(text, key, path.name)
    target.write_text(text)
    return [(target, True), *written]


def _copy_file(source: Path, target_dir: Path) -> list[tuple[Path, bool]]:
    """Copy a file and its companions beside it, the copy naming its companions' copies."""
    text = source.read_text() if source.suffix in _YAML else None
    files: list[tuple[Path, str | None]] = []
    for key, path in companions(source).items():
        rel = _key_value(text or "", key)
        if text is not None and rel is not None and Path(rel).parent != Path():
            text = _set_key_value(text, key, path.name)  # not beside it yet: the copy is
        files.append((path, None))
    done = []
    for path, content in [(source, text), *files]:
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
    match = re.search(_KEY_LINE.format(key=re.escape(key)), text, re.MULTILINE)
    return match.group("value") if match else None


def _set_key_value(text: str, key: str, value: str) -> str:
    """Replace the first `key: value` line, keeping the rest of the file (and its comments)."""
    return re.sub(_KEY_LINE.format(key=re.escape(key)), lambda m: f"{m.group('head')}{value}",
                  text, count=1, flags=re.MULTILINE)
