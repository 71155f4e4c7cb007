"""Installed twinfleet, as a new user gets it: one `twinfleet` package, shipped examples by name.

The wheel: built from a copy of this checkout (pip, with build isolation: setuptools
comes from the package index), installed without `-e` into a fresh venv, and used from
an empty temporary directory that holds a user package called `nodes`.

Each kind of install (`installed`: the wheel, the sdist built by `python -m build
--sdist` and installed by pip, and `pip install -e` of a copy of the checkout), from a
temporary directory: `twinfleet --version`, shipped examples checked by name, the
package data read where the code reads it (maps, launch files, the viewer's static/),
the installed package's files equal to the checkout's, no top-level `runtime`,
`nodes`, `checker` (or any other sub-package name) importable, and a user's project
with its own packages of those names checked and launched (tests/integration/user_project.py).
The sdist holds the package with its data and nothing else (MANIFEST.in).

The venvs get the third-party dependencies as links to the distributions this
interpreter already has (each distribution's own files and dist-info, found from
twinfleet's requirements; no `.pth` file, so nothing of this environment's editable
twinfleet install comes along), and `pip check` confirms they satisfy every declared
requirement of twinfleet. Installing them from the index instead takes ~25 s more
and needs the network for more than the builds.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import tarfile
import tomllib
from dataclasses import dataclass
from importlib.metadata import distribution
from pathlib import Path

import pytest

from tests.integration.itest_support import kill_all, orphaned_nodes, poll
from tests.integration.user_project import expected_modules, logged_modules, write_project
from tests.support import ROOT

try:
    from packaging.requirements import Requirement
except ImportError:  # pip always has it
    from pip._vendor.packaging.requirements import Requirement  # type: ignore[no-redef]

pytestmark = [pytest.mark.slow, pytest.mark.install, pytest.mark.timeout(240)]

LAYERS = ("runtime", "checker", "nodes", "agreement")
#: Every sub-package of twinfleet: none of them may be importable as a top-level module.
SUBPACKAGES = tuple(sorted(p.parent.name for p in (ROOT / "twinfleet").glob("*/__init__.py")))
VERSION = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
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


def new_venv(path: Path) -> Path:
    """A venv at `path` (no pip) holding links to twinfleet's installed dependencies."""
    ok(run([sys.executable, "-m", "venv", "--without-pip", str(path)], path.parent))
    (site,) = path.glob("lib/python*/site-packages")
    link_dependencies(site)
    return path


def pip_into(env: Path, *args: str, cwd: Path) -> None:
    """`pip install --no-deps ARGS` into `env` (this interpreter's pip), then `pip check`."""
    pip = [sys.executable, "-m", "pip", "--python", str(env / "bin" / "python")]
    ok(run([*pip, "install", "-q", "--no-deps", *args], cwd, timeout=180))
    ok(run([*pip, "check"], cwd))


@pytest.fixture(scope="module")
def source(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A copy of this checkout's source (no caches, builds or VCS data): what is built."""
    source = tmp_path_factory.mktemp("source") / "twinfleet"
    shutil.copytree(ROOT, source, ignore=_NOT_SOURCE, symlinks=True)
    return source


@pytest.fixture(scope="module")
def venv(tmp_path_factory: pytest.TempPathFactory, source: Path) -> Path:
    """A fresh venv with the wheel of this checkout installed (not editable)."""
    tmp = tmp_path_factory.mktemp("wheel")
    ok(run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp / "dist"),
            str(source)], tmp, timeout=180))
    (wheel,) = (tmp / "dist").glob("twinfleet-*.whl")
    env = new_venv(tmp / "venv")
    pip_into(env, "--no-index", str(wheel), cwd=tmp)
    return env


@pytest.fixture(scope="module")
def sdist(tmp_path_factory: pytest.TempPathFactory, source: Path) -> Path:
    """The sdist of this checkout, built by `python -m build --sdist` (build isolation:
    setuptools comes from the package index, as for the wheel)."""
    pytest.importorskip("build", reason="`build` (a test extra) builds the sdist")
    dist = tmp_path_factory.mktemp("sdist")
    ok(run([sys.executable, "-m", "build", "--sdist", "--outdir", str(dist), str(source)], dist,
           timeout=180))
    (built,) = dist.glob("twinfleet-*.tar.gz")
    return built


