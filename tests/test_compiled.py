"""derive.compiled: the generated C built into a cached shared library and called through ctypes.

Every shipped robot and function: the compiled single-state results equal the generated Python's
to 1e-12 relative, batches equal the compiled single-state results exactly, the cache is reused,
and a missing compiler, a compile failure, missing code and wrong shapes are one-line errors.
The committed generated/ folder is the input (read only); the cache lives under tmp_path.
"""

from __future__ import annotations

import functools
import json
import os
import shutil
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest

import derive
from derive.errors import DeriveError
from derive.runtime import build, loader

from util import load_module, robots

ROOT = Path(__file__).resolve().parent.parent
GENERATED = ROOT / "generated"
ROBOTS = sorted(json.loads((GENERATED / "MANIFEST.json").read_text())["robots"])
BATCHES = [(5,), (2, 3), (1000,)]


def python_module(robot: str):
    return load_module(GENERATED / robot / "python" / f"{robot}.py", f"test_compiled_{robot}")


@functools.cache
def manifest(robot: str) -> dict:
    """generated/<robot>/manifest.json, read once (Panda's, with its firmware figures, is large). Read only."""
    return json.loads((GENERATED / robot / "manifest.json").read_text())


def manifest_function(robot: str, quantity: str) -> dict:
    return next(f for f in manifest(robot)["functions"] if f["quantity"] == quantity)


def function_ids():
    return [(r, f["python"]["function"]) for r in ROBOTS for f in manifest(r)["functions"]]


