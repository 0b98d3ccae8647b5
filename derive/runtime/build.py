"""Build a robot's generated C into one shared library, cached by content.

- :func:`signatures` reads generated/<robot>/manifest.json into one :class:`Signature` per function.
- :func:`wrapper_source` writes the small C file compiled beside the generated code (in the build
  folder, never in generated/): per function ``<robot>_<fn>_batch``, the loop over n states with
  one stride per input (its length, or 0 to broadcast one value such as p), and
  ``<robot>_<fn>_obj``, the one-state fast path that :mod:`derive.runtime.loader` calls with the
  addresses of the Python objects themselves (see there for why).
- :func:`library` returns ``$XDG_CACHE_HOME/derive/compiled/<hash>/lib<robot>.so`` (default
  ~/.cache/derive/compiled/), the hash being the sha256 of the C sources, the wrapper, the compiler
  (its path and ``--version``) and the flags. A present folder is reused as it is; a missing one is
  built in a temporary folder beside it and renamed into place in one step, so two processes
  building at once each finish with a complete library (the first rename wins, the other build is
  discarded).

The compiler is ``$CC`` (else cc, gcc or clang, the first found); the flags are
``-std=c99 -O2 $CFLAGS -fPIC``, linked with ``-shared ... -lm``.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import re
import shlex
import shutil
import subprocess
import tempfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from derive.codegen.generate import process_alive
from derive.errors import DeriveError

BUILDS = 0
"""Libraries built by this process (a cache hit builds none)."""

HEAD = object.__basicsize__
"""sizeof(PyObject) of this Python (16 on a standard 64-bit build): where an object's own fields start."""


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


def _python_name(name: str, what: str) -> str:
    if not name.isidentifier() or name.startswith("_") or name in {"def", "return", "if", "else", "None", "lambda"}:
        raise DeriveError(f"manifest: {what} '{name}' is not usable as a Python name")
    return name


def signatures(manifest: dict) -> list[Signature]:
    """The functions of a robot's manifest.json, checked for consistency between its C and Python entries."""
    out = []
    robot = manifest.get("robot", "?")
    for f in manifest.get("functions", []):
        c, py = f["c"], f["python"]
        where = f"robot '{robot}': manifest: function {f['name']}"
        if len(c["reads"]) != len(f["inputs"]):
            raise DeriveError(f"{where}: {len(c['reads'])} C inputs for {len(f['inputs'])} inputs")
        inputs = []
        for spec, read in zip(f["inputs"], c["reads"]):
            rows, cols = spec["shape"]
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
            shape = tuple(int(d) for d in ret["shape"])
            size = 1
            for d in shape:
                size *= d
            if size != write["length"]:
                raise DeriveError(f"{where}: output {ret['name']} has shape {shape} but is {write['length']} long in C")
            outputs.append(Argument(_python_name(ret["name"], "output"), shape, write["length"]))
        name = _python_name(py["function"], "function")
        if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", f["name"]):
            raise DeriveError(f"{where}: not a C identifier")
        doc = "\n".join([f"{f['name']} of the generated C, compiled; inputs take any leading batch shape.", ""]
                        + [f"in  {a.name} {list(a.shape)}" + (" (or None)" if a.nullable else "") for a in inputs]
                        + [f"out {a.name} {list(a.shape)}" for a in outputs]
                        + (["out status (int: 0 solved, 1 not converged, 2 bad input)"] if status else []))
        out.append(Signature(name, f["name"], tuple(inputs), tuple(outputs), status, doc))
    names = [s.cname for s in out]
    for s in out:
        for suffix in ("_batch", "_obj"):
            if s.cname + suffix in names:
                raise DeriveError(f"robot '{robot}': the generated function {s.cname}{suffix} clashes with the "
                                  f"compiled wrapper of {s.cname}")
    return out


def wrapper_source(robot: str, sigs: list[Signature]) -> str:
    """The C file compiled with the robot's generated code: the batch loops and the one-state fast paths."""
    lines = [
        f"/* Built by derive.runtime for robot '{robot}' into the build folder (not part of generated/).",
        " * <robot>_<fn>_batch: the generated function over n states, inputs advancing by their stride",
        " * (their length, or 0 for one value shared by all states), outputs contiguous, row-major.",
        " * <robot>_<fn>_obj: one state, given the addresses of the Python objects; returns 0 (-1 for",
        " * a status) unless each input is a C-contiguous aligned float64 numpy array of exactly the",
        " * state's shape (or a Python float for a length-1 input), so Python falls back to _batch. */",
        "#include <stddef.h>",
        "#include <stdint.h>",
        f'#include "{robot}.h"',
        "",
        "#ifdef DERIVE_FLOAT",
        "#error derive.compiled calls the generated code with float64 arrays: do not define DERIVE_FLOAT",
        "#endif",
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
    ]
    for s in sigs:
        # C names: a_ (input), s_ (its stride), r_ (output); o_ / ro_ (an input's / output's Python object), d_ (its data)
        ins = [f"const DERIVE_REAL *a_{a.name}, long s_{a.name}" for a in s.inputs]
        outs = [f"DERIVE_REAL *r_{a.name}" for a in s.outputs] + (["int *status"] if s.status else [])
        args = [(f"a_{a.name} ? a_{a.name} + i * s_{a.name} : NULL" if a.nullable else f"a_{a.name} + i * s_{a.name}")
                for a in s.inputs] + [f"r_{a.name} + i * {a.length}" for a in s.outputs]
        call = f"{s.cname}({', '.join(args)})"
        lines += ["", f"void {s.cname}_batch(long n, {', '.join(ins + outs)})", "{", "    long i;",
                  "    for (i = 0; i < n; ++i)", f"        {'status[i] = ' if s.status else ''}{call};", "}"]
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


