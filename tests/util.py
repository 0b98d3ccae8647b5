"""Shared test helpers: seeded states, numeric evaluation of SX, relative comparison, C builds one
source per compiler process, as many at once as there are CPUs, generated Python modules loaded
with their byte code compiled once per run."""

from __future__ import annotations

import hashlib
import importlib.util
import marshal
import os
import subprocess
import sys
import types
from concurrent.futures import ThreadPoolExecutor
from functools import lru_cache
from pathlib import Path

import casadi as ca
import numpy as np

from derive.runtime.build import translation_units
from derive.symbolic.model import SXModel
from derive.description.model import load_models
from derive.description.robot import Robot

N_STATES = 50
RTOL = 1e-9


@lru_cache(maxsize=None)
def robots() -> dict[str, Robot]:
    return load_models()


@lru_cache(maxsize=None)
def sx_model(name: str) -> SXModel:
    return SXModel(robots()[name])


def params(robot: Robot) -> np.ndarray:
    return np.array([p.default for p in robot.parameters], dtype=float)


def random_q(robot: Robot, rng: np.random.Generator) -> np.ndarray:
    """q uniformly within the joint limits (or [-pi, pi] / [-1, 1] m where a limit is missing)."""
    lo, hi = robot.joint_box()
    q = rng.uniform(lo, hi)
    if robot.floating:  # a random unit quaternion for the base
        quat = rng.normal(size=4)
        q[3:7] = quat / np.linalg.norm(quat)
    return q


def states(robot: Robot, seed: int = 0, n: int = N_STATES):
    """n seeded (q, qd, qdd) triples."""
    rng = np.random.default_rng(seed)
    for _ in range(n):
        yield random_q(robot, rng), rng.normal(size=robot.nv), rng.normal(size=robot.nv)


def sx_function(model: SXModel, expr: ca.SX, inputs=("q", "qd", "qdd", "tau", "p")) -> ca.Function:
    s = model.sym
    syms = [getattr(s, n) for n in inputs]
    return ca.Function("f", syms, [expr])


def evaluate(f: ca.Function, *args) -> np.ndarray:
    return np.array(f(*args)).squeeze()


def assert_close(actual, expected, rtol: float = RTOL, what: str = "") -> None:
    """max|a - e| <= rtol * max|e| (relative to the magnitude of the whole array)."""
    a, e = np.asarray(actual, dtype=float), np.asarray(expected, dtype=float)
    assert a.shape == e.shape, f"{what}: shape {a.shape} != {e.shape}"
    scale = max(np.abs(e).max(initial=0.0), 1e-12)
    err = np.abs(a - e).max(initial=0.0)
    assert err <= rtol * scale, f"{what}: max error {err:.3e} > {rtol:g} * {scale:.3e}"


CODE_CACHE = "DERIVE_TEST_CODE_CACHE"
"""The environment variable naming load_module's folder of compiled modules (tests/conftest.py sets it
to a folder of the run that every worker shares); unset, each load compiles."""


def load_module(path, name: str) -> types.ModuleType:
    """The Python module at ``path`` (a generated module, say), loaded under ``name`` as importlib loads
    a file, without writing byte code beside it. Its code is compiled once per run for every copy of the
    same text (the test modules' copies of generated/ among them): Panda's numpy module alone takes a
    second to compile, and a dozen test modules in two workers load every robot's."""
    path = Path(path)
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    exec(_code(path.read_bytes(), str(path)), module.__dict__)
    return module


def _code(source: bytes, filename: str) -> types.CodeType:
    folder = os.environ.get(CODE_CACHE)
    if not folder:
        return compile(source, filename, "exec", dont_inherit=True)
    key = hashlib.sha256(source + sys.version.encode()).hexdigest()
    cached = Path(folder) / f"{key}.code"
    try:
        code = marshal.loads(cached.read_bytes())
    except (OSError, EOFError, ValueError, TypeError):
        code = compile(source, filename, "exec", dont_inherit=True)
        Path(folder).mkdir(parents=True, exist_ok=True)
        partial = cached.with_name(f".{key}.{os.getpid()}")
        partial.write_bytes(marshal.dumps(code))
        os.replace(partial, cached)  # whole or not at all, whichever worker writes it
        return code
    return _renamed(code, filename)


def _renamed(code: types.CodeType, filename: str) -> types.CodeType:
    """code with its file name (and that of every function in it) ``filename``: what tracebacks show."""
    if code.co_filename == filename:
        return code
    consts = tuple(_renamed(c, filename) if isinstance(c, types.CodeType) else c for c in code.co_consts)
    return code.replace(co_filename=filename, co_consts=consts)


JOBS = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def run_at_once(commands: list[list[str]], **kwargs) -> list[subprocess.CompletedProcess]:
    """subprocess.run(argv, **kwargs) of every command, as many at a time as there are CPUs (as
    derive's own C build does); the results in the order of ``commands``."""
    if not commands:
        return []
    with ThreadPoolExecutor(max_workers=max(1, min(JOBS, len(commands)))) as pool:
        return list(pool.map(lambda argv: subprocess.run(argv, **kwargs), commands))


