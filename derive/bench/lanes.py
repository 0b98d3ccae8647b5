"""Benchmark ``lanes``: the generated C in lane mode (derive_lanes.h), against the scalar C.

Panda inverse_dynamics, mass_matrix, forward_dynamics and ode_jac_x on the same seeded states, in
one run, best of several interleaved repeats (the machines are shared and noisy):

- the scalar C's ns per call (a plain C loop, cc -O2);
- the lane C's ns per state: the same .c files compiled with -DDERIVE_LANES, inputs laid out as
  one vector of lanes per element, for each width this CPU has (AVX2: 4 doubles and 8 floats;
  AVX-512F: 8 doubles and 16 floats), derive_lanes.h's inline sin and cos for doubles;
- derive.compiled's batch per state without lanes (DERIVE_LANES=off: the scalar function in a
  C loop) and with each double width the CPU has (DERIVE_LANES=avx2, avx512f: gathering into
  lanes and putting the results back in C), and the generated NumPy vectorised over the batch;
- the accuracy: the lane results against the scalar C's (largest difference over the largest
  entry of the output, per state) and the worst ulp of the lanes' sin and cos against glibc's
  scalar ones over 1e6 arguments in [-4, 4] and in [-1e5, 1e5], per double width.
"""

from __future__ import annotations

import os
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from derive.description.model import load_robot
from derive.errors import DeriveError
from derive.resources import CHECKOUT
from derive.runtime import build, loader
from derive.solvers.simulate import load_generated

ROBOT = "panda"
FUNCTIONS = (("inverse_dynamics", ("q", "qd", "qdd"), 7), ("mass_matrix", ("q",), 49),
             ("forward_dynamics", ("q", "qd", "qdd"), 7), ("ode_jac_x", ("x", "qdd"), 196))
"""(function, its inputs among q, qd, qdd and x = [q, qd], its output length)."""
TARGET = "derive.compiled batch per state <= 0.30x the scalar C's ns per call with AVX2 (<= 0.20x with AVX-512)"

PROGRAM = r"""
#define _POSIX_C_SOURCE 200112L
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include "%(robot)s.h"
typedef double v4d __attribute__((vector_size(32)));
typedef float v8f __attribute__((vector_size(32)));
typedef double v8d __attribute__((vector_size(64)));
typedef float v16f __attribute__((vector_size(64)));
%(declarations)s
static double now(void) { struct timespec t; clock_gettime(CLOCK_MONOTONIC, &t); return t.tv_sec + 1e-9 * t.tv_nsec; }
static void *lanes_alloc(size_t bytes) { void *p = NULL; return posix_memalign(&p, 64, bytes) ? NULL : p; }
/* states (n x len, row-major) -> blocks of L lanes: element j of block b, lane k = state L b + k */
#define PACK(T, L, src, len, dst) do { long b_, j_, k_; for (b_ = 0; b_ < n / (L); b_++) for (j_ = 0; j_ < (len); j_++) \
    for (k_ = 0; k_ < (L); k_++) (dst)[b_ * (len) + j_][k_] = (src)[((L) * b_ + k_) * (len) + j_]; } while (0)
#define UNPACK(L, src, len, dst) do { long b_, j_, k_; for (b_ = 0; b_ < n / (L); b_++) for (j_ = 0; j_ < (len); j_++) \
    for (k_ = 0; k_ < (L); k_++) (dst)[((L) * b_ + k_) * (len) + j_] = (src)[b_ * (len) + j_][k_]; } while (0)
int main(int argc, char **argv) {
    long n = atol(argv[1]), i; int r, repeats = atoi(argv[3]);
    FILE *f = fopen(argv[2], "rb");
    double *q = malloc(n * 7 * sizeof(double)), *qd = malloc(n * 7 * sizeof(double)), *qdd = malloc(n * 7 * sizeof(double));
    double *x = malloc(n * 14 * sizeof(double)), *out = malloc(n * 196 * sizeof(double)), *lout = malloc(n * 196 * sizeof(double));
    double t0, sink = 0;
    if (!f || fread(q, sizeof(double), n * 7, f) != (size_t)(n * 7) || fread(qd, sizeof(double), n * 7, f) != (size_t)(n * 7)
        || fread(qdd, sizeof(double), n * 7, f) != (size_t)(n * 7)) return 1;
    for (i = 0; i < n; i++) { int k; for (k = 0; k < 7; k++) { x[14*i+k] = q[7*i+k]; x[14*i+7+k] = qd[7*i+k]; } }
%(body)s
    fprintf(stderr, "%%g\n", sink);
    return 0;
}
"""

