"""Motor <-> joint maps of a closed chain (docs/closed-chains.md, models.yaml ``outputs``): the parallel
ankle's generated maps between its motors y = (motor_l, motor_r) and its joints o = (pitch, roll),
against the numpy reference (Newton closures both ways, J from the frames' Jacobians), by round trips,
power balance and finite differences; C against Python; the closed forms against the Newton solve on
other mechanisms; models.yaml's validation."""

from __future__ import annotations

import ctypes
import json
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
import yaml

from derive.cli import main
from derive.description.model import parse_models
from derive.reference.closure import ClosedChainReference
from derive.symbolic.closure import ClosedChainModel
from derive.symbolic.motor_map import motor_joint_maps
from test_codegen import CFunctions, load_python
from util import closed_inputs, robots

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models.yaml"
ANKLE = "parallel_ankle"
MAPS = ("motor_to_joint_position", "motor_to_joint_velocity", "motor_to_joint_torque", "joint_to_motor_position",
        "joint_to_motor_velocity", "joint_to_motor_torque")


def manifest() -> dict:
    return json.loads((ROOT / "generated" / ANKLE / "manifest.json").read_text())


@pytest.fixture(scope="module")
def ankle(committed_library):
    """(robot, numpy reference, C functions by quantity, generated Python module, p)."""
    m, r = manifest(), robots()[ANKLE]
    c = CFunctions(committed_library(ANKLE), m, ctypes.c_double)
    fns = {f["quantity"]: f for f in m["functions"]}
    py = load_python(ANKLE)
    p = np.array([x.default for x in r.parameters])

    def call_c(quantity: str, **a):
        out = [v.ravel() for v in c(fns[quantity], a | {"p": p})]
        return out if len(out) > 1 else out[0]

    return r, ClosedChainReference(r), call_c, py, p


def test_manifest_states_the_maps_and_their_coordinates():
    m = manifest()
    maps = m["closed_chain"]["motor_joint_maps"]
    assert maps["motors"] == ["motor_l", "motor_r"] and maps["joints"] == ["pitch", "roll"]
    assert maps["joint_to_motor"] == "closed form: one crank per rod (a cos t + b sin t = c)"
    fns = {f["quantity"]: f for f in m["functions"]}
    for q in MAPS:
        assert fns[q]["coordinates"] == ("y" if q.startswith("motor_to") else "outputs"), q
        assert fns[q]["motors"] == ["motor_l", "motor_r"] and fns[q]["joints"] == ["pitch", "roll"]
    assert [i["name"] for i in fns["motor_to_joint_position"]["inputs"]] == ["y", "z0", "p"]  # as closure: Newton
    assert [i["name"] for i in fns["joint_to_motor_position"]["inputs"]] == ["o", "p"]  # closed form
    assert [o["name"] for o in fns["joint_to_motor_position"]["outputs"]] == ["y", "status", "residual"]
    assert [i["name"] for i in fns["joint_to_motor_torque"]["inputs"]] == ["o", "tau_o", "p"]


def test_generated_maps_match_the_numpy_reference(ankle):
    """C at 5 seeded states near the reference: each map against the numpy reference to 1e-10 (joint ->
    motor by Newton with the joints held, J = d o / d y from G), Python equal to C to 1e-12."""
    r, ref, call_c, py, p = ankle
    rng = np.random.default_rng(11)
    for _ in range(5):
        a = closed_inputs(r, rng)
        q, _ = ref.closure(a["y"])
        J = ref.output_jacobian(q)
        o, status, residual = call_c("motor_to_joint_position", y=a["y"], z0=a["z0"])
        assert np.abs(o - q[2:]).max() <= 1e-10 and status[0] == 1.0 and residual[0] <= 1e-12
        assert np.abs(call_c("motor_to_joint_velocity", y=a["y"], yd=a["yd"]) - J @ a["yd"]).max() <= 1e-10
        assert np.abs(call_c("motor_to_joint_torque", y=a["y"], tau_y=a["tau_y"])
                      - np.linalg.solve(J.T, a["tau_y"])).max() <= 1e-10
        qo, _ = ref.closure_from_outputs(a["o"])
        Jo = ref.output_jacobian(qo)
        y, status, residual = call_c("joint_to_motor_position", o=a["o"])
        assert np.abs(y - qo[:2]).max() <= 1e-10 and status[0] == 1.0 and residual[0] <= 1e-12
        assert np.abs(call_c("joint_to_motor_velocity", o=a["o"], od=a["od"]) - np.linalg.solve(Jo, a["od"])).max() <= 1e-10
        assert np.abs(call_c("joint_to_motor_torque", o=a["o"], tau_o=a["tau_o"]) - Jo.T @ a["tau_o"]).max() <= 1e-10
        # Python = C
        for got, want in [(py.motor_to_joint_position(a["y"], a["z0"])[0], o),
                          (py.joint_to_motor_position(a["o"])[0], y),
                          (py.motor_to_joint_velocity(a["y"], a["yd"]), call_c("motor_to_joint_velocity", y=a["y"], yd=a["yd"])),
                          (py.joint_to_motor_torque(a["o"], a["tau_o"]),
                           call_c("joint_to_motor_torque", o=a["o"], tau_o=a["tau_o"]))]:
            assert np.abs(got - want).max() <= 1e-12 * max(1.0, np.abs(want).max())


