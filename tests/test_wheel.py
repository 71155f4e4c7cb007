"""The installed wheel, as a new user gets it: one `twinfleet` package, shipped examples by name.

Builds the wheel from a copy of this checkout (pip, with build isolation: setuptools
comes from the package index), installs it without `-e` into a fresh venv, and works
from an empty temporary directory that holds a user package called `nodes`.

The venv gets the third-party dependencies as links to the distributions this
interpreter already has (each distribution's own files and dist-info, found from
twinfleet's requirements; no `.pth` file, so nothing of this environment's editable
twinfleet install comes along), and `pip check` confirms they satisfy every declared
requirement of the wheel. Installing them from the index instead takes ~25 s more
and needs the network for more than the build.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from importlib.metadata import distribution
from pathlib import Path

import pytest

from tests.integration.itest_support import kill_all, poll, processes_mentioning
from tests.support import ROOT

try:
    from packaging.requirements import Requirement
except ImportError:  # pip always has it
    from pip._vendor.packaging.requirements import Requirement  # type: ignore[no-redef]

pytestmark = [pytest.mark.slow, pytest.mark.timeout(240)]

LAYERS = ("runtime", "checker", "nodes", "agreement")
_NOT_SOURCE = shutil.ignore_patterns(".git", "out", "build", "dist", "*.egg-info", "__pycache__",
                                     ".pytest_cache", ".ruff_cache", ".venv", "*.pyc")


def run(argv: list[str], cwd: Path, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    """Run a command with an environment that knows nothing of the checkout."""
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("PYTHON", "TWINFLEET_", "VIRTUAL_ENV"))}
    env["PYTHONUNBUFFERED"] = "1"
    return subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=timeout, check=False)


def ok(result: subprocess.CompletedProcess[str]) -> str:
    assert result.returncode == 0, f"{result.args}:\n{result.stdout}\n{result.stderr}"
    return result.stdout


def dependency_closure(root: str) -> dict[str, object]:
    """Every distribution `root` needs (by normalised name), from installed metadata."""
    seen: dict[str, object] = {}
    todo = [Requirement(r).name for r in distribution(root).requires or []
            if Requirement(r).marker is None or Requirement(r).marker.evaluate({"extra": ""})]
    while todo:
        dist = distribution(todo.pop())
        name = dist.metadata["Name"].lower().replace("_", "-")
        if name in seen:
            continue
        seen[name] = dist
        for text in dist.requires or []:
            req = Requirement(text)
            if req.marker is None or req.marker.evaluate({"extra": ""}):
                todo.append(req.name)
    return seen


def link_dependencies(site: Path) -> None:
    """Link the top-level files of twinfleet's installed dependencies into `site`."""
    for dist in dependency_closure("twinfleet").values():
        base = Path(dist.locate_file(""))  # type: ignore[attr-defined]
        tops = {f.parts[0] for f in dist.files or () if f.parts[0] not in ("..", "__pycache__")
                and f.suffix != ".pth"}  # type: ignore[attr-defined]
        for top in tops:
            if not (site / top).exists():
                (site / top).symlink_to(base / top)


@pytest.fixture(scope="module")
def venv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fresh venv with the wheel of this checkout installed (not editable)."""
    tmp = tmp_path_factory.mktemp("wheel")
    source = tmp / "source"
    shutil.copytree(ROOT, source, ignore=_NOT_SOURCE, symlinks=True)
    ok(run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp / "dist"),
            str(source)], tmp, timeout=180))
    (wheel,) = (tmp / "dist").glob("twinfleet-*.whl")
    env = tmp / "venv"
    ok(run([sys.executable, "-m", "venv", "--without-pip", str(env)], tmp))
    (site,) = env.glob("lib/python*/site-packages")
    link_dependencies(site)
    pip = [sys.executable, "-m", "pip", "--python", str(env / "bin" / "python")]
    ok(run([*pip, "install", "-q", "--no-deps", "--no-index", str(wheel)], tmp))
    ok(run([*pip, "check"], tmp))
    return env


@pytest.fixture
def workdir(tmp_path: Path) -> Path:
    """An empty directory with a user package `nodes` (a `robot.py` that marks its import)."""
    user = tmp_path / "nodes"
    user.mkdir()
    (user / "__init__.py").write_text('"""A user\'s own nodes package."""\n')
    (user / "robot.py").write_text("from pathlib import Path\n"
                                   "Path(__file__).with_name('IMPORTED').touch()\n"
                                   "class Robot:\n    '''Not a twinfleet node.'''\n")
    return tmp_path


