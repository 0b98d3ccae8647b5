"""derive.compiled(robot, device="cuda"): the generated C as CUDA batch kernels (derive/runtime/cuda.py).

Without a GPU (CI): the library builds with nvcc (compile and link, FP64 and FP32), exports a
launcher per chosen function and precision and its host functions, holds its record, is cached
like the CPU library, and a call says "no CUDA device" in one line. With a GPU: its results
equal the CPU library's (FP64 to 1e-12 relative, FP32 to 1e-4), for host arrays, device arrays
in both layouts and broadcast parameters. nvcc is found as in tests/test_cuda.py (PATH or the
`cuda` extra, which `make test` installs; missing in CI is a failure).

nvcc time (2 shared cores, measured): planar_2r's 5 functions ~8 s CPU, Panda's inverse dynamics ~6 s.
"""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest

import derive
from derive.errors import DeriveError
from derive.runtime import build, cuda

ROOT = Path(__file__).resolve().parent.parent
SMALL = ("inverse_dynamics", "mass_matrix", "forward_dynamics", "ode_jac_x", "ik_tcp")
INPUTS = {"inverse_dynamics": ("q", "qd", "qdd"), "mass_matrix": ("q",), "forward_dynamics": ("q", "qd", "tau"),
          "ode_jac_x": ("x", "u"), "ode_rhs": ("x", "u"), "rk4_step": ("x", "u", "dt")}
EMULATED = SMALL + ("ode_rhs", "rk4_step")  # rk4_step calls ode_rhs: in two units of one precision (chunks)
PANDA = ("inverse_dynamics",)


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    """A cache of this module's own, so the CUDA libraries are built here (not found built); the CPU
    libraries the results are compared with come from the usual cache."""
    if cuda.find_nvcc() is None:
        if os.environ.get("CI"):
            pytest.fail("nvcc not found: the `cuda` extra (nvidia-cuda-nvcc) should be installed by `make test`")
        pytest.skip("no nvcc: install the CUDA toolkit or `pip install derive-robotics[cuda]`")
    return tmp_path_factory.mktemp("xdg")


@contextlib.contextmanager
def cached_in(root: Path):
    old = os.environ.get("XDG_CACHE_HOME")
    os.environ["XDG_CACHE_HOME"] = str(root)
    try:
        yield
    finally:
        if old is None:
            os.environ.pop("XDG_CACHE_HOME")
        else:
            os.environ["XDG_CACHE_HOME"] = old


def cuda_compiled(root: Path, robot: str, functions):
    with cached_in(root):
        return derive.compiled(robot, device="cuda", functions=functions)


@pytest.fixture(scope="module")
def small(cache):
    builds = build.BUILDS
    mod = cuda_compiled(cache, "planar_2r", SMALL)
    assert build.BUILDS == builds + 1
    return mod


@pytest.fixture(scope="module")
def panda(cache):
    return cuda_compiled(cache, "panda", PANDA)


def defined_symbols(lib: Path) -> set[str]:
    out = subprocess.run(["nm", "-D", "--defined-only", str(lib)], capture_output=True, text=True, check=True).stdout
    return {line.split()[-1] for line in out.splitlines() if line.strip()}