def test_round_trips_and_power(ankle):
    """motor -> joint -> motor and joint -> motor -> joint to 1e-12 for position, velocity and torque;
    the joint torques do the motor torques' work: tau_o . od = tau_y . yd (the loops carry no power)."""
    r, _, call_c, _, _ = ankle
    rng = np.random.default_rng(12)
    for _ in range(5):
        a = closed_inputs(r, rng)
        o = call_c("motor_to_joint_position", y=a["y"], z0=a["z0"])[0]
        assert np.abs(call_c("joint_to_motor_position", o=o)[0] - a["y"]).max() <= 1e-12
        y = call_c("joint_to_motor_position", o=a["o"])[0]
        assert np.abs(call_c("motor_to_joint_position", y=y, z0=a["z0"])[0] - a["o"]).max() <= 1e-12
        od = call_c("motor_to_joint_velocity", y=a["y"], yd=a["yd"])
        assert np.abs(call_c("joint_to_motor_velocity", o=o, od=od) - a["yd"]).max() <= 1e-12
        tau_o = call_c("motor_to_joint_torque", y=a["y"], tau_y=a["tau_y"])
        assert np.abs(call_c("joint_to_motor_torque", o=o, tau_o=tau_o) - a["tau_y"]).max() <= 1e-12
        assert abs(tau_o @ od - a["tau_y"] @ a["yd"]) <= 1e-12 * max(1.0, abs(a["tau_y"] @ a["yd"]))


def test_velocity_is_the_derivative_of_position(ankle):
    """od = J yd against Richardson-extrapolated central differences of the generated position map (no G
    in the check), to 1e-9; and yd = J^-1 od the same way from joint_to_motor_position."""
    r, _, call_c, _, _ = ankle
    rng = np.random.default_rng(13)
    a = closed_inputs(r, rng)

    def rate(f, x, v, h=1e-3):
        d = lambda s: (f(x + s * v) - f(x - s * v)) / (2 * s)  # noqa: E731
        return (4 * d(h / 2) - d(h)) / 3

    od = rate(lambda y: call_c("motor_to_joint_position", y=y, z0=a["z0"])[0], a["y"], a["yd"])
    assert np.abs(call_c("motor_to_joint_velocity", y=a["y"], yd=a["yd"]) - od).max() <= 1e-9
    yd = rate(lambda o: call_c("joint_to_motor_position", o=o)[0], a["o"], a["od"])
    assert np.abs(call_c("joint_to_motor_velocity", o=a["o"], od=a["od"]) - yd).max() <= 1e-9


def test_out_of_reach_has_status_zero(ankle):
    """A pitch no rod reaches (-1.5 rad): the crank's square root is of a negative number, y is NaN, status 0
    (C; the one-state Python raises ValueError there, as math.sqrt does)."""
    _, _, call_c, _, _ = ankle
    y, status, _ = call_c("joint_to_motor_position", o=np.array([-1.5, 0.0]))
    assert status[0] == 0.0 and np.isnan(y).any()


