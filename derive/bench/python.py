"""Benchmark ``python-speed``: the generated code called from Python, single states and batches.

Measured in one process on the same seeded Panda states, against Pinocchio called from Python:
per-call µs of one state (generated NumPy, compiled, Pinocchio) and per-state µs of a batch of
10 000 (NumPy vectorised, compiled, JAX jit on CPU, a Python loop over Pinocchio), for
inverse_dynamics, mass_matrix, forward_dynamics and ode_jac_x; plus the generated C's own ns
per call (a plain C loop over the same states) for the compiled batch's ratio. Times are the
best of several interleaved repeats (the machines are shared and noisy).
"""

from __future__ import annotations

import importlib
import importlib.util
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from derive.description.model import load_robot
from derive.description.urdf import example_robot_data_dir
from derive.errors import DeriveError
from derive.resources import CHECKOUT
from derive.runtime import compiled
from derive.solvers.simulate import load_generated

ROBOT = "panda"
FUNCTIONS = ("inverse_dynamics", "mass_matrix", "forward_dynamics", "ode_jac_x")
TARGETS = "compiled single call <= 1.0x Pinocchio-from-Python; compiled batch per state <= 1.5x the C's own ns per call; " \
          "NumPy batch per state >= 5x faster than a Python loop over Pinocchio; JAX = NumPy to 1e-12"

LOOP_C = r"""
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "%(robot)s.h"
static double now(void) { struct timespec t; clock_gettime(CLOCK_MONOTONIC, &t); return t.tv_sec + 1e-9 * t.tv_nsec; }
int main(int argc, char **argv) {
    long n = atol(argv[1]), i; int r;
    FILE *f = fopen(argv[2], "rb");
    double *q = malloc(n * 7 * sizeof(double)), *qd = malloc(n * 7 * sizeof(double)), *qdd = malloc(n * 7 * sizeof(double));
    double *x = malloc(n * 14 * sizeof(double)), *out = malloc(n * 196 * sizeof(double)), best[4] = {1e9, 1e9, 1e9, 1e9}, t0, sink = 0;
    if (!f || fread(q, sizeof(double), n * 7, f) != (size_t)(n * 7) || fread(qd, sizeof(double), n * 7, f) != (size_t)(n * 7)
        || fread(qdd, sizeof(double), n * 7, f) != (size_t)(n * 7)) return 1;
    for (i = 0; i < n; i++) { int k; for (k = 0; k < 7; k++) { x[14*i+k] = q[7*i+k]; x[14*i+7+k] = qd[7*i+k]; } }
    for (r = 0; r < 10; r++) {
        t0 = now(); for (i = 0; i < n; i++) %(robot)s_inverse_dynamics(q + 7*i, qd + 7*i, qdd + 7*i, out + 7*i); t0 = now() - t0; if (t0 < best[0]) best[0] = t0; sink += out[3];
        t0 = now(); for (i = 0; i < n; i++) %(robot)s_mass_matrix(q + 7*i, out + 49*i); t0 = now() - t0; if (t0 < best[1]) best[1] = t0; sink += out[3];
        t0 = now(); for (i = 0; i < n; i++) %(robot)s_forward_dynamics(q + 7*i, qd + 7*i, qdd + 7*i, out + 7*i); t0 = now() - t0; if (t0 < best[2]) best[2] = t0; sink += out[3];
        t0 = now(); for (i = 0; i < n; i++) %(robot)s_ode_jac_x(x + 14*i, qdd + 7*i, out + 196*i); t0 = now() - t0; if (t0 < best[3]) best[3] = t0; sink += out[3];
    }
    printf("inverse_dynamics %%.2f\nmass_matrix %%.2f\nforward_dynamics %%.2f\node_jac_x %%.2f\n", best[0]/n*1e9, best[1]/n*1e9, best[2]/n*1e9, best[3]/n*1e9);
    fprintf(stderr, "%%g\n", sink);
    return 0;
}
"""


def _best(fn, repeats: int, number: int) -> float:
    """Best seconds per call of ``fn`` over ``repeats`` runs of ``number`` calls."""
    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        for _ in range(number):
            fn()
        best = min(best, (time.perf_counter() - t) / number)
    return best


def _pinocchio():
    try:
        pin = importlib.import_module("pinocchio")
    except ImportError:
        raise DeriveError("bench python-speed: needs pinocchio (the pinocchio extra: make bench installs it)") from None
    urdf = example_robot_data_dir() / "panda_description" / "urdf" / "panda.urdf"
    full = pin.buildModelFromUrdf(str(urdf))
    locked = [full.getJointId(n) for n in ("panda_finger_joint1", "panda_finger_joint2")]
    model = pin.buildReducedModel(full, locked, pin.neutral(full))
    return pin, model, model.createData()


