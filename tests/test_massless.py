"""A partly massless robot (issue 25, item 5): the ABB IRB140 as its textbook standard DH table
(examples/irb140_dh.yaml, robotics-toolbox's IRB140) with three massless wrist links, so q4, q5, q6
move no mass or inertia and M(q) is singular at every q.

`derive generate` writes everything that exists (FK, Jacobians, M, C, g, ID and its derivatives,
the regressors, IK) with one warning naming the coordinates, leaves out forward dynamics, the ODE
and its Jacobians and says so in manifest.json (``left_out``); ``--strict`` refuses the robot as
before. The generated C (strict C99 flags, through ctypes) and Python match Pinocchio and the
numpy reference to 1e-9 at seeded states; the commands and calls that need forward dynamics say why
in one line.
"""

from __future__ import annotations

import ctypes
import json
from pathlib import Path

import numpy as np
import pytest

from derive.cli import main
from derive.codegen.generate import generate
from derive.description.model import load_models
from derive.errors import DeriveError, NotGenerated
from derive.reference import NumericRobot
from derive.runtime import compiled
from derive.solvers.trajopt import TrajectoryOptimizer
from pin_model import PinRobot
from util import assert_close, build_library, load_module

MODELS = Path(__file__).resolve().parent.parent / "examples" / "irb140_dh.yaml"
ROBOT = load_models(MODELS)["irb140"]
REASON = "coordinates q4, q5, q6 move no mass or inertia, so M(q) is singular"
WARNING = (f"derive: warning: {MODELS}: robot 'irb140': {REASON}: forward dynamics, the ODE and its Jacobians are "
           "not generated (--strict refuses the robot)")
LEFT_OUT = ["forward_dynamics", "forward_dynamics_fext", "ode_rhs", "ode_jac_x", "ode_jac_u", "rk4_step"]
STRICT = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O1", "-fPIC"]
N_STATES = 10
RTOL = 1e-9


@pytest.fixture(scope="module")
def generated(tmp_path_factory):
    """(output folder, warnings) of the IRB140 generated once."""
    out = tmp_path_factory.mktemp("massless") / "generated"
    warnings: list[str] = []
    generate({"irb140": ROBOT}, out, log=lambda line: None, warn=warnings.append)
    return out, warnings


def states():
    rng = np.random.default_rng(0)
    lo, hi = ROBOT.joint_box()
    for _ in range(N_STATES):
        yield rng.uniform(lo, hi), rng.normal(size=6), rng.normal(size=6)


def test_generates_all_but_forward_dynamics_with_one_warning_and_the_manifest_says_so(generated):
    out, warnings = generated
    assert warnings == [WARNING]
    manifest = json.loads((out / "irb140" / "manifest.json").read_text())
    assert manifest["left_out"] == {"functions": [f"irb140_{name}" for name in LEFT_OUT],
                                    "coordinates": ["q4", "q5", "q6"], "reason": REASON}
    names = [fn["name"] for fn in manifest["functions"]]
    assert names == [f"irb140_{n}" for n in (
        "fk_tcp", "jacobian_tcp", "jdot_qd_tcp", "frame_acceleration_tcp", "fk_jacobian_tcp", "fk_all", "mass_matrix",
        "coriolis_matrix", "gravity", "bias", "inverse_dynamics", "inverse_dynamics_derivatives",
        "inverse_dynamics_fext", "com", "com_jacobian", "centroidal_map", "regressor", "base_regressor",
        "bundle_control", "bundle_computed_torque", "ik_tcp", "manipulability_tcp")]
    for name in LEFT_OUT:
        assert not (out / "irb140" / "c" / f"irb140_{name}.c").exists()
    # cached: unchanged, kept, and warned again
    again: list[str] = []
    generate({"irb140": ROBOT}, out, log=lambda line: None, warn=again.append)
    assert again == [WARNING]