@pytest.fixture(scope="module")
def sdist_venv(tmp_path_factory: pytest.TempPathFactory, sdist: Path) -> Path:
    """A fresh venv with the sdist installed (pip builds its wheel from the sdist alone)."""
    tmp = tmp_path_factory.mktemp("sdist-venv")
    env = new_venv(tmp / "venv")
    pip_into(env, str(sdist), cwd=tmp)
    return env


@pytest.fixture(scope="module")
def editable_venv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fresh venv with an editable install (`pip install -e`) of a copy of this checkout."""
    tmp = tmp_path_factory.mktemp("editable")
    shutil.copytree(ROOT, tmp / "checkout", ignore=_NOT_SOURCE, symlinks=True)
    env = new_venv(tmp / "venv")
    pip_into(env, "-e", str(tmp / "checkout"), cwd=tmp)
    return env


@dataclass(frozen=True)
class Install:
    """A venv with twinfleet installed one way, and where its `twinfleet` package must be."""

    kind: str
    env: Path
    package: Path

    def bin(self, name: str) -> str:
        return str(self.env / "bin" / name)


@pytest.fixture(scope="module", params=["wheel", "sdist", "editable"])
def installed(request: pytest.FixtureRequest) -> Install:
    """Each kind of install in turn (module-scoped: one venv of each kind per test run)."""
    env = request.getfixturevalue("venv" if request.param == "wheel" else f"{request.param}_venv")
    if request.param == "editable":
        package = env.parent / "checkout" / "twinfleet"
    else:
        (site,) = env.glob("lib/python*/site-packages")
        package = site / "twinfleet"
    return Install(request.param, env, package)


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
        "twinfleet launch: c1z: cannot read scenario file: no such file, and no shipped example is called "
        "'c1z' (shipped: " + ", ".join(sorted(p.stem for p in (ROOT / "twinfleet" / "launch").glob("*.yaml")))
        + "; `twinfleet examples` describes them)"]


def test_the_cluster_engine_without_ray_is_one_line(venv: Path, workdir: Path) -> None:
    """The default install has no Ray: asking for it says what to install, exit 2."""
    result = run([str(venv / "bin" / "twinfleet"), "check", "c2a", "--statistical",
                  "--cluster", "local", "--simulations", "1"], workdir)
    assert result.returncode == 2, result
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "pip install twinfleet[cluster]" in lines[0], result.stderr
    assert lines[0].startswith("twinfleet check: "), lines


def test_launch_a_shipped_scenario_by_name(venv: Path, workdir: Path) -> None:
    try:
        result = run([str(venv / "bin" / "twinfleet"), "launch", "c1a", "--timeout", "6",
                      "--time-scale", "4"], workdir, timeout=60)
    finally:
        poll(lambda: not orphaned_nodes(), 10)
        leftovers = orphaned_nodes()
        kill_all(leftovers)
    assert not leftovers
    out = result.stdout
    assert "[launcher] fleet 'c1a'" in out and "run ended after" in out, out + result.stderr
    for node in ("map_server", "r1", "r2", "r3", "r4", "r5"):
        assert f"[launcher]   {node}: exit code 0 (ok)" in out, out
    assert not (workdir / "nodes" / "IMPORTED").exists()


def package_files(package: Path) -> list[str]:
    """The files of a `twinfleet` package folder, relative to it (no caches)."""
    return sorted(str(p.relative_to(package)) for p in package.rglob("*")
                  if p.is_file() and "__pycache__" not in p.parts and p.suffix != ".pyc")


#: Run in an installed venv: where `twinfleet` is, the package data that the viewer, the
#: map server and `examples` read, and what each sub-package name imports at top level.
PROBE = """
import importlib, importlib.resources, json, sys
import twinfleet
from twinfleet.runtime.tools.view.viewer import STATIC_DIR
import twinfleet.cli  # adds the shipped examples, as the command does
from twinfleet.runtime.scenario.examples import shipped_scenarios
data = {p: sorted(f.name for f in importlib.resources.files(p).iterdir() if f.is_file()
                  and not f.name.endswith(".py"))
        for p in ("twinfleet.maps", "twinfleet.launch")}
