"""MJCF import through MuJoCo's compiler (``derive import-mjcf``), checked against MuJoCo and Pinocchio.

Fixtures of the project's own (tests/fixtures/mjcf/): ``arm.xml`` (fixed base: an <include> of
defaults and classes, degrees, every orientation spelling, a joint ref, anchors off the body origin,
several joints in one body, a welded body with mass, sites, armature, damping, frictionloss, gears
and a linear equality joint coupling) and ``walker.xml`` (floating: a free joint, a ball joint,
three hinges in one body at an anchor, welded feet, sites, a <frame>).

Conventions converted here (derive.description.mjcf states them): derive's q is MuJoCo's qpos but
for a free joint (derive [p, x y z w], MuJoCo [p, w x y z]), a ball (derive ZYX angles, MuJoCo a
quaternion) and a mimic joint (no entry in derive). MuJoCo's qvel = T(q) v with T: a free joint's
linear block R (derive's linear velocity is in the body frame, MuJoCo's in the world), a ball's
E(q) (Euler rates -> body angular velocity), a mimic's multiplier in its leader's column. Then
qacc = T a + Tdot v, M = T^T M_mj T and tau = T^T tau_mj. MuJoCo's qM holds the armature, its
mj_rne does not, nor damping (a passive force) or frictionloss (a constraint): they are added as
arm qacc + damping qvel + frictionloss sign(qvel). Pinocchio (rigid bodies only) is compared with
MuJoCo's rigid-body part (qM less the armature, mj_rne).

Without the mujoco package the MuJoCo tests are skipped, except in CI (CI=true), where that fails.
"""

from __future__ import annotations

import sys
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from derive.cli import main
from derive.description.mjcf import import_mjcf, import_mjcf_named
from derive.description.model import parse_robot
from derive.reference import NumericRobot
from derive.symbolic.model import SXModel

FIXTURES = Path(__file__).resolve().parent / "fixtures" / "mjcf"
SAMPLES = 5
TOL_MUJOCO = 1e-10
TOL_PINOCCHIO = 1e-9


# --------------------------------------------------------------------------- the conversions


def euler_rates(y: float, x: float) -> np.ndarray:
    """E of w_body = E [dz, dy, dx] for R = Rz(z) Ry(y) Rx(x)."""
    sy, cy, sx, cx = np.sin(y), np.cos(y), np.sin(x), np.cos(x)
    return np.array([[-sy, 0.0, 1.0], [cy * sx, cx, 0.0], [cy * cx, -sx, 0.0]])


def euler_rates_dot(y: float, x: float, dy: float, dx: float) -> np.ndarray:
    sy, cy, sx, cx = np.sin(y), np.cos(y), np.sin(x), np.cos(x)
    return np.array([[-cy * dy, 0.0, 0.0],
                     [-sy * sx * dy + cy * cx * dx, -sx * dx, 0.0],
                     [-sy * cx * dy - cy * sx * dx, -cx * dx, 0.0]])


def zyx_quaternion(z: float, y: float, x: float) -> np.ndarray:
    """(w, x, y, z) of Rz(z) Ry(y) Rx(x): the product of the three half-angle quaternions."""
    def mul(a, b):
        return np.array([a[0] * b[0] - a[1:] @ b[1:], *(a[0] * b[1:] + b[0] * a[1:] + np.cross(a[1:], b[1:]))])
    qz = np.array([np.cos(z / 2), 0, 0, np.sin(z / 2)])
    qy = np.array([np.cos(y / 2), 0, np.sin(y / 2), 0])
    qx = np.array([np.cos(x / 2), np.sin(x / 2), 0, 0])
    return mul(mul(qz, qy), qx)


def quat_xyzw_matrix(q) -> np.ndarray:
    x, y, z, w = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


