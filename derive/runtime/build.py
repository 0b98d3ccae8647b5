"""Build a robot's generated C into one shared library, cached by content.

- :func:`read_generated` reads generated/<robot>/ once into a :class:`Snapshot`: its manifest.json
  and the bytes of its C sources (c/*.c, c/*.h), read again until the manifest is the same before
  and after the sources (a ``derive generate`` into the folder at the same time changes it), and
  checked for being one robot's code of one model.
- :func:`signatures` reads the manifest into one :class:`Signature` per function.
- :func:`wrapper_source` writes the small C file compiled beside the generated code (in the build
  folder, never in generated/): per function ``<robot>_<fn>_batch``, the loop over n states with
  one stride per input (its length, or 0 to broadcast one value such as p), and
  ``<robot>_<fn>_obj``, the one-state fast path that :mod:`derive.runtime.loader` calls with the
  addresses of the Python objects themselves (see there for why); and the library's own record
  (:func:`record`: robot, nq, nv, model hash, each function's input and output lengths, the hash of
  the sources), as const data behind ``<robot>_rt_record()``, and an ``#error`` unless the
  sources' ``<ROBOT>_NQ`` and ``<ROBOT>_NV`` are the manifest's.
- :func:`lane_sources` writes, for the host's lane mode (:func:`host_lanes`: AVX-512F 8 doubles,
  AVX2 4, SSE2 or NEON 2, ``$DERIVE_LANES`` to choose, ``off`` for none), one more source file
  per function the manifest marks lane-wise (``c.lanes``; compiled in as many shared translation
  units as the generated files allow, :func:`translation_units`): its generated .c compiled a
  second time with derive_lanes.h (DERIVE_REAL a vector, one state per lane; only these units get
  the ISA's flag) and ``<robot>_<fn>_lanes_batch``, which gathers blocks of states into lane vectors, calls
  it and puts the results back state by state (in-register transposes; a large batch by
  non-temporal stores, see :data:`STREAM_SOURCE`), all in C. The batch loop and the one-state
  path of such a function both go through it, so a state's results do not depend on the batch
  around it.
- :func:`library` returns ``$XDG_CACHE_HOME/derive/compiled/<hash>/lib<robot>.so`` (default
  ~/.cache/derive/compiled/), the hash being the sha256 of the snapshot's source bytes, the
  wrapper, the compiler (its path and ``--version``), the flags and the lane units with their
  flags. The library is compiled from a copy of exactly the bytes hashed (written into the build
  folder, compiled there), so a ``derive generate`` during the build cannot put other code under
  this hash. A present library
  is used only if the record in its file is the expected one (else it is rebuilt and replaced).

Builds of one hash take turns: the builder holds an advisory lock (``flock``) on
``.<hash>.lock`` in the cache for the whole build, and whoever waited finds the library built. A
build runs in the temporary folder ``.<hash>.tmp-*`` beside the library's folder and is renamed
into place in one step. A temporary folder is removed as left by a dead build only by a process
that holds its hash's lock, so liveness never rests on a pid (which says nothing across PID
namespaces, say a container sharing the cache).

The compiler is ``$CC`` (else cc, gcc or clang, the first found); the flags are
``-std=c99 -O2 $CFLAGS -fPIC``, linked with ``-shared ... -lm``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import fcntl
import hashlib
import json
import mmap
import os
import platform
import re
import shlex
import shutil
import stat
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

from derive.description.files import InputFileError, read_bytes
from derive.errors import DeriveError
from derive.filesystem import forget, register

BUILDS = 0
"""Libraries built by this process (a cache hit builds none)."""

HEAD = object.__basicsize__
"""sizeof(PyObject) of this Python (16 on a standard 64-bit build): where an object's own fields start."""

READS = 5
"""Readings of generated/<robot>/ before :func:`read_generated` gives up on one that keeps changing."""

RECORD_MARK = b"derive.compiled record:"
"""What precedes the record (JSON, then a NUL) in the library's read-only data."""

LEGACY_AGE = 86400.0
"""Seconds after which a temporary build folder named as before the locks (``.<16 hex>.tmp-<pid>-*``,
no lock to ask) is removed: no build lasts a day."""


@dataclass(frozen=True)
class Argument:
    name: str
    shape: tuple[int, ...]  # one state's shape in Python: (n,) for an n x 1 input, (r, c) for a matrix
    length: int             # DERIVE_REALs in C
    nullable: bool = False  # None (NULL in C) allowed: IK's q0 and w


@dataclass(frozen=True)
class Signature:
    """One generated function as the compiled module exposes it."""
    name: str                      # the Python name (no robot prefix)
    cname: str                     # the C name
    inputs: tuple[Argument, ...]
    outputs: tuple[Argument, ...]  # the arrays written, shaped as the generated Python returns them
    status: bool                   # the C function returns an int status (IK), returned last
    doc: str
    lanes: bool = False            # it and what it calls compile in lane mode (manifest.json c.lanes)
    calls: tuple[str, ...] = ()    # the C names of the generated functions it calls


@dataclass(frozen=True)
class Snapshot:
    """One reading of generated/<robot>/: its manifest and the bytes of its C sources, consistent."""
    robot: str
    folder: Path                            # generated/<robot>
    manifest: dict
    sources: tuple[tuple[str, bytes], ...]  # (name, bytes) of each c/*.c and c/*.h, by name
    sources_hash: str                       # sha256 of exactly those names and bytes


# ---- reading generated/<robot>/ ----

def default_generated() -> Path:
    """./generated, where ``derive generate`` writes by default (the folder of
    derive.codegen.generate.default_output, which is not imported here: it loads CasADi and jinja2,
    which running the generated code does not need; a GPU machine's image may have neither)."""
    return Path.cwd() / "generated"


def _read_sources(cdir: Path) -> tuple[tuple[str, bytes], ...]:
    try:
        names = sorted(n for n in os.listdir(cdir) if n.endswith((".c", ".h")))
    except OSError as exc:
        raise InputFileError(f"{cdir}: cannot read the generated C ({exc.strerror or exc})") from None
    out = []
    for name in names:
        path = cdir / name
        try:
            if stat.S_ISDIR(os.stat(path).st_mode):
                continue
        except OSError as exc:
            raise InputFileError(f"{path}: cannot read generated C source ({exc.strerror or exc})") from None
        out.append((name, read_bytes(path, "generated C source")))
    return tuple(out)


def _sources_hash(sources: tuple[tuple[str, bytes], ...]) -> str:
    h = hashlib.sha256()
    for name, data in sources:
        h.update(f"\0{name}\0{len(data)}\0".encode())
        h.update(data)
    return h.hexdigest()


_ORIGIN = re.compile(rb"robot '([^'\n]*)' \(model ([0-9a-f]+)\)")