ULP = r"""
#include <stdint.h>
#include <stdio.h>
#include <string.h>
/* derive_lanes.h's sin and cos (DERIVE_LANES, -include derive_lanes.h) against <math.h>'s, per range */
static long ulps(double a, double b) { int64_t x, y; memcpy(&x, &a, 8); memcpy(&y, &b, 8); return x > y ? x - y : y - x; }
int main(void) {
    static const double bound[] = {4.0, 1.0e5};
    long i, n = 1000000 / DERIVE_LANES;
    int k, b;
    for (b = 0; b < 2; b++) {
        long worst_sin = 0, worst_cos = 0;
        for (i = 0; i < n; i++) {
            DERIVE_REAL a, s, c;
            for (k = 0; k < DERIVE_LANES; k++) a[k] = bound[b] * (-1.0 + 2.0 * (DERIVE_LANES * i + k) / 1e6);
            s = DERIVE_SIN(a); c = DERIVE_COS(a);
            for (k = 0; k < DERIVE_LANES; k++) {
                long us = ulps(s[k], sin(a[k])), uc = ulps(c[k], cos(a[k]));
                if (us > worst_sin) worst_sin = us;
                if (uc > worst_cos) worst_cos = uc;
            }
        }
        printf("%ld %ld ", worst_sin, worst_cos);
    }
    printf("%d\n", DERIVE_LANES_LIBMVEC);
    return 0;
}
"""


def lane_widths() -> list[tuple[str, int, bool, list[str]]]:
    """(label, lanes, float, flags) of each lane build this CPU runs: AVX2 and AVX-512F."""
    cpu = build._cpu_flags()
    out = []
    if "avx2" in cpu:
        out += [("AVX2, 4 doubles", 4, False, ["-mavx2"]), ("AVX2, 8 floats", 8, True, ["-mavx2"])]
    if "avx512f" in cpu:
        out += [("AVX-512F, 8 doubles", 8, False, ["-mavx512f"]), ("AVX-512F, 16 floats", 16, True, ["-mavx512f"])]
    return out


def _program(widths) -> tuple[str, list[tuple[str, list[str], str]]]:
    """The C program timing the scalar function and every lane width, interleaved in each repeat,
    and its lane objects: (source, flags, rename)."""
    vtype = {(4, False): "v4d", (8, True): "v8f", (8, False): "v8d", (16, True): "v16f"}
    decls, objects = [], []
    inputs = {"q": ("q", 7), "qd": ("qd", 7), "qdd": ("qdd", 7), "x": ("x", 14)}
    body = []
    for name, args, m in FUNCTIONS:
        fn = f"{ROBOT}_{name}"
        call = ", ".join(f"{inputs[a][0]} + {inputs[a][1]}*i" for a in args)
        setup, timed, report = [], [], []
        for w, (label, lanes, single, flags) in enumerate(widths):
            vt = vtype[(lanes, single)]
            lane_fn = f"{fn}_w{w}"
            objects.append((f"{fn}.c", flags + [f"-DDERIVE_LANES={lanes}"] + (["-DDERIVE_FLOAT"] if single else []),
                            f"-D{fn}={lane_fn}"))
            decls.append(f"void {lane_fn}({', '.join([f'const {vt} *'] * len(args) + [f'{vt} *'])});")
            vargs = []
            for a in args:
                src, length = inputs[a]
                setup += [f"        {vt} *v{w}_{a} = lanes_alloc(sizeof({vt}) * (n / {lanes}) * {length});",
                          f"        PACK({'float' if single else 'double'}, {lanes}, {src}, {length}, v{w}_{a});"]
                vargs.append(f"v{w}_{a} + {length}*b")
            setup += [f"        {vt} *v{w}_out = lanes_alloc(sizeof({vt}) * (n / {lanes}) * {m});",
                      f"        double best{w} = 1e9;"]
            timed += [f"            t0 = now(); for (b = 0; b < n / {lanes}; b++) {lane_fn}({', '.join(vargs)}, v{w}_out + {m}*b);",
                      f"            t0 = now() - t0; if (t0 < best{w}) best{w} = t0; sink += v{w}_out[0][0];"]
            report.append(f'        printf("lanes{w} {name} %.3f\\n", best{w} / (n / {lanes} * {lanes}) * 1e9);')
            if not single:  # the largest difference from the scalar results, over the output's largest entry
                report += [f"        UNPACK({lanes}, v{w}_out, {m}, lout);",
                           "        { double worst = 0; long s; int j;",
                           f"          for (s = 0; s < n / {lanes} * {lanes}; s++) {{ double big = 0, d = 0;",
                           f"              for (j = 0; j < {m}; j++) {{ big = fmax(big, fabs(out[{m}*s+j])); "
                           f"d = fmax(d, fabs(out[{m}*s+j] - lout[{m}*s+j])); }}",
                           "              if (big > 0 && d / big > worst) worst = d / big; }",
                           f'          printf("error{w} {name} %.3g\\n", worst); }}']
        body += ["    {", "        double best = 1e9;", "        long b;", *setup,
                 "        for (r = 0; r < repeats; r++) {  /* interleaved: a burst of load hits all alike */",
                 f"            t0 = now(); for (i = 0; i < n; i++) {fn}({call}, out + {m}*i);",
                 "            t0 = now() - t0; if (t0 < best) best = t0; sink += out[3];",
                 *timed, "        }",
                 f'        printf("scalar {name} %.3f\\n", best / n * 1e9);', *report, "    }"]
    return PROGRAM % {"robot": ROBOT, "declarations": "\n".join(decls), "body": "\n".join(body)}, objects


