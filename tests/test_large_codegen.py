"""A chain long enough for the large-robot forms, and a tree of two branches, end to end: its forward dynamics by the
articulated-body algorithm, its Coriolis matrix and inverse-dynamics derivatives from the analytic
RNEA derivatives, its ODE Jacobians as loops (LTDL factor and solve) around calls of
forward_dynamics, inverse_dynamics_derivatives and mass_matrix, split C functions, generated in C,
Python and JAX, against the numpy reference (complex step for the derivatives) and each other at
seeded states, with a parameter away from its default, and against Pinocchio (computeRNEADerivatives,
computeABADerivatives); a batch of the Python template functions equals
its states one by one bit for bit."""

from __future__ import annotations

import importlib.util
import json
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest

from derive.bench.large import generic_chain
from derive.codegen.backends import backends
from derive.codegen.catalogue import function_specs, template_functions
from derive.codegen.render import render_robot
from derive.description.model import parse_models
from derive.reference import NumericRobot
from derive.symbolic.model import SXModel
from pin_model import PinRobot
from test_codegen import CFLAGS, CFunctions, reference
from util import assert_close, compile_objects, load_module, states

N = 13  # the fewest joints that take the large-robot forms (above 12)
SHOWN = ("inverse_dynamics", "inverse_dynamics_derivatives", "mass_matrix", "coriolis_matrix", "forward_dynamics",
         "ode_rhs", "ode_jac_x", "ode_jac_u")