def _inconsistency(robot: str, mpath: Path, manifest, cdir: Path, sources) -> str | None:
    """Why the manifest and the sources are not one robot's code of one model, or None."""
    if not isinstance(manifest, dict):
        return f"{mpath} is not a JSON object (run `derive generate`)"
    if manifest.get("robot") != robot:
        return f"{mpath} is the manifest of robot '{manifest.get('robot')}'"
    model = manifest.get("model_hash")
    for name, data in sources:
        m = _ORIGIN.search(data[:600])  # the header the renderer writes: "robot 'r' (model h)"
        if m and (m[1].decode(errors="replace") != robot or m[2].decode() != model):
            return (f"{cdir / name} is the code of robot '{m[1].decode(errors='replace')}' model {m[2].decode()}, "
                    f"but {mpath} of model {model} (run `derive generate`)")
    return None


def read_generated(robot: str, folder: str | Path) -> Snapshot:
    """generated/<robot>/ (``folder``) read into a :class:`Snapshot`; a one-line DeriveError when it
    is missing, unreadable, or not one model's code (after :data:`READS` readings, if it keeps changing)."""
    folder = Path(folder)
    mpath, cdir = folder / "manifest.json", folder / "c"
    if not mpath.is_file() or not cdir.is_dir():
        raise DeriveError(f"robot '{robot}': no generated code at {folder} (run `derive generate`, "
                          "or pass generated=<the folder holding it>)")
    error: DeriveError | None = None
    for attempt in range(READS):
        if attempt:
            time.sleep(0.02 * 2 ** attempt)  # a generate swapping the folder in is done within moments
        try:
            before = read_bytes(mpath, "manifest")
            sources = _read_sources(cdir)
            after = read_bytes(mpath, "manifest")
        except InputFileError as exc:  # a file gone while a generate swaps the folder, or truly unreadable
            error = DeriveError(f"robot '{robot}': {exc}")
            continue
        if before != after:
            error = DeriveError(f"robot '{robot}': {folder} changed while it was read, {READS} times "
                                "(a `derive generate` into it under way?); try again once it has finished")
            continue
        try:
            manifest = json.loads(before)
        except ValueError as exc:
            error = DeriveError(f"robot '{robot}': cannot read {mpath} ({exc}); run `derive generate`")
            continue
        reason = _inconsistency(robot, mpath, manifest, cdir, sources)
        if reason:
            error = DeriveError(f"robot '{robot}': {reason}")
            continue
        return Snapshot(robot, folder, manifest, sources, _sources_hash(sources))
    assert error is not None
    raise error


# ---- the functions of the manifest ----

def _python_name(name, what: str) -> str:
    if not isinstance(name, str) or not name.isidentifier() or name.startswith("_") or \
            name in {"def", "return", "if", "else", "None", "lambda"}:
        raise DeriveError(f"manifest: {what} '{name}' is not usable as a Python name")
    return name


def _length(value, where: str) -> int:
    if type(value) is not int or value < 0:
        raise DeriveError(f"{where}: {value!r} is not a length")
    return value


def signatures(manifest: dict) -> list[Signature]:
    """The functions of a robot's manifest.json, checked for consistency between its C and Python entries."""
    robot = manifest.get("robot", "?") if isinstance(manifest, dict) else "?"
    try:
        return _signatures(manifest, robot)
    except (KeyError, TypeError, ValueError, AttributeError, IndexError) as exc:
        raise DeriveError(f"robot '{robot}': manifest: malformed function entry ({type(exc).__name__}: {exc}); "
                          "run `derive generate`") from None


