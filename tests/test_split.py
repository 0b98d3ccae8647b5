"""Large generated C functions are split into parts the compiler handles in linear time.

The shipped robots' functions stay below the threshold (one function each); here the threshold
and part size are lowered (600 and 300) so the UR5's larger functions split, and the split C (double and
float, -Werror -pedantic) must equal the generated Python, which is never split; outputs mostly of
zeros (the regressors) then have their zeros written by a loop, every other entry by a store.
"""

from __future__ import annotations

import ctypes
import json
import math
import re
import subprocess

import numpy as np
import pytest

import derive.codegen.backends.c as c_backend
from derive.codegen.backends.c import printer as c_printer
from derive.codegen.generate import generate
from derive.resources import CHECKOUT
from util import assert_close, load_module, random_q, robots

CFLAGS = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O1", "-shared", "-fPIC"]


@pytest.fixture(scope="module")
def split_ur5(tmp_path_factory):
    out = tmp_path_factory.mktemp("split")
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(c_printer, "SPLIT_ABOVE", 600)
        mp.setattr(c_printer, "PART_SIZE", 300)
        mp.setattr(c_backend, "ZERO_FILL_MIN", 16)  # the regressors' zeros by a loop (tiago_dual's: 87k of 93k)
        generate({"ur5": robots()["ur5"]}, out, use_cache=False, log=lambda s: None)
    return out / "ur5"


def test_shipped_functions_stay_whole():
    for robot in robots():
        manifest = json.loads((CHECKOUT / "generated" / robot / "manifest.json").read_text())
        for fn in manifest["functions"]:
            if fn["ops"] is not None:
                assert fn["ops"]["total"] <= c_printer.SPLIT_ABOVE, fn["name"]


def test_split_functions_compile_clean_and_equal_python(split_ur5, tmp_path):
    manifest = json.loads((split_ur5 / "manifest.json").read_text())
    split, fills = {}, set()
    for fn in manifest["functions"]:
        if fn["ops"] is None:
            continue
        text = (split_ur5 / fn["c"]["source"]).read_text()
        parts = len(re.findall(r"^static DERIVE_FN DERIVE_NOINLINE void \w+_part\d+\(", text, re.M))
        entries = sum(math.prod(o["shape"]) for o in fn["outputs"])
        if fn["ops"]["total"] + entries > 600:  # ops = instructions for these bodies; then the store parts
            names = "|".join(o["name"] for o in fn["outputs"])
            stores = len(re.findall(rf"^    (?:{names})\[\d+\] = ", text, re.M))
            filled = re.findall(rf"^    for \(long k = 0; k < (\d+)L; k\+\+\) {{.*\n        ({names})\[k\] = DERIVE_LIT\(0\.0\);",
                                text, re.M)
            assert stores < entries if filled else stores == entries, fn["name"]
            assert parts == -(-fn["ops"]["total"] // 300) + -(-stores // 300), fn["name"]
            fills.update(f"{fn['name']}.{name}" for _, name in filled)
            assert (fn["c"]["form"], fn["c"]["parts"]) == ("split", parts), fn["name"]
            assert fn["c"]["zero_filled"] == [name for _, name in filled], fn["name"]
            split[fn["name"]] = fn
            slots = int(re.search(r"DERIVE_REAL W\[(\d+)\];", text).group(1))
            assert 0 < slots < fn["ops"]["total"] // 4, (fn["name"], slots)
        else:
            assert parts == 0 and fn["c"]["form"] == "whole", fn["name"]
    assert {"ur5_ode_jac_x", "ur5_coriolis_matrix"} <= set(split)
    assert {"ur5_regressor.Y", "ur5_ode_jac_x.A"} <= fills  # half zeros or more: a loop writes them
    sources = [str(split_ur5 / f["c"]["source"]) for f in split.values()]
    for flags in ([], ["-DDERIVE_FLOAT"]):
        lib = tmp_path / f"libsplit{len(flags)}.so"
        subprocess.run(["cc", *CFLAGS, *flags, f"-I{split_ur5 / 'c'}", "-o", str(lib), *sources, "-lm"], check=True)
    cdll = ctypes.CDLL(str(tmp_path / "libsplit0.so"))
    py = load_module(split_ur5 / "python" / "ur5.py", "split_ur5")
    r = robots()["ur5"]
    rng = np.random.default_rng(11)
    ptr = ctypes.POINTER(ctypes.c_double)
    for _ in range(3):
        q = random_q(r, rng)
        a = {"q": q, "qd": rng.normal(size=r.nv), "qdd": rng.normal(size=r.nv), "tau": rng.normal(size=r.nv),
             "x": np.concatenate([q, rng.normal(size=r.nv)]), "u": rng.normal(size=r.nv),
             "w": rng.normal(size=6 * len(r.wrench_frames))}
        for fn in split.values():
            ins = [np.ascontiguousarray(a[i["name"]], dtype=float) for i in fn["inputs"]]
            outs = [np.full(o["shape"], np.nan) for o in fn["outputs"]]  # every entry must be written
            f = getattr(cdll, fn["name"])
            f.restype = None
            f(*[v.ctypes.data_as(ptr) for v in ins + outs])
            want = getattr(py, fn["python"]["function"])(*ins)
            want = want if isinstance(want, tuple) else (want,)
            for got, exp, o in zip(outs, want, fn["outputs"]):
                assert_close(got.reshape(np.shape(exp)), exp, rtol=1e-12, what=f"{fn['name']} {o['name']}")