@pytest.mark.parametrize("shape", ["chain", "tree"])
def test_large_robot_forms_match_the_reference(shape, tmp_path):
    import ctypes

    text = _with_parameter(generic_chain(N))
    if shape == "tree":  # joint q8 on link l3 instead of l7: two branches, LTDL along the tree
        text, count = re.subn(r"(name: q8, type: revolute, parent: )l7", r"\g<1>l3", text)
        assert count == 1
    robot = parse_models(text)[f"chain{N}"]
    model = SXModel(robot)
    specs = [s for s in function_specs(model) if s.short_name in SHOWN]
    templates = [t for t in template_functions(model) if t.short_name in SHOWN]
    files = render_robot(robot, specs, "0" * 16, templates=templates,
                         backends=[b for b in backends() if b.name in ("c", "python", "jax")])
    for rel, text in files.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    manifest = json.loads(files["manifest.json"])
    by_name = {fn["quantity"]: fn for fn in manifest["functions"]}
    assert by_name["forward_dynamics"]["algorithm"] == "articulated-body algorithm"
    assert "analytic RNEA derivatives" in by_name["coriolis_matrix"]["algorithm"]
    assert "analytic RNEA derivatives" in by_name["inverse_dynamics_derivatives"]["algorithm"]
    for quantity in ("ode_jac_x", "ode_jac_u"):
        assert by_name[quantity]["c"]["form"] == "template" and by_name[quantity]["ops"] is None
        assert "LTDL" in by_name[quantity]["algorithm"]
    assert by_name["ode_jac_x"]["calls"] == [f"chain{N}_{q}" for q in ("forward_dynamics", "inverse_dynamics_derivatives",
                                                                         "mass_matrix")]
    assert {"file": "c/derive_ltdl.h", "source": "templates/c/support/derive_ltdl.h"} in manifest["support"]
    assert ("L^T D L along the tree" in by_name["ode_jac_u"]["algorithm"]) and (
        (SXModel(robot).newton_euler.dof_parents is None) == (shape == "chain"))
    sources = [tmp_path / fn["c"]["source"] for fn in manifest["functions"]]
    # the template functions (loops around calls: where flow-based warnings such as
    # -Wmaybe-uninitialized can fire) at -O2, the straight-line ones at -O0 (their front-end warnings;
    # the shipped robots' are built at -O1 in conftest.py): all at -O1 took 36 s, this 12 s
    loops = [tmp_path / fn["c"]["source"] for fn in manifest["functions"] if fn["c"]["form"] == "template"]
    assert len(loops) == 2
    (tmp_path / "loops").mkdir()
    (tmp_path / "lines").mkdir()
    objects = [*compile_objects(["cc", *CFLAGS, "-O2", "-fPIC", f"-I{tmp_path / 'c'}"], loops, tmp_path / "loops"),
               *compile_objects(["cc", *CFLAGS, "-O0", "-fPIC", f"-I{tmp_path / 'c'}"],
                                [s for s in sources if s not in loops], tmp_path / "lines")]
    lib = tmp_path / "libchain.so"
    subprocess.run(["cc", "-shared", "-o", str(lib), *map(str, objects), "-lm"], check=True, capture_output=True, text=True)
    c = CFunctions(lib, manifest, ctypes.c_double)
    py = load_module(Path(tmp_path / "python" / f"chain{N}.py"), "large_chain")
    jx = _load_jax(tmp_path)
    ref = NumericRobot(robot, {"m5": float(P[0])})
    pin = PinRobot(robot, {"m5": float(P[0])})
    rng = np.random.default_rng(3)
    batch = {"x": [], "u": []}
    for index, (q, qd, qdd) in enumerate(states(robot, n=2)):
        tau = rng.normal(size=N) * 5
        a = {"q": q, "qd": qd, "qdd": qdd, "tau": tau, "x": np.concatenate([q, qd]), "u": tau, "p": P,
             "wrench_frames": []}
        for fn in manifest["functions"]:
            args = [a[i["name"]] for i in fn["inputs"]]
            want = np.asarray(reference(ref, fn, a), dtype=float).reshape(fn["outputs"][0]["shape"])
            got_c = c(fn, a)[0]
            assert_close(got_c, want, what=f"C {fn['name']}")
            assert_close(np.asarray(getattr(py, fn["python"]["function"])(*args)).reshape(got_c.shape), got_c, rtol=1e-12,
                         what=f"Python vs C {fn['name']}")
            if jx is not None and index == 0:  # JAX op by op (its LTDL loops: a compile per indexing): one state
                assert_close(np.asarray(getattr(jx, fn["jax"]["function"])(*args)).reshape(got_c.shape), got_c,
                             rtol=1e-12, what=f"JAX vs C {fn['name']}")
        # and Pinocchio: computeRNEADerivatives, and computeABADerivatives' dqdd/dx and M^-1
        dqdd, minv = pin.aba_derivatives(q, qd, tau)
        assert_close(c(by_name["inverse_dynamics_derivatives"], a)[0], pin.rnea_derivatives(q, qd, qdd), 1e-9,
                     "C inverse_dynamics_derivatives against Pinocchio")
        assert_close(c(by_name["ode_jac_x"], a)[0][N:], dqdd, 1e-9, "C ode_jac_x against Pinocchio")
        assert_close(c(by_name["ode_jac_u"], a)[0][N:], minv, 1e-9, "C ode_jac_u against Pinocchio")
        batch["x"].append(a["x"])
        batch["u"].append(a["u"])
    x, u = np.array(batch["x"]), np.array(batch["u"])
    for name in ("ode_jac_x", "ode_jac_u"):
        f = getattr(py, name)
        together = f(x, u, P)
        assert together.shape == (2,) + f(x[0], u[0], P).shape
        for k in range(2):
            assert np.array_equal(together[k], f(x[k], u[k], P)), name
        assert np.array_equal(f(x, u[0], P)[1], f(x[1], u[0], P)), name  # batch shapes broadcast


P = np.array([1.9])  # the parameter m5, away from its default


def _with_parameter(text: str) -> str:
    """The chain with the mass of link l5 a parameter m5 (default 1.5): the templates pass p on."""
    text = text.replace("    links:\n", "    parameters: {m5: 1.5}\n    links:\n", 1)
    return re.sub(r"(name: l5, mass: )[0-9.]+", r"\g<1>m5", text)


def _load_jax(folder: Path):
    """The JAX module, or None where the jax extra is not installed (CI installs it)."""
    if importlib.util.find_spec("jax") is None:
        return None
    import jax
    jax.config.update("jax_enable_x64", True)  # the module computes in JAX's default float type
    jx = load_module(Path(folder / "jax" / f"chain{N}.py"), "large_chain_jax")
    return jx