@pytest.fixture(scope="module")
def cache_env(tmp_path_factory):
    """One build cache for the module's tests; no CC from the caller's environment, and CFLAGS=-O0:
    these tests check values, and -O0 keeps IEEE arithmetic as -O2 does (no fast-math either way),
    while a Panda builds in 6 s of CPU instead of 22. The default -O2 build is
    test_concurrent_builds_share_one_library's."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("XDG_CACHE_HOME", str(tmp_path_factory.mktemp("xdg")))
        mp.delenv("CC", raising=False)
        mp.setenv("CFLAGS", "-O0")
        yield


_MODULES: dict = {}


def modules(robot: str):
    if robot not in _MODULES:
        _MODULES[robot] = (derive.compiled(robot, GENERATED), python_module(robot))
    return _MODULES[robot]


def state_inputs(sig, py, fn_name: str, shape: tuple, rng) -> list:
    """Inputs for ``shape`` states (shape () = one state): random, with a reachable T for IK (FK of a
    random q within the limits at that state's p)."""
    names = [a.name for a in sig.inputs]
    p = py.DEFAULT_P * rng.uniform(0.8, 1.2, shape + py.DEFAULT_P.shape) if "p" in names else None
    out = []
    for a in sig.inputs:
        full = shape + a.shape
        if a.name == "p":
            out.append(p)
        elif a.name == "dt":
            out.append(rng.uniform(1e-3, 1e-2, full))
        elif a.name == "w":
            out.append(rng.uniform(0.5, 1.5, full))
        elif a.name in ("y", "x") and "closed_chain" in manifest(py.ROBOT):  # y near the reference configuration
            ref = np.array(manifest(py.ROBOT)["closed_chain"]["reference_y"])
            y = ref + rng.uniform(-0.1, 0.1, shape + ref.shape)
            out.append(y if a.name == "y" else np.concatenate([y, rng.uniform(-1.0, 1.0, y.shape)], axis=-1))
        elif a.name == "o" and "closed_chain" in manifest(py.ROBOT):  # reachable joints: those of y near the reference
            ref = np.array(manifest(py.ROBOT)["closed_chain"]["reference_y"])
            y = ref + rng.uniform(-0.1, 0.1, shape + ref.shape)
            r = robots()[py.ROBOT]
            z0 = np.array([r.reference_q[[c.name for c in r.coordinates].index(z)] for z in r.dependent])
            to_joints = manifest_function(py.ROBOT, "motor_to_joint_position")
            given = {"y": y, "z0": np.broadcast_to(z0, shape + z0.shape), "p": p}
            out.append(np.asarray(py.motor_to_joint_position(*[given[i["name"]] for i in to_joints["inputs"]])[0]))
        elif a.name == "T":
            fk = getattr(py, "fk_" + fn_name.removeprefix("ik_"))
            joints = manifest(py.ROBOT)["joints"]  # q within the limits (and [-1, 1]): a reachable target
            lo = [max(-1.0, j["lower"]) if j.get("lower") is not None else -1.0 for j in joints]
            hi = [min(1.0, j["upper"]) if j.get("upper") is not None else 1.0 for j in joints]
            qs = rng.uniform(lo, hi, shape + (py.NQ,))
            Ts = np.empty(full)
            for idx in np.ndindex(shape):
                Ts[idx] = fk(qs[idx], *([p[idx]] if p is not None else []))
            out.append(Ts)
        else:
            out.append(rng.uniform(-1.0, 1.0, full))
    return out


@functools.cache
def signatures(robot: str) -> dict:
    return {s.name: s for s in build.signatures(manifest(robot))}


def signature(robot: str, name: str):
    return signatures(robot)[name]


def values(result) -> list:
    return list(result) if isinstance(result, tuple) else [result]


def close(c, py, rtol: float) -> None:
    c, py = np.asarray(c), np.asarray(py)
    assert c.shape == py.shape
    scale = max(1.0, float(np.abs(py).max(initial=0.0)))
    assert np.all(np.abs(c - py) <= rtol * scale), f"max |diff| {np.abs(c - py).max():.3g} at scale {scale:.3g}"


@pytest.mark.parametrize("robot, name", function_ids())
def test_single_state_equals_generated_python(cache_env, robot, name):
    cmod, py = modules(robot)
    assert cmod.FAST_PATH  # the one-state fast path is checked and in use on this platform
    sig = signature(robot, name)
    rng = np.random.default_rng(zlib.crc32(f"{robot} {name}".encode()))
    for k in range(3):
        args = state_inputs(sig, py, name, (), rng)
        if name.startswith("ik_") and k > 0:
            args = args[:1] + [None, None] + args[3:]  # q0 and w given, then left to their defaults (None)
        want = values(getattr(py, name)(*args))
        got = values(getattr(cmod, name)(*args))
        assert len(got) == len(want)
        for g, w, ret in zip(got, want, manifest_returns(robot, name)):
            if ret.get("type") == "int":
                assert type(g) is int and g == w
            else:
                assert isinstance(g, np.ndarray) and g.dtype == np.float64 and list(g.shape) == ret["shape"]
                # IK iterates to a tolerance: its q carries the C/Python rounding through the
                # iterations, so q is compared to 1e-9 as tests/test_ik.py does; all else to 1e-12
                close(g, w, 1e-9 if name.startswith("ik_") and ret["name"] == "q" else 1e-12)


def manifest_returns(robot: str, name: str) -> list:
    return next(f["python"]["returns"] for f in manifest(robot)["functions"] if f["python"]["function"] == name)


@pytest.mark.parametrize("robot, name", function_ids())
def test_batches_equal_single_states(cache_env, robot, name):
    cmod, py = modules(robot)
    sig = signature(robot, name)
    fn = getattr(cmod, name)
    rng = np.random.default_rng(zlib.crc32(f"{robot} {name} batch".encode()))
    for shape in BATCHES:
        args = state_inputs(sig, py, name, shape, rng)
        got = values(fn(*args))
        # the same C on the same numbers: bit-identical
        assert_rows_equal(got, [values(fn(*[a[idx] for a in args])) for idx in np.ndindex(shape)], name)
        for g, ret in zip(got, manifest_returns(robot, name)):
            assert g.shape == shape + tuple(ret["shape"])
        # one value of an input for the whole batch (stride 0): p, dt, or any other
        shared = [a[(0,) * len(shape)] for a in args]
        for k in range(len(args) if len(args) > 1 and len(shape) == 2 else 0):
            mixed = args[:k] + [shared[k]] + args[k + 1:]
            assert_rows_equal(values(fn(*mixed)), [values(fn(*[a if j == k else a[idx] for j, a in enumerate(mixed)]))
                                                   for idx in np.ndindex(shape)], f"{name}, input {k} shared")


def assert_rows_equal(got: list, rows: list, what: str) -> None:
    """Each batched result equals, bit for bit, the one-state results stacked in np.ndindex order."""
    for k, g in enumerate(got):
        want = np.reshape(np.stack([np.asarray(row[k]) for row in rows]), np.shape(g))
        np.testing.assert_array_equal(g, want, err_msg=f"{what}: result {k}")


def test_defaults_lists_floats_and_views_agree(cache_env):
    """The general path (lists, float32, strided views, a Python float dt) gives the fast path's numbers."""
    cmod, py = modules("pendulum")
    rng = np.random.default_rng(1)
    x, u = rng.uniform(-1, 1, 2), rng.uniform(-1, 1, 1)
    want = cmod.rk4_step(x, u, np.array([0.01]))
    np.testing.assert_array_equal(cmod.rk4_step(x, u, 0.01), want)
    np.testing.assert_array_equal(cmod.rk4_step(x.tolist(), u.tolist(), [0.01], py.DEFAULT_P.tolist()), want)
    np.testing.assert_array_equal(cmod.rk4_step(np.repeat(x, 2)[::2], u, 0.01), want)
    assert cmod.rk4_step(x.astype(np.float32), u, 0.01).dtype == np.float64
    batch = cmod.rk4_step(np.tile(x, (4, 1)), u, 0.01)
    assert batch.shape == (4, 2) and all(np.array_equal(b, want) for b in batch)
    panda, pp = modules("panda")
    q = rng.uniform(-1, 1, 7)
    T = pp.fk_tcp(q)
    q_ik, residual, status = panda.ik_tcp(T, q0=q + 0.01)
    assert status == 0 and residual.shape == (2,)
    # numpy broadcasting of the batch shapes: (3, 1) states against (4,) states -> (3, 4)
    qs, qds = rng.uniform(-1, 1, (3, 1, 7)), rng.uniform(-1, 1, (4, 7))
    C = panda.coriolis_matrix(qs, qds)
    assert C.shape == (3, 4, 7, 7)
    np.testing.assert_array_equal(C[2, 1], panda.coriolis_matrix(qs[2, 0], qds[1]))
    assert panda.mass_matrix(np.zeros((0, 7))).shape == (0, 7, 7)
    q_ik, residual, status = panda.ik_tcp(np.stack([T, T]))
    assert q_ik.shape == (2, 7) and residual.shape == (2, 2) and status.shape == (2,) and status.tolist() == [0, 0]
    # ints, a flat T: converted as the generated Python converts them
    np.testing.assert_array_equal(panda.gravity(np.arange(7)), panda.gravity(np.arange(7.0)))
    np.testing.assert_array_equal(panda.ik_tcp(T.ravel())[0], panda.ik_tcp(T)[0])


def test_general_path_alone_gives_the_same_numbers(cache_env, monkeypatch):
    """With the one-state fast path off (as where the loader's check of the structs fails), every
    call takes the general path, with the same results."""
    fast, py = modules("planar_2r")
    monkeypatch.setattr(loader, "_init_fast", lambda robot, lib: False)
    slow = loader._module("planar_2r", manifest("planar_2r"), build.signatures(manifest("planar_2r")), fast.LIBRARY)
    assert not slow.FAST_PATH and fast.FAST_PATH
    rng = np.random.default_rng(2)
    for sig in build.signatures(manifest("planar_2r")):
        for shape in [(), (3,)]:
            args = state_inputs(sig, py, sig.name, shape, rng)
            for a, b in zip(values(getattr(slow, sig.name)(*args)), values(getattr(fast, sig.name)(*args))):
                np.testing.assert_array_equal(a, b)


def test_wrong_shapes_are_value_errors(cache_env):
    panda, _ = modules("panda")
    with pytest.raises(ValueError, match=r"q must have shape \(\.\.\., 7\)"):
        panda.mass_matrix(np.zeros(6))
    with pytest.raises(ValueError, match="q must have shape"):
        panda.mass_matrix(np.zeros((7, 1)))
    with pytest.raises(ValueError, match="do not broadcast"):
        panda.inverse_dynamics(np.zeros((5, 7)), np.zeros((4, 7)), np.zeros(7))
    with pytest.raises(ValueError, match=r"T must have shape \(\.\.\., 4, 4\)"):
        panda.ik_tcp(np.eye(3))


def test_cache_is_reused(cache_env):
    cmod, _ = modules("pendulum")
    lib = Path(cmod.LIBRARY)
    mtime, builds = lib.stat().st_mtime_ns, build.BUILDS
    assert lib.parent.parent == Path(os.environ["XDG_CACHE_HOME"]) / "derive" / "compiled"
    again = derive.compiled("pendulum", GENERATED)
    path = build.library("pendulum", GENERATED / "pendulum" / "c", build.signatures(manifest("pendulum")))
    assert again.LIBRARY == lib and path == lib and build.BUILDS == builds and lib.stat().st_mtime_ns == mtime
    # a fresh process finds it too, and builds nothing
    code = ("import derive; from derive.runtime import build; "
            f"m = derive.compiled('pendulum', {str(GENERATED)!r}); print(m.LIBRARY, build.BUILDS)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT).stdout.split()
    assert out == [str(lib), "0"]


def test_changed_source_rebuilds_and_compile_errors_are_one_line(cache_env, tmp_path):
    gen = tmp_path / "gen"
    shutil.copytree(GENERATED / "pendulum", gen / "pendulum")
    source = gen / "pendulum" / "c" / "pendulum_gravity.c"
    source.write_text(source.read_text() + "\n/* edited */\n")
    builds = build.BUILDS
    m = derive.compiled("pendulum", gen)
    assert build.BUILDS == builds + 1 and m.LIBRARY != modules("pendulum")[0].LIBRARY
    np.testing.assert_array_equal(m.gravity([0.3]), modules("pendulum")[0].gravity([0.3]))
    source.write_text(source.read_text() + "\nthis is not C;\n")
    with pytest.raises(DeriveError) as err:
        derive.compiled("pendulum", gen)
    message = str(err.value)
    assert "\n" not in message and message.startswith("cannot compile robot 'pendulum': ") and "error" in message
    assert "pendulum_gravity.c" in message
    leftovers = [p.name for p in (Path(os.environ["XDG_CACHE_HOME"]) / "derive" / "compiled").iterdir() if p.name.startswith(".")]
    assert leftovers == []


def test_edited_files_that_cannot_share_a_unit_are_built_one_by_one(cache_env, tmp_path):
    """derive.compiled builds a robot's files as one translation unit per CPU; files edited so that they
    could not share one (the same static name in two of them, a #define) are built one by one, and
    give the same numbers."""
    gen = tmp_path / "gen"
    shutil.copytree(GENERATED / "pendulum", gen / "pendulum")
    twin = "\nstatic double edited_twin(double a) { return a; }\n"
    for name in ("pendulum_gravity.c", "pendulum_mass_matrix.c"):
        source = gen / "pendulum" / "c" / name
        source.write_text(source.read_text() + twin)
    (gen / "pendulum" / "c" / "pendulum_bias.c").write_text(
        (gen / "pendulum" / "c" / "pendulum_bias.c").read_text() + "\n#define EDITED_MACRO 1\n")
    m = derive.compiled("pendulum", gen)
    committed = modules("pendulum")[0]
    for q in ([0.3], [-1.2]):
        np.testing.assert_array_equal(m.gravity(q), committed.gravity(q))
        np.testing.assert_array_equal(m.mass_matrix(q), committed.mass_matrix(q))
    sources = {p: p.read_bytes() for p in sorted((GENERATED / "pendulum" / "c").glob("*.c"))}
    assert len(build.translation_units(sources, tmp_path)) == min(len(sources), os.cpu_count() or 1)  # unedited: units
    sources[next(iter(sources))] += twin.encode()
    sources[list(sources)[1]] += twin.encode()
    assert build.translation_units(sources, tmp_path) == list(sources)


def test_concurrent_builds_share_one_library(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.delenv("CC", raising=False)
    code = f"import derive; print(derive.compiled('planar_2r', {str(GENERATED)!r}).LIBRARY)"
    procs = [subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
             for _ in range(2)]
    outs = [p.communicate() for p in procs]
    assert all(p.returncode == 0 for p in procs), outs
    libs = {o.strip() for o, _ in outs}
    folders = list((tmp_path / "derive" / "compiled").iterdir())
    assert len(libs) == 1 and [f.name for f in folders] == [Path(libs.pop()).parent.name]


def test_no_compiler_is_a_one_line_error(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.setenv("CC", "/nonexistent/cc")
    with pytest.raises(DeriveError) as err:
        derive.compiled("pendulum", GENERATED)
    message = str(err.value)
    assert "\n" not in message
    assert message.startswith("cannot compile robot 'pendulum': no C compiler found")
    assert message.endswith("(set CC or install gcc)")
    assert not (tmp_path / "derive" / "compiled").exists() or not any((tmp_path / "derive" / "compiled").iterdir())


def test_missing_generated_code_is_a_one_line_error(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    with pytest.raises(DeriveError, match=r"^robot 'nosuch': no generated code at .*derive generate") as err:
        derive.compiled("nosuch", tmp_path / "generated")
    assert "\n" not in str(err.value)
