"""Contacts (models.yaml's ``contacts:``): contact forward dynamics, impulse dynamics at touchdown, their
derivatives and the centroidal terms.

- The description: one-line errors for bad ``contacts:`` and ``contact_sets:``; a model without contacts
  keeps its hash.
- A small floating biped (a surface foot and a point foot, plus a redundant stance) generated in C, Python
  and JAX: its contact dynamics against the independent numpy reference (:mod:`derive.reference.contact`,
  a dense KKT solve on the reference's M, h, J, J'v) to 1e-9 relative, the batched Python module too; the
  redundant stance reports status 0 and finite numbers (never a regularised answer with status 1).
- The fixed-base rrprr with a point contact at its tcp (and a parameter input), all contact quantities
  generated, against Pinocchio's constraintDynamics, impulseDynamics and their derivatives.
- solo12 (four feet and a trot pair), anymal (four feet) and talos_reduced (both soles as surfaces) from
  example-robot-data, floating (the issue's Done-when): the symbolic expressions the generated functions
  print, through CasADi, against Pinocchio's
  constraintDynamics / computeConstraintDynamicsDerivatives, impulseDynamics /
  computeImpulseDynamicsDerivatives (1e-9) and computeCentroidalMomentumTimeVariation (1e-12), and
  against the numpy reference (its RNEA gives the momentum's rate independently).
"""

from __future__ import annotations

import ctypes
import dataclasses
import json
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from derive.codegen.generate import generate
from derive.description.model import load_models, parse_models, parse_robot
from derive.description.robot import (CENTROIDAL_QUANTITIES, CONTACT_QUANTITIES, Contact, ContactSet, ModelError,
                                      model_data)
from derive.description.urdf import example_robot_data_dir, import_urdf_named
from derive.reference import NumericRobot
from derive.reference import contact as ref
from derive.symbolic.contact import ContactModel, centroidal_inertia, centroidal_map_dot_qd, com_acceleration
from derive.symbolic.model import SXModel
from util import assert_close, build_library, load_module

TOL = 1e-9
CFLAGS = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O0", "-fPIC"]

BIPED = """
robots:
  biped:
    base: floating
    links:
      - {name: pelvis, mass: 5.0, com: [0.01, 0.02, 0.03], inertia: [0.1, 0.2, 0.3]}
      - {name: l_hip, mass: 1.0, com: [0.0, 0.02, -0.1], inertia: [0.01, 0.02, 0.015]}
      - {name: l_thigh, mass: 1.5, com: [0.02, 0.0, -0.15], inertia: [0.02, 0.02, 0.01]}
      - {name: l_shin, mass: 0.8, com: [0.0, 0.01, -0.15], inertia: [0.01, 0.012, 0.005]}
      - {name: r_hip, mass: 1.0, com: [0.0, -0.02, -0.1], inertia: [0.01, 0.02, 0.015]}
      - {name: r_thigh, mass: 1.5, com: [0.02, 0.0, -0.15], inertia: [0.02, 0.02, 0.01]}
      - {name: r_shin, mass: 0.8, com: [0.0, -0.01, -0.15], inertia: [0.01, 0.012, 0.005]}
    joints:
      - {name: l_j1, type: revolute, parent: pelvis, child: l_hip, axis: [1, 0, 0], origin: {xyz: [0, 0.1, -0.05], rpy: [0.1, 0, 0]}}
      - {name: l_j2, type: revolute, parent: l_hip, child: l_thigh, axis: [0, 1, 0], origin: {xyz: [0, 0, -0.1]}}
      - {name: l_j3, type: revolute, parent: l_thigh, child: l_shin, axis: [0, 1, 0], origin: {xyz: [0, 0, -0.3], rpy: [0, 0.2, 0]}}
      - {name: r_j1, type: revolute, parent: pelvis, child: r_hip, axis: [1, 0, 0], origin: {xyz: [0, -0.1, -0.05], rpy: [-0.1, 0, 0]}}
      - {name: r_j2, type: revolute, parent: r_hip, child: r_thigh, axis: [0, 1, 0], origin: {xyz: [0, 0, -0.1]}}
      - {name: r_j3, type: revolute, parent: r_thigh, child: r_shin, axis: [0, 1, 0], origin: {xyz: [0, 0, -0.3], rpy: [0, -0.2, 0]}}
    frames:
      - {name: l_foot, link: l_shin, xyz: [0.02, 0, -0.3], rpy: [0.1, -0.2, 0.3], aliases: [left_sole]}
      - {name: r_foot, link: r_shin, xyz: [0.02, 0, -0.3]}
      - {name: l_point, link: l_shin, xyz: [0.02, 0, -0.3]}
    contacts:
      - {frame: left_sole, kind: surface}
      - {frame: r_foot}
      - {frame: l_point, kind: point}
    contact_sets:
      both: [l_foot, r_foot]
      redundant: [l_foot, l_point]
"""