data["static"] = sorted(f.name for f in (importlib.resources.files(
    "twinfleet.runtime.tools.view") / "static").iterdir())
data["STATIC_DIR"] = sorted(f.name for f in STATIC_DIR.iterdir())
tops = {}
for name in sys.argv[1:]:
    try:
        module = importlib.import_module(name)
    except ModuleNotFoundError as exc:
        tops[name] = None if exc.name == name else repr(exc)
    else:
        tops[name] = getattr(module, "__file__", None) or repr(module)
print(json.dumps({"twinfleet": twinfleet.__file__, "data": data, "tops": tops,
                  "shipped": sorted(shipped_scenarios())}))
"""


@pytest.fixture
def empty(tmp_path: Path) -> Path:
    """An empty working directory."""
    path = tmp_path / "empty"
    path.mkdir()
    return path


def test_the_sdist_holds_the_package_and_its_data_and_nothing_else(sdist: Path,
                                                                   source: Path) -> None:
    with tarfile.open(sdist) as tar:
        names = [m.name for m in tar.getmembers() if m.isfile()]
    root = f"twinfleet-{VERSION}/"
    assert all(n.startswith(root) for n in names), names
    names = [n.removeprefix(root) for n in names]
    tops = {n.split("/")[0] for n in names}
    assert tops == {"MANIFEST.in", "PKG-INFO", "README.md", "pyproject.toml", "setup.cfg",
                    "twinfleet", "twinfleet.egg-info"}, tops
    shipped = sorted(n.removeprefix("twinfleet/") for n in names if n.startswith("twinfleet/"))
    assert shipped == package_files(source / "twinfleet")
    for data in ("maps/map50.pgm", "maps/map50.yaml", "maps/corridor12.pgm",
                 "launch/c1a.yaml", "runtime/tools/view/static/index.html",
                 "runtime/tools/view/static/viewer.js"):
        assert data in shipped, data


def test_each_install_has_one_package_with_all_its_files(installed: Install, empty: Path) -> None:
    assert ok(run([installed.bin("twinfleet"), "--version"], empty)).strip() == (
        f"twinfleet {VERSION}")
    probe = json.loads(ok(run([installed.bin("python"), "-c", PROBE, *SUBPACKAGES], empty)))
    assert probe["twinfleet"] == str(installed.package / "__init__.py")
    assert probe["tops"] == dict.fromkeys(SUBPACKAGES), probe["tops"]  # none importable
    checkout = ROOT / "twinfleet"
    assert probe["data"] == {
        "twinfleet.maps": sorted(p.name for p in (checkout / "maps").iterdir()
                                 if p.suffix in (".pgm", ".yaml")),
        "twinfleet.launch": sorted(p.name for p in (checkout / "launch").glob("*.yaml")),
        "static": sorted(p.name for p in (checkout / "runtime/tools/view/static").iterdir()),
        "STATIC_DIR": sorted(p.name for p in (checkout / "runtime/tools/view/static").iterdir()),
    }
    assert probe["shipped"] == sorted(p.stem for p in (checkout / "launch").glob("*.yaml"))
    assert package_files(installed.package) == package_files(checkout)


def test_each_install_checks_shipped_examples(installed: Install, empty: Path) -> None:
    from twinfleet.checker import check

    bounded = run([installed.bin("twinfleet"), "check", "c1a", "--max-states", "50", "--json"],
                  empty)
    out = json.loads(bounded.stdout)
    assert bounded.returncode == 2, bounded.stderr  # no answer within 50 states
    assert (out["verdict"], out["states"]) == ("unknown", 50), out
    assert out["scenario"] == str(installed.package / "launch" / "c1a.yaml")

    expected = check(ROOT / "twinfleet" / "launch" / "headon.yaml")  # violated: they collide
    full = run([installed.bin("twinfleet"), "check", "headon", "--json"], empty)
    out = json.loads(full.stdout)
    assert (full.returncode, out["verdict"], out["violation"]["property"]) == (
        1, "violated", "no_collision"), full.stdout + full.stderr
    assert (out["states"], out["rmc_transitions"]) == (expected.statistics.states,
                                                       expected.rmc_transitions)


def test_each_install_runs_a_users_nodes_runtime_checker_packages(installed: Install,
                                                                  tmp_path: Path) -> None:
    scenario = write_project(tmp_path / "proj")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    relative = os.path.relpath(scenario, elsewhere)
    checked = run([installed.bin("twinfleet"), "check", relative], elsewhere)
    assert "verdict: HOLDS: every property holds" in ok(checked), checked.stdout
    try:
        launched = run([installed.bin("python"), "-m", "twinfleet", "launch", relative,
                        "--timeout", "2"], elsewhere, timeout=60)
    finally:
        poll(lambda: not orphaned_nodes(), 10)
        leftovers = orphaned_nodes()
        kill_all(leftovers)
    out = ok(launched)
    assert not leftovers
    assert ("[launcher] result: PASSED (user_classes, user_modules, started, all_heard, "
            "no_failure hold)") in out, out
    want = expected_modules(tmp_path / "proj")
    assert logged_modules(out) == {"pinger": (want, ()), "listener": (want, ())}, out


# Examples run for real, after a plain wheel install, from an empty directory, in the order
# the help and the README give them: the ones that need no running fleet and end by
# themselves (their outputs feed the next ones: `check --trace-out` writes what `replay`,
# `trace show` and `render` read). Every other example (a live fleet, a browser, a long
# experiment) is parsed by the installed command line, so each command, option and argument
# it shows exists there.
RUN_FOR_REAL = ("check", "replay", "render", "trace", "examples", "interface")


def command_examples() -> list[str]:
    """Every `twinfleet ...` command line of `twinfleet --help` and of the README's command
    blocks, comments dropped (output lines such as ``twinfleet check: ...`` left out)."""
    from twinfleet.cli import build_parser

    commands = set(build_parser()._subparsers._group_actions[0].choices)  # type: ignore[union-attr]
    help_text = build_parser().format_help()
    readme = (ROOT / "README.md").read_text()
    blocks = [b for lang, b in re.findall(r"```(\w*)\n(.*?)```", readme, re.S) if not lang]
    # a comment, or (in the help) a description after two spaces, ends a command
    lines = [re.split(r"#|\s{2,}", line.strip())[0].strip() for text in (help_text, *blocks)
             for line in text.splitlines()]
    return [line for line in dict.fromkeys(lines)
            if line.startswith("twinfleet ") and line.split()[1] in commands]


def test_every_command_example_of_the_help_and_readme_works_installed(venv: Path,
                                                                      workdir: Path) -> None:
    examples = command_examples()
    assert len(examples) >= 20 and "twinfleet launch demo" in examples, examples
    python = str(venv / "bin" / "python")
    parse = ("import shlex, sys\nfrom twinfleet.cli import build_parser\n"
             "for line in sys.argv[1:]: build_parser().parse_args(shlex.split(line)[1:])")
    ok(run([python, "-c", parse, *examples], workdir))
    ran = []
    for line in examples:
        words = shlex.split(line)
        if words[1] not in RUN_FOR_REAL or "--statistical" in words or "--live" in words:
            continue
        result = run([str(venv / "bin" / "twinfleet"), *words[1:]], workdir, timeout=300)
        # a check or replay of a counterexample exits 1; anything else must succeed
        expected = {1} if words[1] in ("check", "replay") and "c2a" in line else {0}
        assert result.returncode in expected, f"{line}:\n{result.stdout}\n{result.stderr}"
        assert "Traceback" not in result.stderr, line
        ran.append(line)
    launched = run([str(venv / "bin" / "twinfleet"), "launch", "demo", "--timeout", "2"],
                   workdir, timeout=60)
    assert launched.returncode == 0 and "result: PASSED" in launched.stdout, launched.stdout
    assert {w.split()[1] for w in ran} >= {"check", "replay", "render"}, ran
