"""Fixtures shared by several test modules.

fresh_generated: the shipped robots generated once per session into a temporary folder, without
the cache (what ``generate(load_models(), out, use_cache=False)`` writes into an empty folder), for
the modules that test freshly generated code rather than the committed generated/. Each module
takes its own copy (fresh_copy), so nothing one module writes there (a build, a __pycache__) is
seen by another; the session's folder itself is only read.

committed_library: the committed generated/<robot>/c built once per session into a shared library
(strict C99, -Wall -Wextra -Werror -pedantic, -O1), double or float: tests/test_codegen.py and
tests/test_regressor.py call the same build.

installed_venv: tests/test_installed.py's wheel and fresh venv (~35 s of pip), started in a thread
when the session starts if that module has tests to run, so that it runs on a second CPU while the
modules before it run on the first; the module's fixture waits for it.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from derive.codegen.generate import generate
from util import build_library, robots

ROOT = Path(__file__).resolve().parent.parent
GENERATED = ROOT / "generated"
STRICT = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"]


@pytest.fixture(scope="session")
def fresh_generated(tmp_path_factory) -> Path:
    """generated/ as derive writes it now: every shipped robot, derived without the cache. Read only."""
    out = tmp_path_factory.mktemp("fresh") / "generated"
    generate(robots(), out, use_cache=False, log=lambda s: None)
    return out


@pytest.fixture(scope="session")
def fresh_copy(fresh_generated, tmp_path_factory):
    """fresh_copy(name) -> a new folder <tmp>/<name>/generated holding a copy of fresh_generated."""

    def copy(name: str) -> Path:
        out = tmp_path_factory.mktemp(name) / "generated"
        shutil.copytree(fresh_generated, out)
        return out

    return copy


@pytest.fixture(scope="session")
def committed_library(tmp_path_factory):
    """committed_library(robot, extra=()) -> the shared library of every C file of generated/<robot>/c,
    built with STRICT -O1 -fPIC and ``extra`` (say -DDERIVE_FLOAT) once per session."""
    folder, built = tmp_path_factory.mktemp("committed_c"), {}

    def get(robot: str, extra=()) -> Path:
        key = (robot, tuple(extra))
        if key not in built:
            built[key] = build_library(["cc", *STRICT, "-O1", "-fPIC", *extra], sorted((GENERATED / robot / "c").glob("*.c")),
                                       folder / f"lib{robot}{'_'.join(extra)}.so")
        return built[key]

    return get


def build_installed(base: Path) -> tuple[Path, Path]:
    """The wheel built (pip wheel, hatchling) into base/dist and installed with the pinned dependencies
    into a new venv base/venv: (the venv's `derive` command, its python). RuntimeError with the failing
    command and its output where a step fails."""
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check", "-q"]

    def run(argv: list[str]) -> None:
        res = subprocess.run(argv, capture_output=True, text=True)  # a thread's output would land in any test's report
        if res.returncode:
            raise RuntimeError(f"{' '.join(argv)}: exit status {res.returncode}\n{res.stdout[-3000:]}{res.stderr[-5000:]}")

    run(pip + ["wheel", "--no-deps", "-w", str(base / "dist"), str(ROOT)])
    (wheel,) = (base / "dist").glob("derive_robotics-*.whl")
    # a venv without pip of its own (ensurepip: ~6 s), installed into by this pip (--python: pip >= 22.3)
    run([sys.executable, "-m", "venv", "--without-pip", str(base / "venv")])
    python = base / "venv" / "bin" / "python"
    run(pip + ["--python", str(python), "install", "-c", str(ROOT / "constraints.txt"), str(wheel)])
    return base / "venv" / "bin" / "derive", python


@pytest.fixture(scope="session", autouse=True)
def installed_venv(request, tmp_path_factory):
    """A function that waits for build_installed (begun in a thread at the session's first test when
    tests/test_installed.py has tests to run) and returns its result or raises its error; None when
    that module does not run."""
    if not any(item.path.name == "test_installed.py" for item in request.session.items):
        yield None
        return
    base = tmp_path_factory.mktemp("installed")
    with ThreadPoolExecutor(max_workers=1) as pool:  # leaving it waits for the build
        yield pool.submit(build_installed, base).result
