"""A chain long enough for the large-robot forms, end to end: its forward dynamics by the
articulated-body algorithm, its Coriolis matrix and ODE Jacobian from the analytic RNEA derivatives,
split C functions (zero entries by a loop where an output is mostly zeros), generated in C and
Python, against the numpy reference (complex step for ode_jac_x) and each other, at seeded states."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np

from derive.bench.large import generic_chain
from derive.codegen.backends import backends
from derive.codegen.catalogue import function_specs
from derive.codegen.render import render_robot
from derive.description.model import parse_models
from derive.reference import NumericRobot
from derive.symbolic.model import SXModel
from test_codegen import CFLAGS, CFunctions, reference
from util import assert_close, build_library, states

N = 13  # the fewest joints that take the large-robot forms (above 12)
SHOWN = ("inverse_dynamics", "mass_matrix", "coriolis_matrix", "forward_dynamics", "ode_rhs", "ode_jac_x", "ode_jac_u")


def test_large_chain_forms_match_the_reference(tmp_path):
    import ctypes

    robot = parse_models(generic_chain(N))[f"chain{N}"]
    specs = [s for s in function_specs(SXModel(robot)) if s.short_name in SHOWN]
    files = render_robot(robot, specs, "0" * 16, backends=[b for b in backends() if b.name in ("c", "python")])
    for rel, text in files.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    manifest = json.loads(files["manifest.json"])
    by_name = {fn["quantity"]: fn for fn in manifest["functions"]}
    assert by_name["forward_dynamics"]["algorithm"] == "articulated-body algorithm"
    assert "analytic RNEA derivatives" in by_name["coriolis_matrix"]["algorithm"]
    assert "analytic RNEA derivatives" in by_name["ode_jac_x"]["algorithm"]
    assert by_name["ode_jac_x"]["c"]["form"] == "split"
    sources = [tmp_path / fn["c"]["source"] for fn in manifest["functions"]]
    lib = build_library(["cc", *CFLAGS, "-O1", "-fPIC", f"-I{tmp_path / 'c'}"], sources, tmp_path / "libchain.so")
    c = CFunctions(lib, manifest, ctypes.c_double)
    spec = importlib.util.spec_from_file_location("large_chain", Path(tmp_path / "python" / f"chain{N}.py"))
    py = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(py)
    ref = NumericRobot(robot)
    rng = np.random.default_rng(3)
    for q, qd, qdd in states(robot, n=2):
        tau = rng.normal(size=N) * 5
        a = {"q": q, "qd": qd, "qdd": qdd, "tau": tau, "x": np.concatenate([q, qd]), "u": tau, "wrench_frames": []}
        for fn in manifest["functions"]:
            args = [a[i["name"]] for i in fn["inputs"]]
            want = np.asarray(reference(ref, fn, a), dtype=float).reshape(fn["outputs"][0]["shape"])
            got_c = c(fn, a)[0]
            assert_close(got_c, want, what=f"C {fn['name']}")
            assert_close(np.asarray(getattr(py, fn["python"]["function"])(*args)).reshape(got_c.shape), got_c, rtol=1e-12,
                         what=f"Python vs C {fn['name']}")