def compile_objects(argv: list[str], sources, out: Path, extra: dict | None = None) -> list[Path]:
    """``argv -c source -o object`` for every source, one compiler process per source, CPUs at once: what
    one ``argv sources...`` call compiles one source after the other; ``extra`` {source: flags} adds
    flags after argv's for some sources. The objects (in ``out``) in source order; CalledProcessError
    (stdout and stderr captured) of the first source that fails."""
    sources = [Path(s) for s in sources]
    extra = {Path(s): flags for s, flags in (extra or {}).items()}
    objects = [Path(out) / f"{k:03d}_{s.stem}.o" for k, s in enumerate(sources)]
    for result in run_at_once([[*argv, *extra.get(s, ()), "-c", str(s), "-o", str(o)] for s, o in zip(sources, objects)],
                              capture_output=True, text=True):
        if result.returncode:
            sys.stderr.write(result.stdout + result.stderr)  # the compiler's messages, in the test's report
        result.check_returncode()
    return objects


def build_library(argv: list[str], sources, lib: Path, extra: dict | None = None) -> Path:
    """The shared library ``lib`` of ``sources``: ``argv -shared -o lib sources... -lm``, its sources
    compiled by compile_objects (argv carries -fPIC and the rest of the flags; ``extra`` {source: flags}
    more for some) next to ``lib``. The sources without extra flags are compiled as one translation
    unit per CPU, as derive.compiled builds a robot (derive.runtime.build.translation_units: 40 % less
    CPU than a process per file; each generated file alone is a unit of the Cortex-M builds,
    tests/test_firmware.py)."""
    lib = Path(lib)
    folder = lib.parent / f"{lib.stem}.objects"
    folder.mkdir(parents=True, exist_ok=True)
    sources = [Path(s) for s in sources]
    extra = {Path(s): flags for s, flags in (extra or {}).items()}
    plain = {s.resolve(): s.read_bytes() for s in sources if s not in extra}
    sources = translation_units(plain, folder, JOBS) + [s for s in sources if s in extra]
    objects = compile_objects(argv, sources, folder, extra)
    subprocess.run([*argv, "-shared", "-o", str(lib), *map(str, objects), "-lm"], check=True, capture_output=True, text=True)
    return lib


Y_SPREAD = 0.1
"""A closed chain's y is drawn within +-Y_SPREAD (rad or m) of its reference configuration's: every
shipped mechanism assembles there, on the reference's branch (tests/test_closed_chains.py)."""


def closed_inputs(robot: Robot, rng: np.random.Generator, shape: tuple = ()) -> dict[str, np.ndarray]:
    """Seeded arguments of a closed chain's functions in y, of shape (*shape, n): y near the reference
    configuration, yd, ydd normal, tau_y and u 5 x normal, x = [y; yd]; z0 (a Newton closure's start)
    the reference configuration's z. With ``outputs`` (the motor <-> joint maps) also the joints o near
    the reference configuration's, od normal, tau_o 5 x normal and w0 (a Newton solve's start, the
    coordinates not in o) the reference's."""
    names = [c.name for c in robot.coordinates]
    y_ref = np.array([robot.reference_q[names.index(c)] for c in robot.independent])
    z_ref = np.array([robot.reference_q[names.index(c)] for c in robot.dependent])
    ny = len(y_ref)
    y = y_ref + rng.uniform(-Y_SPREAD, Y_SPREAD, shape + (ny,))
    yd = rng.normal(size=shape + (ny,))
    tau = 5 * rng.normal(size=shape + (ny,))
    out = {"y": y, "yd": yd, "ydd": rng.normal(size=shape + (ny,)), "tau_y": tau, "u": tau,
           "x": np.concatenate([y, yd], axis=-1), "z0": np.broadcast_to(z_ref, shape + z_ref.shape).copy()}
    if robot.outputs:
        o_ref = np.array([robot.reference_q[names.index(c)] for c in robot.outputs])
        w_ref = np.array([robot.reference_q[i] for i, c in enumerate(names) if c not in robot.outputs])
        out |= {"o": o_ref + rng.uniform(-Y_SPREAD, Y_SPREAD, shape + (ny,)), "od": rng.normal(size=shape + (ny,)),
                "tau_o": 5 * rng.normal(size=shape + (ny,)), "w0": np.broadcast_to(w_ref, shape + w_ref.shape).copy()}
    return out


def tree_robots() -> list[str]:
    """The models.yaml robots without loops, sorted: those whose generated set holds the tree's forward
    dynamics, ODE, regressors, IK and bundles (a closed chain's functions in y: tests/test_codegen.py,
    test_closed_chain_code.py, test_closed_chains.py)."""
    return sorted(n for n, r in robots().items() if not r.closed)
