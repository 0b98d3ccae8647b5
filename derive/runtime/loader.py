"""``derive.compiled(robot)``: the generated Python module's functions, run by the generated C.

``compiled("panda")`` builds generated/panda/c/ into a shared library on first use (cached by
content, see :mod:`derive.runtime.build`) and returns a module with the functions of
generated/panda/python/panda.py under the same names and signatures (``p=DEFAULT_P`` last for
robots with parameters; IK's ``q0=None, w=None``), returning the same shapes for one state.
Every input also takes any leading batch shape, ``(..., n)`` for a vector and ``(..., r, c)`` for a
matrix, broadcast against the others as numpy does (one p, dt or T for a whole batch is shared,
not copied); the outputs are then ``(..., <shape>)`` (``ik_<frame>``'s status an int array), and
the loop over the states runs in C.

Batches (and single states) of the functions the manifest marks lane-wise run through their SIMD
lane variant where the host has one (``mod.LANES`` states per call, ``mod.LANE_FUNCTIONS``; see
:mod:`derive.runtime.build` and docs/code/lanes.md): equal to the scalar C to about 1e-14 relative
(the lanes' sin and cos are within a few ulp), bit for bit between a batch and its single states.

Why ctypes: it is in the standard library, so this adds no dependency and needs neither Python's
headers nor a build step at install time (cffi, Cython, pybind11 or an extension module each need
one); the library it loads is plain C that knows nothing of Python.

The call overhead, and why the one-state path passes object addresses: through ctypes, the usual
way of passing an array, ``a.ctypes.data`` or ``a.__array_interface__["data"][0]``, costs about
1.3 us per array (it builds a helper object or a dict), so a 3-input function would spend 5 us
finding pointers for 0.3 us of arithmetic. Instead each function first calls its C
``<robot>_<fn>_obj`` with ``id()`` of its arguments (the objects' addresses, valid while the call
holds them) and of freshly ``np.empty``-ed outputs; the C reads the data pointer from numpy's
array struct (numpy's C ABI, the fields the PyArray_DATA/NDIM/DIMS/DESCR/FLAGS macros of every
numpy extension read) after checking the exact type, dtype (the float64 singleton), shape and
C-contiguous/aligned flags, and answers "not mine" otherwise; Python then takes the general path
(``np.asarray``, type and shape checks, broadcasting, ``<robot>_<fn>_batch``). That path is taken for
everything else: lists, other dtypes or byte orders, non-contiguous views, misaligned bytes,
batches; it hands the C only native float64, C-contiguous, aligned copies (or the arrays
themselves where they are that already). Numbers only, as in the generated Python: None for an
input that is not IK's q0 or w, complex numbers, text or objects are a TypeError, a wrong shape a
ValueError, each naming the function and the argument. The library is loaded as
``PyDLL`` for the one-state calls (no GIL release and reacquire around a sub-microsecond call)
and as ``CDLL`` for the batch loops and IK (the GIL is released, so threads can run them in
parallel). Before any ``_obj`` function is used, the loader checks the C's reading of the structs
on known objects (arrays accepted and refused, a float); if any answer is wrong, every call takes
the general path, which is correct, only slower.

Before that, and before any other call into it, the loader compares the library's own record
(``<robot>_rt_record``: robot, nq, nv, model hash, every function's input and output lengths;
see :mod:`derive.runtime.build`) with the module it builds from the manifest: a library that is
not this code is refused in one line, never called.
"""

from __future__ import annotations

import ctypes
import json
import math
import re
import types
from pathlib import Path

import numpy as np

from derive.errors import DeriveError, NotGenerated
from derive.runtime.build import Argument, Signature, default_generated, library, read_generated, record, signatures
from derive.runtime.cuda_arrays import compiled_cuda

_LOADED: dict[tuple[str, str], types.ModuleType] = {}


