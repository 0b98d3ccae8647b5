"""Closed chains and MuJoCo (docs/closed-chains.md, "MuJoCo"): derive export writes the loops as MuJoCo
equalities (connect, weld; a distance rod as a body on a ball joint whose far end a connect holds) with the
closed reference configuration as a keyframe; MuJoCo, its equalities made stiff, agrees with derive's forward
dynamics in y; derive import-mjcf reads the equalities back as loops (the same M_y and ID_y), and reads
hand-written body and site connect / weld equalities with MuJoCo's own meaning (its constraint residuals at
random q)."""

from __future__ import annotations

import re
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest
import yaml

from derive.cli import main
from derive.description.closure import Poses
from derive.description.export import FLOOR, quat_between, export_mjcf
from derive.description.mjcf import import_mjcf
from derive.description.model import load_models, parse_robot
from derive.reference.closure import ClosedChainReference

MODELS = Path(__file__).resolve().parent.parent / "models.yaml"
CONNECT = ("fourbar", "slider_crank", "fivebar", "example2")  # planar loops -> <connect>
RODS = ("delta", "parallel_ankle")  # distance loops -> a rod body on a ball joint, its end held by <connect>
SHIPPED = CONNECT + RODS
EPS = 1e-4
"""MuJoCo's regularisation (1 - d) / d at its stiffest impedance d = 0.9999 (mjMAXIMP)."""
COPIES = 32
"""Each equality written this many times: MuJoCo's soft rows are then springs in parallel, the regularisation
EPS / COPIES (MuJoCo's floor on EPS is per row)."""


@lru_cache(maxsize=None)
def shipped():
    return load_models(MODELS)


@lru_cache(maxsize=None)
def reference(name: str) -> ClosedChainReference:
    return ClosedChainReference(shipped()[name])


def stiff(mujoco, name: str, eps: float, copies: int = 1):
    """The exported MJCF compiled, each equality written ``copies`` times, at impedance d = 1 / (1 + eps)
    (regularisation R = eps diagApprox per row), solref 2 ms (which drops out at a closed state with consistent
    rates: r = 0, J qvel = 0)."""
    text = export_mjcf(shipped()[name]).text
    text = re.sub(r"( *)(<connect )name=\"[^\"]*\" (.*\n)", lambda g: g.group(0) + (g.group(1) + g.group(2) + g.group(3))
                  * (copies - 1), text)
    m = mujoco.MjModel.from_xml_string(text)
    assert m.neq == copies * len(shipped()[name].loops)
    d = 1 / (1 + eps)
    m.eq_solref[:] = [0.002, 1.0]
    m.eq_solimp[:] = [d, d, 0.001, 0.5, 2.0]
    m.opt.tolerance = 0.0
    m.opt.iterations = 1000
    return m


def close_rods(mujoco, m, d) -> None:
    """Turns each rod (a body on a ball joint whose end site a connect holds) onto its other site and gives it
    the angular velocity w = u x (v_other - v_ball) / L that keeps its end there (no spin about its own axis;
    the rod's moments are MuJoCo's least, so a spin would not matter), the tree's qpos and qvel as set."""
    for e in range(m.neq):
        end, other = int(m.eq_obj1id[e]), int(m.eq_obj2id[e])
        b = int(m.site_bodyid[end])
        if int(m.body_jntnum[b]) != 1 or int(m.jnt_type[m.body_jntadr[b]]) != int(mujoco.mjtJoint.mjJNT_BALL):
            continue
        j = int(m.body_jntadr[b])
        qa, va = int(m.jnt_qposadr[j]), int(m.jnt_dofadr[j])
        d.qpos[qa:qa + 4], d.qvel[va:va + 3] = [1, 0, 0, 0], 0
        mujoco.mj_forward(m, d)
        length = float(np.linalg.norm(m.site_pos[end]))
        u = (d.site_xpos[other] - d.xpos[b]) / length
        R = d.xmat[b].reshape(3, 3)
        d.qpos[qa:qa + 4] = quat_between(m.site_pos[end] / length, R.T @ u)
        v_other, v_ball = np.zeros(6), np.zeros(6)
        mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_SITE, other, v_other, 0)
        mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_BODY, b, v_ball, 0)  # [w; v] of the parent at the ball
        mujoco.mj_kinematics(m, d)
        w = np.cross(u, v_other[3:] - v_ball[3:]) / length
        d.qvel[va:va + 3] = d.xmat[b].reshape(3, 3).T @ (w - v_ball[:3])  # a ball's qvel: relative, in the rod frame


