"""CUDA-ready C: the generated C compiles unchanged as CUDA device code (nvcc -x cu), and the
example batch kernel (examples/cuda/) builds against it. No GPU is needed to compile.

nvcc comes from the CUDA toolkit on PATH or from the `cuda` extra (the nvidia-cuda-nvcc wheel),
which `make test` installs. Without either the test is skipped, except in CI (CI=true), where
a missing compiler is a failure.
"""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

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
    support headers included) compile as CUDA, and every one of them is in the object. One nvcc for
    one translation unit that includes every source (each nvcc spends ~2 s on the CUDA headers: 27
    of them took 70 s of CPU, this one 3 s); that each source stands alone is the strict C build's
    test (tests/test_codegen.py, one compiler per source)."""
    exe, _ = nvcc
    src = GENERATED / "planar_2r" / "c"
    sources = sorted(src.glob("*.c"))
    unit = tmp_path / "all.cu"
    unit.write_text("".join(f'#include "{s}"\n' for s in sources))
    obj = tmp_path / "all.o"
    res = subprocess.run([str(exe), "-x", "cu", "-rdc=true", "-Werror", "all-warnings", f"-I{src}", "-c", str(unit),
                          "-o", str(obj)], cwd=tmp_path, capture_output=True, text=True)
    assert res.returncode == 0, res.stderr[-3000:]
    manifest = json.loads((GENERATED / "planar_2r" / "manifest.json").read_text())
    symbols = subprocess.run(["nm", "--defined-only", str(obj)], capture_output=True, text=True, check=True).stdout
    defined = {line.split()[-1] for line in symbols.splitlines() if line.strip()}
    names = [fn["name"] for fn in manifest["functions"]]
    assert len(names) == len(sources) and all(any(d.startswith(f"_Z{len(n)}{n}") or d == n for d in defined)
                                               for n in names), sorted(defined)


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