# ---------------------------------------------------------------------------------------------- description

def arm(extra: str) -> str:
    return ("robots:\n  arm:\n    links: [{name: base}, {name: l1, mass: 1.0}, {name: l2, mass: 1.0}, {name: l3, mass: 1.0}]\n"
            "    joints: [{name: j1, type: revolute, parent: base, child: l1, axis: [0, 0, 1]},\n"
            "             {name: j2, type: revolute, parent: l1, child: l2, axis: [0, 1, 0], origin: {xyz: [0, 0, 0.3]}},\n"
            "             {name: j3, type: revolute, parent: l2, child: l3, axis: [0, 1, 0], origin: {xyz: [0.3, 0, 0]}}]\n"
            "    frames: [{name: tip, link: l3, xyz: [0.2, 0, 0]}]\n" + extra)


BAD = {
    "not_a_list": ("    contacts: tip\n", "contacts", "expected a non-empty list of {frame, kind}"),
    "unknown_frame": ("    contacts: [{frame: toe}]\n", "contacts[0].frame", "unknown frame 'toe'"),
    "unknown_kind": ("    contacts: [{frame: tip, kind: line}]\n", "contacts[0].kind", "unknown contact kind 'line' (known: point, surface)"),
    "unknown_field": ("    contacts: [{frame: tip, mu: 0.7}]\n", "contacts[0].mu", "unknown field"),
    "no_frame": ("    contacts: [{kind: point}]\n", "contacts[0].frame", "missing"),
    "twice": ("    contacts: [{frame: tip}, {frame: tip, kind: surface}]\n", "contacts[1].frame", "listed twice"),
    "fixed_root": ("    contacts: [{frame: base}]\n", "contacts[0].frame", "is the fixed base"),
    "too_many_rows": ("    contacts: [{frame: tip, kind: surface}]\n", "contacts", "6 constraint rows for 3 velocities"),
    "set_not_a_contact": ("    contacts: [{frame: tip}]\n    contact_sets: {stance: [l2]}\n", "contact_sets.stance[0]",
                          "'l2' is not a contact (contacts: tip)"),
    "set_empty": ("    contacts: [{frame: tip}]\n    contact_sets: {stance: []}\n", "contact_sets.stance",
                  "non-empty list of contact frames"),
    "set_name": ("    contacts: [{frame: tip}]\n    contact_sets: {2legs: [tip]}\n", "contact_sets.2legs", ""),
    "sets_without_contacts": ("    contact_sets: {stance: [tip]}\n", "contacts", "missing: contact_sets name frames"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_contacts_give_one_line_naming_the_field(case):
    extra, field, problem = BAD[case]
    with pytest.raises(ModelError) as info:
        parse_models(arm(extra))
    message = str(info.value)
    assert "\n" not in message and "robot 'arm'" in message and f"{field}:" in message and problem in message, message


def test_contacts_parse_with_aliases_and_default_set():
    robot = parse_models(BIPED)["biped"]
    assert robot.contacts == (Contact("l_foot", "surface"), Contact("r_foot", "point"), Contact("l_point", "point"))
    assert robot.stances == (ContactSet("both", ("l_foot", "r_foot")), ContactSet("redundant", ("l_foot", "l_point")))
    one = parse_models(arm("    contacts: [{frame: tip}]\n"))["arm"]
    assert one.stances == (ContactSet("all", ("tip",)),) and one.centroidal
    assert one.control_bundles[0].quantities == ("mass_matrix", "bias", "jacobian_tip", "jdot_qd_tip")  # the control tick
    plain = load_models()["ur5"]
    assert not plain.contacts and not plain.stances and "contacts" not in model_data(plain)  # the hash stays


def test_bad_contacts_from_the_command_line(tmp_path, capsys):
    from derive.cli import main
    models = tmp_path / "models.yaml"
    models.write_text(arm("    contacts: [{frame: tip, kind: line}]\n"))
    assert main(["--models", str(models), "generate", "--out", str(tmp_path / "out")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("derive: error: ") and "contacts[0].kind" in lines[0], lines
    assert not (tmp_path / "out" / "arm").exists()


def test_singular_mass_matrix_leaves_the_contact_functions_out_by_name(tmp_path):
    """A coordinate that moves no mass (the ankle of a massless toe): M is singular, so the contact functions,
    which solve with M^-1, are left out like forward dynamics and named in manifest.json's left_out."""
    text = ("robots:\n  legm:\n    base: floating\n"
            "    links: [{name: body, mass: 2.0, inertia: [0.1, 0.1, 0.1]}, {name: shin, mass: 0.5, inertia: [0.01, 0.01, 0.01]},"
            " {name: toe}]\n"
            "    joints: [{name: knee, type: revolute, parent: body, child: shin, axis: [0, 1, 0]},"
            " {name: ankle, type: revolute, parent: shin, child: toe, axis: [1, 0, 0]}]\n"
            "    frames: [{name: foot, link: toe, xyz: [0, 0, -0.3]}]\n"
            "    contacts: [{frame: foot}]\n"
            "    generate: {quantities: [contact_dynamics, com]}\n")
    generate({"legm": parse_models(text)["legm"]}, tmp_path, log=lambda s: None, warn=lambda s: None)
    manifest = json.loads((tmp_path / "legm" / "manifest.json").read_text())
    assert [f["name"] for f in manifest["functions"]] == ["legm_com"]
    assert "legm_contact_dynamics_all" in manifest["left_out"]["functions"]


# ---------------------------------------------------------------------------------------------- generated code

class Generated:
    """One robot generated into a temporary folder: its manifest, Python and JAX modules and C library."""

    def __init__(self, robot, out: Path, jax_too: bool = True):
        self.robot = robot
        generate({robot.name: robot}, out, log=lambda s: None)
        folder = out / robot.name
        self.manifest = json.loads((folder / "manifest.json").read_text())
        self.fn = {f["name"].removeprefix(robot.name + "_"): f for f in self.manifest["functions"]}
        self.py = load(folder / "python" / f"{robot.name}.py", f"contacts_{robot.name}")
        self.jax = load(folder / "jax" / f"{robot.name}.py", f"contacts_jax_{robot.name}") if jax_too else None
        lib = build_library(["cc", *CFLAGS], sorted((folder / "c").glob("*.c")), out / f"lib{robot.name}.so")
        self.lib = ctypes.CDLL(str(lib))

    def c(self, short: str, *args) -> list[np.ndarray]:
        f = self.fn[short]
        ins = [np.ascontiguousarray(np.atleast_1d(a), dtype=float) for a in args]
        outs = [np.zeros(o["shape"]) for o in f["outputs"]]
        ptr = ctypes.POINTER(ctypes.c_double)
        getattr(self.lib, f["name"])(*[a.ctypes.data_as(ptr) for a in ins + outs])
        return outs

    def python(self, short: str, *args) -> list[np.ndarray]:
        result = getattr(self.py, short)(*args)
        return [np.asarray(r) for r in (result if isinstance(result, tuple) else (result,))]

    def all(self, short: str, *args, jax: bool = True) -> list[list[np.ndarray]]:
        """[Python, C(, JAX)] outputs of ``short`` at ``args``, each a list of arrays of the manifest's shapes
        (JAX where the module was generated with it and ``jax``: eager calls cost a dispatch per operation)."""
        shapes = [tuple(o["shape"]) for o in self.fn[short]["outputs"]]

        def shaped(result):
            result = result if isinstance(result, tuple) else (result,)
            return [np.asarray(r, dtype=float).reshape(s) for r, s in zip(result, shapes)]
        out = [shaped(getattr(self.py, short)(*args)), [o.reshape(s) for o, s in zip(self.c(short, *args), shapes)]]
        if self.jax is not None and jax:
            out.append(shaped(getattr(self.jax, short)(*args)))
        return out


def load(path: Path, name: str):
    mod = load_module(path, name)
    return mod


def unit_quaternion_state(rng, nr: NumericRobot):
    q = nr.random_configuration(rng)
    return q, rng.normal(size=nr.nv), 5 * rng.normal(size=nr.nv)


@pytest.fixture(scope="module")
def biped(tmp_path_factory):
    pytest.importorskip("jax")
    import jax
    jax.config.update("jax_enable_x64", True)
    robot = dataclasses.replace(parse_models(BIPED)["biped"], generate_quantities=("contact_dynamics",))
    return Generated(robot, tmp_path_factory.mktemp("biped"))


def test_biped_contact_functions_match_the_reference(biped):
    """C, Python and JAX of contact_dynamics_both against the numpy KKT solve: the surface foot's six rows
    and the point foot's three."""
    robot = biped.robot
    nr = NumericRobot(robot)
    both = [(c.frame, c.kind) for c in robot.contacts if c.frame in ("l_foot", "r_foot")]
    rng = np.random.default_rng(0)
    assert [o["shape"] for o in biped.fn["contact_dynamics_both"]["outputs"]] == [[12, 1], [9, 1], [1, 1]]
    for k in range(4):
        q, v, tau = unit_quaternion_state(rng, nr)
        qdd, lam = ref.contact_dynamics(nr, q, v, tau, both)
        for lang, (a, l, status) in zip(("Python", "C", "JAX"), biped.all("contact_dynamics_both", q, v, tau, jax=k == 0)):
            assert_close(a.ravel(), qdd, TOL, f"qdd ({lang})")
            assert_close(l.ravel(), lam, TOL, f"lambda ({lang})")
            assert status.item() == 1.0, lang
        J, a0 = ref.contact_rows(nr, q, v, both)
        assert_close(J @ qdd, -a0, TOL, "the contacts are held")


def test_the_residual_forms_equal_the_reference():
    """What the derivatives differentiate, against the numpy reference: the RNEA with the contact forces as
    external wrenches (each rotated into its body, carried by the backward pass) equals ID - J^T lam, and the
    contacts' acceleration from the forward pass equals J qdd + a0; the surface foot's six rows, the point
    foot's three, at seeded states."""
    robot = parse_models(BIPED)["biped"]
    model, nr = SXModel(robot), NumericRobot(robot)
    s = model.sym
    stance = next(c for c in robot.stances if c.name == "both")
    cm = ContactModel(model, stance)
    lam = ca.SX.sym("lam", cm.rows)
    f = ca.Function("f", [s.q, s.qd, s.qdd, lam],
                    [model.newton_euler.rnea(s.qd, s.qdd, external=cm.wrenches(lam)), cm.acceleration(s.qdd)])
    contacts = [(c.frame, c.kind) for c in robot.contacts if c.frame in ("l_foot", "r_foot")]
    rng = np.random.default_rng(5)
    for _ in range(3):
        q, v, _ = unit_quaternion_state(rng, nr)
        a, l = rng.normal(size=nr.nv), rng.normal(size=cm.rows)
        tau, acc = (np.asarray(x).ravel() for x in f(q, v, a, l))
        J, a0 = ref.contact_rows(nr, q, v, contacts)
        assert_close(tau, nr.rnea(q, v, a) - J.T @ l, TOL, "RNEA with the contact wrenches")
        assert_close(acc, J @ a + a0, TOL, "the contacts' acceleration")


def test_quaternion_columns_are_the_rotations():
    """The derivatives' quaternion columns in closed form (gravity and the contact forces rotated, the KKT
    inverse's blocks at the base's linear rows) against the Jacobian of the residual by AD, on the tangent
    space (times T = d quat / d theta) and zero along the quaternion; the biped's surface and point feet (its
    stance 'both'), contact and impulse derivatives, at seeded unit quaternions."""
    robot = parse_models(BIPED)["biped"]
    model, nr = SXModel(robot), NumericRobot(robot)
    s, e = model.sym, ca.SX.sym("e")
    rng = np.random.default_rng(8)
    for stance in [c for c in robot.stances if c.name == "both"]:
        cm = ContactModel(model, stance)
        k, n = cm.kkt, s.nv
        qdd, lam, _ = cm.forward
        v_plus, imp, _ = cm.impulse(e)
        a, l = ca.SX.sym("a", n), ca.SX.sym("l", cm.rows)
        quat = s.q[3:7]
        F = ca.vertcat(model.newton_euler.inverse_dynamics(a, smooth=True, split=True, external=cm.wrenches(l)),
                       cm.acceleration(a))
        dF = ca.substitute(ca.jacobian(F, quat), ca.vertcat(a, l), ca.vertcat(qdd, lam))
        by_ad = k.solve(-dF[:n, :], -dF[n:, :])
        G = ca.vertcat(model.newton_euler.mass_matrix @ (a - s.qd) - cm.jacobian.T @ l, cm.jacobian @ (a + e * s.qd))
        dG = ca.substitute(ca.jacobian(G, quat), ca.vertcat(a, l), ca.vertcat(v_plus, imp))
        by_ad_impulse = k.solve(-dG[:n, :], -dG[n:, :])
        da, dl = cm.forward_derivatives
        dv, di = cm.impulse_derivatives(e)
        f = ca.Function("f", [s.q, s.qd, s.tau, e], [da, dl, dv, di, *by_ad, *by_ad_impulse])
        names = ("dqdd", "dlam", "dv_plus", "dimpulse")
        for _ in range(3):
            q, v, tau = unit_quaternion_state(rng, nr)
            out = [np.asarray(x) for x in f(q, v, tau, rng.uniform(0, 1))]
            T = quaternion_tangent(q[3:7])
            for name, whole, ad in zip(names, out[:4], out[4:]):
                # relative to the whole derivative: dv_plus's quaternion columns are 0 (AD: rounding, 1e-14)
                err = np.abs(whole[:, 3:7] @ T - ad @ T).max()
                assert err <= 1e-12 * np.abs(whole).max(), f"{name} on the tangent space: {err:.2e}"
            along_quaternion(q, nr.nq, n, list(zip(names, out[:4])), stance.name)


def test_biped_redundant_stance_reports_status_zero(biped):
    """A surface and a point at the same origin: 9 rows of rank 6, pivots of S exactly zero or rounding. status
    is 0 in every language, the numbers finite (no division by zero raises in Python, nothing is regularised
    into a plausible answer with status 1)."""
    rng = np.random.default_rng(1)
    nr = NumericRobot(biped.robot)
    for _ in range(3):
        q, v, tau = unit_quaternion_state(rng, nr)
        for lang, outs in zip(("Python", "C", "JAX"), biped.all("contact_dynamics_redundant", q, v, tau)):
            assert outs[-1].item() == 0.0 and all(np.isfinite(x).all() for x in outs), lang
    batch = biped.py.contact_dynamics_redundant(np.stack([q, q]), np.stack([v, v]), np.stack([tau, tau]))
    assert np.asarray(batch[2]).ravel().tolist() == [0.0, 0.0]


def test_biped_batched_python(biped):
    """The numpy module on a batch equals it state by state."""
    rng = np.random.default_rng(2)
    nr = NumericRobot(biped.robot)
    states = [unit_quaternion_state(rng, nr) for _ in range(5)]
    Q, V, T = (np.stack(x) for x in zip(*states))
    qdd_b, lam_b, status_b = biped.py.contact_dynamics_both(Q, V, T)
    for k, (q, v, tau) in enumerate(states):
        qdd, lam, _ = biped.py.contact_dynamics_both(q, v, tau)
        assert_close(np.asarray(qdd_b)[k], np.asarray(qdd), 1e-14, "batched qdd")
        assert_close(np.asarray(lam_b)[k], np.asarray(lam), 1e-14, "batched lambda")
    assert np.asarray(status_b).ravel().tolist() == [1.0] * 5


# ---------------------------------------------------------------------------------------------- Pinocchio

pin = pytest.importorskip("pinocchio")


def erd(rel: str) -> str:
    base = example_robot_data_dir()
    if base is None:
        pytest.fail("example-robot-data is not installed (the Makefile installs it with pinocchio)")
    return str(base / rel)


def pinocchio_contacts(pm, frames: dict[str, str], kinds: list[tuple[str, str]]):
    """Pinocchio's rigid contact models (LOCAL_WORLD_ALIGNED) and datas for derive's (frame, kind) list."""
    models = []
    for frame, kind in kinds:
        f = pm.frames[pm.getFrameId(frames.get(frame, frame))]
        contact_type = pin.ContactType.CONTACT_6D if kind == "surface" else pin.ContactType.CONTACT_3D
        models.append(pin.RigidConstraintModel(contact_type, pm, f.parentJoint, f.placement, pin.LOCAL_WORLD_ALIGNED))
    models = pin.StdVec_RigidConstraintModel(models)
    datas = pin.StdVec_RigidConstraintData([m.createData() for m in models])
    return models, datas


def prox():
    """No proximal regularisation: mu = 0, one iteration (Pinocchio's exact KKT solve)."""
    return pin.ProximalSettings(1e-14, 0.0, 1)


def tangent(pm, q) -> np.ndarray:
    """d(q (+) dv)/d dv at dv = 0 (nq x nv): what turns derive's d/dq (coordinates) into Pinocchio's."""
    T = np.zeros((pm.nq, pm.nv))
    if pm.nq == pm.nv:
        return np.eye(pm.nv)
    T[:3, :3] = pin.Quaternion(q[6], *q[3:6]).matrix()
    T[3:7, 3:6] = quaternion_tangent(q[3:7])
    T[7:, 6:] = np.eye(pm.nv - 6)
    return T


def quaternion_tangent(quat) -> np.ndarray:
    """d quat / d theta (4 x 3) for quat = [x, y, z, w] turned by exp(theta) in its own frame: 1/2 quat (x) (e_k, 0)."""
    q = pin.Quaternion(quat[3], *quat[:3])
    return np.column_stack([0.5 * (q * pin.Quaternion(0.0, *np.eye(3)[k])).coeffs() for k in range(3)])


def check_against_pinocchio(pm, q, v, tau, e, kinds, frames, outputs: dict, what: str) -> None:
    """``outputs``: derive's qdd, lam, dqdd, dlam, v_plus, impulse, dv_plus, dimpulse (those present)."""
    pd = pm.createData()
    models, datas = pinocchio_contacts(pm, frames, kinds)
    pin.initConstraintDynamics(pm, pd, models, datas)
    nq, nv = pm.nq, pm.nv
    T = tangent(pm, q)
    qdd = pin.constraintDynamics(pm, pd, q, v, tau, models, datas, prox())
    assert_close(outputs["qdd"], qdd, TOL, f"{what}: qdd vs constraintDynamics")
    assert_close(outputs["lam"], pd.lambda_c, TOL, f"{what}: lambda vs constraintDynamics")
    if "dqdd" in outputs:
        d = pin.computeConstraintDynamicsDerivatives(pm, pd, models, datas, prox())
        dqdd, dlam = outputs["dqdd"], outputs["dlam"]
        for name, mine, theirs in (("ddq_dq", dqdd[:, :nq] @ T, d[0]), ("ddq_dv", dqdd[:, nq:nq + nv], d[1]),
                                   ("ddq_dtau", dqdd[:, nq + nv:], d[2]), ("dlambda_dq", dlam[:, :nq] @ T, d[3]),
                                   ("dlambda_dv", dlam[:, nq:nq + nv], d[4]), ("dlambda_dtau", dlam[:, nq + nv:], d[5])):
            assert_close(mine, theirs, TOL, f"{what}: {name}")
        along_quaternion(q, nq, nv, [("dqdd", dqdd), ("dlam", dlam)], what)
    v_plus = pin.impulseDynamics(pm, pd, q, v, models, datas, e, prox())
    assert_close(outputs["v_plus"], v_plus, TOL, f"{what}: v+ vs impulseDynamics")
    assert_close(outputs["impulse"], pd.impulse_c, TOL, f"{what}: impulse vs impulseDynamics")
    if "dv_plus" in outputs:
        pin.computeImpulseDynamicsDerivatives(pm, pd, models, datas, e, prox())
        dv, dimp = outputs["dv_plus"], outputs["dimpulse"]
        assert_close(dv[:, :nq] @ T, pd.ddq_dq, TOL, f"{what}: dv+/dq")
        assert_close(dv[:, nq:], pd.ddq_dv + np.eye(nv), TOL, f"{what}: dv+/dv- (Pinocchio's ddq_dv is the jump's)")
        assert_close(dimp[:, :nq] @ T, pd.dlambda_dq, TOL, f"{what}: dimpulse/dq")
        assert_close(dimp[:, nq:], pd.dlambda_dv, TOL, f"{what}: dimpulse/dv-")
        along_quaternion(q, nq, nv, [("dv_plus", dv), ("dimpulse", dimp)], what)


def along_quaternion(q, nq: int, nv: int, named: list, what: str) -> None:
    """A floating base's quaternion columns are the rotation's: zero along the (unit) quaternion itself."""
    if nq == nv:
        return
    for name, d in named:
        d = np.asarray(d)
        assert np.abs(d[:, 3:7] @ q[3:7]).max() <= 1e-12 * np.abs(d).max(), f"{what}: {name} along the quaternion"


def check_baumgarte(pm, q, v, tau, frames: list[str], anchor, gains, qdd, lam, what: str) -> None:
    """derive's contact_dynamics_baumgarte against constraintDynamics with Baumgarte parameters (Kp, Kd) and each
    point's joint2_placement (on the universe) at its anchor."""
    pd = pm.createData()
    models = []
    for k, frame in enumerate(frames):
        f = pm.frames[pm.getFrameId(frame)]
        c = pin.RigidConstraintModel(pin.ContactType.CONTACT_3D, pm, f.parentJoint, f.placement, 0,
                                     pin.SE3(np.eye(3), np.asarray(anchor[3 * k:3 * k + 3])), pin.LOCAL_WORLD_ALIGNED)
        bp = c.m_baumgarte_parameters
        bp.Kp, bp.Kd = gains
        c.setBaumgarteCorrectorParameters(bp)
        models.append(c)
    models = pin.StdVec_RigidConstraintModel(models)
    datas = pin.StdVec_RigidConstraintData([m.createData() for m in models])
    pin.initConstraintDynamics(pm, pd, models, datas)
    expected = pin.constraintDynamics(pm, pd, q, v, tau, models, datas, prox())
    assert_close(qdd, expected, TOL, f"{what}: qdd vs constraintDynamics with Baumgarte")
    assert_close(lam, pd.lambda_c, TOL, f"{what}: lambda vs constraintDynamics with Baumgarte")


def test_fixed_base_contact_functions_against_pinocchio(tmp_path):
    """rrprr with its tcp held (3 rows of 5 velocities): every contact quantity generated (the parameters
    input p included), Python and C against Pinocchio at seeded states, and A_G' qd, the CoM acceleration."""
    from derive.description.export import to_urdf
    base = load_models()["rrprr"]
    robot = dataclasses.replace(base, name="rrprr_contact", contacts=(Contact("tcp", "point"),),
                                generate_quantities=CONTACT_QUANTITIES + CENTROIDAL_QUANTITIES)
    gen = Generated(robot, tmp_path, jax_too=False)
    fixed = [q for q in CONTACT_QUANTITIES if q != "contact_inverse_dynamics"]  # that one is a floating base's
    assert sorted(gen.fn) == sorted([f"{q}_all" for q in fixed] + list(CENTROIDAL_QUANTITIES))
    pm = pin.buildModelFromXML(to_urdf(base))
    p = np.array([x.default for x in robot.parameters])
    rng = np.random.default_rng(3)
    for _ in range(4):
        q = rng.uniform(-1, 1, pm.nq)
        q[1] = rng.uniform(0, 0.3)
        v, tau = rng.normal(size=pm.nv), 5 * rng.normal(size=pm.nv)
        e = 0.4
        for lang in ("Python", "C"):
            call = gen.python if lang == "Python" else gen.c
            qdd, lam, status = call("contact_dynamics_all", q, v, tau, p)
            dqdd, dlam = call("contact_dynamics_derivatives_all", q, v, tau, p)
            v_plus, imp, status_i = call("impulse_dynamics_all", q, v, e, p)
            dv, dimp = call("impulse_dynamics_derivatives_all", q, v, e, p)
            assert status.item() == status_i.item() == 1.0
            shape = (pm.nv, pm.nq + 2 * pm.nv)
            check_against_pinocchio(pm, q, v, tau, e, [("tcp", "point")], {"tcp": "tcp"}, {
                "qdd": qdd.ravel(), "lam": lam.ravel(), "dqdd": dqdd.reshape(shape), "dlam": dlam.reshape(3, shape[1]),
                "v_plus": v_plus.ravel(), "impulse": imp.ravel(), "dv_plus": dv.reshape(pm.nv, 2 * pm.nv),
                "dimpulse": dimp.reshape(3, 2 * pm.nv)}, f"rrprr ({lang})")
            anchor, gains = rng.normal(size=3), rng.uniform(1, 10, 2)
            qdd_b, lam_b, status_b = call("contact_dynamics_baumgarte_all", q, v, tau, anchor, gains, p)
            assert status_b.item() == 1.0
            check_baumgarte(pm, q, v, tau, ["tcp"], anchor, gains, qdd_b.ravel(), lam_b.ravel(), f"rrprr ({lang})")
            a = rng.normal(size=pm.nv)
            pd = pm.createData()
            pin.computeCentroidalMomentumTimeVariation(pm, pd, q, v, 0 * v)
            assert_close(call("centroidal_map_dot_qd", q, v, p)[0].ravel(), np.r_[pd.dhg.linear, pd.dhg.angular], 1e-12,
                         f"A_G' qd ({lang})")
            pin.centerOfMass(pm, pd, q, v, a)
            assert_close(call("com_acceleration", q, v, a, p)[0].ravel(), pd.acom[0], 1e-12, f"CoM acceleration ({lang})")
            pin.ccrba(pm, pd, q, v)
            assert_close(call("centroidal_inertia", q, p)[0].reshape(3, 3), pd.Ig.inertia, 1e-12, f"I_G ({lang})")


LEGGED = {  # example-robot-data file, contacts (frame, kind), stances (None: one set of all)
    "solo12": ("solo_description/robots/solo12.urdf", [(f, "point") for f in ("FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT")],
               {"stance": ["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"], "trot": ["FL_FOOT", "HR_FOOT"]}),
    "anymal": ("anymal_b_simple_description/robots/anymal.urdf",
               [(f, "point") for f in ("LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT")], None),
    "talos_reduced": ("talos_data/robots/talos_reduced.urdf", [("left_sole_link", "surface"), ("right_sole_link", "surface")],
                      None),
}


def legged(key: str):
    """A robot of :data:`LEGGED` imported whole (floating) with its contacts; per stance its contact functions
    as one CasADi Function of (q, qd, tau, e) (the expressions the generated code prints), the centroidal
    terms as one of (q, qd, qdd), and Pinocchio's free-flyer model of the same URDF."""
    rel, contacts, sets = LEGGED[key]
    name, entry = import_urdf_named("example-robot-data:" + rel, floating=True, friction=False)
    entry = {**entry, "contacts": [{"frame": f, "kind": k} for f, k in contacts]}
    if sets:
        entry["contact_sets"] = sets
    robot = parse_robot(name, entry)
    model = SXModel(robot)
    s, e = model.sym, ca.SX.sym("e")
    functions = {}
    anchor, gains = ca.SX.sym("anchor", 12), ca.SX.sym("gains", 2)
    for stance in robot.stances:
        cm = ContactModel(model, stance)
        functions[stance.name] = ca.Function(stance.name, [s.q, s.qd, s.tau, e], [
            *cm.forward, *cm.forward_derivatives, *cm.impulse(e), *cm.impulse_derivatives(e)])
        if cm.points_only:
            functions[stance.name + "_baumgarte"] = ca.Function("b", [s.q, s.qd, s.tau, anchor[:cm.rows], gains],
                                                                list(cm.stabilised(anchor[:cm.rows], gains)))
    centroidal = ca.Function("centroidal", [s.q, s.qd, s.qdd], [centroidal_map_dot_qd(model), com_acceleration(model),
                                                               centroidal_inertia(model)])
    pm = pin.buildModelFromUrdf(erd(rel), pin.JointModelFreeFlyer())
    return robot, functions, centroidal, pm


@pytest.fixture(scope="module", params=sorted(LEGGED))
def legged_robot(request):
    return legged(request.param)


def test_legged_contact_dynamics_against_pinocchio(legged_robot):
    """The issue's Done-when on solo12 (four feet and a trot pair), anymal (four feet) and talos_reduced (both
    soles as surfaces): contact FD and its derivatives, impulse dynamics and its derivatives equal Pinocchio's
    to 1e-9 at seeded states (point stances: with Baumgarte stabilisation too); FD and impulse also the numpy
    reference."""
    robot, functions, _, pm = legged_robot
    nr = NumericRobot(robot)
    rng = np.random.default_rng(4)
    for stance in robot.stances:
        kinds = [(f, robot.contact(f).kind) for f in stance.frames]
        for _ in range(3):
            q = pin.randomConfiguration(pm, -np.ones(pm.nq), np.ones(pm.nq))
            v, tau, e = rng.normal(size=pm.nv), 5 * rng.normal(size=pm.nv), rng.uniform(0, 1)
            qdd, lam, status, dqdd, dlam, v_plus, imp, status_i, dv, dimp = (
                np.asarray(x) for x in functions[stance.name](q, v, tau, e))
            assert status.item() == status_i.item() == 1.0
            check_against_pinocchio(pm, q, v, tau, e, kinds, {}, {
                "qdd": qdd.ravel(), "lam": lam.ravel(), "dqdd": dqdd, "dlam": dlam, "v_plus": v_plus.ravel(),
                "impulse": imp.ravel(), "dv_plus": dv, "dimpulse": dimp}, f"{robot.name} {stance.name}")
            qdd_r, lam_r = ref.contact_dynamics(nr, q, v, tau, kinds)
            assert_close(qdd.ravel(), qdd_r, TOL, "qdd vs the numpy reference")
            assert_close(lam.ravel(), lam_r, TOL, "lambda vs the numpy reference")
            v_r, imp_r = ref.impulse_dynamics(nr, q, v, e, kinds)
            assert_close(v_plus.ravel(), v_r, TOL, "v+ vs the numpy reference")
            assert_close(imp.ravel(), imp_r, TOL, "impulse vs the numpy reference")
            if stance.name + "_baumgarte" in functions:
                anchor, gains = rng.normal(size=3 * len(kinds)), rng.uniform(1, 10, 2)
                qdd_b, lam_b, _ = (np.asarray(x).ravel() for x in functions[stance.name + "_baumgarte"](q, v, tau, anchor, gains))
                check_baumgarte(pm, q, v, tau, list(stance.frames), anchor, gains, qdd_b, lam_b, f"{robot.name} {stance.name}")


def test_legged_centroidal_terms_against_pinocchio(legged_robot):
    """A_G' qd equals computeCentroidalMomentumTimeVariation's dhg at a = 0 to 1e-12, the CoM acceleration
    centerOfMass(q, v, a)'s acom, both the numpy reference's RNEA momentum rate, and the composite inertia
    about the CoM ccrba's Ig."""
    robot, _, centroidal, pm = legged_robot
    pd = pm.createData()
    nr = NumericRobot(robot)
    rng = np.random.default_rng(5)
    for _ in range(5):
        q = pin.randomConfiguration(pm, -np.ones(pm.nq), np.ones(pm.nq))
        v, a = rng.normal(size=(2, pm.nv))
        dh, acc, inertia = (np.asarray(x) for x in centroidal(q, v, a))
        dh, acc = dh.ravel(), acc.ravel()
        pin.ccrba(pm, pd, q, v)
        assert_close(inertia, pd.Ig.inertia, 1e-12, "I_G vs ccrba's Ig")
        pin.computeCentroidalMomentumTimeVariation(pm, pd, q, v, 0 * v)
        assert_close(dh, np.r_[pd.dhg.linear, pd.dhg.angular], 1e-12, "A_G' qd vs Pinocchio")
        pin.centerOfMass(pm, pd, q, v, a)
        assert_close(acc, pd.acom[0], 1e-12, "CoM acceleration vs Pinocchio")
        assert_close(dh, ref.centroidal_momentum_rate(nr, q, v, np.zeros(pm.nv)), 1e-12, "A_G' qd vs the reference")
        assert_close(acc, ref.centroidal_momentum_rate(nr, q, v, a)[:3] / nr.total_mass, 1e-12, "CoM acceleration vs the reference")