def mujoco_ydd(mujoco, name: str, q, qd, tau_y, eps: float, copies: int = 1) -> np.ndarray:
    """MuJoCo's qacc at (q, qd) with tau_y on the independent joints (qfrc_applied), read on y."""
    robot, ref = shipped()[name], reference(name)
    m = stiff(mujoco, name, eps, copies)
    d = mujoco.MjData(m)
    joints = [m.joint(c.name) for c in robot.coordinates]
    for i, j in enumerate(joints):
        d.qpos[j.qposadr[0]], d.qvel[j.dofadr[0]] = q[i], qd[i]
    close_rods(mujoco, m, d)
    for k, i in enumerate(ref.y):
        d.qfrc_applied[joints[i].dofadr[0]] = tau_y[k]
    mujoco.mj_forward(m, d)
    rows = d.efc_type == mujoco.mjtConstraint.mjCNSTR_EQUALITY
    assert rows.any() and np.abs(d.efc_pos[rows]).max() <= 1e-12  # the state is closed
    assert np.abs(d.efc_vel[rows]).max() <= 1e-12 * max(1.0, np.abs(qd).max())  # and its rates consistent
    return np.array([d.qacc[joints[i].dofadr[0]] for i in ref.y])


def states(name: str, moving: bool):
    ref = reference(name)
    for seed in range(3):
        rng = np.random.default_rng(seed)
        ny = len(ref.y)
        q, residual = ref.closure(ref.q_ref[ref.y] + rng.uniform(-0.1, 0.1, ny))
        assert residual <= 1e-12
        yd = rng.normal(size=ny) if moving else np.zeros(ny)
        yield q, yd, rng.normal(size=ny)


@pytest.mark.parametrize("moving", [False, True], ids=["at_rest", "moving"])
@pytest.mark.parametrize("name", SHIPPED)
def test_mujoco_agrees_on_ydd(mujoco, name, moving):
    """At 3 closed states with random tau_y, at rest or moving (yd random, qvel = G yd, the rods turning with
    the mechanism): MuJoCo's ydd is derive's forward dynamics (Gdot yd included: MuJoCo's connect rows carry
    the loop's velocity product Jdot qvel) up to its regularisation, which is linear in eps = (1 - d) / d:
    - eps = 1e-4 and 2e-4 extrapolated to 0 (Richardson) agree to 1e-5 relative (observed <= 3.3e-6, the Delta
      moving; the ankle 1.7e-7, the planar ones 2.3e-8);
    - raw, at MuJoCo's stiffest d = 0.9999, one equality per loop: within 1e-4 for the planar mechanisms
      (observed <= 5.9e-5); 7.3e-4 (1.6e-3 moving) for the Delta and 7.9e-4 for the ankle, whose light arms
      and cranks take up MuJoCo's soft rows' give (eps diagApprox f: diagApprox 3.96 and 5.3 / kg, the inverse
      masses at the rods' ends, against 0.7 / kg for the four-bar);
    - raw, each equality written COPIES = 32 times (the regularisation eps / 32): within 1e-4 for all six
      (observed <= 5.0e-5, the Delta moving; the ankle 2.5e-5)."""
    ref = reference(name)
    for q, yd, tau in states(name, moving):
        ydd = ref.forward_dynamics(q, yd, tau)
        scale = np.abs(ydd).max()
        qd = ref.projection(q) @ yd
        one, two = (mujoco_ydd(mujoco, name, q, qd, tau, k * EPS) for k in (1, 2))
        assert np.abs(2 * one - two - ydd).max() <= 1e-5 * scale
        raw = np.abs(one - ydd).max() / scale
        assert raw <= (1e-4 if name in CONNECT else 2e-3)
        assert np.abs(two - ydd).max() / scale == pytest.approx(2 * raw, rel=0.05)  # linear in eps
        assert np.abs(mujoco_ydd(mujoco, name, q, qd, tau, EPS, COPIES) - ydd).max() <= 1e-4 * scale


def as_exported(name: str) -> dict:
    """The models.yaml entry with the massless links' mass and moments raised as the MJCF holds them."""
    entry = yaml.safe_load(MODELS.read_text())["robots"][name]
    robot = shipped()[name]
    largest = max(float(Poses(robot).num(lk.mass)) for lk in robot.links)
    for link in entry["links"]:
        if name == "delta" and link["name"].startswith("carriage"):
            link.update(mass=FLOOR * largest, inertia=[1e-14] * 3)
    return entry