def content_hash(robot: str, cdir: Path, wrapper: str, cc: list[str], cflags: list[str]) -> str:
    h = hashlib.sha256()
    h.update(json.dumps({"robot": robot, "compiler": compiler_identity(cc), "flags": cflags, "link": ["-shared", "-lm"]}).encode())
    for path in sorted(cdir.iterdir()):
        if path.suffix in (".c", ".h") and path.is_file():
            h.update(f"\0{path.name}\0".encode())
            h.update(path.read_bytes())
    h.update(b"\0wrapper\0" + wrapper.encode())
    return h.hexdigest()


def _first_error(stderr: str) -> str:
    lines = [ln.strip() for ln in stderr.splitlines() if ln.strip()]
    for ln in lines:
        if re.search(r"\berror\b", ln, re.IGNORECASE):
            return ln[:400]
    return (lines[0][:400] if lines else "no message")


def _run(argv: list[str], robot: str) -> None:
    try:
        r = subprocess.run(argv, capture_output=True, text=True)
    except OSError as exc:
        raise DeriveError(f"cannot compile robot '{robot}': {argv[0]}: {exc.strerror or exc}") from None
    if r.returncode != 0:
        raise DeriveError(f"cannot compile robot '{robot}': {_first_error(r.stderr + r.stdout)}")


_STALE = re.compile(r"^\.[0-9a-f]+\.tmp-(?P<pid>\d+)-")


def _remove_stale(root: Path) -> None:
    """Remove the temporary folders of builds whose process is gone."""
    for entry in root.iterdir():
        m = _STALE.match(entry.name)
        if not m or not entry.is_dir():
            continue
        if not process_alive(int(m["pid"])):
            shutil.rmtree(entry, ignore_errors=True)


def library(robot: str, cdir: Path, sigs: list[Signature]) -> Path:
    """The shared library of ``robot``'s generated C in ``cdir``: from the cache, or built into it."""
    global BUILDS
    cc = compiler(robot)
    cflags = flags(robot)
    wrapper = wrapper_source(robot, sigs)
    root = cache_root()
    digest = content_hash(robot, cdir, wrapper, cc, cflags)
    final = root / digest
    lib = final / f"lib{robot}.so"
    if lib.is_file():
        return lib
    try:
        root.mkdir(parents=True, exist_ok=True)
        _remove_stale(root)
        tmp = Path(tempfile.mkdtemp(prefix=f".{digest[:16]}.tmp-{os.getpid()}-", dir=root))
    except OSError as exc:
        raise DeriveError(f"cannot compile robot '{robot}': cannot write the build cache {root} ({exc.strerror or exc})") from None
    try:
        src = tmp / f"{robot}_runtime.c"
        src.write_text(wrapper)
        sources = sorted(cdir.glob("*.c")) + [src]
        objects = [tmp / f"{k:03d}_{s.stem}.o" for k, s in enumerate(sources)]
        jobs = [cc + cflags + [f"-I{cdir}", "-c", str(s), "-o", str(o)] for s, o in zip(sources, objects)]
        pool = ThreadPoolExecutor(max_workers=max(1, min(len(jobs), os.cpu_count() or 1)))
        try:
            for future in [pool.submit(_run, job, robot) for job in jobs]:
                future.result()  # the first failure, in source order
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
        _run(cc + cflags + ["-shared", "-o", str(tmp / lib.name)] + [str(o) for o in objects] + ["-lm"], robot)
        for o in objects:
            o.unlink()
        os.chmod(tmp, 0o755)
        BUILDS += 1
        try:
            os.rename(tmp, final)
        except OSError as exc:
            if exc.errno not in (errno.EEXIST, errno.ENOTEMPTY) or not lib.is_file():
                raise
            shutil.rmtree(tmp, ignore_errors=True)  # another process built the same library first
    except OSError as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        raise DeriveError(f"cannot compile robot '{robot}': {exc.filename or root}: {exc.strerror or exc}") from None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return lib