def _c_function(lib, name: str, n_in: int):
    fn = getattr(lib, f"irb140_{name}")
    fn.argtypes = [ctypes.POINTER(ctypes.c_double)] * (n_in + 1)
    fn.restype = None

    def call(*args, shape):
        arrays = [np.ascontiguousarray(a, dtype=float) for a in args]
        out = np.zeros(shape)
        fn(*[a.ctypes.data_as(ctypes.POINTER(ctypes.c_double)) for a in arrays],
           out.ctypes.data_as(ctypes.POINTER(ctypes.c_double)))
        return out

    return call


def test_generated_c_and_python_match_pinocchio_and_the_reference(generated, tmp_path):
    """FK, Jacobian, M, g, ID and dID/dx of the tcp at seeded states, in C and Python, against Pinocchio
    and derive's numpy reference to 1e-9 (relative to each array's largest entry)."""
    out, _ = generated
    folder = out / "irb140"
    names = ("fk_tcp", "jacobian_tcp", "mass_matrix", "gravity", "inverse_dynamics", "inverse_dynamics_derivatives")
    sources = [folder / "c" / f"irb140_{name}.c" for name in names]
    lib = ctypes.CDLL(str(build_library(["cc", *STRICT, f"-I{folder / 'c'}"], sources, tmp_path / "libirb140.so")))
    py = load_module(folder / "python" / "irb140.py", "irb140_massless")
    c = {name: _c_function(lib, name, k) for name, k in (("fk_tcp", 1), ("jacobian_tcp", 1), ("mass_matrix", 1),
                                                        ("gravity", 1), ("inverse_dynamics", 3),
                                                        ("inverse_dynamics_derivatives", 3))}
    pin, ref = PinRobot(ROBOT), NumericRobot(ROBOT)
    for q, qd, qdd in states():
        expected = {"fk_tcp": (pin.pose(q, "tcp"), ref.frame_pose(q, "tcp")),
                    "jacobian_tcp": (pin.jacobian(q, "tcp"), ref.jacobian(q, "tcp")),
                    "mass_matrix": (pin.crba(q), ref.crba(q)),
                    "gravity": (pin.gravity(q), ref.gravity(q)),
                    "inverse_dynamics": (pin.rnea(q, qd, qdd), ref.rnea(q, qd, qdd)),
                    "inverse_dynamics_derivatives": (pin.rnea_derivatives(q, qd, qdd), None)}
        args = {"fk_tcp": (q,), "jacobian_tcp": (q,), "mass_matrix": (q,), "gravity": (q,),
                "inverse_dynamics": (q, qd, qdd), "inverse_dynamics_derivatives": (q, qd, qdd)}
        for name, (want_pin, want_ref) in expected.items():
            got_c = c[name](*args[name], shape=want_pin.shape)
            got_py = np.asarray(getattr(py, name)(*args[name])).reshape(want_pin.shape)
            for got, lang in ((got_c, "C"), (got_py, "Python")):
                assert_close(got, want_pin, RTOL, f"{name} ({lang}) vs Pinocchio")
                if want_ref is not None:
                    assert_close(got, want_ref, RTOL, f"{name} ({lang}) vs the reference")
        M = ref.crba(q)
        assert np.all(M[3:, :] == 0) and np.all(M[:, 3:] == 0)  # the wrist moves nothing: M is singular
    assert py.LEFT_OUT == tuple(LEFT_OUT) and not hasattr(py, "ode_rhs")
    with pytest.raises(AttributeError) as info:
        py.forward_dynamics
    assert str(info.value) == (f"robot 'irb140': forward_dynamics was not generated: {REASON} (forward dynamics, the "
                               "ODE and its Jacobians do not exist)")