@pytest.mark.parametrize("name", SHIPPED)
def test_export_and_import_back_gives_the_same_reduced_model(mujoco, name, tmp_path):
    """derive export --mjcf, then derive import-mjcf: the same loops, independent coordinates and closed
    reference configuration (the keyframe 'reference'); M_y and ID_y at 3 states agree to 1e-12 relative
    (observed 2e-15) with the model as the MJCF holds it (the Delta's massless carriages raised to MuJoCo's
    least mass)."""
    robot = shipped()[name]
    path = tmp_path / f"{name}.xml"
    assert main(["export", "--models", str(MODELS), name, "--mjcf", str(path)]) == 0
    back = parse_robot(name, import_mjcf(path))
    original = parse_robot(name, as_exported(name))
    assert back.independent == robot.independent and back.dependent == robot.dependent
    assert [(lp.a, lp.b) for lp in back.loops] == [(lp.a, lp.b) for lp in robot.loops]
    assert [lp.kind for lp in back.loops] == ["point" if name in CONNECT else "distance"] * len(robot.loops)
    assert [float(Poses(back).num(lp.length)) for lp in back.loops if lp.kind == "distance"] == [
        float(Poses(robot).num(lp.length)) for lp in robot.loops if lp.kind == "distance"]
    names = [c.name for c in back.coordinates]
    order = [names.index(c.name) for c in robot.coordinates]
    np.testing.assert_allclose(np.array(back.reference_q)[order], robot.reference_q, rtol=0, atol=1e-12)
    a, b = ClosedChainReference(original), ClosedChainReference(back)
    for q, yd, ydd in states(name, moving=True):
        qb = np.zeros(len(q))
        qb[order] = q
        Ma, ta = a.mass_matrix(q), a.inverse_dynamics(q, yd, ydd)
        assert np.abs(b.mass_matrix(qb) - Ma).max() <= 1e-12 * np.abs(Ma).max()
        assert np.abs(b.inverse_dynamics(qb, yd, ydd) - ta).max() <= 1e-12 * np.abs(ta).max()


# --------------------------------------------------------------------------- hand-written MJCF


# A planar parallelogram four-bar (crank, coupler, rocker; hinges about z), drawn closed at qpos0 with a
# 0.1 rad ref on the crank, then three more ways to close a loop: connect between sites, weld of a body
# to the world (a 4R chain welded at its tip), weld between sites.
FOURBAR = """<mujoco model="{name}"><compiler angle="radian"/><option gravity="0 -9.81 0"/>
<worldbody>
  <body name="crank"><joint name="crank" axis="0 0 1" ref="0.1" actuatorfrcrange="-5 5"/>
    <inertial pos="0 0.1 0" mass="0.3" diaginertia="1e-3 1e-5 1e-3"/>
    <body name="coupler" pos="0 0.2 0"><joint name="coupler" axis="0 0 1"/>
      <inertial pos="0.25 0 0" mass="0.6" diaginertia="1e-5 1e-2 1e-2"/><site name="c_end" pos="0.5 0 0"/></body></body>
  <body name="rocker" pos="0.5 0 0"><joint name="rocker" axis="0 0 1"/>
    <inertial pos="0 0.1 0" mass="0.4" diaginertia="1e-3 1e-5 1e-3"/><site name="r_end" pos="0 0.2 0"/></body>
</worldbody>
<equality>{equality}</equality></mujoco>"""
CHAIN = """<mujoco model="chain"><compiler angle="radian"/><option gravity="0 -9.81 0"/>
<worldbody><site name="ground_site" pos="0.3 0.4 0" euler="0 0 0.3"/>
  <body name="l1" euler="0 0 0.9"><joint name="j1" axis="0 0 1"/><inertial pos="0.1 0 0" mass="0.3" diaginertia="1e-5 1e-3 1e-3"/>
    <body name="l2" pos="0.2 0 0" euler="0 0 -0.8"><joint name="j2" axis="0 0 1"/><inertial pos="0.1 0 0" mass="0.3" diaginertia="1e-5 1e-3 1e-3"/>
      <body name="l3" pos="0.2 0 0" euler="0 0 -0.9"><joint name="j3" axis="0 0 1"/><inertial pos="0.1 0 0" mass="0.3" diaginertia="1e-5 1e-3 1e-3"/>
        <body name="l4" pos="0.2 0 0" euler="0 0 -0.7"><joint name="j4" axis="0 0 1"/><inertial pos="0.05 0 0" mass="0.2" diaginertia="1e-5 1e-3 1e-3"/>
          <site name="tip" pos="0.1 0 0"/></body></body></body></body>
</worldbody>
<equality>{equality}</equality></mujoco>"""


def write(tmp_path, text: str, name: str = "m") -> Path:
    path = tmp_path / f"{name}.xml"
    path.write_text(text)
    return path


