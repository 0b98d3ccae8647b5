"""CUDA-ready C: the generated C compiles unchanged as CUDA device code (nvcc -x cu), and the
example batch kernel (examples/cuda/) builds against it. No GPU is needed to compile.

nvcc comes from the CUDA toolkit on PATH or from the `cuda` extra (the nvidia-cuda-nvcc wheel),
which `make test` installs. Without either the test is skipped, except in CI (CI=true), where
a missing compiler is a failure.
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
from pathlib import Path

import pytest

from util import run_at_once

ROOT = Path(__file__).resolve().parent.parent
GENERATED = ROOT / "generated"


def find_nvcc() -> tuple[Path, list[str]] | None:
    """(nvcc, extra flags) from PATH or the nvidia-cuda-nvcc wheel; None if neither."""
    on_path = shutil.which("nvcc")
    if on_path:
        return Path(on_path), []
    spec = importlib.util.find_spec("nvidia")
    for base in (spec.submodule_search_locations if spec else []):
        for nvcc in sorted(Path(base).glob("cu*/bin/nvcc")):
            return nvcc, [f"-L{nvcc.parent.parent / 'lib'}"]
    return None


@pytest.fixture(scope="module")
def nvcc():
    found = find_nvcc()
    if found is None:
        if os.environ.get("CI"):
            pytest.fail("nvcc not found: the `cuda` extra (nvidia-cuda-nvcc) should be installed by `make test`")
        pytest.skip("no nvcc: install the CUDA toolkit or `pip install derive-robotics[cuda]`")
    return found


def test_every_generated_c_file_compiles_as_cuda_device_code(nvcc, tmp_path):
    """DERIVE_FN is __host__ __device__ under nvcc: all of a robot's functions (IK, RK4 and the
    support headers included) compile as CUDA. One nvcc per source, as many at once as there are CPUs
    (each spends ~1 s on the CUDA headers; one nvcc for all of them compiles one after the other)."""
    exe, _ = nvcc
    src = GENERATED / "planar_2r" / "c"
    sources = sorted(str(p) for p in src.glob("*.c"))
    results = run_at_once([[str(exe), "-x", "cu", "-rdc=true", "-Werror", "all-warnings", f"-I{src}", "-c", source]
                           for source in sources], cwd=tmp_path, capture_output=True, text=True)
    for source, res in zip(sources, results):
        assert res.returncode == 0, f"{source}: {res.stderr[-3000:]}"
    assert len(list(tmp_path.glob("*.o"))) == len(sources)


def test_example_batch_kernel_builds(nvcc, tmp_path):
    exe, flags = nvcc
    src = GENERATED / "panda" / "c"
    res = subprocess.run([str(exe), "-O2", "-x", "cu", "-rdc=true", f"-I{src}",
                          str(ROOT / "examples" / "cuda" / "batch_inverse_dynamics.cu"),
                          str(src / "panda_inverse_dynamics.c"), *flags, "-o", str(tmp_path / "batch")],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr[-3000:]
    assert (tmp_path / "batch").is_file()


def test_c_headers_define_the_qualifier():
    text = (GENERATED / "panda" / "c" / "derive_real.h").read_text()
    assert "#define DERIVE_FN __host__ __device__" in text
    header = (GENERATED / "panda" / "c" / "panda_inverse_dynamics.h").read_text()
    assert "DERIVE_FN void panda_inverse_dynamics(" in header