def parse(name: str, **changes):
    entry = yaml.safe_load(MODELS.read_text())["robots"][name] | changes
    return parse_models(yaml.safe_dump({"robots": {"mech": entry}}))["mech"]


@pytest.mark.parametrize("name,outputs,method", [
    ("fourbar", ["rocker"], "closed form: circle-circle"),
    ("fivebar", ["elbow1", "elbow2"], "closed form: circle-circle"),
    ("parallel_ankle", ["pitch", "roll"], "closed form: one crank per rod (a cos t + b sin t = c)")])
def test_closed_forms_equal_the_newton_solve(name, outputs, method):
    """Joint -> motor position by the closed form and by 8 Newton steps from the reference (CasADi), at 3
    seeded joint positions reached from y near the reference: the same y to 1e-12, which the numpy closure
    maps back onto the joints."""
    r = parse(name, outputs=outputs)
    ccm = ClosedChainModel(r)
    red = ccm.in_y()
    ref = ClosedChainReference(r)
    names = [c.name for c in r.coordinates]
    oi = [names.index(c) for c in outputs]
    p = [x.default for x in r.parameters]
    solve = {}
    for closed_form in (True, False):
        mm = motor_joint_maps(ccm, red, closed_form)
        assert (mm.method == method) == closed_form, mm.method
        ins = [mm.o] + ([] if mm.w0 is None else [mm.w0]) + [ccm.sym.p]
        solve[closed_form] = (ca.Function("f", ins, [mm.motor_position, mm.motor_residual]), mm.w0 is not None)
    rng = np.random.default_rng(14)
    for _ in range(3):
        y = ref.q_ref[ref.y] + rng.uniform(-0.1, 0.1, len(ref.y))
        q, _ = ref.closure(y)
        got = []
        for f, newton in solve.values():
            args = [q[oi]] + ([np.delete(ref.q_ref, oi)] if newton else []) + [p]
            yy, res = (np.array(v, dtype=float).ravel() for v in f(*args))
            assert res[0] <= 1e-12
            got.append(yy)
        assert np.abs(got[0] - got[1]).max() <= 1e-12
        assert np.abs(got[0] - y).max() <= 1e-12


BAD = [
    ({"outputs": ["pitch", "knee"]}, "outputs[1]: unknown coordinate 'knee' (coordinates: motor_l, motor_r, pitch, roll)"),
    ({"outputs": ["pitch"]}, "outputs: 1 coordinate(s) given, but the mechanism has 2 degree(s) of freedom"),
    ({"outputs": ["pitch", "pitch"]}, "outputs: a coordinate is listed twice"),
    ({"outputs": ["motor_l", "motor_r"]}, "outputs: the same as independent: the motor <-> joint maps would be the identity"),
    ({"outputs": "pitch"}, "outputs: expected a non-empty list of coordinate names"),
]


@pytest.mark.parametrize("changes,message", BAD, ids=[m.split(":")[0] + str(i) for i, (_, m) in enumerate(BAD)])
def test_bad_outputs_are_one_line_errors(tmp_path, capsys, changes, message):
    entry = yaml.safe_load(MODELS.read_text())["robots"][ANKLE] | changes
    path = tmp_path / "models.yaml"
    path.write_text(yaml.safe_dump({"robots": {ANKLE: entry}}))
    assert main(["dof", "--models", str(path), ANKLE]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"derive: error: {path}: robot '{ANKLE}': ") and message in err, err
    assert err.count("\n") == 1


def test_outputs_that_are_no_chart():
    """theta1 and theta2 lie in example2's four-bar (one DOF between them): d(outputs)/dy is singular."""
    with pytest.raises(Exception, match=r"outputs: \(theta1, theta2, theta4\) is not a valid chart at the reference "
                                        r"configuration: d\(outputs\)/dy is singular there"):
        parse("example2", outputs=["theta1", "theta2", "theta4"])


def test_outputs_need_loops():
    entry = yaml.safe_load(MODELS.read_text())["robots"]["planar_2r"] | {"outputs": ["q1", "q2"]}
    with pytest.raises(Exception, match=r"loops: expected a non-empty list .* \(independent, reference and outputs need loops\)"):
        parse_models(yaml.safe_dump({"robots": {"mech": entry}}))