def mujoco_residuals(mujoco, path: Path, robot, seed: int):
    """At a random q (off the closure): MuJoCo's equality residuals (efc_pos, per equality) and derive's
    frames' world poses (numpy, the description's forward kinematics)."""
    m = mujoco.MjModel.from_xml_path(str(path))
    d = mujoco.MjData(m)
    q = np.random.default_rng(seed).uniform(-1, 1, robot.nq)
    for c, value in zip(robot.coordinates, q):
        d.qpos[m.joint(c.name).qposadr[0]] = value
    mujoco.mj_forward(m, d)
    rows = d.efc_type == mujoco.mjtConstraint.mjCNSTR_EQUALITY
    return [d.efc_pos[rows & (d.efc_id == e)] for e in range(m.neq)], Poses(robot)(q)


@pytest.mark.parametrize("equality", ['<connect name="pin" body1="coupler" body2="rocker" anchor="0.5 0 0"/>',
                                      '<connect site1="c_end" site2="r_end"/>'])
def test_hand_written_connect_means_what_it_means_to_mujoco(mujoco, tmp_path, equality):
    """The body form's frames (anchor in body1; body2's point from MuJoCo's qpos0) and the site form's: at
    random q MuJoCo's residual rows are derive's d = p_a - p_b (1e-14); derive closes the loop at qpos0
    (the crank's ref 0.1 rad is the reference) with the crank (it has an effort limit) independent."""
    path = write(tmp_path, FOURBAR.format(name="par", equality=equality))
    entry = import_mjcf(path)
    robot = parse_robot("par", entry)
    assert robot.independent == ("crank",) and entry["reference"] == {"crank": 0.1}
    lp = robot.loops[0]
    assert lp.kind == "point" and ((lp.a, lp.b) == ("pin_a", "pin_b") if "pin" in equality else ("c_end", "r_end"))
    for seed in range(3):
        residuals, poses = mujoco_residuals(mujoco, path, robot, seed)
        np.testing.assert_allclose(residuals[0], poses[lp.a][1] - poses[lp.b][1], rtol=0, atol=1e-14)
    q, residual = ClosedChainReference(robot).closure([0.3])
    assert residual <= 1e-12


def test_hand_written_weld_means_what_it_means_to_mujoco(mujoco, tmp_path):
    """A planar 4R chain whose tip is welded to the world (body form, torquescale 3) or to a world site (site
    form): derive's weld loop (6 rows, rank 3: mobility 1); at random q MuJoCo's position rows are derive's
    d and its rotation rows have norm torquescale sin(theta / 2), theta the turn between derive's frames."""
    for equality, scale in (('<weld body1="world" body2="l4" anchor="0.1 0 0" torquescale="3"/>', 3.0),
                            ('<weld site1="ground_site" site2="tip"/>', 1.0)):
        # the site form: drawn so that tip = ground_site at qpos0 is not needed; close the chain there first
        path = write(tmp_path, CHAIN.format(equality=equality), "chain")
        if "site1" in equality:
            m = mujoco.MjModel.from_xml_path(str(path))
            d = mujoco.MjData(m)
            mujoco.mj_forward(m, d)
            tip = d.site_xpos[m.site("tip").id].copy()
            R = d.site_xmat[m.site("tip").id].reshape(3, 3)
            turn = np.arctan2(R[1, 0], R[0, 0])
            path.write_text(path.read_text().replace('pos="0.3 0.4 0" euler="0 0 0.3"',
                                                     f'pos="{float(tip[0])!r} {float(tip[1])!r} 0" euler="0 0 {float(turn)!r}"'))
        robot = parse_robot("chain", import_mjcf(path))
        assert robot.loops[0].kind == "weld" and len(robot.independent) == 1 and len(robot.loop_rows) == 3
        for seed in range(3):
            residuals, poses = mujoco_residuals(mujoco, path, robot, seed)
            lp = robot.loops[0]
            (Ra, pa), (Rb, pb) = poses[lp.a], poses[lp.b]
            np.testing.assert_allclose(residuals[0][:3], pa - pb, rtol=0, atol=1e-14)
            theta = np.arccos(np.clip((np.trace(Ra.T @ Rb) - 1) / 2, -1, 1))
            assert np.linalg.norm(residuals[0][3:]) == pytest.approx(scale * np.sin(theta / 2), rel=1e-12, abs=1e-15)


