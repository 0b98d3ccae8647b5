"""``derive.compiled(robot, device="cuda")``: the generated C as CUDA batch kernels, one thread per state.

The generated C is CUDA-ready (``DERIVE_FN`` in derive_real.h; tests/test_cuda.py). This module
writes, per precision (FP64, and FP32 with ``DERIVE_FLOAT``), one CUDA translation unit that
includes the generated sources of the chosen functions (and of the functions they call) with
``DERIVE_FN`` defined as ``__device__`` (device code only: no host copy of the big functions to
compile), and adds per function

- ``<fn>_kernel_f64`` / ``_f32``: a ``__global__`` kernel, one thread per state (a grid-stride
  loop over n states). Each input and output is addressed by a pointer and two strides in
  elements: the state stride s and the element stride e, element j of state i at ``a[i*s + j*e]``.
  The thread gathers its state's inputs into local arrays, calls the generated function and
  scatters the outputs.
- ``<fn>_cuda_f64`` / ``_f32``: the host launcher (``extern "C"``): n, (pointer, s, e) per input
  and output, then for IK the status array (pointer, s), then the stream; it returns the
  ``cudaError_t`` of the launch. Blocks of :data:`BLOCK` threads.

Layout and coalescing: the strides take either layout. States-major (array of structures, the
CPU API's ``(n, 7)``: s = 7, e = 1) makes the 32 threads of a warp read 32 addresses 56 bytes
apart; elements-major (structure of arrays, a ``(7, n)`` array passed transposed as ``x.T``:
s = 1, e = n) makes them read 32 neighbouring values, one transaction: that is the coalesced
layout, which the benchmark measures beside the other. Outputs allocated here are states-major
(the CPU API's shapes); a warp writes those through shared memory (:data:`STAGE`), so that its
stores are coalesced too. Pass ``out=`` arrays of the other layout to write elements-major.

The library also holds CUDA's runtime (nvcc links libcudart statically: nothing to install beside
the driver) and small host functions (device count, allocation, copies, pointer queries,
synchronisation) that :mod:`derive.runtime.cuda_arrays` calls through ctypes, and the record
(:func:`derive.runtime.build.record` plus the device, the precisions and the functions) that the
cache checks. It is built by nvcc (``$NVCC``, else ``nvcc`` on PATH, else the nvidia-cuda-nvcc
wheel of the ``cuda`` extra) for ``$DERIVE_CUDA_ARCH`` (default: the GPUs of this machine as
nvcc's device query reports them, else nvcc's default architecture with its PTX, which the driver
compiles for a newer GPU on first load), cached by content exactly as the CPU library
(:func:`derive.runtime.build.cached_library`: lock, temporary folder, one rename). No GPU is
needed to build; a call without one raises :class:`NoDevice` in one line.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import os
import re
import shlex
import shutil
import subprocess
from pathlib import Path

from derive.errors import DeriveError
from derive.runtime.build import (RECORD_MARK, Signature, Snapshot, cached_library, compiler_identity, record,
                                  run_compiler, run_parallel)

PRECISIONS = {"float64": "f64", "float32": "f32"}
"""The precisions a library holds, by numpy dtype name, and the suffix of their C names."""

BLOCK = 64
"""Threads per block of every kernel: two warps. Measured on an H200 (Panda, 1e7 states) against
CUDA's occupancy choice (256-512): faster for inverse_dynamics (FP64 elements-major 1.2e10 against
9.2e9 states/s), forward_dynamics and every states-major output, within 5 % for ode_jac_x
elements-major (2.5e8 against 2.6e8)."""

STAGE = 1568
"""Reals of shared memory per warp for states-major outputs (12.5 kB in FP64): an output of up to
STAGE entries is put together for S = min(32, STAGE // length) states of the warp at a time and
written as one contiguous run by neighbouring threads (a store per entry and state would touch 32
sectors per warp instruction: the Panda's mass matrix 1.07e9 states/s that way, 8.8e9 staged)."""

ARCH_DEFAULT = "sm_75"
"""The architecture built when no GPU is found and $DERIVE_CUDA_ARCH is unset: nvcc's own default
(Turing), with its PTX, which newer GPUs' drivers compile on first load."""


class NoDevice(DeriveError):
    """The CUDA library is built, but this machine has no usable CUDA device (or driver)."""


# ---- nvcc ----

def find_nvcc() -> tuple[list[str], list[str]] | None:
    """(the nvcc command, extra link flags): ``$NVCC``, else nvcc on PATH, else the nvidia-cuda-nvcc
    wheel (``pip install derive-robotics[cuda]``, its libcudart_static beside it); None if none."""
    env = os.environ.get("NVCC", "").strip()
    if env:
        try:
            argv = shlex.split(env)
        except ValueError:
            argv = [env]
        if argv and shutil.which(argv[0]):
            return [shutil.which(argv[0])] + argv[1:], []
        return None
    on_path = shutil.which("nvcc")
    if on_path:
        return [on_path], []
    spec = importlib.util.find_spec("nvidia")
    for base in (spec.submodule_search_locations if spec else []):
        for nvcc in sorted(Path(base).glob("cu*/bin/nvcc"), reverse=True):  # the newest toolkit first
            return [str(nvcc)], [f"-L{nvcc.parent.parent / 'lib'}"]
    return None


def nvcc(robot: str) -> tuple[list[str], list[str]]:
    """:func:`find_nvcc`, or a one-line DeriveError naming the extra to install."""
    found = find_nvcc()
    if found is None:
        where = f"NVCC={os.environ['NVCC']} is not a program" if os.environ.get("NVCC", "").strip() else \
            "no nvcc on PATH and no nvidia-cuda-nvcc wheel"
        raise DeriveError(f"cannot compile robot '{robot}' for CUDA: {where} (install the CUDA toolkit, or "
                          "`pip install derive-robotics[cuda]`, or set NVCC)")
    return found


def device_architectures(argv: list[str]) -> list[str]:
    """The compute capabilities of this machine's GPUs (``["90"]``) from nvcc's device query
    (``__nvcc_device_query`` beside nvcc), or [] without a GPU, a driver or the query."""
    query = Path(argv[0]).parent / "__nvcc_device_query"
    if not query.is_file():
        return []
    try:
        r = subprocess.run([str(query)], capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.SubprocessError):
        return []
    if r.returncode != 0:
        return []
    return sorted(set(re.findall(r"\b(\d{2,3}[a-z]?)\b", r.stdout)))


def arch_flags(robot: str, argv: list[str]) -> list[str]:
    """nvcc's architecture flags: ``$DERIVE_CUDA_ARCH`` (``native``, the default: this machine's GPUs,
    else :data:`ARCH_DEFAULT`; ``sm_90``, ``compute_90``, or several separated by commas), SASS and
    PTX for each."""
    choice = os.environ.get("DERIVE_CUDA_ARCH", "").strip().lower() or "native"
    if choice == "native":
        found = device_architectures(argv)
        names = [f"sm_{a}" for a in found] or [ARCH_DEFAULT]
    else:
        names = [c.strip() for c in choice.split(",") if c.strip()]
    out = []
    for name in names:
        m = re.fullmatch(r"(sm|compute)_(\d{2,3}[a-z]?)", name)
        if not m:
            raise DeriveError(f"DERIVE_CUDA_ARCH={choice}: {name!r} is not a CUDA architecture (native, sm_90, "
                              "compute_90, or several separated by commas)")
        code = f"sm_{m[2]}" if m[1] == "sm" else f"compute_{m[2]}"
        out += ["-gencode", f"arch=compute_{m[2]},code=[{code},compute_{m[2]}]" if m[1] == "sm" else
                f"arch=compute_{m[2]},code={code}"]
    return out


NVCC_FLAGS = ["-O3", "-std=c++14", "-Xcompiler", "-fPIC", "-Xcompiler", "-O2"]
"""The compile flags (before the architecture flags and $NVCCFLAGS)."""


def flags(robot: str, argv: list[str]) -> list[str]:
    try:
        extra = shlex.split(os.environ.get("NVCCFLAGS", ""))
    except ValueError as exc:
        raise DeriveError(f"cannot compile robot '{robot}' for CUDA: NVCCFLAGS is not a list of shell words ({exc})") from None
    return [*NVCC_FLAGS, *arch_flags(robot, argv), *extra]


# ---- the functions and their sources ----

def select(robot: str, sigs: list[Signature], functions) -> list[Signature]:
    """The signatures named in ``functions`` (Python names, in the manifest's order; None: all)."""
    if functions is None:
        return list(sigs)
    if isinstance(functions, str):
        functions = [functions]
    names = {s.name for s in sigs}
    wanted = list(functions)
    for name in wanted:
        if name not in names:
            raise DeriveError(f"robot '{robot}': derive.compiled(device='cuda'): no function {name!r} "
                              f"(known: {', '.join(sorted(names))})")
    if not wanted:
        raise DeriveError(f"robot '{robot}': derive.compiled(device='cuda'): functions= names none")
    return [s for s in sigs if s.name in set(wanted)]


def needed_sources(chosen: list[Signature], sigs: list[Signature], snap: Snapshot) -> list[str]:
    """The .c files of the chosen functions and of every function they call, in the manifest's order."""
    by_c = {s.cname: s for s in sigs}
    need: set[str] = set()
    todo = [s.cname for s in chosen]
    while todo:
        c = todo.pop()
        if c in need:
            continue
        need.add(c)
        todo += [d for d in (by_c[c].calls if c in by_c else ())]
    present = {name for name, _ in snap.sources}
    return [f"{s.cname}.c" for s in sigs if s.cname in need and f"{s.cname}.c" in present]


def chunks(chosen: list[Signature], manifest: dict, count: int) -> list[list[Signature]]:
    """``chosen`` in at most ``count`` groups of about equal arithmetic (manifest ops, largest first
    to the lightest group), each in the manifest's order: one translation unit per group and
    precision, so nvcc runs on every CPU (one unit of a big function takes it a minute)."""
    ops = {f.get("name"): (f.get("ops") or {}).get("total", 0) for f in manifest.get("functions", [])
           if isinstance(f, dict)}
    count = max(1, min(count, len(chosen)))
    groups: list[list[Signature]] = [[] for _ in range(count)]
    load = [0] * count
    for s in sorted(chosen, key=lambda s: -(ops.get(s.cname) or 0)):
        k = load.index(min(load))
        groups[k].append(s)
        load[k] += (ops.get(s.cname) or 0) + 1
    order = {s.cname: i for i, s in enumerate(chosen)}
    return [sorted(g, key=lambda s: order[s.cname]) for g in groups if g]


def cuda_record(robot: str, manifest: dict, chosen: list[Signature], sources_hash: str | None) -> str:
    """The library's record: :func:`derive.runtime.build.record` of the chosen functions, with the
    device and the precisions."""
    data = json.loads(record(robot, manifest, chosen, sources_hash))
    data["device"] = "cuda"
    data["precisions"] = list(PRECISIONS)
    return json.dumps(data, sort_keys=True, separators=(",", ":"))


def _bytes_array(data: bytes) -> list[str]:
    return ["    " + ", ".join(str(b) for b in data[k:k + 24]) + "," for k in range(0, len(data), 24)]


def unit_source(robot: str, chosen: list[Signature], files: list[str], suffix: str,
                sigs: list[Signature] | None = None, tag: str | None = None) -> str:
    """A CUDA translation unit of one precision (``suffix`` f64 or f32): the generated sources
    ``files`` as device functions (every generated name, ``sigs``, renamed ``<name>_<tag>``, tag
    default ``suffix``: nvcc gives each a host stub, which would clash between the units that
    include it), a kernel and a host launcher per chosen function."""
    lines = [f"/* Built by derive.runtime.cuda for robot '{robot}' ({suffix}) into the build folder (not part of generated/). */",
             *(["#define DERIVE_FLOAT"] if suffix == "f32" else []),
             "#define DERIVE_FN __device__",
             *[f"#define {c} {c}_{tag or suffix}" for c in sorted({s.cname for s in (sigs or chosen)})],
             "#include <cuda_runtime.h>",
             f'#include "{robot}.h"',
             *[f'#include "{name}"' for name in files],
             "",
             "typedef long long derive_cu_n;"]
    for s in chosen:
        # C names: a_/s_/e_ an input's pointer, state stride and element stride, li_ its local copy;
        # r_/rs_/re_ and lo_ an output's (an input and an output may share a name); st_ IK's status
        params = [f"const DERIVE_REAL *a_{a.name}, derive_cu_n s_{a.name}, derive_cu_n e_{a.name}" for a in s.inputs]
        params += [f"DERIVE_REAL *r_{a.name}, derive_cu_n rs_{a.name}, derive_cu_n re_{a.name}" for a in s.outputs]
        if s.status:
            params += ["int *st_status, derive_cu_n st_stride"]
        body = []
        for a in s.inputs:
            load = [f"            for (int j = 0; j < {a.length}; ++j)",
                    f"                li_{a.name}[j] = a_{a.name}[i * s_{a.name} + j * e_{a.name}];"]
            body += [f"        DERIVE_REAL li_{a.name}[{a.length}];"]
            body += ([f"        if (a_{a.name}) {{", *load, "        }"] if a.nullable else [ln[4:] for ln in load])
        body += [f"        DERIVE_REAL lo_{a.name}[{a.length}];" for a in s.outputs]
        args = [f"a_{a.name} ? li_{a.name} : 0" if a.nullable else f"li_{a.name}" for a in s.inputs]
        args += [f"lo_{a.name}" for a in s.outputs]
        call = f"{s.cname}({', '.join(args)})"
        body += [f"        st_status[i * st_stride] = {call};" if s.status else f"        {call};"]
        for a in s.outputs:
            scatter = [f"for (int j = 0; j < {a.length}; ++j)",
                       f"    r_{a.name}[i * rs_{a.name} + j * re_{a.name}] = lo_{a.name}[j];"]
            if a.length > STAGE:
                body += [f"        {ln}" for ln in scatter]
                continue
            # states-major (rs = length, re = 1): the warp's outputs are one contiguous run; staged in
            # rounds of S states through shared memory, it is written by neighbouring threads
            per = min(32, STAGE // a.length)
            body += [f"        if (rs_{a.name} == {a.length} && re_{a.name} == 1) {{",
                     f"            for (int r0 = 0; r0 < count; r0 += {per}) {{",
                     f"                if (lane >= r0 && lane < r0 + {per})",
                     f"                    for (int j = 0; j < {a.length}; ++j)",
                     f"                        stage[(lane - r0) * {a.length} + j] = lo_{a.name}[j];",
                     "                __syncwarp(active);",
                     f"                const int m = (count - r0 < {per} ? count - r0 : {per}) * {a.length};",
                     f"                DERIVE_REAL *run = r_{a.name} + (first + r0) * {a.length};",
                     "                for (int k = lane; k < m; k += count)",
                     "                    run[k] = stage[k];",
                     "                __syncwarp(active);",
                     "            }",
                     "        } else {",
                     *[f"            {ln}" for ln in scatter],
                     "        }"]
        if any(a.length <= STAGE for a in s.outputs):
            body = ["        const int width = blockDim.x < 32 ? (int)blockDim.x : 32;  /* a warp (1 in a host emulation) */",
                    "        const int lane = (int)(threadIdx.x % width);",
                    "        DERIVE_REAL *stage = derive_cu_stage[threadIdx.x / width];",
                    "        const derive_cu_n first = i - lane;  /* the warp's first state, this round */",
                    "        const int count = n - first < width ? (int)(n - first) : width;",
                    "        const unsigned active = count == 32 ? 0xffffffffu : (1u << count) - 1;",
                    *body]
            shared = [f"    __shared__ DERIVE_REAL derive_cu_stage[{BLOCK // 32}][{STAGE}];"]
        else:
            shared = []
        names = [f"a_{a.name}, s_{a.name}, e_{a.name}" for a in s.inputs] + \
                [f"r_{a.name}, rs_{a.name}, re_{a.name}" for a in s.outputs] + (["st_status, st_stride"] if s.status else [])
        kernel = f"{s.cname}_kernel_{suffix}"
        lines += ["",
                  f"__global__ void {kernel}(derive_cu_n n, {', '.join(params)})",
                  "{",
                  *shared,
                  "    for (derive_cu_n i = blockIdx.x * (derive_cu_n)blockDim.x + threadIdx.x; i < n;",
                  "         i += (derive_cu_n)blockDim.x * gridDim.x) {",
                  *body,
                  "    }",
                  "}",
                  "",
                  f'extern "C" int {s.cname}_cuda_{suffix}(derive_cu_n n, {", ".join(params)}, void *stream)',
                  "{",
                  f"    const int block = {BLOCK};",
                  "    if (n <= 0)",
                  "        return 0;",
                  "    derive_cu_n blocks = (n + block - 1) / block;",
                  "    if (blocks > 2147483647LL)",
                  "        blocks = 2147483647LL;",
                  f"    {kernel}<<<(unsigned)blocks, block, 0, (cudaStream_t)stream>>>(n, {', '.join(names)});",
                  "    return (int)cudaGetLastError();",
                  "}"]
    return "\n".join(lines) + "\n"


def host_source(robot: str, rec: str) -> str:
    """The host functions of the library: the record and thin wrappers of CUDA's runtime (each
    returns a cudaError_t), so Python needs no other CUDA library."""
    mark = RECORD_MARK + rec.encode()
    p = f"{robot}_cu"
    return "\n".join([
        f"/* Built by derive.runtime.cuda for robot '{robot}': its record and the host functions Python calls. */",
        "#include <stddef.h>",
        "#include <cuda_runtime.h>",
        "",
        f'extern "C" const char {p}_record_text[{len(mark) + 1}] = {{',
        *_bytes_array(mark + b"\0"),
        "};",
        "",
        f'extern "C" const char *{p}_record(void) {{ return {p}_record_text + {len(RECORD_MARK)}; }}',
        "/* The number of devices; the error when there is no driver or none (never a crash). */",
        f'extern "C" int {p}_devices(int *count) {{ *count = 0; return (int)cudaGetDeviceCount(count); }}',
        f'extern "C" const char *{p}_error_name(int err) {{ return cudaGetErrorName((cudaError_t)err); }}',
        f'extern "C" const char *{p}_error_text(int err) {{ return cudaGetErrorString((cudaError_t)err); }}',
        f'extern "C" int {p}_current(int *device) {{ return (int)cudaGetDevice(device); }}',
        "/* The current device's name into buf (size bytes, NUL-terminated). */",
        f'extern "C" int {p}_device_name(char *buf, int size)',
        "{",
        "    int device = 0;",
        "    cudaDeviceProp prop;",
        "    cudaError_t err = cudaGetDevice(&device);",
        "    if (err == cudaSuccess)",
        "        err = cudaGetDeviceProperties(&prop, device);",
        "    if (err != cudaSuccess || size <= 0)",
        "        return (int)err;",
        "    int k = 0;",
        "    for (; k < size - 1 && prop.name[k]; ++k)",
        "        buf[k] = prop.name[k];",
        "    buf[k] = 0;",
        "    return 0;",
        "}",
        f'extern "C" int {p}_alloc(void **p, size_t bytes) {{ return (int)cudaMalloc(p, bytes ? bytes : 1); }}',
        f'extern "C" int {p}_free(void *p) {{ return (int)cudaFree(p); }}',
        "/* dst <- src, either on the host or the device (unified addressing tells which). */",
        f'extern "C" int {p}_copy(void *dst, const void *src, size_t bytes) {{ return (int)cudaMemcpy(dst, src, bytes, cudaMemcpyDefault); }}',
        f'extern "C" int {p}_synchronize(void *stream) {{ return (int)cudaStreamSynchronize((cudaStream_t)stream); }}',
        "/* Where p points: 2 device memory, 3 managed, 1 registered host, 0 other host memory; its device. */",
        f'extern "C" int {p}_where(const void *p, int *type, int *device)',
        "{",
        "    cudaPointerAttributes at;",
        "    cudaError_t err = cudaPointerGetAttributes(&at, p);",
        "    if (err != cudaSuccess) {",
        "        cudaGetLastError();",
        "        *type = 0;",
        "        *device = -1;",
        "        return (int)err;",
        "    }",
        "    *type = (int)at.type;",
        "    *device = at.device;",
        "    return 0;",
        "}",
        "/* Events, for timing a stream (the benchmark). */",
        f'extern "C" int {p}_event(void **e) {{ return (int)cudaEventCreate((cudaEvent_t *)e); }}',
        f'extern "C" int {p}_record_event(void *e, void *stream) {{ return (int)cudaEventRecord((cudaEvent_t)e, (cudaStream_t)stream); }}',
        f'extern "C" int {p}_elapsed(float *ms, void *start, void *stop)',
        "{",
        "    cudaError_t err = cudaEventSynchronize((cudaEvent_t)stop);",
        "    return (int)(err != cudaSuccess ? err : cudaEventElapsedTime(ms, (cudaEvent_t)start, (cudaEvent_t)stop));",
        "}",
        f'extern "C" int {p}_event_free(void *e) {{ return (int)cudaEventDestroy((cudaEvent_t)e); }}',
    ]) + "\n"


def library(robot: str, snap: Snapshot, sigs: list[Signature], chosen: list[Signature]) -> tuple[Path, str]:
    """The CUDA library of the ``chosen`` functions (from the cache, else built), and its record."""
    argv, link = nvcc(robot)
    fl = flags(robot, argv)
    rec = cuda_record(robot, snap.manifest, chosen, snap.sources_hash)
    groups = chunks(chosen, snap.manifest, max(1, (os.cpu_count() or 1) // len(PRECISIONS)))
    units = {}
    for suffix in PRECISIONS.values():
        for k, group in enumerate(groups):
            tag = suffix if len(groups) == 1 else f"{suffix}_{k}"
            units[f"{robot}_cuda_{tag}.cu"] = unit_source(robot, group, needed_sources(group, sigs, snap), suffix, sigs, tag)
    units[f"{robot}_cuda_host.cu"] = host_source(robot, rec)
    h = hashlib.sha256()
    h.update(json.dumps({"robot": robot, "device": "cuda", "compiler": compiler_identity(argv), "flags": fl,
                         "link": ["-shared", *link]}).encode())
    h.update(b"\0sources\0" + snap.sources_hash.encode())
    for name, text in sorted(units.items()):
        h.update(f"\0{name}\0".encode() + text.encode())
    digest = h.hexdigest()
    name = f"lib{robot}_cuda.so"
    cdir = snap.folder / "c"

    def make(tmp: Path) -> Path:
        copy = tmp / "src"
        copy.mkdir()
        for fname, data in snap.sources:
            (copy / fname).write_bytes(data)
        objects, jobs = [], []
        for fname, text in sorted(units.items()):
            (tmp / fname).write_text(text)
            obj = tmp / f"{Path(fname).stem}.o"
            objects.append(obj)
            jobs.append(argv + fl + [f"-I{copy}", "-c", str(tmp / fname), "-o", str(obj)])
        run_parallel(jobs, robot, copy, cdir)
        built = tmp / name
        run_compiler(argv + fl + ["-shared", "-o", str(built), *map(str, objects), *link], robot, copy, cdir)
        for o in objects:
            o.unlink()
        shutil.rmtree(copy)
        return built

    what = f"{len(chosen)} functions for CUDA, FP64 and FP32, with {Path(argv[0]).name}"
    return cached_library(robot, digest, name, rec, make, what), rec