def compiled(robot: str, generated: str | Path | None = None, device: str = "cpu",
             functions=None) -> types.ModuleType:
    """The compiled functions of ``robot`` from ``<generated>/<robot>/`` (default ./generated).

    Builds the library on first use (seconds) and reuses it from the cache afterwards.
    Raises a one-line :class:`DeriveError` when the robot's generated code is missing, no C
    compiler is found or compiling fails.

    ``device="cuda"``: the same C as CUDA batch kernels (nvcc; FP64 and FP32), called on device
    arrays (:mod:`derive.runtime.cuda_arrays`); ``functions`` (Python names) chooses which are
    compiled (default all; nvcc takes seconds per function). It builds without a GPU; its calls
    then raise :class:`derive.runtime.cuda.NoDevice`.
    """
    if device == "cuda":
        return compiled_cuda(robot, generated, functions)
    if device != "cpu":
        raise DeriveError(f"derive.compiled: device={device!r} is not a device (cpu or cuda)")
    if functions is not None:
        raise DeriveError("derive.compiled: functions= chooses the CUDA kernels (device='cuda'); the CPU library "
                          "holds every function")
    if not isinstance(robot, str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", robot):
        raise DeriveError(f"derive.compiled: {robot!r} is not a robot name (letters, digits and _, as in models.yaml)")
    folder = Path(generated) if generated is not None else default_generated()
    snap = read_generated(robot, folder / robot)
    sigs = signatures(snap.manifest)
    path = library(robot, snap, sigs)
    key = (robot, str(path))
    if key not in _LOADED:
        _LOADED[key] = _module(robot, snap.manifest, sigs, path)
    return _LOADED[key]


def _module(robot: str, manifest: dict, sigs: list[Signature], path: Path) -> types.ModuleType:
    try:
        clib = ctypes.CDLL(str(path))
    except OSError as exc:
        raise DeriveError(f"robot '{robot}': cannot load {path} ({exc})") from None
    _check_record(robot, manifest, sigs, path, clib)
    pylib = ctypes.PyDLL(str(path))  # the same library, already loaded
    fast = _init_fast(robot, pylib)
    mod = types.ModuleType(f"derive.compiled.{robot}",
                           f"Robot '{robot}': its generated C, compiled into {path}, called through ctypes.")
    params = manifest.get("parameters") or []
    default_p = np.array([float(p["default"]) for p in params], dtype=np.float64)
    default_p.setflags(write=False)
    mod.ROBOT = robot
    mod.NQ = manifest.get("nq")
    mod.NV = manifest.get("nv")
    mod.JOINTS = tuple(j["name"] for j in manifest.get("joints", []))
    mod.PARAMETERS = {p["name"]: float(p["default"]) for p in params}
    mod.DEFAULT_P = default_p
    mod.LIBRARY = path
    mod.FAST_PATH = fast
    mod.FUNCTIONS = tuple(s.name for s in sigs)
    mod.LANES, mod.LANE_FUNCTIONS = _lanes(robot, clib, sigs)
    for s in sigs:
        fn = _bind(robot, s, pylib, clib, fast, default_p if params else None)
        fn.__module__ = mod.__name__
        setattr(mod, s.name, fn)
    _aliases(mod, manifest)
    mod.LEFT_OUT = _left_out(robot, mod, manifest)
    return mod


def _aliases(mod: types.ModuleType, manifest: dict) -> None:
    """Every function of a frame with other names (manifest.json's ``aliases``, {alias: frame}) also
    under those names, as the generated Python module and the C header spell them."""
    aliases = manifest.get("aliases")
    if not isinstance(aliases, dict):
        return
    for name in mod.FUNCTIONS:
        for alias, frame in aliases.items():
            if isinstance(frame, str) and name.endswith("_" + frame) and not name.startswith("bundle_"):
                setattr(mod, name[: -len(frame)] + alias, getattr(mod, name))


def _left_out(robot: str, mod: types.ModuleType, manifest: dict) -> tuple[str, ...]:
    """The functions generation left out (manifest.json's ``left_out``), by short name; asking ``mod``
    for one raises :class:`NotGenerated` naming why, not a bare AttributeError."""
    entry = manifest.get("left_out")
    if not isinstance(entry, dict):
        return ()
    prefix = f"{robot}_"
    names = tuple(n[len(prefix):] for n in entry.get("functions", ()) if isinstance(n, str) and n.startswith(prefix))
    reason = entry.get("reason", "see its manifest.json")

    def __getattr__(name: str):
        if name in names:
            raise NotGenerated(f"robot '{robot}': {name} was not generated: {reason} "
                               "(forward dynamics, the ODE and its Jacobians do not exist)")
        raise AttributeError(f"module {mod.__name__!r} has no attribute {name!r}")

    mod.__getattr__ = __getattr__
    return names


def _check_record(robot: str, manifest: dict, sigs: list[Signature], path: Path, lib: ctypes.CDLL) -> None:
    """Before any call into the library: its own record (robot, nq, nv, model hash, every function's
    input and output lengths) must be the module's, else a one-line DeriveError."""
    want = json.loads(record(robot, manifest, sigs, None))
    try:
        get = getattr(lib, f"{robot}_rt_record")
        get.argtypes = []
        get.restype = ctypes.c_char_p
        have = json.loads(get().decode())
        have.pop("sources", None)
    except (AttributeError, ValueError, UnicodeDecodeError):
        have = None
    if have != want:
        if not isinstance(have, dict):
            what = "holds no record of what it is"
        else:
            keys = [k for k in sorted(set(want) | set(have)) if want.get(k) != have.get(k)]
            what = "is not this module's code: " + "; ".join(
                f"{k} {_brief(have.get(k))} in the library, {_brief(want.get(k))} in the manifest" for k in keys)
        raise DeriveError(f"robot '{robot}': {path} {what} (it changed after it was checked? "
                          "call derive.compiled again)")


def _lanes(robot: str, lib: ctypes.CDLL, sigs: list[Signature]) -> tuple[int, tuple[str, ...]]:
    """States per call of the lane variants the batch loops use (0: none) and the functions that
    have one (those the manifest marks lane-wise, when the library was built with lanes)."""
    get = getattr(lib, f"{robot}_rt_lanes", None)
    if get is None:
        return 0, ()
    get.argtypes = []
    get.restype = ctypes.c_int
    count = int(get())
    names = tuple(s.name for s in sigs if count and hasattr(lib, f"{s.cname}_lanes_batch"))
    return count, names


def _brief(value) -> str:
    text = json.dumps(value)
    return text if len(text) <= 60 else f"{text[:57]}..."


def _init_fast(robot: str, lib: ctypes.PyDLL) -> bool:
    """Hand the C the addresses it compares against, then check its reading of numpy's and
    Python's structs on known objects: True when every answer is right."""
    init = getattr(lib, f"{robot}_rt_init")
    init.argtypes = [ctypes.c_void_p] * 3
    init.restype = None
    init(id(np.ndarray), id(np.dtype(np.float64)), id(float))
    probe = getattr(lib, f"{robot}_rt_in")
    probe.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_long, ctypes.c_long]
    probe.restype = ctypes.c_void_p
    vec = np.arange(7.0)
    mat = np.arange(16.0).reshape(4, 4)
    strided = vec[::2]
    ints = np.arange(7)
    swapped = vec.astype(vec.dtype.newbyteorder())
    transposed = mat.T
    listed = [0.0] * 7
    number = 2.5
    accepted = probe(id(vec), 1, 7, 0) == vec.ctypes.data and probe(id(mat), 2, 4, 4) == mat.ctypes.data
    refused = [probe(id(vec), 1, 6, 0), probe(id(mat), 1, 16, 0), probe(id(mat), 2, 4, 3), probe(id(strided), 1, 4, 0),
               probe(id(ints), 1, 7, 0), probe(id(swapped), 1, 7, 0), probe(id(transposed), 2, 4, 4),
               probe(id(listed), 1, 7, 0), probe(id(number), 1, 2, 0)]
    at = probe(id(number), 1, 1, 0)
    data = getattr(lib, f"{robot}_rt_data")
    data.argtypes = [ctypes.c_void_p]
    data.restype = ctypes.c_void_p
    pointers = data(id(vec)) == vec.ctypes.data and data(id(transposed)) == transposed.ctypes.data
    return bool(accepted and not any(refused) and at and ctypes.c_double.from_address(at).value == number and pointers)


