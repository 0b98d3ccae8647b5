"""Fixtures shared by several test modules.

`make test` runs the suite in parallel (pytest-xdist, ``-n``): each worker process runs these
session fixtures itself, so everything expensive in them is made once for the whole run, by the
first worker that asks, in a folder that every worker of the run shares (shared_folder), under a
file lock; the other workers wait for it and use it (made_once). A plain ``pytest`` run (no
``-n``) makes them in its own temporary folder as before.

code_cache: generated Python modules (tests/util.py's load_module) compiled once for the whole run.

generated_copy: a module's own copy of the committed generated/, for the modules that build or
import there, so that nothing one module writes (a build, a __pycache__) is seen by another.
test_codegen.py's test_regeneration_is_byte_identical checks in the same run that the committed
folder is what derive writes now without the cache.

committed_library: the committed generated/<robot>/c built once per run into a shared library
(strict C99, -Wall -Wextra -Werror -pedantic at -O0; the double build's template functions at -O1), double or float: tests/test_codegen.py and
tests/test_regressor.py call the same build.

mujoco: the mujoco module, skipped without it except under CI=true (tests/test_mjcf.py, tests/test_export.py).

installed_venv: tests/test_installed.py's wheel and fresh venv (~35 s of pip), started in a thread
when the session starts if that module has tests to run (by the first worker to start, under
xdist), so that it runs on a CPU of its own while other modules run; the module's fixture waits
for it.

Under xdist with ``-n`` alone (its ``--dist load``), a worker takes a whole module at a time (its
module fixtures and caches are set up once, and its last tests, such as the test_zz_report ones,
see what the earlier ones recorded), the modules of HEAVY first, so that none of them is left for
the end; the tests of the SPREAD modules, which share nothing costly but the session fixtures,
go one by one to whichever worker is free. Naming another ``--dist`` gets xdist's own.
"""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import signal
import subprocess
import sys
import traceback
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Callable, TypeVar

import pytest

from util import CODE_CACHE, build_library

# pytest-xdist's workers ignore SIGINT, and an ignored signal is inherited by every process a test
# starts (derive then keeps it ignored, as a background job must): give the tests' processes Python's
# ordinary Ctrl-C back.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

# XLA:CPU for the tests (before jax makes its first backend, which reads XLA_FLAGS; every worker
# imports this first): they check values, not speed. LLVM at -O0 compiles about 3x faster (Panda's
# forward_dynamics 2.5 s instead of 7 s), and the loop emitters instead of the fusion emitters halve
# the compile of each operation that eager (un-jitted) calls compile one by one (test_jax.py: 1,048 of
# them; 55 to 27 ms each). Neither turns on fast-math: the numbers are checked to the same 1e-12. A flag
# that the caller's XLA_FLAGS sets is left as it is.
for _flag in ("--xla_backend_optimization_level=0", "--xla_cpu_use_fusion_emitters=false"):
    if _flag.partition("=")[0] not in os.environ.get("XLA_FLAGS", ""):
        os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {_flag}".strip()

ROOT = Path(__file__).resolve().parent.parent
GENERATED = ROOT / "generated"
STRICT = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"]

T = TypeVar("T")

# The longest modules (pytest --durations), longest first: started first under xdist, so that the
# run does not end waiting for one of them.
HEAVY = ("test_cuda.py", "test_cuda_batch.py", "test_compiled.py", "test_batch.py", "test_jax.py", "test_codegen.py",
         "test_urdf_trees.py", "test_simulate.py", "test_whole_robots.py", "test_bad_input_corpus.py",
         "test_trajopt.py", "test_regressor.py", "test_ode.py")
# Modules whose tests are spread one by one over the workers: long, and nothing but the session
# fixtures (shared by all workers) is costly to set up for them. Not test_jax.py: each process
# pays for loading the modules and for JAX's per-operation compiles (spread, it took 277 s of CPU
# where one worker takes 181 s).
SPREAD = frozenset({"test_codegen.py", "test_batch.py"})


def pytest_collection_modifyitems(items: list) -> None:
    """Under xdist, every worker orders its collection the same way: the HEAVY modules first, in
    that order, then the others as collected (a stable sort: tests keep their order in a module)."""
    if os.environ.get("PYTEST_XDIST_WORKER"):
        rank = {name: k for k, name in enumerate(HEAVY)}
        items.sort(key=lambda item: rank.get(item.path.name, len(HEAVY)))


@pytest.hookimpl(optionalhook=True)  # a hook of pytest-xdist's, called only where it runs
def pytest_xdist_make_scheduler(config, log):
    """For ``-n`` alone (xdist's default --dist load): ModuleScheduling."""
    if config.getvalue("dist") != "load":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class ModuleScheduling(LoadScopeScheduling):
        """Work units of whole modules, in the order collected (pytest_collection_modifyitems), a
        SPREAD module's tests one unit each."""

        def _split_scope(self, nodeid: str) -> str:
            module = nodeid.split("::", 1)[0]
            return nodeid if Path(module).name in SPREAD else module

    config.option.loadscopereorder = False  # keep the collection's order, not the largest units first
    return ModuleScheduling(config, log)


def shared_folder(tmp_path_factory) -> Path:
    """The temporary folder that every process of this run shares: under pytest-xdist the parent of
    the worker's own (pytest-N, made by the controller for this run alone, holding popen-gw0, ...),
    otherwise the session's own."""
    base = tmp_path_factory.getbasetemp()
    return base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base