@pytest.mark.parametrize("which", ["small", "panda"])
def test_the_library_exports_a_launcher_per_function_and_precision(which, request):
    mod = request.getfixturevalue(which)
    robot, names = ("planar_2r", SMALL) if which == "small" else ("panda", PANDA)
    assert mod.LIBRARY.name == f"lib{robot}_cuda.so" and mod.LIBRARY.is_file()
    assert set(mod.FUNCTIONS) == set(names) and mod.PRECISIONS == ("float64", "float32")
    symbols = defined_symbols(mod.LIBRARY)
    launchers = {s for s in symbols if s.startswith(f"{robot}_") and "_cuda_f" in s}
    assert launchers == {f"{robot}_{n}_cuda_{p}" for n in names for p in ("f64", "f32")}
    host = {"record", "devices", "error_name", "error_text", "current", "alloc", "free", "copy", "synchronize",
            "where", "event", "record_event", "elapsed", "event_free"}
    assert {f"{robot}_cu_{h}" for h in host} <= symbols
    # the record the cache checks: the CPU record of these functions, the device and the precisions
    rec = json.loads(build.file_record(mod.LIBRARY))
    manifest = json.loads((ROOT / "generated" / robot / "manifest.json").read_text())
    assert rec["device"] == "cuda" and rec["precisions"] == ["float64", "float32"]
    assert rec["model_hash"] == manifest["model_hash"] and rec["nq"] == manifest["nq"]
    assert [f[0] for f in rec["functions"]] == [f"{robot}_{n}" for n in mod.FUNCTIONS]


def test_second_call_is_the_cached_library(small, cache):
    builds = build.BUILDS
    again = cuda_compiled(cache, "planar_2r", list(reversed(SMALL)))
    assert again is small and build.BUILDS == builds


def test_kernel_source_gathers_and_scatters_by_two_strides(small):
    """The unit's kernel reads element j of state i at a[i*s + j*e] and IK's nullable inputs as NULL;
    a states-major output goes through the warp's shared memory."""
    units = sorted(small.LIBRARY.parent.glob("planar_2r_cuda_f64*.cu"))  # one per group of functions (CPUs)
    text = "".join(u.read_text() for u in units)
    assert units and "#define DERIVE_FN __device__" in text and "DERIVE_FLOAT" not in text
    assert "li_q[j] = a_q[i * s_q + j * e_q];" in text
    assert "r_tau[i * rs_tau + j * re_tau] = lo_tau[j];" in text
    # states-major outputs staged per warp in shared memory, written as one run (blocks of 64)
    assert "__shared__ DERIVE_REAL derive_cu_stage[2][1568];" in text and "if (rs_tau == 2 && re_tau == 1) {" in text
    assert "stage[(lane - r0) * 2 + j] = lo_tau[j];" in text and "__syncwarp(active);" in text
    assert "const int block = 64;" in text
    assert "st_status[i * st_stride] = planar_2r_ik_tcp(" in text and "a_w ? li_w : 0" in text
    assert all("#define DERIVE_FLOAT" in u.read_text() for u in small.LIBRARY.parent.glob("planar_2r_cuda_f32*.cu"))


NO_DEVICE = r"""
import sys, numpy as np, derive
from derive.runtime.cuda import NoDevice
m = derive.compiled("planar_2r", device="cuda", functions=sys.argv[1].split(","))
print(m.device_count())
try:
    m.inverse_dynamics(np.zeros(2), np.zeros(2), np.zeros(2))
except NoDevice as exc:
    print(exc)
"""


