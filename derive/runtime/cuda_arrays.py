"""The Python side of ``derive.compiled(robot, device="cuda")``: device arrays in, kernels launched, arrays out.

The module returned has the robot's functions under their Python names (those chosen with
``functions=``), each taking the inputs of the CPU API plus ``out=`` and ``stream=``:

- **Device arrays** of any library, read without a copy: objects with ``__cuda_array_interface__``
  (CuPy, PyTorch, Numba, this module's :class:`DeviceArray`) or with ``__dlpack__`` on a CUDA
  device (JAX, PyTorch, CuPy). Their dtype chooses the kernel: float64 or float32 (all device
  inputs alike); each may have any strides that give one state stride and one element stride
  (states-major ``(n, 7)``, or elements-major ``x.T`` of a ``(7, n)`` array: the coalesced layout,
  see :mod:`derive.runtime.cuda`). The outputs are allocated like the first device input: a
  ``torch.empty`` on its device for PyTorch, a ``cupy.empty`` for CuPy, else a :class:`DeviceArray`
  (which CuPy, PyTorch and Numba take without a copy through its ``__cuda_array_interface__``), or
  written into ``out=`` (one array, or a tuple for several outputs). The call is asynchronous on
  ``stream`` (an integer handle: ``cupy.cuda.Stream.ptr``, ``torch.cuda.Stream.cuda_stream``;
  default 0, the legacy default stream).
- **Host arrays** (numpy, lists, numbers), as for the CPU: copied to the device, computed, copied
  back; numpy arrays are returned (float64 unless every array input is float32). This is the
  path the tests and the comparison with the CPU take, needing no GPU library in Python.

Inputs shared by every state (``p``, or one ``q`` for many ``qd``) broadcast as on the CPU (stride
0); other batch shapes must be equal. Pointers are checked with ``cudaPointerGetAttributes``
(device or managed memory of the current device) before a launch, so host memory handed as a
device pointer is a one-line error, not a crashed context. Without a CUDA device (or driver) every
call raises :class:`derive.runtime.cuda.NoDevice` in one line; building needs none.

No dependency is added: ctypes calls the library, which holds CUDA's runtime (static), and
PyTorch, CuPy or JAX are used only when the caller's arrays are theirs (never imported here).
"""

from __future__ import annotations

import ctypes
import json
import math
import re
import sys
import types
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from derive.errors import DeriveError
from derive.runtime.build import Argument, Signature, default_generated, read_generated, signatures
from derive.runtime.cuda import PRECISIONS, NoDevice, library, select

_LOADED: dict[tuple[str, str], types.ModuleType] = {}

MEMORY_TYPES = {2: "device", 3: "managed"}
"""cudaPointerAttributes.type values a kernel may read and write."""

DLPACK_CUDA = (2, 13)
"""DLPack device types on a CUDA GPU: kDLCUDA, kDLCUDAManaged."""