def _c_loop(generated: Path, q, qd, qdd) -> dict[str, float]:
    """ns per call of the generated C in a plain C loop over the same states (cc -O2)."""
    c_dir = generated / ROBOT / "c"
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / "loop.c").write_text(LOOP_C % {"robot": ROBOT})
        np.concatenate([q.ravel(), qd.ravel(), qdd.ravel()]).astype(np.float64).tofile(tmp / "states.bin")
        sources = [str(c_dir / f"{ROBOT}_{f}.c") for f in FUNCTIONS]
        subprocess.run(["cc", "-std=c99", "-O2", f"-I{c_dir}", str(tmp / "loop.c"), *sources, "-lm", "-o",
                        str(tmp / "loop")], check=True)
        out = subprocess.run([str(tmp / "loop"), str(len(q)), str(tmp / "states.bin")], check=True, capture_output=True,
                             text=True).stdout
    return {name: float(value) for name, value in (line.split() for line in out.splitlines())}


def _jax_module(generated: Path):
    try:
        jax = importlib.import_module("jax")
    except ImportError:
        return None, None
    jax.config.update("jax_enable_x64", True)  # the module computes in JAX's default float type
    path = generated / ROBOT / "jax" / f"{ROBOT}.py"
    spec = importlib.util.spec_from_file_location(f"derive_bench_{ROBOT}_jax", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return jax, mod


def bench_python(args) -> str:
    generated = CHECKOUT / "generated"
    n = 1000 if args.quick else 10_000
    repeats = 3 if args.quick else 7
    rng = np.random.default_rng(0)
    py = load_generated(ROBOT, generated)
    lo, hi = load_robot(ROBOT, CHECKOUT / "models.yaml").joint_box()
    Q = rng.uniform(lo, hi, (n, 7))
    V, A = rng.normal(size=(n, 7)), rng.normal(size=(n, 7))
    X = np.concatenate([Q, V], axis=1)
    c = compiled(ROBOT, generated=generated)
    pin, model, data = _pinocchio()
    jax, jx = _jax_module(generated)
    q, v, a, x = Q[0], V[0], A[0], X[0]
    calls = {
        "inverse_dynamics": ((q, v, a), (Q, V, A), lambda i: pin.rnea(model, data, Q[i], V[i], A[i])),
        "mass_matrix": ((q,), (Q,), lambda i: pin.crba(model, data, Q[i])),
        "forward_dynamics": ((q, v, a), (Q, V, A), lambda i: pin.aba(model, data, Q[i], V[i], A[i])),
        "ode_jac_x": ((x, a), (X, A), lambda i: pin.computeABADerivatives(model, data, Q[i], V[i], A[i])),
    }
    c_own = _c_loop(generated, Q, V, A)
    single, batch = [], []
    for name, (one, many, pin_call) in calls.items():
        f_py, f_c = getattr(py, name), getattr(c, name)
        number = 200 if name == "ode_jac_x" else 2000
        t_py = _best(lambda: f_py(*one), repeats, max(20, number // 20))
        t_c = _best(lambda: f_c(*one), repeats, number)
        t_pin = _best(lambda: pin_call(0), repeats, number)
        single.append(f"| {name} | {1e6 * t_py:.1f} | {1e6 * t_c:.2f} | {1e6 * t_pin:.2f} | {t_c / t_pin:.2f} |")
        t_npb = _best(lambda: f_py(*many), max(2, repeats // 2), 1) / n
        t_cb = _best(lambda: f_c(*many), repeats, 1) / n
        t_loop = _best(lambda: [pin_call(i) for i in range(n)], max(2, repeats // 2), 1) / n
        ref = f_py(*many)
        if jx is not None:
            f_jx = jax.jit(getattr(jx, name))
            out = f_jx(*many)
            out.block_until_ready()
            diff = float(np.max(np.abs(np.asarray(out) - ref)) / max(np.max(np.abs(ref)), 1e-300))
            t_jx = _best(lambda: f_jx(*many).block_until_ready(), repeats, 1) / n
            jax_cols = f"{1e6 * t_jx:.3f} | {diff:.1e}"
        else:
            jax_cols = "(jax not installed) | -"
        ns_c = c_own[name]
        batch.append(f"| {name} | {1e6 * t_npb:.3f} | {1e6 * t_cb:.3f} | {jax_cols} | {1e6 * t_loop:.2f} | "
                     f"{ns_c:.0f} | {1e9 * t_cb / ns_c:.2f} | {t_loop / t_npb:.1f} |")
    return "\n".join([
        "## Generated code from Python: single states and batches (Panda)", "",
        f"Targets: {TARGETS}. Same process, same seeded states; best of {repeats} repeats.", "",
        "One state, µs per call:", "",
        "| function | generated NumPy | compiled (`derive.compiled`) | Pinocchio from Python | compiled / Pinocchio |",
        "|---|---|---|---|---|", *single, "",
        f"Batch of {n} states, µs per state:", "",
        "| function | NumPy vectorised | compiled | JAX jit (CPU) | JAX vs NumPy (max rel.) | Python loop over Pinocchio | "
        "C own ns/call (plain C loop) | compiled / C own | Pinocchio loop / NumPy batch |",
        "|---|---|---|---|---|---|---|---|---|", *batch])


def benchmarks() -> dict:
    return {"python-speed": bench_python}