def test_site_packages_holds_one_package(venv: Path, workdir: Path) -> None:
    (site,) = venv.glob("lib/python*/site-packages")
    for layer in LAYERS:
        assert not (site / layer).exists() and not (site / f"{layer}.py").exists(), layer
    assert not list(site.glob("*.pth"))
    where = ok(run([str(venv / "bin" / "python"), "-c", "import twinfleet, twinfleet.nodes.robot;"
                    "print(twinfleet.__file__); print(twinfleet.nodes.robot.__file__)"], workdir))
    assert where.splitlines() == [str(site / "twinfleet" / "__init__.py"),
                                  str(site / "twinfleet" / "nodes" / "robot.py")]
    record = (next(site.glob("twinfleet-*.dist-info")) / "RECORD").read_text().splitlines()
    tops = {line.split(",")[0].split("/")[0] for line in record}
    assert {t for t in tops if not t.startswith("..")} == {"twinfleet", next(
        site.glob("twinfleet-*.dist-info")).name}


def test_check_a_shipped_scenario_by_name_beside_a_user_nodes_package(venv: Path,
                                                                     workdir: Path) -> None:
    from twinfleet.checker import check

    expected = check(ROOT / "twinfleet" / "launch" / "c1a_rebeca.yaml")  # today 19,559 states
    for argv in ([str(venv / "bin" / "twinfleet")],  # the console script
                 [str(venv / "bin" / "python"), "-m", "twinfleet"]):  # the work dir on sys.path
        out = json.loads(ok(run([*argv, "check", "c1a_rebeca", "--json"], workdir)))
        assert out["verdict"] == "holds"
        assert (out["states"], out["rmc_transitions"]) == (expected.statistics.states,
                                                           expected.rmc_transitions)
        assert out["scenario"].startswith(str(venv)), out["scenario"]
    assert not (workdir / "nodes" / "IMPORTED").exists()
    # The user package does shadow a top-level `nodes` here, so the test above can fail.
    ok(run([str(venv / "bin" / "python"), "-c", "import nodes.robot"], workdir))
    assert (workdir / "nodes" / "IMPORTED").exists()


def test_examples_list_copy_and_a_bad_name(venv: Path, workdir: Path) -> None:
    twinfleet = str(venv / "bin" / "twinfleet")
    listed = ok(run([twinfleet, "examples"], workdir))
    assert "c1a_rebeca  Paper case C1a (working), profile rebeca" in listed
    ok(run([twinfleet, "examples", "--copy", "c1a"], workdir))
    assert "map: map50.yaml" in (workdir / "c1a.yaml").read_text()
    out = run([twinfleet, "check", "c1a.yaml", "--max-states", "50", "--json"], workdir)
    assert out.returncode == 2 and json.loads(out.stdout)["scenario"] == "c1a.yaml", out.stderr
    bad = run([twinfleet, "launch", "c1z"], workdir)
    assert bad.returncode == 2
    assert bad.stderr.strip().splitlines() == [
        "error: c1z: cannot read scenario file: no such file, and no shipped example is called "
        "'c1z' (shipped: " + ", ".join(sorted(p.stem for p in (ROOT / "twinfleet" / "launch").glob("*.yaml")))
        + "; `twinfleet examples` describes them)"]


def test_launch_a_shipped_scenario_by_name(venv: Path, workdir: Path) -> None:
    shipped = next(venv.glob("lib/python*/site-packages")) / "twinfleet" / "launch" / "c1a.yaml"
    try:
        result = run([str(venv / "bin" / "twinfleet"), "launch", "c1a", "--timeout", "6",
                      "--time-scale", "4"], workdir, timeout=60)
    finally:
        poll(lambda: not processes_mentioning(str(shipped)), 10)
        leftovers = processes_mentioning(str(shipped))
        kill_all(leftovers)
    assert not leftovers
    out = result.stdout
    assert "[launcher] fleet 'c1a'" in out and "run ended after" in out, out + result.stderr
    for node in ("map_server", "r1", "r2", "r3", "r4", "r5"):
        assert f"[launcher]   {node}: exit code 0 (ok)" in out, out
    assert not (workdir / "nodes" / "IMPORTED").exists()