class Map:
    """derive (q, v, a) of a robot imported from MuJoCo model ``m`` -> MuJoCo's (qpos, qvel, qacc), and T."""

    def __init__(self, mujoco, m, robot):
        self.mj, self.m, self.robot = mujoco, m, robot
        self.qi = {c.name: i for i, c in enumerate(robot.coordinates)}
        self.vi = {n: i for i, n in enumerate(robot.velocity_names)}
        self.mimic = {j.name: j.mimic for j in robot.joints if j.mimic is not None}

    def __call__(self, q, v, a):
        m, mj = self.m, self.mj
        qpos, T, tdot_v = np.zeros(m.nq), np.zeros((m.nv, len(v))), np.zeros(m.nv)
        for j in range(m.njnt):
            name, kind = m.joint(j).name, int(m.jnt_type[j])
            p, d = int(m.jnt_qposadr[j]), int(m.jnt_dofadr[j])
            if kind == int(mj.mjtJoint.mjJNT_FREE):
                R = quat_xyzw_matrix(q[3:7])
                qpos[p:p + 3], qpos[p + 3], qpos[p + 4:p + 7] = q[:3], q[6], q[3:6]
                T[d:d + 3, 0:3], T[d + 3:d + 6, 3:6] = R, np.eye(3)
                tdot_v[d:d + 3] = R @ np.cross(v[3:6], v[0:3])  # d/dt (R v_body) = R (a_body + w x v_body)
            elif kind == int(mj.mjtJoint.mjJNT_BALL):
                z, y, x = (q[self.qi[f"{name}_{s}"]] for s in "zyx")
                cols = [self.vi[f"{name}_{s}"] for s in "zyx"]
                qpos[p:p + 4] = zyx_quaternion(z, y, x)
                T[d:d + 3, cols] = euler_rates(y, x)
                tdot_v[d:d + 3] = euler_rates_dot(y, x, v[cols[1]], v[cols[2]]) @ v[cols]
            elif name in self.mimic:
                mimic = self.mimic[name]
                qpos[p] = mimic.multiplier * q[self.qi[mimic.joint]] + mimic.offset
                T[d, self.vi[mimic.joint]] = mimic.multiplier
            else:
                qpos[p] = q[self.qi[name]]
                T[d, self.vi[name]] = 1.0
        return qpos, T @ v, T @ a + tdot_v, T


def mujoco_dynamics(mujoco, m, qpos, qvel, qacc):
    """(M with armature, M of the rigid bodies, tau with the actuators, tau of the rigid bodies, data)."""
    d = mujoco.MjData(m)
    d.qpos[:], d.qvel[:] = qpos, qvel
    mujoco.mj_forward(m, d)
    M = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, M)
    d.qacc[:] = qacc
    rne = np.zeros(m.nv)
    mujoco.mj_rne(m, d, 1, rne)
    actuators = m.dof_armature * qacc + m.dof_damping * qvel + m.dof_frictionloss * np.sign(qvel)
    return M, M - np.diag(m.dof_armature), rne + actuators, rne, d


def symbolic(robot):
    """CasADi functions of the derived model (what the generated code is printed from): M(q), the inverse
    dynamics (q, qd, qdd) and the poses of ``robot.frame_names`` stacked (4 rows each)."""
    sx = SXModel(robot)
    s = sx.sym
    return (ca.Function("M", [s.q], [sx.mass_matrix("newton-euler")]),
            ca.Function("ID", [s.q, s.qd, s.qdd], [sx.inverse_dynamics("newton-euler")]),
            ca.Function("FK", [s.q], [ca.vertcat(*[sx.fk(n) for n in robot.frame_names])]))