def _bind(robot: str, s: Signature, pylib, clib, fast: bool, default_p):
    """The Python function of ``s``: the one-state fast path, then the general path."""
    batch = getattr(clib, f"{s.cname}_batch")
    batch.argtypes = ([ctypes.c_long] + [ctypes.c_void_p, ctypes.c_long] * len(s.inputs)
                      + [ctypes.c_void_p] * (len(s.outputs) + s.status))
    batch.restype = None
    names = [a.name for a in s.inputs]
    signature = []
    for k, a in enumerate(s.inputs):
        if a.nullable:
            signature.append(f"{a.name}=None")
        elif default_p is not None and a.name == "p" and k == len(s.inputs) - 1:
            signature.append("p=DEFAULT_P")
        else:
            signature.append(a.name)
    outs = [f"_o{k}" for k in range(len(s.outputs))]
    lines = [f"def {s.name}({', '.join(signature)}):"]
    if fast:  # the data pointer of a numpy array: 0.2 us through the C, 1.3 us through a.ctypes.data
        data = getattr(pylib, f"{robot}_rt_data")
        data.argtypes = [ctypes.c_void_p]
        data.restype = ctypes.c_void_p
        pointer = lambda x: data(id(x))  # noqa: E731
    else:
        pointer = _pointer
    env = {"_general": _general(s, batch, pointer), "DEFAULT_P": default_p}
    if fast:
        # IK may iterate for milliseconds: that one releases the GIL (it reads the objects first)
        obj = getattr(clib if s.status else pylib, f"{s.cname}_obj")
        obj.argtypes = [ctypes.c_void_p] * (len(s.inputs) + len(s.outputs))
        obj.restype = ctypes.c_int
        env.update(_fast=obj, _empty=np.empty, _id=id)
        ids = [f"None if {a.name} is None else _id({a.name})" if a.nullable else f"_id({a.name})" for a in s.inputs]
        ids += [f"_id({o})" for o in outs]
        lines += [f"    {o} = _empty({a.shape!r})" for o, a in zip(outs, s.outputs)]
        if s.status:
            values = outs + ["_st"]
            lines += [f"    _st = _fast({', '.join(ids)})", "    if _st >= 0:", f"        return {', '.join(values)}"]
        else:
            lines += [f"    if _fast({', '.join(ids)}):", f"        return {', '.join(outs)}"]
    lines.append(f"    return _general({', '.join(names)})")
    try:
        exec(compile("\n".join(lines) + "\n", f"<derive.compiled {robot}>", "exec"), env)
    except SyntaxError as exc:
        raise DeriveError(f"robot '{robot}': function {s.name}: cannot build its Python signature ({exc.msg})") from None
    fn = env[s.name]
    fn.__doc__ = s.doc
    return fn