def test_without_a_device_a_call_is_one_line_no_cuda_device(small, cache):
    """CUDA_VISIBLE_DEVICES="" hides any GPU, so this runs alike on a machine with one."""
    # hidden GPUs make `native` mean the default architecture: name the one `small` was built for
    arch = os.environ.get("DERIVE_CUDA_ARCH", "").strip() or \
        ",".join(f"sm_{a}" for a in cuda.device_architectures(cuda.find_nvcc()[0])) or cuda.ARCH_DEFAULT
    env = {**os.environ, "CUDA_VISIBLE_DEVICES": "", "PYTHONPATH": str(ROOT), "XDG_CACHE_HOME": str(cache),
           "DERIVE_CUDA_ARCH": arch}
    r = subprocess.run([sys.executable, "-c", NO_DEVICE, ",".join(SMALL)], capture_output=True, text=True, env=env,
                       cwd=ROOT, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "compiling" not in r.stderr, r.stderr  # the library the test built, from the cache
    count, message = r.stdout.splitlines()
    assert count == "0"
    assert message.startswith("robot 'planar_2r': no CUDA device (cudaGetDeviceCount: cudaError") and "\n" not in message
    assert "Traceback" not in r.stderr


def test_bad_requests_are_one_line(cache):
    with pytest.raises(DeriveError, match=r"^robot 'planar_2r': derive.compiled\(device='cuda'\): no function 'nope'"):
        cuda_compiled(cache, "planar_2r", ["nope"])
    with pytest.raises(DeriveError, match=r"device='tpu' is not a device \(cpu or cuda\)"):
        derive.compiled("planar_2r", device="tpu")
    with pytest.raises(DeriveError, match="functions= chooses the CUDA kernels"):
        derive.compiled("planar_2r", functions=["mass_matrix"])


def test_a_compile_error_is_one_line(cache, monkeypatch):
    monkeypatch.setenv("NVCCFLAGS", "-DDERIVE_REAL=no_such_type")
    with pytest.raises(DeriveError, match=r"^cannot compile robot 'planar_2r': .*error") as info:
        cuda_compiled(cache, "planar_2r", ["mass_matrix"])
    assert "\n" not in str(info.value)


def test_architecture_choice(monkeypatch):
    argv = ["/nonexistent/nvcc"]
    monkeypatch.setenv("DERIVE_CUDA_ARCH", "sm_90,compute_80")
    assert cuda.arch_flags("r", argv) == ["-gencode", "arch=compute_90,code=[sm_90,compute_90]",
                                          "-gencode", "arch=compute_80,code=compute_80"]
    monkeypatch.setenv("DERIVE_CUDA_ARCH", "native")  # no device query beside a missing nvcc: the default
    assert cuda.arch_flags("r", argv) == ["-gencode", f"arch=compute_75,code=[{cuda.ARCH_DEFAULT},compute_75]"]
    monkeypatch.setenv("DERIVE_CUDA_ARCH", "volta")
    with pytest.raises(DeriveError, match="DERIVE_CUDA_ARCH=volta: 'volta' is not a CUDA architecture"):
        cuda.arch_flags("r", argv)


# ---- on a GPU: the same results as the CPU ----

def states(robot_cpu, n, rng):
    nv = robot_cpu.NV
    return rng.uniform(-1.5, 1.5, (n, nv)), rng.uniform(-1, 1, (n, nv)), rng.uniform(-1, 1, (n, nv))


def close(gpu, cpu, rtol):
    gpu, cpu = np.asarray(gpu), np.asarray(cpu)
    assert gpu.shape == cpu.shape
    scale = np.maximum(1.0, np.abs(cpu).max(axis=tuple(range(1, cpu.ndim)), keepdims=True)) if cpu.ndim > 1 else \
        np.maximum(1.0, np.abs(cpu).max())
    worst = float(np.max(np.abs(gpu - cpu) / scale))
    assert worst <= rtol, worst


def test_results_equal_the_cpu_on_a_gpu(small, panda):
    if small.device_count() == 0:
        pytest.skip("no CUDA device on this machine: the GPU results cannot be compared (they are where one exists)")
    for mod, robot in ((small, "planar_2r"), (panda, "panda")):
        compare_with_the_cpu(mod, derive.compiled(robot), 257)  # not a multiple of a block
    cpu = derive.compiled("planar_2r")
    T = cpu.fk_tcp(np.array([0.3, -0.4]))
    q0 = np.random.default_rng(7).uniform(-1, 1, (5, 2))
    qg, _, st = small.ik_tcp(T, q0)  # one target for five starts
    _, _, sc = cpu.ik_tcp(np.broadcast_to(T, (5, 4, 4)), q0)
    assert list(st) == list(sc)
    # the GPU's q solves it as the IK's tolerance says (its iterates may round differently: fused multiply-adds)
    assert all(np.abs(cpu.fk_tcp(qg[k])[:3, 3] - T[:3, 3]).max() <= 1e-5 for k in range(5) if st[k] == 0)


def compare_with_the_cpu(mod, cpu, n: int) -> None:
    """Every function of ``mod`` but IK against the CPU library on n seeded states: host arrays
    (FP64, one state, lists, FP32), device arrays states-major, elements-major in and out=, and one
    state's input shared by the batch with p a device array."""
    rng = np.random.default_rng(3)
    q, qd, qdd = states(cpu, n, rng)
    x = np.concatenate([q, qd], axis=1)
    for name in mod.FUNCTIONS:
        if name.startswith("ik_"):
            continue
        given = {"q": q, "qd": qd, "qdd": qdd, "tau": qdd, "x": x, "u": qdd, "dt": np.full((n, 1), 0.01)}
        args = tuple(given[k] for k in INPUTS[name])
        want = getattr(cpu, name)(*args)
        fn = getattr(mod, name)
        close(fn(*args), want, 1e-12)                                   # host arrays: numpy out
        close(fn(*[a[5] for a in args]), want[5], 1e-12)                # one state
        close(fn(*[a.tolist() for a in args]), want, 1e-12)             # lists
        got32 = fn(*[a.astype(np.float32) for a in args])
        assert got32.dtype == np.float32
        close(got32, want, 1e-4)                                        # the FP32 kernel
        dev = [mod.to_device(a) for a in args]
        res = fn(*dev)                                                  # device arrays, states-major
        assert isinstance(res, mod.DeviceArray) and res.shape == want.shape
        close(res.get(), want, 1e-12)
        # elements-major in and out (the coalesced layout), through strided __cuda_array_interface__ views
        t = [mod.to_device(np.ascontiguousarray(a.T)) for a in args]
        views = [cuda_view(d, a.shape, (1, n)) for d, a in zip(t, args)]
        core = want.shape[1:]
        out = mod.empty((int(np.prod(core)), n))
        strides = (1,) + tuple(n * int(np.prod(core[k + 1:])) for k in range(len(core)))
        assert fn(*views, out=cuda_view(out, want.shape, strides)) is not None
        close(out.get().T.reshape(want.shape), want, 1e-12)
        if len(args) == 1:
            continue
        # one state's input for the whole batch (stride 0), p (where the robot has one) a device array
        shared = [args[0][0]] + list(args[1:])
        want_shared = getattr(cpu, name)(*[np.broadcast_to(shared[0], args[0].shape), *args[1:]])
        extra = {"p": mod.to_device(cpu.DEFAULT_P)} if len(cpu.DEFAULT_P) else {}
        close(fn(*[mod.to_device(a) for a in shared], **extra).get(), want_shared, 1e-12)


class cuda_view:
    """A strided view of a DeviceArray (elements), as __cuda_array_interface__ says it."""

    def __init__(self, base, shape, strides):
        self.base = base
        item = base.dtype.itemsize
        self.__cuda_array_interface__ = {"shape": tuple(shape), "typestr": base.dtype.str, "version": 3,
                                         "data": (base.ptr, False), "strides": tuple(s * item for s in strides),
                                         "stream": 1}


# ---- derive bench cuda without a GPU ----

def test_bench_cuda_without_a_device_says_so_and_writes_nothing(monkeypatch, tmp_path):
    from derive import bench
    from derive.bench import cuda as bench_cuda

    monkeypatch.setattr(bench_cuda, "device_architectures", lambda argv: [])  # as on a machine without a GPU
    monkeypatch.setattr(bench_cuda, "find_nvcc", lambda: ([str(tmp_path / "nvcc")], []))
    (tmp_path / "__nvcc_device_query").write_text("")
    monkeypatch.delenv("DERIVE_CUDA_ARCH", raising=False)
    out = tmp_path / "results.md"
    args = types.SimpleNamespace(names=["cuda"], out=str(out), quick=True)
    with pytest.raises(DeriveError) as info:
        bench.run(args, bench_cuda.benchmarks())  # as `python -m derive.bench.cuda` and `derive bench cuda` run it
    assert str(info.value) == (f"bench cuda: no CUDA device on this machine (nvcc's device query finds none): "
                               f"nothing measured; {out} not written")
    assert not out.exists()
    # a run of all: the section is left out, and one measured earlier (on a GPU) kept
    out.write_text("# derive benchmark results\n\n## CUDA batch kernels (Panda): states per second\n\nearlier\n")
    benches = {"other": lambda a: "## Other\n\nnew\n", **bench_cuda.benchmarks()}
    assert bench.run(types.SimpleNamespace(names=[], out=str(out), quick=True), benches) == 0
    text = out.read_text()
    assert "## CUDA batch kernels (Panda): states per second\n\nearlier\n" in text and "## Other\n\nnew\n" in text


# ---- the kernels and the Python glue on the CPU: CUDA's runtime emulated ----

FAKE_CUDA = r"""
/* Just enough of cuda_runtime.h to compile derive's CUDA units as host C++: one "thread" (grid and
   block of 1) runs the kernel's grid-stride loop over every state; memory is the host's. */
#include <cstdlib>
#include <cstring>
#define __global__
#define __device__
#define __host__
#define __shared__ static
static void __syncwarp(unsigned = 0xffffffffu) {}
struct fake_dim3 { unsigned x, y, z; };
static const fake_dim3 blockIdx = {0, 0, 0}, threadIdx = {0, 0, 0}, blockDim = {1, 1, 1}, gridDim = {1, 1, 1};
typedef int cudaError_t;
enum { cudaSuccess = 0 };
typedef void *cudaStream_t;
typedef void *cudaEvent_t;
enum cudaMemcpyKind { cudaMemcpyDefault = 4 };
struct cudaPointerAttributes { int type; int device; };
struct cudaDeviceProp { char name[256]; };
template <class K> static cudaError_t cudaOccupancyMaxPotentialBlockSize(int *g, int *b, K, int, int) { *g = 1; *b = 1; return 0; }
static cudaError_t cudaGetLastError(void) { return 0; }
static cudaError_t cudaGetDeviceCount(int *n) { *n = 1; return 0; }
static const char *cudaGetErrorName(cudaError_t) { return "cudaErrorFake"; }
static const char *cudaGetErrorString(cudaError_t) { return "fake"; }
static cudaError_t cudaGetDevice(int *d) { *d = 0; return 0; }
static cudaError_t cudaGetDeviceProperties(cudaDeviceProp *p, int) { strcpy(p->name, "host emulation"); return 0; }
static cudaError_t cudaMalloc(void **p, size_t n) { *p = malloc(n); return *p ? 0 : 2; }
static cudaError_t cudaFree(void *p) { free(p); return 0; }
static cudaError_t cudaMemcpy(void *d, const void *s, size_t n, cudaMemcpyKind) { memcpy(d, s, n); return 0; }
static cudaError_t cudaStreamSynchronize(cudaStream_t) { return 0; }
static cudaError_t cudaPointerGetAttributes(cudaPointerAttributes *a, const void *) { a->type = 2; a->device = 0; return 0; }
static cudaError_t cudaEventCreate(cudaEvent_t *e) { *e = 0; return 0; }
static cudaError_t cudaEventRecord(cudaEvent_t, cudaStream_t) { return 0; }
static cudaError_t cudaEventSynchronize(cudaEvent_t) { return 0; }
static cudaError_t cudaEventElapsedTime(float *ms, cudaEvent_t, cudaEvent_t) { *ms = 0; return 0; }
static cudaError_t cudaEventDestroy(cudaEvent_t) { return 0; }
"""


@pytest.fixture(scope="module")
def emulated(tmp_path_factory):
    """planar_2r's CUDA units (the same text nvcc compiles) built by g++ against FAKE_CUDA, loaded by
    the same Python module code as the real library."""
    import re
    import shutil

    from derive.runtime import cuda_arrays

    gxx = shutil.which("g++") or shutil.which("c++")
    if gxx is None:
        if os.environ.get("CI"):
            pytest.fail("no g++ (nvcc needs it too)")
        pytest.skip("no g++")
    tmp = tmp_path_factory.mktemp("emulated")
    robot = "planar_2r"
    snap = build.read_generated(robot, ROOT / "generated" / robot)
    sigs = build.signatures(snap.manifest)
    chosen = cuda.select(robot, sigs, EMULATED)
    rec = cuda.cuda_record(robot, snap.manifest, chosen, snap.sources_hash)
    (tmp / "fake_cuda.h").write_text(FAKE_CUDA)
    groups = cuda.chunks(chosen, snap.manifest, 4)  # as on an 8-core machine
    assert len(groups) == 4 and sorted(s.name for g in groups for s in g) == sorted(EMULATED)
    assert next(g for g in groups if any(s.name == "rk4_step" for s in g)) != \
        next(g for g in groups if any(s.name == "ode_rhs" for s in g))
    units = [cuda.unit_source(robot, g, cuda.needed_sources(g, sigs, snap), s, sigs, f"{s}_{k}")
             for s in ("f64", "f32") for k, g in enumerate(groups)] + [cuda.host_source(robot, rec)]
    paths = []
    for k, text in enumerate(units):
        text = text.replace("#include <cuda_runtime.h>", '#include "fake_cuda.h"')
        text = re.sub(r"<<<[^>]*>>>\(", "(", text)  # a launch: a plain call
        paths.append(tmp / f"unit{k}.cpp")
        paths[-1].write_text(text)
    lib = tmp / f"lib{robot}_cuda.so"
    r = subprocess.run([gxx, "-O1", "-fPIC", "-shared", f"-I{tmp}", f"-I{ROOT / 'generated' / robot / 'c'}",
                        *map(str, paths), "-o", str(lib)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-3000:]
    return cuda_arrays._module(robot, snap.manifest, chosen, lib, rec)


def test_emulated_kernels_equal_the_cpu_in_every_layout(emulated):
    assert emulated.device_count() == 1 and emulated.device_name() == "host emulation"
    compare_with_the_cpu(emulated, derive.compiled("planar_2r"), 37)


def test_emulated_ik_status_and_optional_inputs(emulated):
    cpu = derive.compiled("planar_2r")
    rng = np.random.default_rng(4)
    T = cpu.fk_tcp(np.array([0.3, -0.4]))
    q0 = rng.uniform(-1, 1, (4, 2))
    qg, rg, st = emulated.ik_tcp(T, q0)  # one target for four starts
    qc, rc, sc = cpu.ik_tcp(np.broadcast_to(T, (4, 4, 4)), q0)
    assert st.dtype == np.intc and list(st) == list(sc)
    close(qg, qc, 1e-12)
    close(rg, rc, 1e-9)
    q1, r1, s1 = emulated.ik_tcp(T)  # q0=None, w=None: NULL in the kernel
    qc1, rc1, sc1 = cpu.ik_tcp(T)
    assert s1 == sc1 and isinstance(s1, int)
    close(q1, qc1, 1e-12)
    w = np.array([1.0, 1.0, 0.0, 0.0, 0.0, 1.0])
    close(emulated.ik_tcp(T, q0[0], w=w)[0], cpu.ik_tcp(T, q0[0], w=w)[0], 1e-12)


def test_emulated_bad_calls_are_one_line_errors(emulated):
    q = np.zeros((3, 2))
    with pytest.raises(ValueError, match=r"^mass_matrix: q must have shape \(\.\.\., 2, 1\)|^mass_matrix: q must have shape"):
        emulated.mass_matrix(np.zeros((3, 5)))
    with pytest.raises(TypeError, match="mix float32 and float64"):
        emulated.inverse_dynamics(emulated.to_device(q), emulated.to_device(q, np.float32), emulated.to_device(q))
    with pytest.raises(ValueError, match="batch shapes differ"):
        emulated.inverse_dynamics(q, np.zeros((4, 2)), q)
    with pytest.raises(ValueError, match=r"out= needs 1 arrays \(M\), got 2"):
        emulated.mass_matrix(emulated.to_device(q), out=(emulated.empty((3, 2, 2)), emulated.empty((3, 2, 2))))
    with pytest.raises(ValueError, match=r"out M has shape \(4, 2, 2\), the states need \(3, 2, 2\)"):
        emulated.mass_matrix(emulated.to_device(q), out=emulated.empty((4, 2, 2)))
    with pytest.raises(TypeError, match="out M must be a CUDA device array"):
        emulated.mass_matrix(emulated.to_device(q), out=np.zeros((3, 2, 2)))
    with pytest.raises(TypeError, match=r"missing argument 'qdd'"):
        emulated.inverse_dynamics(q, q)
    with pytest.raises(ValueError, match="not one state stride and one element stride"):
        base = emulated.empty((3, 2, 2))
        emulated.mass_matrix(emulated.to_device(q), out=cuda_view(base, (3, 2, 2), (4, 1, 2)))


class dlpack_on_gpu:
    """A numpy array offered through DLPack as if on CUDA device 0 (JAX's way in), for the emulation."""

    def __init__(self, a):
        self.a = a

    def __dlpack_device__(self):
        return (2, 0)

    def __dlpack__(self, stream=None):
        assert stream == 1  # the legacy default stream, which the call runs on
        return self.a.__dlpack__()


def test_emulated_dlpack_inputs_and_outputs(emulated):
    cpu = derive.compiled("planar_2r")
    rng = np.random.default_rng(5)
    q, qd, qdd = states(cpu, 11, rng)
    want = cpu.inverse_dynamics(q, qd, qdd)
    soa = [np.ascontiguousarray(a.T).T for a in (q, qd, qdd)]  # elements-major: strides (1, n) elements
    res = emulated.inverse_dynamics(*[dlpack_on_gpu(a) for a in soa])
    assert isinstance(res, emulated.DeviceArray)
    close(res.get(), want, 1e-12)
    out = np.zeros((2, 11)).T
    emulated.inverse_dynamics(dlpack_on_gpu(q), dlpack_on_gpu(qd), dlpack_on_gpu(qdd), out=dlpack_on_gpu(out))
    close(out, want, 1e-12)
    # host inputs into a device out=: written there, out returned as given
    dev_out = emulated.empty((11, 2))
    assert emulated.inverse_dynamics(q, qd, qdd, out=dev_out) is dev_out
    close(dev_out.get(), want, 1e-12)
    # an input written on another stream (its interface says which): waited for, then read
    other = cuda_view(emulated.to_device(q), q.shape, (2, 1))
    other.__cuda_array_interface__["stream"] = 12345
    close(emulated.inverse_dynamics(other, qd, qdd).get(), want, 1e-12)
    with pytest.raises(TypeError, match="DLPack dtype .* is not float32 or float64"):
        emulated.inverse_dynamics(dlpack_on_gpu(np.zeros((3, 2), np.int64)), q[:3], q[:3])


# ---- what a GPU machine's image needs: numpy, PyYAML, nvcc (no CasADi, jinja2 or Pinocchio) ----

def test_the_runtime_and_this_benchmark_import_no_casadi():
    """derive.compiled (CPU and CUDA) and `python -m derive.bench.cuda` run where only numpy and
    PyYAML are installed, as on a GPU machine's image; this module runs there with --noconftest."""
    code = ("import sys, derive.runtime, derive.runtime.cuda_arrays, derive.bench.cuda\n"
            "print(sorted(m for m in ('casadi', 'jinja2', 'sympy', 'pinocchio', 'jax') if m in sys.modules))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT,
                       env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=120)
    assert r.returncode == 0 and r.stdout.strip() == "[]", r.stdout + r.stderr[-2000:]


def test_the_runtime_finds_the_generated_folder_the_generator_writes():
    pytest.importorskip("casadi", reason="the generator needs CasADi (a GPU machine's image may lack it)")
    from derive.codegen.generate import default_output

    assert build.default_generated() == default_output()