def compare(mujoco, file: str, pin=None) -> dict[str, float]:
    """Max errors of derive's reference, its derived model (CasADi) and Pinocchio (if given) against MuJoCo
    at seeded random states."""
    m = mujoco.MjModel.from_xml_path(str(FIXTURES / file))
    name, entry = import_mjcf_named(FIXTURES / file)
    robot = parse_robot(name, entry)
    ref = NumericRobot(robot)
    sym_M, sym_id, sym_fk = symbolic(robot)
    row = {n: 4 * i for i, n in enumerate(robot.frame_names)}
    pinr = pin.PinRobot(robot) if pin is not None else None
    convert = Map(mujoco, m, robot)
    rng = np.random.default_rng(0)
    errors = dict.fromkeys(["M", "tau", "pose", "sym M", "sym tau", "sym pose", "pin M", "pin tau", "pin pose"], 0.0)
    bodies = [b for b in range(1, m.nbody) if m.body(b).name in robot.frame_names]
    sites = [s for s in range(m.nsite) if m.site(s).name in robot.frame_names]
    for _ in range(SAMPLES):
        q = ref.random_configuration(rng)
        v, a = rng.normal(size=robot.nv), rng.normal(size=robot.nv)
        qpos, qvel, qacc, T = convert(q, v, a)
        M, M_rigid, tau, tau_rigid, d = mujoco_dynamics(mujoco, m, qpos, qvel, qacc)
        errors["M"] = max(errors["M"], np.abs(ref.crba(q) - T.T @ M @ T).max())
        errors["tau"] = max(errors["tau"], np.abs(ref.rnea(q, v, a) - T.T @ tau).max())
        fk = ref.fk(q)
        placed = [(m.body(b).name, d.xpos[b], d.xmat[b]) for b in bodies]
        placed += [(m.site(s).name, d.site_xpos[s], d.site_xmat[s]) for s in sites]
        for frame, xpos, xmat in placed:
            errors["pose"] = max(errors["pose"], np.abs(fk[frame][:3, 3] - xpos).max(),
                                 np.abs(fk[frame][:3, :3] - xmat.reshape(3, 3)).max())
        errors["sym M"] = max(errors["sym M"], np.abs(np.array(sym_M(q)) - T.T @ M @ T).max())
        errors["sym tau"] = max(errors["sym tau"], np.abs(np.array(sym_id(q, v, a)).ravel() - T.T @ tau).max())
        poses = np.array(sym_fk(q))
        for frame, xpos, xmat in placed:
            pose = poses[row[frame]:row[frame] + 4]
            errors["sym pose"] = max(errors["sym pose"], np.abs(pose[:3, 3] - xpos).max(),
                                     np.abs(pose[:3, :3] - xmat.reshape(3, 3)).max())
        if pinr is not None:
            errors["pin M"] = max(errors["pin M"], np.abs(pinr.crba(q) - T.T @ M_rigid @ T).max())
            errors["pin tau"] = max(errors["pin tau"], np.abs(pinr.rnea(q, v, a) - T.T @ tau_rigid).max())
            for frame, xpos, xmat in placed:
                pose = pinr.pose(q, frame)
                errors["pin pose"] = max(errors["pin pose"], np.abs(pose[:3, 3] - xpos).max(),
                                         np.abs(pose[:3, :3] - xmat.reshape(3, 3)).max())
    errors["frames"] = len(placed)
    return errors


@pytest.fixture(scope="module")
def pin():
    pytest.importorskip("pinocchio")
    import pin_model
    return pin_model


# --------------------------------------------------------------------------- against MuJoCo and Pinocchio


@pytest.mark.parametrize("file, frames", [("arm.xml", 11), ("walker.xml", 11)])
def test_import_matches_mujoco_and_pinocchio(mujoco, pin, file, frames, capsys):
    """M, inverse dynamics (armature, damping and frictionloss included) and every body and site pose of
    the imported model, by the reference and by the derived CasADi model the generated code is printed
    from, agree with MuJoCo's mj_fullM, mj_rne and xpos/xmat to 1e-10, and Pinocchio's crba, rnea and
    frame placements with MuJoCo's rigid-body part to 1e-9, at seeded random states."""
    errors = compare(mujoco, file, pin)
    print(file, {k: f"{v:.1e}" if k != "frames" else v for k, v in errors.items()}, file=sys.stderr)
    assert errors["frames"] == frames  # every MuJoCo body but the world (and the dropped floor), every site
    for key in ("M", "tau", "pose", "sym M", "sym tau", "sym pose"):
        assert errors[key] <= TOL_MUJOCO, (file, key, errors)
    for key in ("pin M", "pin tau", "pin pose"):
        assert errors[key] <= TOL_PINOCCHIO, (file, key, errors)