def _run_c(generated: Path, states, n: int, repeats: int, widths) -> dict[str, float]:
    c_dir = generated / ROBOT / "c"
    program, objects = _program(widths)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / "main.c").write_text(program)
        np.concatenate([s.ravel() for s in states]).astype(np.float64).tofile(tmp / "states.bin")
        objs = []
        for k, (source, flags, rename) in enumerate(objects):
            obj = tmp / f"lanes{k}.o"
            subprocess.run(["cc", "-std=c99", "-O2", *flags, rename, f"-I{c_dir}", "-include", "derive_lanes.h", "-c",
                            str(c_dir / source), "-o", str(obj)], check=True)
            objs.append(str(obj))
        sources = [str(c_dir / f"{ROBOT}_{name}.c") for name, _, _ in FUNCTIONS]
        subprocess.run(["cc", "-std=c99", "-O2", f"-I{c_dir}", str(tmp / "main.c"), *sources, *objs, "-lm", "-o",
                        str(tmp / "main")], check=True)
        out = subprocess.run([str(tmp / "main"), str(n), str(tmp / "states.bin"), str(repeats)], check=True,
                             capture_output=True, text=True).stdout
        figures = {}
        for line in out.splitlines():
            what, name, value = line.split()
            figures[(what, name)] = float(value)
        ulp = {}
        (tmp / "ulp.c").write_text(ULP)
        for label, lanes, single, flags in widths:
            if single:
                continue
            subprocess.run(["cc", "-std=c99", "-O2", *flags, f"-DDERIVE_LANES={lanes}", f"-I{c_dir}", "-include",
                            "derive_lanes.h", str(tmp / "ulp.c"), "-lm", "-o", str(tmp / "ulp")], check=True)
            ulp[label] = tuple(int(v) for v in subprocess.run([str(tmp / "ulp")], check=True, capture_output=True,
                                                              text=True).stdout.split())
    return figures, ulp


def _compiled(mode: str, generated: Path):
    """derive.compiled built with DERIVE_LANES=mode (each mode its own cached library)."""
    old = os.environ.get("DERIVE_LANES")
    os.environ["DERIVE_LANES"] = mode
    try:
        return loader.compiled(ROBOT, generated)
    finally:
        if old is None:
            del os.environ["DERIVE_LANES"]
        else:
            os.environ["DERIVE_LANES"] = old