def compiled_cuda(robot: str, generated: str | Path | None = None, functions=None) -> types.ModuleType:
    """The CUDA batch functions of ``robot`` (``functions``: their Python names, default all),
    built on first use (nvcc, once; cached) and loaded through ctypes."""
    if not isinstance(robot, str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", robot):
        raise DeriveError(f"derive.compiled: {robot!r} is not a robot name (letters, digits and _, as in models.yaml)")
    folder = Path(generated) if generated is not None else default_generated()
    snap = read_generated(robot, folder / robot)
    sigs = signatures(snap.manifest)
    chosen = select(robot, sigs, functions)
    path, rec = library(robot, snap, sigs, chosen)
    key = (robot, str(path))
    if key not in _LOADED:
        _LOADED[key] = _module(robot, snap.manifest, chosen, path, rec)
    return _LOADED[key]


class _Runtime:
    """The library's host functions (CUDA's runtime inside it), and the device check."""

    def __init__(self, robot: str, path: Path, clib: ctypes.CDLL):
        self.robot, self.path, self.lib = robot, path, clib
        p = f"{robot}_cu"
        c_p, c_int_p = ctypes.c_void_p, ctypes.POINTER(ctypes.c_int)
        spec = {"devices": [c_int_p], "current": [c_int_p], "alloc": [ctypes.POINTER(c_p), ctypes.c_size_t],
                "free": [c_p], "copy": [c_p, c_p, ctypes.c_size_t], "synchronize": [c_p],
                "where": [c_p, c_int_p, c_int_p], "event": [ctypes.POINTER(c_p)], "record_event": [c_p, c_p],
                "elapsed": [ctypes.POINTER(ctypes.c_float), c_p, c_p], "event_free": [c_p],
                "device_name": [ctypes.c_char_p, ctypes.c_int]}
        for name, argtypes in spec.items():
            fn = getattr(clib, f"{p}_{name}")
            fn.argtypes, fn.restype = argtypes, ctypes.c_int
            setattr(self, name, fn)
        for name in ("error_name", "error_text"):
            fn = getattr(clib, f"{p}_{name}")
            fn.argtypes, fn.restype = [ctypes.c_int], ctypes.c_char_p
            setattr(self, name, fn)
        self.ready = False

    def message(self, err: int) -> str:
        return f"{(self.error_name(err) or b'?').decode()}: {(self.error_text(err) or b'?').decode()}"

    def count(self) -> tuple[int, str]:
        """(devices, the reason when none)."""
        n = ctypes.c_int(0)
        err = self.devices(ctypes.byref(n))
        if err:
            return 0, f"cudaGetDeviceCount: {self.message(err)}"
        return n.value, "" if n.value else "cudaGetDeviceCount: 0 devices"

    def require(self) -> None:
        if self.ready:
            return
        n, why = self.count()
        if not n:
            raise NoDevice(f"robot '{self.robot}': no CUDA device ({why}); the CUDA library is built "
                           f"({self.path}) but running it needs an NVIDIA GPU and its driver")
        self.ready = True

    def check(self, err: int, what: str) -> None:
        if err:
            raise DeriveError(f"robot '{self.robot}': {what}: CUDA error {self.message(err)}")

    def device(self) -> int:
        d = ctypes.c_int(0)
        self.check(self.current(ctypes.byref(d)), "cudaGetDevice")
        return d.value


class DeviceArray:
    """An array in CUDA device memory allocated by derive's library (C order): ``shape``, ``dtype``,
    ``get()`` (a numpy copy) and ``__cuda_array_interface__`` (CuPy, PyTorch and Numba take it
    without a copy: ``cupy.asarray(a)``, ``torch.as_tensor(a, device="cuda")``). Freed when
    collected (keep it while a library uses its memory)."""

    def __init__(self, runtime: _Runtime, shape: tuple[int, ...], dtype, stream: int = 0):
        self._rt = runtime
        self.shape = tuple(int(d) for d in shape)
        self.dtype = np.dtype(dtype)
        self.nbytes = math.prod(self.shape) * self.dtype.itemsize
        self.stream = stream
        ptr = ctypes.c_void_p()
        runtime.require()
        runtime.check(runtime.alloc(ctypes.byref(ptr), self.nbytes), f"cudaMalloc of {self.nbytes} bytes")
        self.ptr = ptr.value or 0

    @property
    def __cuda_array_interface__(self) -> dict:
        return {"shape": self.shape, "typestr": self.dtype.str, "data": (self.ptr, False), "version": 3,
                "strides": None, "stream": self.stream or 1}

    def get(self) -> np.ndarray:
        """A numpy copy (after the work on its stream)."""
        out = np.empty(self.shape, self.dtype)
        self._rt.check(self._rt.synchronize(self.stream), "cudaStreamSynchronize")
        self._rt.check(self._rt.copy(out.ctypes.data, self.ptr, self.nbytes), "cudaMemcpy to the host")
        return out

    def __array__(self, dtype=None, copy=None):
        out = self.get()
        return out if dtype is None else out.astype(dtype)

    def __repr__(self) -> str:
        return f"DeviceArray(shape={self.shape}, dtype={self.dtype})"

    def __del__(self):
        ptr, self.ptr = getattr(self, "ptr", 0), 0
        if ptr:
            try:
                self._rt.free(ptr)
            except Exception:  # the interpreter shutting down
                pass


@dataclass
class _View:
    """One array as the kernel sees it: data pointer, shape and strides in elements."""
    ptr: int
    shape: tuple[int, ...]
    strides: tuple[int, ...]
    dtype: np.dtype
    owner: object        # what keeps the memory alive (the array, a DLPack capsule, a DeviceArray)
    device: bool         # on the device already (False: a host array, copied)
    stream: int | None = None  # the producer's stream to wait for (__cuda_array_interface__ v3), if any


# ---- reading the caller's arrays ----

class _DLDevice(ctypes.Structure):
    _fields_ = [("device_type", ctypes.c_int32), ("device_id", ctypes.c_int32)]


class _DLDataType(ctypes.Structure):
    _fields_ = [("code", ctypes.c_uint8), ("bits", ctypes.c_uint8), ("lanes", ctypes.c_uint16)]


class _DLTensor(ctypes.Structure):
    _fields_ = [("data", ctypes.c_void_p), ("device", _DLDevice), ("ndim", ctypes.c_int32), ("dtype", _DLDataType),
                ("shape", ctypes.POINTER(ctypes.c_int64)), ("strides", ctypes.POINTER(ctypes.c_int64)),
                ("byte_offset", ctypes.c_uint64)]


_CAPSULE_POINTER = ctypes.pythonapi.PyCapsule_GetPointer
_CAPSULE_POINTER.argtypes, _CAPSULE_POINTER.restype = [ctypes.py_object, ctypes.c_char_p], ctypes.c_void_p


def _c_strides(shape: tuple[int, ...]) -> tuple[int, ...]:
    out, step = [], 1
    for d in reversed(shape):
        out.append(step)
        step *= max(d, 1)
    return tuple(reversed(out))


def _from_cai(x, where: str) -> _View:
    cai = x.__cuda_array_interface__
    dtype = np.dtype(cai["typestr"])
    shape = tuple(int(d) for d in cai["shape"])
    if cai.get("strides") is None:
        strides = _c_strides(shape)
    else:
        if any(s % dtype.itemsize for s in cai["strides"]):
            raise ValueError(f"{where}: strides {tuple(cai['strides'])} are not whole elements of {dtype}")
        strides = tuple(int(s) // dtype.itemsize for s in cai["strides"])
    if cai.get("mask") is not None:
        raise ValueError(f"{where}: masked device arrays are not read")
    stream = cai.get("stream")
    return _View(int(cai["data"][0] or 0), shape, strides, dtype, x, True, int(stream) if stream else None)


def _from_dlpack(x, where: str, stream: int) -> _View:
    kind, _ = x.__dlpack_device__()
    if int(kind) not in DLPACK_CUDA:
        raise ValueError(f"{where}: DLPack device type {int(kind)} is not a CUDA device (give a CUDA array, or a numpy one)")
    try:
        capsule = x.__dlpack__(stream=stream or 1)  # 1: the legacy default stream, in DLPack's words
    except TypeError:
        capsule = x.__dlpack__()
    address = _CAPSULE_POINTER(capsule, b"dltensor")  # not renamed "used_dltensor": its destructor frees it
    t = _DLTensor.from_address(address)
    code, bits, lanes = t.dtype.code, t.dtype.bits, t.dtype.lanes
    if code != 2 or bits not in (32, 64) or lanes != 1:
        raise TypeError(f"{where}: DLPack dtype (code {code}, {bits} bits, {lanes} lanes) is not float32 or float64")
    dtype = np.dtype(np.float64 if bits == 64 else np.float32)
    shape = tuple(t.shape[k] for k in range(t.ndim))
    strides = tuple(t.strides[k] for k in range(t.ndim)) if t.strides else _c_strides(shape)
    if t.byte_offset % dtype.itemsize:
        raise ValueError(f"{where}: DLPack byte offset {t.byte_offset} is not whole elements")
    return _View((t.data or 0) + t.byte_offset, shape, strides, dtype, (x, capsule), True)


def _flat_stride(shape: tuple[int, ...], strides: tuple[int, ...]) -> int | None:
    """The stride s such that the element of row-major index j is at j * s (dims of size 1 ignored),
    or None when the dims do not flatten to one stride."""
    step, size = None, 1
    for d, st in zip(reversed(shape), reversed(strides)):
        if d == 1:
            continue
        if step is None:
            step = st
        elif st != step * size:
            return None
        size *= d
    return 0 if step is None else step


# ---- the module ----

def _module(robot: str, manifest: dict, chosen: list[Signature], path: Path, rec: str) -> types.ModuleType:
    try:
        clib = ctypes.CDLL(str(path))
    except OSError as exc:
        raise DeriveError(f"robot '{robot}': cannot load {path} ({exc})") from None
    get = getattr(clib, f"{robot}_cu_record", None)
    have = None
    if get is not None:
        get.argtypes, get.restype = [], ctypes.c_char_p
        try:
            have = json.loads(get().decode())
        except (ValueError, UnicodeDecodeError):
            have = None
    if have != json.loads(rec):
        raise DeriveError(f"robot '{robot}': {path} is not the CUDA library of this code (it changed after it was "
                          "checked? call derive.compiled again)")
    rt = _Runtime(robot, path, clib)
    mod = types.ModuleType(f"derive.compiled.{robot}.cuda",
                           f"Robot '{robot}': its generated C as CUDA batch kernels in {path}, called through ctypes.")
    params = manifest.get("parameters") or []
    default_p = np.array([float(p["default"]) for p in params], dtype=np.float64)
    default_p.setflags(write=False)
    mod.ROBOT, mod.NQ, mod.NV = robot, manifest.get("nq"), manifest.get("nv")
    mod.DEVICE = "cuda"
    mod.LIBRARY = path
    mod.PRECISIONS = tuple(PRECISIONS)
    mod.FUNCTIONS = tuple(s.name for s in chosen)
    mod.DEFAULT_P = default_p
    mod.PARAMETERS = {p["name"]: float(p["default"]) for p in params}
    mod.DeviceArray = DeviceArray

    def device_count() -> int:
        """CUDA devices this process sees (0 without a GPU or driver)."""
        return rt.count()[0]

    def to_device(x, dtype=np.float64, stream: int = 0) -> DeviceArray:
        """A host array copied into a new :class:`DeviceArray` of ``dtype`` (float64 or float32)."""
        rt.require()
        host = np.ascontiguousarray(x, dtype=dtype)
        out = DeviceArray(rt, host.shape, host.dtype, stream)
        rt.check(rt.copy(out.ptr, host.ctypes.data, host.nbytes), "cudaMemcpy to the device")
        return out

    def synchronize(stream: int = 0) -> None:
        """Wait for the work queued on ``stream``."""
        rt.require()
        rt.check(rt.synchronize(stream), "cudaStreamSynchronize")

    def empty(shape, dtype=np.float64, stream: int = 0) -> DeviceArray:
        """A new uninitialised :class:`DeviceArray`."""
        return DeviceArray(rt, tuple(shape), dtype, stream)

    def device_name() -> str:
        """The current CUDA device's name."""
        rt.require()
        buf = ctypes.create_string_buffer(256)
        rt.check(rt.device_name(buf, len(buf)), "cudaGetDeviceProperties")
        return buf.value.decode(errors="replace")

    mod.device_count, mod.device_name, mod.to_device, mod.synchronize, mod.empty = \
        device_count, device_name, to_device, synchronize, empty
    mod.runtime = rt
    for s in chosen:
        fn = _bind(robot, s, rt, clib, default_p if params else None)
        fn.__module__ = mod.__name__
        setattr(mod, s.name, fn)
    return mod


def _bind(robot: str, s: Signature, rt: _Runtime, clib, default_p):
    launch = {}
    for dtype, suffix in PRECISIONS.items():
        fn = getattr(clib, f"{s.cname}_cuda_{suffix}")
        fn.argtypes = ([ctypes.c_longlong] + [ctypes.c_void_p, ctypes.c_longlong, ctypes.c_longlong] * (len(s.inputs) + len(s.outputs))
                       + ([ctypes.c_void_p, ctypes.c_longlong] if s.status else []) + [ctypes.c_void_p])
        fn.restype = ctypes.c_int
        launch[np.dtype(dtype)] = fn
    names = [a.name for a in s.inputs]
    defaults = {a.name: None for a in s.inputs if a.nullable}
    if default_p is not None and names and names[-1] == "p":
        defaults["p"] = default_p

    def call(*args, out=None, stream: int = 0, **kwargs):
        values = _arguments(s, names, defaults, args, kwargs)
        return _call(robot, s, rt, launch, values, out, int(stream or 0), default_p)

    call.__name__ = call.__qualname__ = s.name
    call.__doc__ = (s.doc or "") + "\n\nOn the CUDA device: device arrays in (float64 or float32), arrays of the same " \
        "library out (or ``out=``); host arrays in, numpy arrays out. See derive.runtime.cuda_arrays."
    return call


def _arguments(s: Signature, names: list[str], defaults: dict, args: tuple, kwargs: dict) -> list:
    if len(args) > len(names):
        raise TypeError(f"{s.name}() takes {len(names)} arguments ({', '.join(names)}), {len(args)} given")
    values = dict(zip(names, args))
    for k, v in kwargs.items():
        if k not in names:
            raise TypeError(f"{s.name}() got an unexpected argument {k!r}")
        if k in values:
            raise TypeError(f"{s.name}() got argument {k!r} twice")
        values[k] = v
    for name in names:
        if name not in values:
            if name not in defaults:
                raise TypeError(f"{s.name}() missing argument {name!r}")
            values[name] = defaults[name]
    return [values[n] for n in names]


def _view(s: Signature, a: Argument, value, stream: int) -> _View | np.ndarray:
    where = f"{s.name}: {a.name}"
    if hasattr(value, "__cuda_array_interface__"):
        return _from_cai(value, where)
    if hasattr(value, "__dlpack_device__") and hasattr(value, "__dlpack__") and not isinstance(value, np.ndarray):
        kind, _ = value.__dlpack_device__()
        if int(kind) in DLPACK_CUDA:
            return _from_dlpack(value, where, stream)
    try:
        x = np.asarray(value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where} is not an array of numbers ({exc})") from None
    if x.dtype.kind not in "biuf":
        raise TypeError(f"{where} must be real numbers (bool, int or float), got {type(value).__name__} ({x.dtype})")
    return x


def _layout(s: Signature, a: Argument, shape: tuple[int, ...], strides: tuple[int, ...]):
    """(batch shape, state stride, element stride) of an input or output, or a ValueError."""
    k = len(a.shape)
    if len(shape) < k:
        if math.prod(shape) != a.length:
            raise _shape_error(s, a, shape)
        batch, core, core_strides = (), shape, strides
    else:
        if shape[len(shape) - k:] != a.shape:
            raise _shape_error(s, a, shape)
        batch, core, core_strides = shape[:len(shape) - k], shape[len(shape) - k:], strides[len(shape) - k:]
    e = _flat_stride(core, core_strides)
    st = _flat_stride(batch, strides[:len(batch)])
    if e is None or st is None:
        raise ValueError(f"{s.name}: {a.name}: strides {strides} (elements) of shape {shape} are not one state stride "
                         "and one element stride (pass a contiguous array, or the transpose of one)")
    return batch, st, e or 1


def _shape_error(s: Signature, a: Argument, shape) -> ValueError:
    core = ", ".join(str(d) for d in a.shape)
    return ValueError(f"{s.name}: {a.name} must have shape (..., {core}) (one state: {a.length} elements), got shape {tuple(shape)}")


def _check_pointer(rt: _Runtime, s: Signature, name: str, v: _View, device: int) -> None:
    if not v.ptr:
        raise ValueError(f"{s.name}: {name}: a null device pointer")
    kind, dev = ctypes.c_int(0), ctypes.c_int(-1)
    rt.where(v.ptr, ctypes.byref(kind), ctypes.byref(dev))
    if kind.value not in MEMORY_TYPES:
        raise ValueError(f"{s.name}: {name}: its pointer is not CUDA device memory (cudaPointerGetAttributes type "
                         f"{kind.value})")
    if kind.value == 2 and dev.value != device:
        raise ValueError(f"{s.name}: {name} is on CUDA device {dev.value}, the current device is {device} "
                         "(call it with that device current)")


def _allocate(rt: _Runtime, like, shape: tuple[int, ...], dtype: np.dtype, stream: int):
    """An output of ``shape``: in the library of ``like`` (the first device input) when it is a
    PyTorch or CuPy array, else a :class:`DeviceArray`."""
    module = type(like).__module__.split(".")[0] if like is not None else ""
    if module == "torch" and "torch" in sys.modules:
        torch = sys.modules["torch"]
        return torch.empty(shape, dtype=torch.float64 if dtype == np.float64 else torch.float32, device=like.device)
    if module == "cupy" and "cupy" in sys.modules:
        return sys.modules["cupy"].empty(shape, dtype=dtype)
    return DeviceArray(rt, shape, dtype, stream)


def _call(robot: str, s: Signature, rt: _Runtime, launch: dict, values: list, out, stream: int, default_p=None):
    rt.require()
    views = [None if (v is None and a.nullable) else _view(s, a, v, stream) for a, v in zip(s.inputs, values)]
    on_device = [v for v in views if isinstance(v, _View)]
    dtypes = {v.dtype for v in on_device}
    if len(dtypes) > 1:
        raise TypeError(f"{s.name}: the device inputs mix {' and '.join(sorted(str(d) for d in dtypes))} (one precision a call)")
    if dtypes:
        dtype = dtypes.pop()
        if dtype.name not in PRECISIONS:
            raise TypeError(f"{s.name}: device arrays of {dtype} (float64 or float32 only)")
    else:
        arrays = [v for v, given in zip(views, values) if isinstance(v, np.ndarray) and v.ndim and given is not default_p]
        dtype = np.dtype(np.float32) if arrays and all(v.dtype == np.float32 for v in arrays) else np.dtype(np.float64)
    device = rt.device()
    keep = []
    inputs = []  # (view or None, batch shape)
    for a, v in zip(s.inputs, views):
        if v is None:
            inputs.append((None, ()))
            continue
        if isinstance(v, np.ndarray):  # a host array: copied to the device
            host = np.ascontiguousarray(v, dtype=dtype)
            dev = DeviceArray(rt, host.shape, dtype, stream)
            rt.check(rt.copy(dev.ptr, host.ctypes.data, host.nbytes), "cudaMemcpy to the device")
            keep.append(dev)
            v = _View(dev.ptr, host.shape, _c_strides(host.shape), dtype, dev, False)
        elif math.prod(v.shape):
            _check_pointer(rt, s, a.name, v, device)
        if v.stream is not None and v.stream != (stream or 1):  # written on another stream: wait for it
            rt.check(rt.synchronize(v.stream), f"{s.name}: {a.name}: cudaStreamSynchronize of its stream")
        batch, st, e = _layout(s, a, v.shape, v.strides)
        inputs.append(((v, st, e), batch))
    shapes = [b for _, b in inputs if b and math.prod(b) != 1]
    shape = shapes[0] if shapes else next((b for _, b in inputs if b), ())
    for a, (entry, b) in zip(s.inputs, inputs):
        if entry is not None and b and math.prod(b) != 1 and b != shape:
            given = ", ".join(f"{a2.name} {b2}" for a2, (e2, b2) in zip(s.inputs, inputs) if e2 is not None)
            raise ValueError(f"{s.name}: the inputs' batch shapes differ: {given} (equal, or one state for all)")
    n = math.prod(shape)
    argv: list = [n]
    for a, (entry, b) in zip(s.inputs, inputs):
        if entry is None:
            argv += [None, 0, 1]
            continue
        v, st, e = entry
        argv += [v.ptr, st if (b and math.prod(b) != 1) else 0, e]
    host = not on_device and out is None  # host arrays in (and no out=): numpy arrays out
    like = on_device[0].owner if on_device else None
    if isinstance(like, tuple):  # a DLPack input: (array, capsule)
        like = like[0]
    results, out_views = _outputs(rt, s, out, shape, dtype, host, like, stream, device)
    for a, (v, st, e) in zip(s.outputs, out_views):
        argv += [v.ptr, st, e]
    status = None
    if s.status:
        status = DeviceArray(rt, shape, np.intc, stream)
        argv += [status.ptr, 1]
    argv.append(stream or None)
    if n:
        err = launch[dtype](*argv)
        rt.check(err, f"{s.name}: kernel launch ({n} states)")
    del keep
    if host:
        results = [r.get() for r in results]
        if status is not None:
            st_host = status.get()
            results.append(int(st_host) if shape == () else st_host)
    elif status is not None:
        results.append(status)
    return results[0] if len(results) == 1 else tuple(results)


def _outputs(rt: _Runtime, s: Signature, out, shape, dtype, host: bool, like, stream: int, device: int):
    """The output arrays (given ``out=``, or allocated) and their (view, state stride, element stride)."""
    if out is None:
        results = [(DeviceArray(rt, shape + a.shape, dtype, stream) if host else
                    _allocate(rt, like, shape + a.shape, dtype, stream)) for a in s.outputs]
    else:
        results = list(out) if isinstance(out, (tuple, list)) else [out]
        if len(results) != len(s.outputs):
            raise ValueError(f"{s.name}: out= needs {len(s.outputs)} arrays ({', '.join(a.name for a in s.outputs)}), "
                             f"got {len(results)}")
    views = []
    for a, r in zip(s.outputs, results):
        v = _view(s, a, r, stream)
        if not isinstance(v, _View):
            raise TypeError(f"{s.name}: out {a.name} must be a CUDA device array, got {type(r).__name__}")
        if v.dtype != dtype:
            raise TypeError(f"{s.name}: out {a.name} is {v.dtype}, the inputs {dtype}")
        if math.prod(v.shape):
            _check_pointer(rt, s, f"out {a.name}", v, device)
        batch, st, e = _layout(s, a, v.shape, v.strides)
        if batch != shape:
            raise ValueError(f"{s.name}: out {a.name} has shape {v.shape}, the states need {shape + a.shape}")
        views.append((v, st, e))
    return results, views