def test_arm_entry_reads_the_compiled_model(mujoco):
    """Defaults and classes through the <include>, degrees, the ref, the coupling and the gears as MuJoCo
    compiled them: armature/damping/frictionloss per class, j3's ref in the origin (q = qpos), the mimic
    fr = fl + 0.001, the motor gear 100 of j1; welded bodies and sites as frames."""
    entry = import_mjcf(FIXTURES / "arm.xml")
    joints = {j["name"]: j for j in entry["joints"]}
    assert list(joints) == ["j1", "j2", "j3", "j3_slide", "wx", "wy", "wz", "fl", "fr"]
    assert joints["j1"]["actuator"] == {"armature": 0.1, "viscous": 1.5, "coulomb": 0.2, "gear_ratio": 100.0}
    assert joints["j2"]["actuator"] == {"armature": 0.3, "viscous": 3.0, "coulomb": 0.2}
    assert joints["fl"]["actuator"] == {"armature": 0.002, "viscous": 0.1, "gear_ratio": 5.0}
    assert joints["fr"]["mimic"] == {"joint": "fl", "multiplier": 1.0, "offset": 0.001}
    assert joints["j1"]["limits"] == {"lower": -170 * np.pi / 180, "upper": 170 * np.pi / 180}
    assert [(j["parent"], j["child"]) for j in entry["joints"][:4]] == [
        ("world", "base"), ("base", "upper_j2"), ("upper_j2", "fore_j3"), ("fore_j3", "fore")]
    frames = {f["name"]: f["link"] for f in entry["frames"]}
    assert frames == {"mount": "world", "upper": "upper_j2", "wrist": "wrist_wz", "camera": "wrist_wz",
                      "origin_marker": "world", "tool": "wrist_wz", "lens": "wrist_wz"}
    assert entry["source"] == "arm.xml, imported by `derive import-mjcf " + str(FIXTURES / "arm.xml") + "`"
    ideal = import_mjcf(FIXTURES / "arm.xml", actuators=False)
    assert not any("actuator" in j for j in ideal["joints"])


def test_walker_floats_as_the_file_says_and_fixed_on_request(mujoco, capsys):
    """The free joint gives base: floating (the floor dropped); --fixed welds the torso at its initial
    pose (z 1.2, euler 0.1 0.2 0.3 rad: MuJoCo's default xyz sequence); the ball joint is spherical."""
    floating = parse_robot("walker", import_mjcf(FIXTURES / "walker.xml"))
    assert floating.floating and floating.root == "torso" and floating.nv == 6 + 3 + 8
    assert next(j for j in floating.joints if j.name == "neck").type == "spherical"
    fixed = parse_robot("walker", import_mjcf(FIXTURES / "walker.xml", floating=False))
    assert not fixed.floating and fixed.root == "world" and fixed.nv == 3 + 8
    m = mujoco.MjModel.from_xml_path(str(FIXTURES / "walker.xml"))
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)  # qpos0: the torso at its initial pose
    pose = NumericRobot(fixed).fk(np.zeros(fixed.nq))["torso"]
    torso = m.body("torso").id
    assert np.abs(pose[:3, 3] - d.xpos[torso]).max() <= 1e-15
    assert np.abs(pose[:3, :3] - d.xmat[torso].reshape(3, 3)).max() <= 1e-15


# --------------------------------------------------------------------------- the command and its refusals