def _best(fn, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def bench_lanes(args) -> str:
    generated = CHECKOUT / "generated"
    n = 4096 if args.quick else 16384
    repeats = 3 if args.quick else 11
    widths = lane_widths()
    if not widths:
        raise DeriveError("bench lanes: measures AVX2 or AVX-512F lanes, which this CPU has not")
    rng = np.random.default_rng(0)
    lo, hi = load_robot(ROBOT, CHECKOUT / "models.yaml").joint_box()
    Q = rng.uniform(lo, hi, (n, 7))
    V, A = rng.normal(size=(n, 7)), rng.normal(size=(n, 7))
    X = np.concatenate([Q, V], axis=1)
    figures, ulp = _run_c(generated, (Q, V, A), n, repeats, widths)
    cpu = build._cpu_flags()
    modes = [(label, mode) for label, mode in (("AVX2, 4 doubles", "avx2"), ("AVX-512F, 8 doubles", "avx512f"))
             if mode in cpu]  # derive.compiled built for each double width the CPU has
    before = _compiled("off", generated)
    built = {mode: _compiled(mode, generated) for _, mode in modes}
    py = load_generated(ROBOT, generated)
    host = build.host_lanes()
    batches = {"q": Q, "qd": V, "qdd": A, "x": X}
    rows, worst, missed = [], 0.0, []
    for name, inputs, _ in FUNCTIONS:
        many = [batches[a] for a in inputs]
        calls = {"before": getattr(before, name), "numpy": getattr(py, name),
                 **{mode: getattr(lib, name) for mode, lib in built.items()}}
        times = dict.fromkeys(calls, float("inf"))
        for _ in range(repeats):  # interleaved: a burst of load hits all alike
            for key, fn in calls.items():  # each the best of 3 calls in a row: its own caches warm, as the C loop's are
                times[key] = min(times[key], _best(lambda: fn(*many), 3))
        a = calls["before"](*many)
        axes = tuple(range(1, a.ndim))
        for mode in built:
            rel = np.max(np.max(np.abs(a - calls[mode](*many)), axis=axes) / np.max(np.abs(a), axis=axes))
            worst = max(worst, float(rel))
        ns = figures[("scalar", name)]
        lane_cols = " | ".join(f"{figures[(f'lanes{w}', name)]:.1f} ({figures[(f'lanes{w}', name)] / ns:.2f}x)"
                               for w in range(len(widths)))
        errors = ", ".join(f"{figures[(f'error{w}', name)]:.1e}" for w, (_, _, single, _) in enumerate(widths) if not single)
        per = {key: 1e9 * t / n for key, t in times.items()}
        ratios = []
        for _, mode in modes:
            ratio, bound = per[mode] / ns, 0.20 if mode == "avx512f" else 0.30
            ratios.append(f"**{ratio:.2f}x** ({per[mode] / per['before']:.2f}x)")
            if ratio > bound:
                missed.append(f"{name} {mode} {ratio:.2f}x")
        rows.append(f"| {name} | {ns:.1f} | {lane_cols} | {per['before']:.1f} | "
                    + " | ".join(f"{per[mode]:.1f}" for _, mode in modes) + " | " + " | ".join(ratios)
                    + f" | {per['numpy']:.1f} | {errors} |")
    has = ", ".join(f for f in ("avx2", "fma", "avx512f") if f in cpu)
    header = ("| function | scalar C ns/call | " + " | ".join(f"lane C ns/state, {label}" for label, _, _, _ in widths)
              + " | derive.compiled batch ns/state, no lanes | " + " | ".join(f"derive.compiled, {label}" for label, _ in modes)
              + " | " + " | ".join(f"{label.split(',')[0]} / scalar C (/ no lanes)" for label, _ in modes)
              + " | NumPy batch ns/state | lane vs scalar (max diff / max entry) |")
    return "\n".join([
        "## SIMD lanes (Panda)", "",
        f"Target: {TARGET}. One run, {n} seeded states, best of {repeats} interleaved repeats (derive.compiled and NumPy: each the best of 3 calls in a row within a repeat); the CPU has {has or 'none of avx2, avx512f'} "
        f"(derive.compiled picks {host.isa}, {host.count} states a call, by default; each double width is built here with "
        "`DERIVE_LANES=<mode>`). The lane C is the same .c files compiled with "
        "`-DDERIVE_LANES=<n> -include derive_lanes.h` (cc -O2 and the ISA's flag), inputs one vector of lanes per element; "
        "derive.compiled gathers the batch into lanes and puts the results back in C (in-register transposes; "
        "non-temporal stores for outputs of 2 MiB or more). The scalar C is a separate C program; "
        "\"no lanes\" is derive.compiled with `DERIVE_LANES=off` (the scalar C in its batch loop) in the same process "
        "as the lane columns.", "",
        header, "|" + "---|" * (header.count("|") - 1), *rows, "",
        f"Target missed: {', '.join(missed)}." if missed else "Target met for every function and width.", "",
        " ".join(f"The {label} lanes' sin and cos against glibc's scalar ones, 1e6 arguments in [-4, 4]: worst "
                 f"{u[0]} and {u[1]} ulp; in [-1e5, 1e5]: {u[2]} and {u[3]} ulp ("
                 f"{'derive_lanes.h: its inline kernel' if u[4] else '<math.h> per lane'}; libmvec for the other "
                 "functions)." for label, u in ulp.items()) +
        f" The largest lane-vs-scalar difference over all four functions and both widths: {worst:.1e} of the output's "
        "largest entry (derive.compiled with lanes vs without). Float lanes are timed only (single precision). "
        "No AVX-512 figures where the CPU has none."])


def benchmarks() -> dict:
    return {"lanes": bench_lanes}
