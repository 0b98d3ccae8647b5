"""Benchmark ``jax``: the JAX flavour on the CPU against the NumPy batch, Panda.

jax.jit(jax.vmap(f)) of generated/panda/jax/panda.py on a batch of seeded states, float64 (turned on
here, as a user does), against the NumPy module called on the same batch in the same run: per-state
µs (best of interleaved repeats, the machines are shared and noisy), the ratio JAX / NumPy (the
target: <= 1.0), the seconds jit takes to lower and compile, and the kernels XLA makes (fusions in
the compiled HLO), for inverse_dynamics, mass_matrix, forward_dynamics and ode_jac_x.

Per core: the measurement runs in a child process pinned to one CPU, so XLA's threads share it as
NumPy's one thread has it (unpinned on a 2-core machine, XLA ran independent kernels on both cores
and looked up to 2x faster than it is per core; on a loaded one, slower).
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import subprocess
import sys
import time

import numpy as np

from derive.description.model import load_robot
from derive.errors import DeriveError
from derive.resources import CHECKOUT
from derive.solvers.simulate import load_generated

ROBOT = "panda"
FUNCTIONS = ("inverse_dynamics", "mass_matrix", "forward_dynamics", "ode_jac_x")
TARGET = "JAX jit(vmap) per state <= 1.0x the NumPy batch (CPU, float64)"


def _jax_module():
    try:
        jax = importlib.import_module("jax")
    except ImportError:
        raise DeriveError("bench jax: needs jax (the jax extra: make bench installs it)") from None
    jax.config.update("jax_enable_x64", True)  # the modules compute in JAX's default float type
    path = CHECKOUT / "generated" / ROBOT / "jax" / f"{ROBOT}.py"
    spec = importlib.util.spec_from_file_location(f"derive_bench_{ROBOT}_jax_speed", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return jax, mod


def pinned() -> None:
    """In a child before it runs: one CPU, the last this process may use (its threads inherit it)."""
    os.sched_setaffinity(0, {max(os.sched_getaffinity(0))})


def bench_jax(args) -> str:
    code = "import sys; from derive.bench.jax_speed import measure; print(measure(sys.argv[1] == 'quick'))"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(CHECKOUT), os.environ.get("PYTHONPATH", "")])}
    try:
        return subprocess.run([sys.executable, "-c", code, "quick" if args.quick else "full"], check=True,
                              capture_output=True, text=True, preexec_fn=pinned, env=env).stdout
    except subprocess.CalledProcessError as e:
        lines = e.stderr.strip().splitlines()
        raise DeriveError(f"bench jax: {lines[-1] if lines else f'exit code {e.returncode}'}") from None


def measure(quick: bool) -> str:
    """The section, measured in this process (bench_jax runs it pinned to one CPU)."""
    jax, jx = _jax_module()
    py = load_generated(ROBOT, CHECKOUT / "generated")
    n = 1000 if quick else 10_000
    repeats = 5 if quick else 15
    rng = np.random.default_rng(0)
    lo, hi = load_robot(ROBOT, CHECKOUT / "models.yaml").joint_box()
    Q = rng.uniform(lo, hi, (n, 7))
    V, A = rng.normal(size=(n, 7)), rng.normal(size=(n, 7))
    X = np.concatenate([Q, V], axis=1)
    many = {"inverse_dynamics": (Q, V, A), "mass_matrix": (Q,), "forward_dynamics": (Q, V, A), "ode_jac_x": (X, A)}
    rows = []
    for name in FUNCTIONS:
        f_py, args_ = getattr(py, name), many[name]
        start = time.perf_counter()
        compiled = jax.jit(jax.vmap(getattr(jx, name))).lower(*args_).compile()
        t_compile = time.perf_counter() - start
        kernels = sum(line.lstrip().startswith("%") and " fusion(" in line
                      for line in compiled.as_text().splitlines())
        ref = f_py(*args_)
        got = np.asarray(compiled(*args_)).reshape(ref.shape)
        diff = float(np.max(np.abs(got - ref)) / max(np.max(np.abs(ref)), 1e-300))
        t_jx = t_np = float("inf")
        for _ in range(repeats):  # interleaved: both see the same load
            t = time.perf_counter()
            compiled(*args_).block_until_ready()
            t_jx = min(t_jx, time.perf_counter() - t)
            t = time.perf_counter()
            f_py(*args_)
            t_np = min(t_np, time.perf_counter() - t)
        rows.append(f"| {name} | {1e6 * t_jx / n:.3f} | {1e6 * t_np / n:.3f} | {t_jx / t_np:.2f} | "
                    f"{t_compile:.1f} | {kernels} | {diff:.1e} |")
    return "\n".join([
        "## JAX flavour on the CPU against the NumPy batch (Panda)", "",
        f"Target: {TARGET}. jaxlib {importlib.import_module('jaxlib').__version__}; batch of {n} states, "
        f"same process and states, best of {repeats} interleaved repeats, the process pinned to one CPU (per core: "
        "XLA's threads share it).", "",
        "| function | JAX jit(vmap) µs/state | NumPy batch µs/state | JAX / NumPy | jit lower+compile s | "
        "XLA kernels | max rel. diff |",
        "|---|---|---|---|---|---|---|", *rows])


def benchmarks() -> dict:
    return {"jax": bench_jax}
