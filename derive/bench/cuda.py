"""Benchmark ``cuda``: states per second of the CUDA batch kernels (derive.compiled(robot, device="cuda")).

Panda inverse_dynamics, mass_matrix, forward_dynamics and ode_jac_x at 1e3 to 1e7 states, FP64 and
FP32, inputs and outputs already on the device in both layouts: elements-major (each element of
every state contiguous: the coalesced layout) and states-major (the CPU API's (n, len) rows). The
kernel time is CUDA events around a run of launches on the default stream, called through the
library's launchers (ctypes, no per-call array handling), after one warm-up launch; the states
per second are n over the time per launch. Beside it: the CPU library (derive.compiled, one
core, its lanes) on the same states, and the largest difference of the GPU results from the CPU
ones over the first 1000 states (FP64, and FP32 against the FP64 CPU results), relative to the
largest entry of each state's output.

Without a CUDA device (or without nvcc) this benchmark is not run: ``derive bench cuda`` says so
in one line and writes nothing; ``derive bench`` (all) leaves its section out.

``python -m derive.bench.cuda [--quick] [--out FILE]`` runs it alone, importing nothing of derive
but the runtime (no CasADi, no other benchmark's dependencies: a GPU machine's image may have only
numpy, PyYAML and nvcc).
"""

from __future__ import annotations

import argparse
import ctypes
import os
import sys
import time

import numpy as np

from derive.bench import Unavailable, run
from derive.errors import DeriveError
from derive.runtime import compiled
from derive.runtime.cuda import NoDevice, device_architectures, find_nvcc

ROBOT = "panda"
FUNCTIONS = (("inverse_dynamics", ("q", "qd", "qdd")), ("mass_matrix", ("q",)),
             ("forward_dynamics", ("q", "qd", "qdd")), ("ode_jac_x", ("x", "qdd")))
SIZES = (1_000, 10_000, 100_000, 1_000_000, 10_000_000)
QUICK_SIZES = (1_000, 100_000)
TARGET_SECONDS = 0.2
"""Device time aimed at per measurement (launches repeated up to it)."""


def benchmarks():
    bench_cuda.check = _check_device
    return {"cuda": bench_cuda}


def _check_device() -> None:
    found = find_nvcc()
    if found is None:
        raise Unavailable("cuda: no nvcc (install the CUDA toolkit or `pip install derive-robotics[cuda]`): nothing measured")
    query = os.path.join(os.path.dirname(found[0][0]), "__nvcc_device_query")
    if os.path.isfile(query) and not device_architectures(found[0]) and not os.environ.get("DERIVE_CUDA_ARCH"):
        raise Unavailable("cuda: no CUDA device on this machine (nvcc's device query finds none): nothing measured")


class _Events:
    def __init__(self, rt):
        self.rt = rt
        self.start, self.stop = ctypes.c_void_p(), ctypes.c_void_p()
        rt.check(rt.event(ctypes.byref(self.start)), "cudaEventCreate")
        rt.check(rt.event(ctypes.byref(self.stop)), "cudaEventCreate")

    def time(self, launch, k: int) -> float:
        """Seconds per launch over k launches."""
        rt = self.rt
        rt.check(rt.record_event(self.start, None), "cudaEventRecord")
        for _ in range(k):
            launch()
        rt.check(rt.record_event(self.stop, None), "cudaEventRecord")
        ms = ctypes.c_float(0)
        rt.check(rt.elapsed(ctypes.byref(ms), self.start, self.stop), "cudaEventElapsedTime")
        return ms.value * 1e-3 / k

    def close(self):
        self.rt.event_free(self.start)
        self.rt.event_free(self.stop)


def _inputs(n: int, rng) -> dict[str, np.ndarray]:
    q = rng.uniform(-1.5, 1.5, (n, 7))
    qd = rng.uniform(-1.0, 1.0, (n, 7))
    qdd = rng.uniform(-1.0, 1.0, (n, 7))
    return {"q": q, "qd": qd, "qdd": qdd, "x": np.concatenate([q, qd], axis=1)}