def _shape_error(s: Signature, a: Argument, x: np.ndarray) -> ValueError:
    core = ", ".join(str(d) for d in a.shape)
    return ValueError(f"{s.name}: {a.name} must have shape (..., {core}) (one state: {a.length} elements), "
                      f"got shape {x.shape}")


REAL_KINDS = "biuf"
"""numpy dtype kinds taken as numbers (bool, signed and unsigned integers, floats), as float64;
anything else (None, complex, text, objects) is a TypeError, not NaN or a dropped imaginary part."""


def _given(value, x: np.ndarray) -> str:
    if value is None:
        return "None"
    if x.dtype.kind == "c":
        return f"complex numbers ({x.dtype})"
    if x.dtype.kind in "USa":
        return f"text ({x.dtype})"
    if x.dtype.kind == "O" and x.ndim:
        return "an array of Python objects (None, or not all numbers?)"
    return f"{type(value).__name__} ({x.dtype})"


def _real(s: Signature, a: Argument, value) -> np.ndarray:
    """``value`` as a float64 array of native byte order; a TypeError or ValueError naming the function and argument."""
    try:
        x = np.asarray(value)
    except (TypeError, ValueError) as exc:  # a ragged list, say
        raise ValueError(f"{s.name}: {a.name} is not an array of numbers ({exc})") from None
    if x.dtype is _FLOAT64:
        return x
    if x.dtype.kind not in REAL_KINDS:
        raise TypeError(f"{s.name}: {a.name} must be real numbers (bool, int or float), got {_given(value, x)}")
    return x.astype(_FLOAT64)  # native byte order too


_FLOAT64 = np.dtype(np.float64)


def _pointer(x: np.ndarray) -> int:
    return x.ctypes.data


def _general(s: Signature, batch, pointer):
    """Any input: numpy conversion, shape checks, broadcasting, then one call of the C batch loop."""
    inputs, outputs = s.inputs, s.outputs

    def general(*args):
        arrays, shapes = [], []
        for a, value in zip(inputs, args):
            if value is None and a.nullable:
                arrays.append(None)
                shapes.append(())
                continue
            x = _real(s, a, value)
            k = len(a.shape)
            if x.ndim < k:  # fewer axes than one state: one state, of any shape with the right size (as the Python)
                if x.size != a.length:
                    raise _shape_error(s, a, x)
                x = x.reshape(a.shape)
            elif x.shape[x.ndim - k:] != a.shape:
                raise _shape_error(s, a, x)
            arrays.append(x)
            shapes.append(x.shape[:x.ndim - k])
        shape = ()
        for sh in shapes:  # the common cases, each batch shape () or the same: without numpy
            if sh and sh != shape:
                if shape:
                    shape = None
                    break
                shape = sh
        try:
            shape = np.broadcast_shapes(*shapes) if shape is None else shape
        except ValueError:
            given = ", ".join(f"{a.name} {sh}" for a, sh, x in zip(inputs, shapes, arrays) if x is not None)
            raise ValueError(f"{s.name}: the inputs' batch shapes do not broadcast together: {given}") from None
        n = math.prod(shape)
        argv: list = [n]
        keep = []
        for a, x, sh in zip(inputs, arrays, shapes):
            if x is None:
                argv += [None, 0]
                continue
            if math.prod(sh) == 1:  # one value for every state: stride 0
                x, stride = x.reshape(a.shape), 0
            elif sh == shape:
                stride = a.length
            else:
                x, stride = np.broadcast_to(x, shape + a.shape), a.length
            flags = x.flags
            if not (flags.c_contiguous and flags.aligned):  # a view, or misaligned bytes (np.frombuffer)
                x = np.array(x, order="C")
            keep.append(x)
            argv += [pointer(x), stride]
        results = [np.empty(shape + a.shape) for a in outputs]
        if s.status:
            results.append(np.empty(shape, dtype=np.intc))
        batch(*argv, *[pointer(r) for r in results])
        del keep
        if s.status and shape == ():
            results[-1] = int(results[-1])
        return results[0] if len(results) == 1 else tuple(results)

    return general