def _signatures(manifest: dict, robot: str) -> list[Signature]:
    out = []
    for f in manifest.get("functions", []):
        c, py = f["c"], f["python"]
        where = f"robot '{robot}': manifest: function {f['name']}"
        if len(c["reads"]) != len(f["inputs"]):
            raise DeriveError(f"{where}: {len(c['reads'])} C inputs for {len(f['inputs'])} inputs")
        inputs = []
        for spec, read in zip(f["inputs"], c["reads"]):
            rows, cols = (_length(d, f"{where}: input {spec['name']}") for d in spec["shape"])
            if rows * cols != read["length"]:
                raise DeriveError(f"{where}: input {spec['name']} is {rows}x{cols} but {read['length']} long in C")
            inputs.append(Argument(_python_name(spec["name"], "input"), (rows,) if cols == 1 else (rows, cols),
                                   read["length"], bool(read.get("nullable"))))
        returns = list(py["returns"])
        status = bool(returns) and returns[-1].get("type") == "int"
        if status != (c["returns"] == "int"):
            raise DeriveError(f"{where}: the C function returns {c['returns']}, the Python {returns[-1] if returns else None}")
        arrays = returns[:-1] if status else returns
        if len(arrays) != len(c["writes"]):
            raise DeriveError(f"{where}: {len(c['writes'])} C outputs for {len(arrays)} Python values")
        outputs = []
        for ret, write in zip(arrays, c["writes"]):
            shape = tuple(_length(d, f"{where}: output {ret['name']}") for d in ret["shape"])
            size = 1
            for d in shape:
                size *= d
            if size != write["length"]:
                raise DeriveError(f"{where}: output {ret['name']} has shape {shape} but is {write['length']} long in C")
            outputs.append(Argument(_python_name(ret["name"], "output"), shape, write["length"]))
        name = _python_name(py["function"], "function")
        if not isinstance(f["name"], str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", f["name"]):
            raise DeriveError(f"{where}: not a C identifier")
        doc = "\n".join([f"{f['name']} of the generated C, compiled; inputs take any leading batch shape.", ""]
                        + [f"in  {a.name} {list(a.shape)}" + (" (or None)" if a.nullable else "") for a in inputs]
                        + [f"out {a.name} {list(a.shape)}" for a in outputs]
                        + (["out status (int: 0 solved, 1 not converged, 2 bad input)"] if status else []))
        calls = tuple(c for c in f.get("calls") or () if isinstance(c, str))
        out.append(Signature(name, f["name"], tuple(inputs), tuple(outputs), status, doc, c.get("lanes") is True, calls))
    lane_wise = {s.cname for s in out if s.lanes}
    out = [dataclasses.replace(s, lanes=s.lanes and all(c in lane_wise for c in s.calls)) for s in out]
    names = [s.cname for s in out]
    for s in out:
        for suffix in ("_batch", "_obj", "_rt_record", "_lanes", "_lanes_batch"):
            if s.cname + suffix in names:
                raise DeriveError(f"robot '{robot}': the generated function {s.cname}{suffix} clashes with the "
                                  f"compiled wrapper of {s.cname}")
    return out


# ---- lane mode: the batch loops evaluate LANES states per call ----

@dataclass(frozen=True)
class Lanes:
    """How the batch loops use the lane mode of the generated C (derive_lanes.h)."""
    count: int                # states per call of a lane function; 0: none, every state by the scalar function
    isa: str                  # "avx512f", "avx2", "sse2", "neon", or "" (none)
    flags: tuple[str, ...]    # the compiler flags of the lane translation units (only those)


LANE_MODES = {"avx512f": Lanes(8, "avx512f", ("-mavx512f",)), "avx2": Lanes(4, "avx2", ("-mavx2",)),
              "sse2": Lanes(2, "sse2", ()), "neon": Lanes(2, "neon", ()), "off": Lanes(0, "", ())}
"""The lane modes by name (``DERIVE_LANES=<name>`` chooses one). avx512f and avx2 compute sin and
cos by derive_lanes.h's inline kernel and call glibc's libmvec for the other elementary functions
(within a few ulp of <math.h>); sse2 and
neon call <math.h> once per lane, so their results are the scalar function's bit for bit."""


def _cpu_flags() -> set[str]:
    """The CPU's feature flags from /proc/cpuinfo (Linux), or an empty set."""
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith("flags"):
                    return set(line.partition(":")[2].split())
    except OSError:
        pass
    return set()


def host_lanes() -> Lanes:
    """The lane mode for this machine: ``$DERIVE_LANES`` (auto, off, avx512f, avx2, sse2 or neon),
    else the widest the CPU has: AVX-512F 8 doubles, AVX2 4, any other x86-64 (SSE2) or
    AArch64 (NEON) 2; off elsewhere."""
    choice = os.environ.get("DERIVE_LANES", "").strip().lower()
    if choice in ("", "auto"):
        machine = platform.machine().lower()
        if machine in ("x86_64", "amd64"):
            cpu = _cpu_flags()
            return LANE_MODES["avx512f" if "avx512f" in cpu else "avx2" if "avx2" in cpu else "sse2"]
        if machine in ("aarch64", "arm64"):
            return LANE_MODES["neon"]
        return LANE_MODES["off"]
    if choice in ("0", "no", "none", "scalar"):
        choice = "off"
    if choice not in LANE_MODES:
        raise DeriveError(f"DERIVE_LANES={choice}: not a lane mode (auto, off, {', '.join(m for m in LANE_MODES if m != 'off')})")
    cpu = _cpu_flags() if choice in ("avx512f", "avx2") else set()
    if cpu and choice not in cpu:  # its instructions would end the process (SIGILL) at the first batch
        raise DeriveError(f"DERIVE_LANES={choice}: this CPU has no {choice} (its flags in /proc/cpuinfo); "
                          "use auto or off")
    return LANE_MODES[choice]


STACK_VECTORS = 512
"""Most vectors (inputs and outputs of one lane call) that a lane batch keeps on the stack (16 KiB
of AVX2 vectors: the Panda's ode_jac_x needs 217); more (a large robot's regressor) on the heap."""


STREAM_SOURCE = r"""
#ifndef DERIVE_RT_STREAM_SOURCE
#define DERIVE_RT_STREAM_SOURCE
/* A batch whose outputs reach DERIVE_RT_STREAM_BYTES is written with non-temporal stores: they
   go to memory by whole cache lines without first reading each line into the caches (a plain
   store reads it: twice the memory traffic), and leave the caches to the inputs. Smaller batches
   keep plain stores, so their results stay in the caches for the caller. */
#ifndef DERIVE_RT_STREAM_BYTES
#define DERIVE_RT_STREAM_BYTES (2L << 20)
#endif
#include <string.h>
/* the lanes of two vectors picked by constant indices (0..L-1: a's, L..2L-1: b's) */
#if defined(__clang__)
#define DERIVE_RT_SHUFFLE(a, b, ...) __builtin_shufflevector(a, b, __VA_ARGS__)
#else
typedef long long derive_rt_index __attribute__((vector_size(sizeof(DERIVE_REAL))));
#define DERIVE_RT_SHUFFLE(a, b, ...) __builtin_shuffle(a, b, (derive_rt_index){__VA_ARGS__})
#endif
/* the non-temporal stores by the compilers' builtins, not <immintrin.h> (a third of a second of
   parsing in each lane unit): a line of 8 doubles as one AVX-512 vector, two AVX or four SSE2 ones */
#if defined(__AVX512F__)
#define DERIVE_RT_NT 8
#elif defined(__AVX__)
#define DERIVE_RT_NT 4
#elif defined(__SSE2__)
#define DERIVE_RT_NT 2
#endif
#ifdef DERIVE_RT_NT
typedef double derive_rt_line __attribute__((vector_size(DERIVE_RT_NT * 8)));
#if defined(__clang__)
#define DERIVE_RT_STREAM(p, v) __builtin_nontemporal_store(v, (derive_rt_line *)(p))
#elif DERIVE_RT_NT == 8
#define DERIVE_RT_STREAM(p, v) __builtin_ia32_movntpd512(p, v)
#elif DERIVE_RT_NT == 4
#define DERIVE_RT_STREAM(p, v) __builtin_ia32_movntpd256(p, v)
#else
#define DERIVE_RT_STREAM(p, v) __builtin_ia32_movntpd(p, v)
#endif
#endif

/* out[0, count) = st[0, count), st 64-byte aligned; with stream, the whole 64-byte lines of out
   by non-temporal stores, the partial first and last lines (shared with the neighbouring block)
   by plain ones */
static void derive_rt_put(double *out, const double *st, long count, int stream)
{
    long k = 0, head = (long)((64 - (uintptr_t)out % 64) % 64 / 8), end;
    if (!stream || (uintptr_t)out % 8 || head > count) {
        memcpy(out, st, (size_t)count * sizeof(double));
        return;
    }
    for (; k < head; ++k)
        out[k] = st[k];
    end = head + (count - head) / 8 * 8;
    for (; k < end; k += 8) {
#ifdef DERIVE_RT_NT
        int c;
        for (c = 0; c < 8; c += DERIVE_RT_NT) {
            derive_rt_line line;
            memcpy(&line, st + k + c, sizeof line);
            DERIVE_RT_STREAM(out + k + c, line);
        }
#else
        memcpy(out + k, st + k, 8 * sizeof(double));
#endif
    }
    for (; k < count; ++k)
        out[k] = st[k];
}

/* the non-temporal stores ordered before the stores that follow (another thread reading the results) */
static void derive_rt_stream_end(void)
{
#ifdef DERIVE_RT_NT
    __builtin_ia32_sfence();
#endif
}
#endif
""".strip("\n").split("\n")


def _transpose(count: int, src: str, dst: str, stride: int) -> list[str]:
    """C lines: the count vectors ``src.format(e)`` (vector e: element e, lane k: state k) transposed in
    registers, row k (state k's count elements) stored to dst + k * stride. log2(count) rounds of
    lane shuffles: round g pairs rows r and r + g (r & g == 0) and swaps their g-lane blocks."""
    rows = [f"t{e}" for e in range(count)]
    out = [f"                const DERIVE_REAL {', '.join(f'{r} = {src.format(e)}' for e, r in enumerate(rows))};"]
    g, step = 1, 0
    while g < count:
        new = list(rows)
        decl = []
        for r in range(count):
            if r & g:
                continue
            lo = [p if not p & g else count + p - g for p in range(count)]   # a[p], or b[p - g] where p & g
            hi = [p + g if not p & g else count + p for p in range(count)]    # a[p + g], or b[p] where p & g
            new[r], new[r + g] = f"s{step}_{r}", f"s{step}_{r + g}"
            decl += [f"{new[r]} = DERIVE_RT_SHUFFLE({rows[r]}, {rows[r + g]}, {', '.join(map(str, lo))})",
                     f"{new[r + g]} = DERIVE_RT_SHUFFLE({rows[r]}, {rows[r + g]}, {', '.join(map(str, hi))})"]
        out += [f"                const DERIVE_REAL {d};" for d in decl]
        rows, g, step = new, g * 2, step + 1
    out += [f"                memcpy({dst} + {k * stride}, &{r}, sizeof {r});" for k, r in enumerate(rows)]
    return out


def lane_source(robot: str, s: Signature, lanes: Lanes) -> str:
    """The translation unit of ``s``'s lane variant: its generated .c compiled with DERIVE_REAL a
    vector of ``lanes.count`` reals, renamed ``<fn>_lanes`` (its callees too), and
    ``<fn>_lanes_batch``: n states in blocks of count, each input element gathered into a vector
    (lane k: state i + k; the last block's missing lanes repeat the last state), one call, the
    outputs transposed back (:func:`_transpose`) and copied out (``derive_rt_put``). So a
    state's results do not depend on where in a batch it is, or whether it is alone (n = 1: the
    one-state path). Returns n, or 0 without memory for the vectors (the caller then loops over
    the scalar function)."""
    ins = [f"const double *a_{a.name}, long s_{a.name}" for a in s.inputs]
    outs = [f"double *r_{a.name}" for a in s.outputs]
    total = sum(a.length for a in s.inputs + s.outputs)
    count = lanes.count
    on_stack = total <= STACK_VECTORS
    out_total = sum(a.length for a in s.outputs)
    widest = max(a.length for a in s.outputs)
    lines = [f"/* Built by derive.runtime for robot '{robot}': {s.cname} in lane mode ({lanes.isa}, {count} states a call). */",
             "#include <stdint.h>",
             "#include <stdlib.h>",
             f"#define DERIVE_LANES {count}",
             '#include "derive_lanes.h"',
             *[f"#define {c} {c}_lanes" for c in (s.cname, *s.calls)],
             f'#include "{s.cname}.c"',
             "",
             *STREAM_SOURCE,
             "",
             f"long {s.cname}_lanes_batch(long n, {', '.join(ins + outs)})",
             "{",
             "    long i;",
             "    int j, k;",
             f"    const int stream = (double)n * {out_total * 8} >= DERIVE_RT_STREAM_BYTES;"]
    if on_stack:
        lines += [f"    DERIVE_REAL v[{total}];",
                  f"    double st[{count * widest}] __attribute__((aligned(64)));  /* one output of a block, state by state */"]
    else:
        lines += [f"    /* {total} vectors, aligned, and one output of a block state by state: on the heap (they would not fit the stack) */",
                  f"    unsigned char *raw = malloc({total} * sizeof(DERIVE_REAL) + sizeof(DERIVE_REAL) + {count * widest} * sizeof(double));",
                  "    DERIVE_REAL *v;",
                  "    double *st;",
                  "    if (!raw)",
                  "        return 0;",
                  "    v = (DERIVE_REAL *)(raw + sizeof(DERIVE_REAL) - (uintptr_t)raw % sizeof(DERIVE_REAL));",
                  f"    st = (double *)(v + {total});"]
    # the states of the block (the last block's missing lanes repeat the last state); each input
    # vector built from its lanes in registers: lane stores into a vector in memory and then one
    # vector load would stall the store forwarding
    lines += [f"    for (i = 0; i < n; i += {count}) {{",
              *[f"        const long at{k} = i + {k} < n ? i + {k} : n - 1;" if k else "        const long at0 = i;"
                for k in range(count)]]
    at = 0
    offsets = {}
    for a in s.inputs + s.outputs:
        offsets[a.name] = at
        at += a.length
    for a in s.inputs:
        lanes_of = ", ".join(f"a_{a.name}[at{k} * s_{a.name} + j]" for k in range(count))
        lines += [f"        for (j = 0; j < {a.length}; ++j)",
                  f"            v[{offsets[a.name]} + j] = (DERIVE_REAL){{{lanes_of}}};"]
    lines.append(f"        {s.cname}_lanes({', '.join(f'v + {offsets[a.name]}' for a in s.inputs + s.outputs)});")
    # a whole block: each output's count * length doubles (contiguous in r_) put together state by
    # state in st (in the L1 cache), then copied out in order (the lanes scattered straight to r_
    # take twice as long); a large batch by cache lines that bypass the caches
    lines.append(f"        if (i + {count} <= n) {{")
    for a in s.outputs:
        lines += [f"            for (j = 0; j + {count} <= {a.length}; j += {count}) {{",
                  *_transpose(count, f"v[{offsets[a.name]} + j + {{}}]", "st + j", a.length),
                  "            }",
                  f"            for (; j < {a.length}; ++j) {{",
                  f"                const DERIVE_REAL t = v[{offsets[a.name]} + j];",
                  *[f"                st[{k * a.length} + j] = t[{k}];" for k in range(count)],
                  "            }",
                  f"            derive_rt_put(r_{a.name} + i * {a.length}, st, {count * a.length}, stream);"]
    lines.append("        } else {")
    for a in s.outputs:
        lines += [f"            for (k = 0; i + k < n; ++k)",
                  f"                for (j = 0; j < {a.length}; ++j)",
                  f"                    r_{a.name}[(i + k) * {a.length} + j] = v[{offsets[a.name]} + j][k];"]
    lines += ["        }", "    }", "    if (stream)", "        derive_rt_stream_end();",
              *([] if on_stack else ["    free(raw);"]), "    return n;", "}"]
    return "\n".join(lines) + "\n"


def lane_sources(robot: str, sigs: list[Signature], lanes: Lanes, snapshot: Snapshot | None = None) -> dict[str, str]:
    """{file name: text} of the lane translation units, one per lane-wise function (none when
    ``lanes.count`` is 0, or the snapshot has no derive_lanes.h: code generated before it)."""
    if not lanes.count or (snapshot is not None and "derive_lanes.h" not in dict(snapshot.sources)):
        return {}
    return {f"{s.cname}_lanes.c": lane_source(robot, s, lanes) for s in sigs
            if s.lanes and not s.status and not any(a.nullable for a in s.inputs)}


# ---- the library's own record, and the wrapper ----

def record(robot: str, manifest: dict, sigs: list[Signature], sources_hash: str | None) -> str:
    """What a library says of itself (JSON): the robot, nq, nv, the model hash, per function its C
    name, input and output lengths and status, and (None for the loader's check, which leaves it
    out) the hash of the sources it was compiled from."""
    data = {"robot": robot, "nq": manifest.get("nq"), "nv": manifest.get("nv"), "model_hash": manifest.get("model_hash"),
            "functions": [[s.cname, [a.length for a in s.inputs], [a.length for a in s.outputs], s.status] for s in sigs]}
    if sources_hash is not None:
        data["sources"] = sources_hash
    return json.dumps(data, sort_keys=True, separators=(",", ":"))


def file_record(lib: Path) -> str | None:
    """The record in the library file ``lib`` (its bytes, without loading it), or None when the
    file is missing, unreadable or holds no single record."""
    try:
        with open(lib, "rb") as f:
            if not stat.S_ISREG(os.fstat(f.fileno()).st_mode):
                return None
            with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as m:
                found = set()
                at = m.find(RECORD_MARK)
                while at >= 0 and len(found) < 2:
                    end = m.find(b"\0", at)
                    if end < 0:
                        return None
                    found.add(m[at + len(RECORD_MARK):end])
                    at = m.find(RECORD_MARK, end)
    except (OSError, ValueError):  # ValueError: an empty file cannot be mapped
        return None
    if len(found) != 1:
        return None
    try:
        return found.pop().decode()
    except UnicodeDecodeError:
        return None


def _bytes_array(data: bytes) -> list[str]:
    """``data`` as the lines of a C array initialiser (numbers: no string-literal length limit)."""
    return ["    " + ", ".join(str(b) for b in data[k:k + 24]) + "," for k in range(0, len(data), 24)]


def wrapper_source(robot: str, sigs: list[Signature], manifest: dict | None = None, rec: str | None = None,
                   lanes: int = 0, lane_wise: frozenset[str] | set[str] = frozenset()) -> str:
    """The C file compiled with the robot's generated code: the batch loops, the one-state fast
    paths and the record ``rec`` (default: :func:`record` of ``manifest``, without a sources hash).
    The batch loops of the functions in ``lane_wise`` (C names) first call their lane variant
    (:func:`lane_source`, ``lanes`` states a call) and loop over the tail it leaves;
    ``<robot>_rt_lanes()`` returns ``lanes``."""
    manifest = manifest or {}
    rec = rec if rec is not None else record(robot, manifest, sigs, None)
    prefix = robot.upper()
    nq, nv = manifest.get("nq"), manifest.get("nv")
    lines = [
        f"/* Built by derive.runtime for robot '{robot}' into the build folder (not part of generated/).",
        " * <robot>_<fn>_batch: the generated function over n states, inputs advancing by their stride",
        " * (their length, or 0 for one value shared by all states), outputs contiguous, row-major.",
        " * <robot>_<fn>_obj: one state, given the addresses of the Python objects; returns 0 (-1 for",
        " * a status) unless each input is a C-contiguous aligned float64 numpy array of exactly the",
        " * state's shape (or a Python float for a length-1 input), so Python falls back to _batch.",
        " * <robot>_rt_record: what this library is (JSON), checked by the loader before any call. */",
        "#include <stddef.h>",
        "#include <stdint.h>",
        f'#include "{robot}.h"',
        "",
        "#ifdef DERIVE_FLOAT",
        "#error derive.compiled calls the generated code with float64 arrays: do not define DERIVE_FLOAT",
        "#endif",
    ]
    if type(nq) is int and type(nv) is int:
        lines += [f"#if !defined({prefix}_NQ) || !defined({prefix}_NV) || {prefix}_NQ != {nq} || {prefix}_NV != {nv}",
                  f"#error derive.compiled: {robot}.h is not the code of this manifest.json (nq {nq}, nv {nv})",
                  "#endif"]
    mark = RECORD_MARK + rec.encode()
    lines += [
        "",
        f"const char {robot}_rt_record_text[{len(mark) + 1}] = {{",
        *_bytes_array(mark + b"\0"),
        "};",
        "",
        f"const char *{robot}_rt_record(void)",
        "{",
        f"    return {robot}_rt_record_text + {len(RECORD_MARK)};",
        "}",
        "",
        "/* The PyObject header of the Python that built this library (its last field is the type), then",
        " * the leading fields of numpy's array object (PyArrayObject_fields: numpy's C ABI, which the",
        " * PyArray_DATA, PyArray_NDIM, PyArray_DIMS, PyArray_DESCR and PyArray_FLAGS macros compiled into",
        " * every numpy extension read directly) and of a Python float (PyFloatObject). The loader checks",
        f" * {robot}_rt_in on known objects before it uses any _obj function. */",
        f"#define DERIVE_RT_HEAD {HEAD}",
        "#define DERIVE_RT_C_CONTIGUOUS_ALIGNED 0x0101",
        "typedef struct { char *data; int nd; intptr_t *dims; intptr_t *strides; void *base; const void *descr; int flags; } derive_rt_array;",
        "static const void *derive_rt_ndarray, *derive_rt_float64, *derive_rt_float;",
        "",
        f"void {robot}_rt_init(const void *ndarray_type, const void *float64_dtype, const void *float_type)",
        "{",
        "    derive_rt_ndarray = ndarray_type;",
        "    derive_rt_float64 = float64_dtype;",
        "    derive_rt_float = float_type;",
        "}",
        "",
        "/* The data of object o if it is one state of shape (d0,) (nd 1) or (d0, d1) (nd 2), else NULL. */",
        f"const DERIVE_REAL *{robot}_rt_in(const void *o, int nd, long d0, long d1)",
        "{",
        "    const void *type = *(const void *const *)((const char *)o + DERIVE_RT_HEAD - sizeof(void *));",
        "    if (type == derive_rt_ndarray) {",
        "        const derive_rt_array *a = (const derive_rt_array *)((const char *)o + DERIVE_RT_HEAD);",
        "        if (a->descr == derive_rt_float64 && a->nd == nd && a->dims[0] == d0 && (nd == 1 || a->dims[1] == d1)",
        "                && (a->flags & DERIVE_RT_C_CONTIGUOUS_ALIGNED) == DERIVE_RT_C_CONTIGUOUS_ALIGNED)",
        "            return (const DERIVE_REAL *)a->data;",
        "        return NULL;",
        "    }",
        "    if (type == derive_rt_float && type != NULL && nd == 1 && d0 == 1)",
        "        return (const DERIVE_REAL *)((const char *)o + DERIVE_RT_HEAD);",
        "    return NULL;",
        "}",
        "",
        "static DERIVE_REAL *derive_rt_out(void *o)",
        "{",
        "    return (DERIVE_REAL *)((derive_rt_array *)((char *)o + DERIVE_RT_HEAD))->data;",
        "}",
        "",
        "/* The data pointer of a numpy array o (the general path's arrays, already converted and checked). */",
        f"void *{robot}_rt_data(void *o)",
        "{",
        "    return derive_rt_out(o);",
        "}",
        "",
        "/* States per call of the lane variants the batch loops use (0: none). */",
        f"int {robot}_rt_lanes(void)",
        "{",
        f"    return {lanes if lane_wise else 0};",
        "}",
    ]
    for s in sigs:
        # C names: a_ (input), s_ (its stride), r_ (output); o_ / ro_ (an input's / output's Python object), d_ (its data)
        ins = [f"const DERIVE_REAL *a_{a.name}, long s_{a.name}" for a in s.inputs]
        outs = [f"DERIVE_REAL *r_{a.name}" for a in s.outputs] + (["int *status"] if s.status else [])
        args = [(f"a_{a.name} ? a_{a.name} + i * s_{a.name} : NULL" if a.nullable else f"a_{a.name} + i * s_{a.name}")
                for a in s.inputs] + [f"r_{a.name} + i * {a.length}" for a in s.outputs]
        call = f"{s.cname}({', '.join(args)})"
        start = "    long i = 0;"
        if s.cname in lane_wise:
            names = [f"a_{a.name}, s_{a.name}" for a in s.inputs] + [f"r_{a.name}" for a in s.outputs]
            decl = [f"const double *a_{a.name}, long s_{a.name}" for a in s.inputs] + [f"double *r_{a.name}" for a in s.outputs]
            lines += ["", f"long {s.cname}_lanes_batch(long n, {', '.join(decl)});"]
            start = f"    long i = {s.cname}_lanes_batch(n, {', '.join(names)});"
        lines += ["", f"void {s.cname}_batch(long n, {', '.join(ins + outs)})", "{", start,
                  "    for (; i < n; ++i)", f"        {'status[i] = ' if s.status else ''}{call};", "}"]
        fail = "-1" if s.status else "0"
        params = [f"const void *o_{a.name}" for a in s.inputs] + [f"void *ro_{a.name}" for a in s.outputs]
        body = []
        for a in s.inputs:
            d1 = a.shape[1] if len(a.shape) == 2 else 0
            get = f"{robot}_rt_in(o_{a.name}, {len(a.shape)}, {a.shape[0]}, {d1})"
            if a.nullable:
                body += [f"    const DERIVE_REAL *d_{a.name} = o_{a.name} ? {get} : NULL;",
                         f"    if (o_{a.name} && !d_{a.name})", f"        return {fail};"]
            else:
                body += [f"    const DERIVE_REAL *d_{a.name} = {get};", f"    if (!d_{a.name})", f"        return {fail};"]
        call = f"{s.cname}({', '.join([f'd_{a.name}' for a in s.inputs] + [f'derive_rt_out(ro_{a.name})' for a in s.outputs])})"
        if s.cname in lane_wise:  # the lane variant, as in a batch: one state's results wherever it is
            pointers = [f"d_{a.name}, 0" for a in s.inputs] + [f"derive_rt_out(ro_{a.name})" for a in s.outputs]
            lanes_call = f"{s.cname}_lanes_batch(1, {', '.join(pointers)})"
            body += [f"    if ({lanes_call})", "        return 1;"]
        body += [f"    return {call};"] if s.status else [f"    {call};", "    return 1;"]
        lines += ["", f"int {s.cname}_obj({', '.join(params)})", "{", *body, "}"]
    return "\n".join(lines) + "\n"


# ---- the compiler ----

_IDENTITY: dict[tuple, str] = {}


def compiler(robot: str) -> list[str]:
    """The compiler command: $CC split like a shell word list, else cc, gcc or clang (the first found)."""
    cc = os.environ.get("CC", "").strip()
    if cc:
        try:
            argv = shlex.split(cc)
        except ValueError:
            argv = [cc]
        if argv and shutil.which(argv[0]):
            return [shutil.which(argv[0])] + argv[1:]
        raise DeriveError(f"cannot compile robot '{robot}': no C compiler found: CC={cc} is not a program "
                          "(set CC or install gcc)")
    for name in ("cc", "gcc", "clang"):
        path = shutil.which(name)
        if path:
            return [path]
    raise DeriveError(f"cannot compile robot '{robot}': no C compiler found: no cc, gcc or clang on PATH (set CC or install gcc)")


def flags(robot: str) -> list[str]:
    """-std=c99 -O2, then $CFLAGS (a later -O wins), then -fPIC."""
    try:
        extra = shlex.split(os.environ.get("CFLAGS", ""))
    except ValueError as exc:
        raise DeriveError(f"cannot compile robot '{robot}': CFLAGS is not a list of shell words ({exc})") from None
    return ["-std=c99", "-O2", *extra, "-fPIC"]


def compiler_identity(argv: list[str]) -> str:
    """The compiler's path, size, mtime and ``--version`` output (memoised per binary)."""
    st = os.stat(argv[0])
    key = (tuple(argv), st.st_size, st.st_mtime_ns)
    if key not in _IDENTITY:
        try:
            r = subprocess.run(argv + ["--version"], capture_output=True, text=True, timeout=60)
            version = r.stdout.strip()
        except (OSError, subprocess.SubprocessError):
            version = ""
        _IDENTITY[key] = json.dumps([list(key[0]), key[1], key[2], version])
    return _IDENTITY[key]


def cache_root() -> Path:
    """$XDG_CACHE_HOME/derive/compiled (an absolute XDG_CACHE_HOME only, as the XDG spec says), else ~/.cache/derive/compiled."""
    base = os.environ.get("XDG_CACHE_HOME", "")
    root = Path(base) if base and os.path.isabs(base) else Path.home() / ".cache"
    return root / "derive" / "compiled"


def content_hash(robot: str, snapshot: Snapshot, wrapper: str, cc: list[str], cflags: list[str],
                 lanes: Lanes = LANE_MODES["off"], units: dict[str, str] | None = None) -> str:
    h = hashlib.sha256()
    h.update(json.dumps({"robot": robot, "compiler": compiler_identity(cc), "flags": cflags, "link": ["-shared", "-lm"]}).encode())
    h.update(b"\0sources\0" + snapshot.sources_hash.encode())
    h.update(b"\0wrapper\0" + wrapper.encode())
    if units:
        h.update(b"\0lanes\0" + json.dumps([lanes.count, lanes.isa, list(lanes.flags)]).encode())
        for name, text in sorted(units.items()):
            h.update(f"\0{name}\0".encode() + text.encode())
    return h.hexdigest()


def _first_error(stderr: str) -> str:
    lines = [ln.strip() for ln in stderr.splitlines() if ln.strip()]
    for ln in lines:
        if re.search(r"\berror\b", ln, re.IGNORECASE):
            return ln[:400]
    return (lines[0][:400] if lines else "no message")


def run_compiler(argv: list[str], robot: str, copy: Path | None = None, origin: Path | None = None) -> None:
    """Run the compiler; a failure is one line, the copy's paths (``copy``) named as the originals'."""
    try:
        r = subprocess.run(argv, capture_output=True, text=True)
    except OSError as exc:
        raise DeriveError(f"cannot compile robot '{robot}': {argv[0]}: {exc.strerror or exc}") from None
    if r.returncode != 0:
        message = _first_error(r.stderr + r.stdout)
        if copy is not None and origin is not None:
            message = message.replace(f"{copy}{os.sep}", f"{origin}{os.sep}")
        raise DeriveError(f"cannot compile robot '{robot}': {message}")


# ---- locks and the temporary folders of builds ----

@contextlib.contextmanager
def _lock(root: Path, digest: str, wait: bool = True) -> Iterator[bool | None]:
    """Hold the advisory lock of builds of ``digest``: yields True once held (waiting for it when
    ``wait``), False when another process holds it (``wait`` False), None where the file system
    has no flock (then nothing is serialised and no temporary folder is judged dead).

    The lock file ``.<digest>.lock`` is removed by its holder on release (before unlocking); a
    waiter that then holds a removed file takes the new one, so none is left behind."""
    path = root / f".{digest}.lock"
    flags_ = os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
    while True:
        try:
            fd = os.open(path, flags_, 0o666)
        except OSError:
            yield None
            return
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
        except BlockingIOError:
            os.close(fd)
            yield False
            return
        except OSError:  # ENOLCK, EOPNOTSUPP: no locks here
            os.close(fd)
            yield None
            return
        except BaseException:  # KeyboardInterrupt while waiting
            os.close(fd)
            raise
        try:
            st, mine = os.stat(path, follow_symlinks=False), os.fstat(fd)
            held = (st.st_dev, st.st_ino) == (mine.st_dev, mine.st_ino)
        except OSError:
            held = False
        if held:
            break
        os.close(fd)  # its holder removed it as we waited: the lock is the file now there
    register(path, False)  # a signal handler ending the process at once removes it too
    try:
        yield True
    finally:
        with contextlib.suppress(OSError):
            os.unlink(path)
        forget(path)
        os.close(fd)


_TEMPORARY = re.compile(r"^\.(?P<digest>[0-9a-f]{64})\.tmp-")
_LOCK_FILE = re.compile(r"^\.(?P<digest>[0-9a-f]{64})\.lock$")
_LEGACY = re.compile(r"^\.[0-9a-f]{16}\.tmp-")


def _remove_stale(root: Path, own: str | None) -> None:
    """Remove what dead builds left in the cache: temporary folders (``own``'s, whose lock the
    caller holds, and any other whose lock is free) and lock files nobody holds. Never raises."""
    try:
        entries = list(os.scandir(root))
    except OSError:
        return
    now = time.time()
    for entry in entries:
        name = entry.name
        try:
            folder = entry.is_dir(follow_symlinks=False)
        except OSError:
            continue
        m = _TEMPORARY.match(name)
        if m and folder:
            if m["digest"] == own:
                shutil.rmtree(entry.path, ignore_errors=True)
                continue
            with _lock(root, m["digest"], wait=False) as held:
                if held:
                    shutil.rmtree(entry.path, ignore_errors=True)
            continue
        m = _LOCK_FILE.match(name)
        if m and m["digest"] != own:
            with _lock(root, m["digest"], wait=False):
                pass  # held: nobody else had it, and releasing it removed the file
            continue
        if _LEGACY.match(name) and folder:
            with contextlib.suppress(OSError):
                if now - entry.stat(follow_symlinks=False).st_mtime > LEGACY_AGE:
                    shutil.rmtree(entry.path, ignore_errors=True)


# ---- the build ----

def library(robot: str, source: Snapshot | str | Path, sigs: list[Signature]) -> Path:
    """The shared library of ``robot``'s generated C: ``source`` a :class:`Snapshot`, or the c/
    folder (read here). From the cache when the record in its file is the expected one, else
    built (or rebuilt) into it."""
    snap = source if isinstance(source, Snapshot) else read_generated(robot, Path(source).parent)
    cc = compiler(robot)
    cflags = flags(robot)
    lanes = host_lanes()
    units = lane_sources(robot, sigs, lanes, snap)
    expected = record(robot, snap.manifest, sigs, snap.sources_hash)
    lane_wise = {name[:-len("_lanes.c")] for name in units}
    wrapper = wrapper_source(robot, sigs, snap.manifest, expected, lanes.count, lane_wise)
    digest = content_hash(robot, snap, wrapper, cc, cflags, lanes, units)
    # the first build of a big robot takes tens of seconds (panda: ~30 s on one core): say so, once
    files = sum(name.endswith(".c") for name, _ in snap.sources) + 1

    def make(tmp: Path) -> Path:
        return _compile(robot, snap, wrapper, cc, cflags, tmp, f"lib{robot}.so", lanes, units)

    return cached_library(robot, digest, f"lib{robot}.so", expected, make, f"{files} C files")


def cached_library(robot: str, digest: str, name: str, expected: str, make, what: str) -> Path:
    """The library file ``name`` in the cache folder ``digest`` (:func:`cache_root`): the present
    one when the record in its file (:func:`file_record`) is ``expected``, else built by
    ``make(tmp)`` (which compiles into the temporary folder ``tmp`` and returns the library's path
    there) under the digest's lock and renamed into place in one step (see the module's
    docstring). ``what`` says what is compiled in the one progress line a build prints (a cache
    hit prints nothing). Used by the CPU library and by :mod:`derive.runtime.cuda`."""
    root = cache_root()
    final = root / digest
    lib = final / name
    if file_record(lib) == expected:
        return lib
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DeriveError(f"cannot compile robot '{robot}': cannot write the build cache {root} ({exc.strerror or exc})") from None
    with _lock(root, digest) as held:
        if file_record(lib) == expected:  # built by the process we waited for
            return lib
        _remove_stale(root, digest if held else None)
        print(f"derive: compiling {robot} ({what}, once; cached in {root}) ...", file=sys.stderr, flush=True)
        start = time.perf_counter()
        _install(robot, final, lib, expected, bool(held), make)
        print(f"derive: compiled {robot} in {time.perf_counter() - start:.1f} s (cached: later calls load it at once)",
              file=sys.stderr, flush=True)
    return lib


def _compile(robot: str, snap: Snapshot, wrapper: str, cc: list[str], cflags: list[str], tmp: Path, name: str,
             lanes: Lanes = LANE_MODES["off"], units: dict[str, str] | None = None) -> Path:
    """Compile ``snap``'s sources (a copy of their bytes) with the wrapper and the lane units in
    ``tmp``; the library's path there."""
    cdir = snap.folder / "c"
    copy = tmp / "src"
    copy.mkdir()
    for fname, data in snap.sources:
        (copy / fname).write_bytes(data)
    src = tmp / f"{robot}_runtime.c"
    src.write_text(wrapper)
    files = {copy / fname: data for fname, data in snap.sources if fname.endswith(".c")}
    sources = translation_units(files, tmp) + [src]
    jobs = [cc + cflags + [f"-I{copy}", "-c", str(s)] for s in sources]
    lane_files = {}
    for fname, text in sorted((units or {}).items()):  # the lane variants: only these get the ISA's flags
        (tmp / fname).write_text(text)
        lane_files[tmp / fname] = text.encode()
    # a lane unit renames its function (and callees) to <fn>_lanes by #define, for the rest of its
    # translation unit: harmless to the lane units after it, which rename the same way
    for unit in translation_units(lane_files, tmp, name="lanes_unit", judge=files):
        sources.append(unit)
        jobs.append(cc + cflags + list(lanes.flags) + [f"-I{copy}", "-c", str(unit)])
    objects = [tmp / f"{k:03d}_{s.stem}.o" for k, s in enumerate(sources)]
    jobs = [job + ["-o", str(o)] for job, o in zip(jobs, objects)]
    run_parallel(jobs, robot, copy, cdir)
    built = tmp / name
    run_compiler(cc + cflags + ["-shared", "-o", str(built)] + [str(o) for o in objects] + ["-lm"], robot, copy, cdir)
    for o in objects:
        o.unlink()
    shutil.rmtree(copy)
    return built


_STATIC = re.compile(rb"^static\b[^;{(=]*?\b(\w+)\s*[(\[=;]", re.MULTILINE)
_MACRO = re.compile(rb"^\s*#\s*(define|undef)\b", re.MULTILINE)


def translation_units(sources: dict[Path, bytes], tmp: Path, parts: int | None = None, name: str = "unit",
                      judge: dict[Path, bytes] | None = None) -> list[Path]:
    """``sources`` ({path: its bytes}) as ``parts`` translation units, one per CPU by default (``tmp/<name>_<k>.c``, each
    including its share of the files, balanced by size, in their order): the compiler then reads the
    robot's headers once per unit, not once per file, at the same parallelism (a Panda's 48 files at
    -O0: 2.1 s of CPU, not 3.7; the whole library with its 40 lane variants 8.0 s, not 10.3). Safe
    for what derive writes: a file-scope static carries its function's name, the headers have include
    guards, no .c file defines a macro. A set of files that breaks that (an edited file: a #define, or
    a static name in two files) is compiled file by file, as are no more files than parts. ``judge``:
    the files whose statics and macros decide, if not ``sources`` themselves (the lane variants: the
    generated files they include)."""
    paths = list(sources)
    parts = max(1, parts or os.cpu_count() or 1)
    judge = sources if judge is None else judge
    statics = [static for data in judge.values() for static in set(_STATIC.findall(data))]
    if (len(paths) <= parts or len(statics) != len(set(statics))
            or any(_MACRO.search(data) for data in judge.values())):
        return paths
    sizes = [len(sources[p]) for p in paths]
    load, shares = [0] * parts, [[] for _ in range(parts)]
    for k in sorted(range(len(paths)), key=lambda k: (-sizes[k], k)):  # largest first, to the lightest unit
        j = min(range(parts), key=lambda j: (load[j], j))
        load[j] += sizes[k]
        shares[j].append(k)
    units = []
    for j, share in enumerate(shares):
        unit = tmp / f"{name}_{j}.c"
        unit.write_text("".join(f'#include "{paths[k]}"\n' for k in sorted(share)))
        units.append(unit)
    return units


def run_parallel(jobs: list[list[str]], robot: str, copy: Path | None = None, origin: Path | None = None) -> None:
    """Run the compiler commands ``jobs`` on as many threads as there are CPUs; the first failure
    in their order is raised (one line, see :func:`run_compiler`)."""
    if not jobs:
        return
    pool = ThreadPoolExecutor(max_workers=max(1, min(len(jobs), os.cpu_count() or 1)))
    try:
        for future in [pool.submit(run_compiler, job, robot, copy, origin) for job in jobs]:
            future.result()  # the first failure, in source order
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _install(robot: str, final: Path, lib: Path, expected: str, replace: bool, make) -> None:
    """Build with ``make`` in a temporary folder beside ``final`` and rename it into place
    (``replace``: over a present ``final`` whose library is not the expected one; only under the
    digest's lock)."""
    global BUILDS
    root = final.parent
    prefix = f".{final.name}.tmp-"
    try:
        tmp = Path(tempfile.mkdtemp(prefix=prefix, dir=root))
    except OSError as exc:
        raise DeriveError(f"cannot compile robot '{robot}': cannot write the build cache {root} ({exc.strerror or exc})") from None
    register(tmp, True)
    aside = None
    try:
        built = make(tmp)
        if built != tmp / lib.name:
            os.rename(built, tmp / lib.name)
            built = tmp / lib.name
        if file_record(built) != expected:
            raise DeriveError(f"cannot compile robot '{robot}': the library built does not hold its "
                              f"record (do CFLAGS strip its data?)")
        with open(built, "rb") as f:  # on disk before the rename makes it the cache's
            os.fsync(f.fileno())
        os.chmod(tmp, 0o755)
        BUILDS += 1
        if replace and os.path.lexists(final):  # a library that is not what its hash says: replaced
            aside = Path(tempfile.mkdtemp(prefix=prefix, dir=root))
            os.rename(final, aside / "old")
        try:
            os.rename(tmp, final)
        except OSError as exc:
            if exc.errno not in (errno.EEXIST, errno.ENOTEMPTY, errno.EISDIR) or file_record(lib) != expected:
                raise
            shutil.rmtree(tmp, ignore_errors=True)  # a process that takes no lock built the same library first
        forget(tmp)
    except OSError as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        forget(tmp)
        raise DeriveError(f"cannot compile robot '{robot}': {exc.filename or root}: {exc.strerror or exc}") from None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        forget(tmp)
        raise
    finally:
        if aside is not None:
            shutil.rmtree(aside, ignore_errors=True)