def test_command_prints_and_appends(mujoco, tmp_path, capsys):
    assert main(["import-mjcf", str(FIXTURES / "arm.xml")]) == 0
    out = capsys.readouterr().out
    assert out.startswith("  # mjcf_arm: generated by `derive import-mjcf` from arm.xml")
    models = tmp_path / "models.yaml"
    assert main(["import-mjcf", str(FIXTURES / "walker.xml"), "--fixed", "--no-actuators", "--name", "w",
                 "--out", str(models)]) == 0
    from derive.description.model import load_models
    robot = load_models(models)["w"]
    assert not robot.floating and not robot.actuated
    assert "--fixed --no-actuators --name w" in robot.source


REFUSED = {
    "connect": ('<equality><connect name="loop" body1="b" body2="world" anchor="0 0 0"/></equality>',
                "<equality name=\"loop\">: <connect> closes a kinematic loop: closed chains are not supported yet"),
    "weld": ('<equality><weld body1="b"/></equality>',
             "equality 0: <weld> closes a kinematic loop"),
    "polycoef": ('<equality><joint joint1="j2" joint2="j1" polycoef="0 1 0.5 0 0"/></equality>',
                 "equality 0: polycoef 0 1 0.5 0 0 is not linear: only q1 = c0 + c1 q2 couplings"),
}
BODY = ('<mujoco model="tiny"><worldbody><body name="b"><joint name="j1"/><geom size="0.1"/>'
        '<body name="c" pos="0 0 0.3"><joint name="j2"/><geom size="0.1"/></body></body></worldbody>{}</mujoco>')


@pytest.mark.parametrize("kind", sorted(REFUSED))
def test_refusals_are_one_line(mujoco, tmp_path, capsys, kind):
    xml, message = REFUSED[kind]
    path = tmp_path / "tiny.xml"
    path.write_text(BODY.format(xml))
    assert main(["import-mjcf", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"derive: error: {path}: robot 'tiny': {message}"), err


def test_urdf_is_not_read_through_mujoco(tmp_path, capsys):
    """A URDF given to import-mjcf is refused before MuJoCo sees it; an MJCF given to import-urdf names
    import-mjcf."""
    urdf = tmp_path / "r.urdf"
    urdf.write_text('<robot name="r"><link name="a"/></robot>')
    assert main(["import-mjcf", str(urdf)]) == 2
    assert capsys.readouterr().err == (f"derive: error: {urdf}: robot 'r': not an MJCF file: the root element is "
                                       "<robot>, not <mujoco> (a URDF: derive import-urdf FILE)\n")
    assert main(["import-urdf", str(FIXTURES / "walker.xml")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.endswith("not <robot> (an MJCF file: derive import-mjcf FILE)\n"), err


def test_missing_mujoco_names_the_extra(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "mujoco", None)  # import mujoco raises ImportError
    assert main(["import-mjcf", str(FIXTURES / "arm.xml")]) == 2
    assert capsys.readouterr().err == (f"derive: error: {FIXTURES / 'arm.xml'}: reading MJCF needs MuJoCo's "
                                       "compiler, the mujoco package: pip install 'derive-robotics[mjcf]'\n")


@pytest.mark.parametrize("text, message", [(None, "cannot read MJCF (No such file or directory)"),
                                           ("", "robot 'bad': line 1, column 1: malformed XML: no element found"),
                                           ('<mujoco><worldbody><body><joint foo="1"/></body></worldbody></mujoco>',
                                            "robot 'bad': MuJoCo's compiler refused it: XML Error: Schema violation: "
                                            "unrecognized attribute: 'foo'; Element 'joint', line 1")])
def test_unreadable_files_are_one_line(mujoco, tmp_path, capsys, text, message):
    path = tmp_path / "bad.xml"
    if text is not None:
        path.write_text(text)
    assert main(["import-mjcf", str(path)]) == 2
    assert capsys.readouterr().err == f"derive: error: {path}: {message}\n"