def test_strict_refuses_as_before_even_from_the_cache(generated, capsys, tmp_path):
    out, _ = generated
    refusal = (f"derive: error: {MODELS}: robot 'irb140': joints (q4): coordinate 'q4' moves no mass or inertia, so "
               "M(q) is singular and forward dynamics do not exist; give the links it moves a mass (links[i].mass) or "
               "inertia about its axis")
    for folder in (tmp_path / "fresh", out):  # fresh, and cached without --strict
        assert main(["--models", str(MODELS), "generate", "--strict", "--out", str(folder)]) == 2
        assert capsys.readouterr().err.splitlines() == [refusal]
    assert not (tmp_path / "fresh").exists()
    with pytest.raises(DeriveError, match="coordinate 'q4' moves no mass"):
        generate({"irb140": ROBOT}, tmp_path / "api", log=lambda line: None, strict=True)


def test_what_needs_forward_dynamics_says_why_in_one_line(generated, capsys):
    out, _ = generated
    mod = compiled("irb140", out)
    assert mod.LEFT_OUT == tuple(LEFT_OUT) and not hasattr(mod, "ode_rhs")
    assert_close(mod.gravity(np.zeros(6)), NumericRobot(ROBOT).gravity(np.zeros(6)), RTOL, "compiled gravity")
    with pytest.raises(NotGenerated) as info:
        mod.forward_dynamics(np.zeros(6), np.zeros(6), np.zeros(6))
    assert str(info.value) == (f"robot 'irb140': forward_dynamics was not generated: {REASON} (forward dynamics, "
                               "the ODE and its Jacobians do not exist)")
    with pytest.raises(AttributeError, match="has no attribute 'nothing'"):
        mod.nothing
    needs = (f"derive: error: {MODELS}: robot 'irb140': {{}} needs forward dynamics, which do not exist: "
             "coordinates q4, q5, q6 move no mass or inertia, so M(q) is singular; give the links they move a mass or "
             "inertia")
    zeros = ["0"] * 6
    capsys.readouterr()  # compiled()'s progress lines where this run built the library (no cache yet)
    assert main(["--models", str(MODELS), "simulate", "irb140", "--q0", *zeros, "--t", "0.01",
                 "--generated", str(out)]) == 2
    assert capsys.readouterr().err.splitlines() == [needs.format("simulate")]
    with pytest.raises(DeriveError) as info:
        TrajectoryOptimizer(ROBOT)
    assert f"derive: error: {info.value}" == needs.format("trajopt")


FLOATING_TIP = """\
robots:
  hopper:
    base: floating
    links:
      - {name: body, mass: 3.0, com: [0.01, 0.0, 0.02], inertia: [0.05, 0.06, 0.07]}
      - {name: leg, mass: 0.5, com: [0.0, 0.0, -0.2], inertia: [0.01, 0.01, 0.002]}
      - {name: pointer}
    joints:
      - {name: hip, type: revolute, parent: body, child: leg, axis: [0, 1, 0], origin: {xyz: [0, 0, -0.1]}}
      - {name: wrist, type: revolute, parent: leg, child: pointer, axis: [0, 0, 1], origin: {xyz: [0, 0, -0.4]}}
"""


def test_a_floating_base_names_its_massless_joint_not_a_base_velocity(tmp_path):
    """M's rows are v's entries (the base's 6 velocities, then the joints'), not q's 7 entries: the
    massless `wrist` on a floating base is named as itself, in the refusal and in the manifest."""
    from derive.description.model import parse_models
    from derive.symbolic.model import SXModel
    from derive.codegen.checks import check_mass_matrix

    robot = parse_models(FLOATING_TIP)["hopper"]
    assert robot.floating and robot.nq == robot.nv + 1
    model = SXModel(robot)
    assert check_mass_matrix(model, strict=False) == ["wrist"]
    with pytest.raises(DeriveError, match=r"joints \(wrist\): coordinate 'wrist' moves no mass or inertia"):
        check_mass_matrix(model)
    generate({"hopper": robot}, tmp_path, log=lambda line: None, warn=lambda line: None)
    manifest = json.loads((tmp_path / "hopper" / "manifest.json").read_text())
    assert manifest["left_out"]["coordinates"] == ["wrist"]
