"""The direction of imports between the parts (docs/architecture.md, "Packages and the
direction of imports"), read from the source's syntax tree, so a function-level import
counts as much as one at the top of a module."""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# What the simulator may import of the application: the shared records and utilities, the
# root exception, and the package's root (its version string).
SIM_ALLOWED = ("companion.core", "companion.errors")


@functools.cache
def syntax_tree(path: Path) -> ast.Module:
    """The parsed module (each file is parsed once for all the checks)."""
    return ast.parse(path.read_text(encoding="utf-8"), str(path))


def imported_modules(path: Path) -> list[tuple[int, str]]:
    """Every module ``path`` imports (absolute names), with the line it is imported on."""
    tree = syntax_tree(path)
    package = ".".join(path.relative_to(ROOT).with_suffix("").parts[:-1])
    out: list[tuple[int, str]] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.extend((node.lineno, alias.name) for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                base = f"{parent}.{base}" if base else parent
            if base == "companion":  # "from companion import x" names a module or the version
                out.extend((node.lineno, f"companion.{alias.name}") for alias in node.names)
            else:
                out.append((node.lineno, base))
    return out


def _inside(name: str, prefixes: tuple[str, ...]) -> bool:
    return any(name == p or name.startswith(p + ".") for p in prefixes)


def forbidden(folder: str, banned: tuple[str, ...], allowed: tuple[str, ...] = ()
              ) -> list[str]:
    """``file:line imports module`` for each import under ``folder`` of a ``banned``
    module that is not ``allowed``."""
    bad = []
    for path in sorted((ROOT / folder).rglob("*.py")):
        for line, name in imported_modules(path):
            if _inside(name, banned) and not _inside(name, allowed):
                bad.append(f"{path.relative_to(ROOT)}:{line} imports {name}")
    return bad


def test_simulator_is_a_leaf() -> None:
    """companion/sim imports of the application only the shared records (companion.core)
    and the root exception; the application imports the simulator, never the reverse."""
    allowed = (*SIM_ALLOWED, "companion.sim", "companion.__version__")
    assert forbidden("companion/sim", ("companion",), allowed) == []


@pytest.mark.parametrize("folder", ["companion/sources", "companion/landmarks", "companion/core"])
def test_the_simulator_is_not_imported_by_the_production_parts(folder: str) -> None:
    """Frame sources, the landmark database and the shared records never import the
    simulator (a source that knows its truth says so through a protocol)."""
    assert forbidden(folder, ("companion.sim",)) == []


#: The simulator and what exists only to fly it (the scripted demo and its fake autopilot).
SIMULATOR = ("companion.sim", "companion.simulated", "companion.follow", "companion.demo",
             "companion.demo_autopilot")


def module_file(name: str) -> Path | None:
    """The file of an application module (a package's ``__init__.py``), None for others."""
    path = ROOT / Path(*name.split("."))
    for candidate in (path / "__init__.py", path.with_suffix(".py")):
        if candidate.is_file():
            return candidate
    return None


def import_chains(start: str, banned: tuple[str, ...]) -> list[str]:
    """``start <- ... <- banned module`` for each ``banned`` module that ``start`` imports,
    directly or through any module of the application it imports (at any level)."""
    importer: dict[str, str | None] = {start: None}
    todo = [start]
    while todo:
        path = module_file(todo.pop())
        if path is None:
            continue
        here = ".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
        for _, name in imported_modules(path):
            if name.startswith("companion") and name not in importer:
                importer[name] = here
                todo.append(name)
    chains = []
    for name in sorted(n for n in importer if _inside(n, banned)):
        chain, at = [name], importer[name]
        while at is not None:
            chain.append(at)
            at = importer[at]
        chains.append(" <- ".join(chain))
    return chains


def test_run_does_not_import_the_simulator() -> None:
    """``companion run`` (its command module and every module of the application it
    imports) never imports the simulator: the simulated cameras are plugged into the source
    factory (companion.simulated.register, called by the command line), and what run needs
    of them -- their truth, their textures, their camera -- comes through the protocols of
    companion.sources.base.  On the parent commit run_cmd imported companion.follow,
    companion.simulated and companion.sim.{scenario,simulator,square}."""
    assert import_chains("companion.cli.run_cmd", SIMULATOR) == []


#: Run in a fresh interpreter: the command line built as ``companion run`` builds it, a
#: ``run`` parsed and a recorded stream opened through the factory; prints what of the
#: simulator got loaded.
_RUN_PROCESS = """
import asyncio, sys
import numpy as np
from companion.cli import build_parser
from companion.core.frames import Frame
from companion.core.stream_format import StreamMeta
from companion.core.stream_io import StreamWriter
from companion.sources.config import SourceConfig
from companion.sources.factory import open_source
from tracker.camera import CameraModel

build_parser().parse_args(["run", "--config", "vehicle.toml"])
import companion.cli.run_cmd
writer = StreamWriter(sys.argv[1], StreamMeta(fps=30.0, camera=CameraModel()), "png")
writer.write(Frame(0, 0, np.zeros((480, 640, 3), np.uint8)), None)
writer.close()
source = asyncio.run(open_source(SourceConfig(spec="stream:" + sys.argv[1])))
source.close()
print(sorted(m for m in sys.modules if m.startswith(tuple(sys.argv[2:]))))
"""


def test_the_run_process_does_not_load_the_simulator(tmp_path: Path) -> None:
    """What the syntax tree cannot see: the command line builds every command's parser and
    names the simulator's source kinds (companion.cli.PLUGINS, imported by name).  A run
    process that opens a stream loads none of the simulator (at 635b027 it loaded 16 of its
    modules as the parser was built: companion.simulated eagerly, and demo, synth and
    record at their modules' top)."""
    import subprocess
    import sys

    banned = ("companion.sim", "companion.simulated", "companion.follow", "companion.demo",
              "companion.calibration_boards")
    done = subprocess.run([sys.executable, "-c", _RUN_PROCESS, str(tmp_path / "s"), *banned],
                          capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip() == "[]", done.stdout


def test_the_import_chains_are_found() -> None:
    """The check above sees an import directly and through modules in between (the demo
    imports the simulator, whose simulator module imports its world)."""
    assert import_chains("companion.demo", ("companion.sim.world",)) == [
        "companion.sim.world <- companion.sim.simulator <- companion.demo"]
    assert import_chains("companion.sources.factory", SIMULATOR) == []


def test_core_imports_only_errors() -> None:
    """The shared records import nothing else of the application."""
    assert forbidden("companion/core", ("companion",), SIM_ALLOWED) == []
@pytest.mark.parametrize(("folder", "banned"), [
    ("tracker", ("companion", "mavlink_bridge", "sitl_tests", "tests", "benchmarks")),
    ("mavlink_bridge", ("companion", "tracker", "sitl_tests", "tests", "benchmarks")),
    ("companion", ("sitl_tests", "tests", "benchmarks")),
    ("benchmarks", ("sitl_tests", "tests")),
    ("sitl_tests", ("benchmarks",)),
    ("testsupport", ("tests", "sitl_tests", "benchmarks")),
    ("companion", ("testsupport",)),
])
def test_package_layers(folder: str, banned: tuple[str, ...]) -> None:
    """tracker and mavlink_bridge stay below companion; no package, benchmark or scenario
    test imports the tests or another's scripts: shared code lives in the package or in
    testsupport, which imports none of them. On the parent commit benchmarks imported
    tests.calibration.boards, tests.landmarks.pgcluster and sitl_tests.harness."""
    assert forbidden(folder, banned) == []


def loads_by_path(folder: str) -> list[str]:
    """``file:line`` of each call that runs a Python file by its path (which hides an
    import from the checks above)."""
    bad = []
    for path in sorted((ROOT / folder).rglob("*.py")):
        for node in ast.walk(syntax_tree(path)):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute | ast.Name):
                name = node.func.attr if isinstance(node.func, ast.Attribute) else node.func.id
                if name in ("spec_from_file_location", "run_path"):
                    bad.append(f"{path.relative_to(ROOT)}:{node.lineno} calls {name}")
    return bad


@pytest.mark.parametrize("folder", ["tests", "sitl_tests", "benchmarks", "companion"])
def test_no_module_is_loaded_by_its_path(folder: str) -> None:
    """sitl_tests/test_soak.py loaded benchmarks/soak.py by path; shared code is imported
    from the package or from testsupport instead."""
    assert loads_by_path(folder) == []


@pytest.mark.parametrize("package", ["companion", "tracker", "mavlink_bridge", "fieldbounds"])
def test_every_folder_of_a_shipped_package_is_a_package(package: str) -> None:
    """setup.py's find_packages ships only folders with an ``__init__.py``: a folder without
    one imports in the checkout (a namespace package) and is missing from the wheel."""
    folders = {p.parent for p in (ROOT / package).rglob("*.py")}
    assert sorted(str(f.relative_to(ROOT)) for f in folders
                  if not (f / "__init__.py").is_file()) == []