def test_import_mjcf_independent_option_and_the_source_line(mujoco, tmp_path, capsys):
    path = write(tmp_path, FOURBAR.format(name="par", equality='<connect site1="c_end" site2="r_end"/>'))
    models = tmp_path / "models.yaml"
    assert main(["import-mjcf", str(path), "--independent", "rocker", "--out", str(models)]) == 0
    robot = load_models(models)["par"]
    assert robot.independent == ("rocker",) and not robot.independent_chosen
    assert "--independent rocker" in robot.source
    capsys.readouterr()
    assert main(["info", "--models", str(models), "par"]) == 0
    assert "loops[0]: c_end = r_end (point, 3 rows)" in capsys.readouterr().out


FLOATING = """<mujoco model="par"><worldbody><body name="base"><freejoint/>
<inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/><site name="s0" pos="0.2 0 0"/>
<body name="arm"><joint name="j" axis="0 0 1"/><inertial pos="0.1 0 0" mass="1" diaginertia="1 1 1"/>
<site name="s1" pos="0.2 0 0"/></body></body></worldbody><equality>{equality}</equality></mujoco>"""
REFUSED = {
    "apart": ('<connect site1="c_end" site2="r_end"/>', {"0.5 0 0\"/></body></body>": "0.9 0 0\"/></body></body>"},
              [], "loops[0].frames: 'c_end' and 'r_end' do not close at the reference configuration: residual "
                  "max |phi| = "),
    "torquescale": ('<weld body1="coupler" body2="rocker" torquescale="0"/>', {}, [],
                    "equality 0: torquescale 0 leaves the rotation free: write it as <connect>"),
    "independent": ('<connect site1="c_end" site2="r_end"/>', {}, ["--independent", "crank,rocker"],
                    "independent: 2 coordinate(s) given, but the loops leave nq - rank K = 3 - 2 = 1"),
    "no loops": ("", {}, ["--independent", "crank"], "--independent: only a closed chain"),
    "keyframe": ('<connect site1="c_end" site2="r_end"/>', {}, ["--keyframe", "home"],
                 "<key name=\"home\">: no keyframe of that name (keyframes: none)"),
    "tendon": ('<tendon tendon1="t" polycoef="0 1 0 0 0"/>', {"</worldbody>": "</worldbody><tendon><spatial name=\"t\">"
               "<site site=\"c_end\"/><site site=\"r_end\"/></spatial></tendon>"}, [],
               "equality 0: <tendon> equality constraints are supported only as a distance loop"),
    "floating": ('<connect site1="s0" site2="s1"/>', FLOATING, [],
                 "loops: closed chains need a fixed base here; this robot has a floating base (in the imported entry)"),
}


@pytest.mark.parametrize("case", sorted(REFUSED))
def test_closed_chain_import_refusals_are_one_line(mujoco, tmp_path, capsys, case):
    equality, edits, args, message = REFUSED[case]
    text = (edits if isinstance(edits, str) else FOURBAR).format(name="par", equality=equality)
    for old, new in ({} if isinstance(edits, str) else edits).items():
        assert old in text
        text = text.replace(old, new)
    path = write(tmp_path, text)
    assert main(["import-mjcf", str(path), *args]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"derive: error: {path}: robot 'par': ") and message in err, err


def test_export_refuses_what_mujoco_cannot_hold(tmp_path, capsys):
    """A hinge loop (MuJoCo has no hinge equality) and a planar loop whose frames are apart along the normal
    are one line each; URDF export notes that it leaves the loops out."""
    entry = yaml.safe_load(MODELS.read_text())["robots"]["fourbar"]
    hinge = dict(entry, loops=[{"frames": ["coupler_tip", "rocker_tip"], "kind": "hinge", "axis": [0, 0, 1]}])
    models = tmp_path / "models.yaml"
    models.write_text(yaml.safe_dump({"robots": {"fourbar": hinge}}))
    assert main(["export", "--models", str(models), "fourbar", "--mjcf", str(tmp_path / "f.xml")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "loops[0]: MuJoCo has no hinge equality" in err, err
    assert not (tmp_path / "f.xml").exists()
    planar = dict(entry, frames=[{"name": "coupler_tip", "link": "coupler", "xyz": ["b", 0, 0]},
                                 {"name": "rocker_tip", "link": "rocker", "xyz": ["c", 0, 0.1]}])
    models.write_text(yaml.safe_dump({"robots": {"fourbar": planar}}))
    assert main(["export", "--models", str(models), "fourbar", "--mjcf", str(tmp_path / "f.xml")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "loops[0]: a planar loop is a <connect> in MJCF only where its frames coincide at " \
                                    "the reference configuration: they are 0.1 m apart along the normal" in err, err
    assert main(["export", "--models", str(MODELS), "fourbar", "--urdf", str(tmp_path / "f.urdf")]) == 0
    assert "URDF has no loop closures: the 1 loop(s) are left out" in capsys.readouterr().err