def _measure(mod, lib, name, names, host, dtype, layout, events) -> tuple[float, np.ndarray]:
    """(seconds per launch, the outputs of the first min(n, 1000) states) of ``name`` on ``host``'s states."""
    rt = mod.runtime
    cname = f"{ROBOT}_{name}"
    launcher = getattr(lib, f"{cname}_cuda_{'f64' if dtype == np.float64 else 'f32'}")
    args = [host[k] for k in names]
    n = len(args[0])
    out_len = {"inverse_dynamics": 7, "mass_matrix": 49, "forward_dynamics": 7, "ode_jac_x": 196}[name]
    keep, argv = [], [n]
    for a in args:
        if layout == "elements":
            d = mod.to_device(np.ascontiguousarray(a.T), dtype)
            argv += [d.ptr, 1, n]
        else:
            d = mod.to_device(a, dtype)
            argv += [d.ptr, a.shape[1], 1]
        keep.append(d)
    out = mod.empty((out_len, n) if layout == "elements" else (n, out_len), dtype)
    argv += [out.ptr, 1, n] if layout == "elements" else [out.ptr, out_len, 1]
    argv.append(None)
    fn = launcher
    fn.argtypes = [ctypes.c_longlong] + [ctypes.c_void_p, ctypes.c_longlong, ctypes.c_longlong] * (len(args) + 1) + [ctypes.c_void_p]
    fn.restype = ctypes.c_int

    def launch():
        err = fn(*argv)
        if err:
            rt.check(err, f"{name} launch")

    launch()  # warm-up (and the module's first load)
    mod.synchronize()
    once = events.time(launch, 1)
    k = max(1, min(1000, int(TARGET_SECONDS / max(once, 1e-7))))
    per = events.time(launch, k)
    m = min(n, 1000)  # the first m states' outputs only (ode_jac_x at 1e7 states is 16 GB)
    item = np.dtype(dtype).itemsize
    if layout == "elements":
        head = np.empty((out_len, m), dtype)
        for j in range(out_len):
            rt.check(rt.copy(head[j].ctypes.data, out.ptr + j * n * item, m * item), "cudaMemcpy to the host")
        head = head.T
    else:
        head = np.empty((m, out_len), dtype)
        rt.check(rt.copy(head.ctypes.data, out.ptr, head.nbytes), "cudaMemcpy to the host")
    return per, head.astype(np.float64)


def _worst(got: np.ndarray, want: np.ndarray) -> float:
    scale = np.maximum(1.0, np.abs(want).max(axis=1, keepdims=True))
    return float(np.max(np.abs(got - want) / scale))


def bench_cuda(args) -> str:
    _check_device()
    try:
        mod = compiled(ROBOT, device="cuda", functions=[f for f, _ in FUNCTIONS])
        if not mod.device_count():
            mod.runtime.require()
    except NoDevice as exc:
        raise Unavailable(f"cuda: {exc}: nothing measured") from None
    cpu = compiled(ROBOT)
    lib = ctypes.CDLL(str(mod.LIBRARY))
    sizes = QUICK_SIZES if getattr(args, "quick", False) else SIZES
    rng = np.random.default_rng(0)
    events = _Events(mod.runtime)
    rows, accuracy = [], []
    try:
        for n in sizes:
            host = _inputs(n, rng)
            for name, names in FUNCTIONS:
                m = min(n, 1000)
                want = getattr(cpu, name)(*[host[k][:m] for k in names]).reshape(m, -1)
                start = time.perf_counter()
                getattr(cpu, name)(*[host[k][:m] for k in names])
                cpu_rate = m / (time.perf_counter() - start)
                cells = []
                for dtype in (np.float64, np.float32):
                    for layout in ("elements", "states"):
                        per, got = _measure(mod, lib, name, names, host, dtype, layout, events)
                        cells.append(n / per)
                        if n == sizes[0]:
                            accuracy.append((name, np.dtype(dtype).name, layout, _worst(got, want)))
                rows.append((name, n, cells, cpu_rate))
            del host
    finally:
        events.close()
    lines = ["## CUDA batch kernels (Panda): states per second", "",
             f"`derive bench cuda`: derive.compiled(\"{ROBOT}\", device=\"cuda\") kernels, one thread per state, "
             "inputs and outputs on the device; CUDA events around repeated launches (after a warm-up). "
             "Elements-major is the coalesced layout (element j of every state contiguous), states-major the "
             "CPU API's (n, len) rows. CPU: derive.compiled batch on one core, same states (first 1000).", "",
             f"GPU: {_device_name(mod)}; library {mod.LIBRARY.name} ({os.environ.get('DERIVE_CUDA_ARCH') or 'native'} architecture).", "",
             "| function | states | FP64 elements-major | FP64 states-major | FP32 elements-major | FP32 states-major | CPU FP64 (1 core) |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for name, n, cells, cpu_rate in rows:
        lines.append(f"| {name} | {n:.0e} | " + " | ".join(f"{c:.3g}" for c in cells) + f" | {cpu_rate:.3g} |")
    lines += ["", f"Largest difference from the CPU's FP64 results over the first {min(sizes[0], 1000)} states "
              "(relative to each state's largest entry):", "",
              "| function | precision | layout | worst |", "|---|---|---|---:|"]
    lines += [f"| {name} | {prec} | {layout}-major | {worst:.2e} |" for name, prec, layout, worst in accuracy]
    return "\n".join(lines) + "\n"


def _device_name(mod) -> str:
    arch = device_architectures(find_nvcc()[0]) if find_nvcc() else []
    return f"{mod.device_name()} ({mod.device_count()} device(s), compute capability {', '.join(arch) or '?'})"


def main(argv: list[str] | None = None) -> int:
    """``python -m derive.bench.cuda``: this benchmark alone into bench/results.md (or --out)."""
    parser = argparse.ArgumentParser(prog="python -m derive.bench.cuda", description=__doc__.splitlines()[0])
    parser.add_argument("--out", help="results file (default: bench/results.md)")
    parser.add_argument("--quick", action="store_true", help="1e3 and 1e5 states only")
    args = parser.parse_args(argv)
    args.names = ["cuda"]
    try:
        return run(args, benchmarks())
    except DeriveError as exc:
        print(f"derive: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