def _lock(path: Path, wait: bool = True):
    """An exclusive flock on ``path`` (created if missing): the open file, whose closing releases it;
    None when ``wait`` is False and another process (or thread) holds it."""
    file = open(path, "a")
    try:
        fcntl.flock(file, fcntl.LOCK_EX if wait else fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        file.close()
        return None
    return file


def _make(folder: Path, make: Callable[[Path], T]) -> T:
    """make(folder) unless a process of this run did (its ``.done`` record) or failed (``.error``:
    raised here too, not tried again). Called with folder's lock held."""
    done, error = folder.with_name(folder.name + ".done"), folder.with_name(folder.name + ".error")
    if error.is_file():
        raise RuntimeError(f"{folder}: failed in another process of this test run:\n{error.read_text()}")
    if not done.is_file():
        try:
            make(folder)
        except BaseException:
            error.write_text(traceback.format_exc())
            raise
        done.touch()
    return folder


def made_once(folder: Path, make: Callable[[Path], object]) -> Path:
    """``folder`` as make(folder) fills it, made once for the whole run: by the first process to
    ask, while the others wait for it (a flock on ``<folder>.lock``). Its error, where it failed,
    is raised in every process that asks, without trying again."""
    lock = _lock(folder.with_name(folder.name + ".lock"))
    try:
        return _make(folder, make)
    finally:
        lock.close()


def begin_once(pool: ThreadPoolExecutor, folder: Path, make: Callable[[Path], object]) -> Callable[[], Path]:
    """made_once(folder, make) begun now in ``pool`` when no other process of the run is making it
    (then this one holds the lock until it is done); returns the function that waits for it."""
    lock = _lock(folder.with_name(folder.name + ".lock"), wait=False)
    if lock is None:  # another worker is making it: wait for it when asked
        return lambda: made_once(folder, make)

    def work() -> Path:
        try:
            return _make(folder, make)
        finally:
            lock.close()

    return pool.submit(work).result


@pytest.fixture(scope="session", autouse=True)
def code_cache(tmp_path_factory):
    """util.load_module's compiled modules, shared by every worker of the run (a generated module is
    compiled once, whichever test module or copy of generated/ loads it)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv(CODE_CACHE, str(shared_folder(tmp_path_factory) / "code"))
        yield


@pytest.fixture(scope="session")
def generated_copy(tmp_path_factory):
    """generated_copy(name) -> a new folder <tmp>/<name>/generated holding a copy of the committed
    generated/ (without Python's byte-code caches): what derive writes now, as
    tests/test_codegen.py's test_regeneration_is_byte_identical checks, byte for byte, in the same run."""

    def copy(name: str) -> Path:
        out = tmp_path_factory.mktemp(name) / "generated"
        shutil.copytree(GENERATED, out, ignore=shutil.ignore_patterns("__pycache__"))
        return out

    return copy


@pytest.fixture(scope="session")
def committed_library(tmp_path_factory):
    """committed_library(robot, extra=()) -> the shared library of every C file of generated/<robot>/c,
    built with STRICT -fPIC and ``extra`` (say -DDERIVE_FLOAT) once per run, -O1 without extra, else -O0."""
    folder = shared_folder(tmp_path_factory) / "committed_c"
    folder.mkdir(exist_ok=True)

    def get(robot: str, extra=()) -> Path:
        name = f"lib{robot}{'_'.join(extra)}"
        # -O0 (the front end's warnings), but -O1 for the double build of the template functions (loops
        # and calls), where flow-based warnings (-Wmaybe-uninitialized, ...) need an optimiser. The
        # straight-line functions have no flow for those warnings to follow, and every committed C file
        # has also built clean under -Werror at -O2 for Cortex-M (its firmware figures, which
        # tests/test_firmware.py requires of every function). A Panda builds in 4 s of CPU, not 40.
        sources = sorted((GENERATED / robot / "c").glob("*.c"))
        manifest = json.loads((GENERATED / robot / "manifest.json").read_text())
        loops = set() if extra else {(GENERATED / robot / fn["c"]["source"]).name
                                     for fn in manifest["functions"] if fn["c"]["form"] == "template"}
        made = made_once(folder / name, lambda lib: build_library(
            ["cc", *STRICT, "-O0", "-fPIC", *extra], sources, lib / f"{name}.so",
            extra={s: ["-O1"] for s in sources if s.name in loops}))
        return made / f"{name}.so"

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
    tests/test_installed.py has tests to run, by the first worker to start) and returns its result
    or raises its error; None when that module does not run."""
    if not any(item.path.name == "test_installed.py" for item in request.session.items):
        yield None
        return
    base = shared_folder(tmp_path_factory) / "installed"
    with ThreadPoolExecutor(max_workers=1) as pool:  # leaving it waits for the build
        wait = begin_once(pool, base, build_installed)

        def result() -> tuple[Path, Path]:
            wait()
            return base / "venv" / "bin" / "derive", base / "venv" / "bin" / "python"

        yield result


@pytest.fixture(scope="session")
def mujoco():
    """The mujoco module (MuJoCo as a second oracle); skipped without it, except in CI (CI=true), where
    the `mjcf` extra is installed and its absence fails."""
    try:
        import mujoco
    except ImportError:
        if os.environ.get("CI"):
            pytest.fail("mujoco not installed: the `mjcf` extra should be installed by `make test`")
        pytest.skip("no mujoco: pip install 'derive-robotics[mjcf]'")
    return mujoco
