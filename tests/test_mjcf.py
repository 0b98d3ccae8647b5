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


def compare(mujoco, file: str | Path, pin=None) -> dict[str, float]:
    """Max errors of derive's reference, its derived model (CasADi) and Pinocchio (if given) against MuJoCo
    at seeded random states (``file`` in the fixtures, or a path)."""
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


def test_a_massless_body_with_inertia_counts(mujoco, tmp_path):
    """MuJoCo keeps the rotational inertia of a body with mass 0 welded to a moving one (example-robot-data's
    bolt has four such feet, written so by mj_saveLastXML); the import dropped it (M 2.9e-4 off on bolt)."""
    path = tmp_path / "feet.xml"
    path.write_text('<mujoco><compiler inertiafromgeom="false"/><worldbody><body name="leg"><joint name="j" axis="1 0 0"/>'
                    '<inertial pos="0 0 -0.1" mass="0.1" diaginertia="1e-4 1e-4 1e-5"/><body name="foot" pos="0 0 -0.2">'
                    '<inertial pos="0 0 0.01" quat="0.7 0 0 0.7" mass="0" diaginertia="8e-7 6e-7 5e-7"/></body></body>'
                    '</worldbody></mujoco>')
    errors = compare(mujoco, path)
    assert errors["M"] <= TOL_MUJOCO and errors["tau"] <= TOL_MUJOCO, errors
    leg = import_mjcf(path)["links"][1]
    assert leg["mass"] == 0.1  # the foot's moments turned 90 degrees about z (its quat) and added
    assert [leg["inertia"][k] for k in ("ixx", "iyy", "izz")] == pytest.approx([1e-4 + 6e-7, 1e-4 + 8e-7, 1e-5 + 5e-7],
                                                                            rel=1e-15)


# --------------------------------------------------------------------------- MJCF written by MuJoCo from URDFs

# (URDF in example-robot-data, with a free joint): a fixed arm, an arm with a mimic finger, a floating quadruped
ERD_MJCF = {"ur5": ("ur_description/urdf/ur5_robot.urdf", False),
            "panda": ("panda_description/urdf/panda.urdf", False),
            "solo12": ("solo_description/robots/solo12.urdf", True)}
TOL_ROUNDED = 1e-5
"""derive against Pinocchio on the original URDF: mj_saveLastXML writes 6 significant digits (MuJoCo
4.0.0 has no option for more), so the imported numbers differ from the URDF's by up to 5e-7 relative;
measured 2.7e-6 at most (solo12's M). A convention error is of order 1."""


def mujoco_written(mujoco, urdf: Path, out: Path, free: bool) -> Path:
    """The URDF, its visual and collision geometry stripped, compiled by MuJoCo with fusestatic="false"
    (every link stays a body; MuJoCo fuses fixed joints away otherwise) and written out by
    mj_saveLastXML; ``free``: a <freejoint> added to the root body of what MuJoCo wrote."""
    import xml.etree.ElementTree as ET
    root = ET.parse(urdf).getroot()
    for parent in list(root.iter()):
        for child in [c for c in parent if c.tag in ("visual", "collision")]:
            parent.remove(child)
    ET.SubElement(ET.SubElement(root, "mujoco"), "compiler", fusestatic="false", discardvisual="true")
    model = mujoco.MjModel.from_xml_string(ET.tostring(root, encoding="unicode"))
    mujoco.mj_saveLastXML(str(out), model)
    if free:
        tree = ET.parse(out)
        tree.getroot().find("worldbody").find("body").insert(0, ET.Element("freejoint", name="root_joint"))
        tree.write(out)
    return out


def pinocchio_errors(pin, model, robot, samples: int = 3) -> dict[str, float]:
    """Largest relative differences of M and ID (rigid bodies) and of the body poses between derive's
    reference of ``robot`` and Pinocchio's ``model`` (joints by name; its free flyer's q and v are derive's;
    a mimic joint, an ordinary joint in ``model``, follows its leader: v_pin = G v)."""
    ref = NumericRobot(robot)
    data = model.createData()
    qi = {c.name: i for i, c in enumerate(robot.coordinates)}
    vi = {n: i for i, n in enumerate(robot.velocity_names)}
    mimic = {j.name: j.mimic for j in robot.joints if j.mimic is not None}
    rng = np.random.default_rng(3)
    worst = {"M": 0.0, "ID": 0.0, "pose": 0.0}
    for _ in range(samples):
        q = ref.random_configuration(rng)
        v, a = rng.normal(size=robot.nv), rng.normal(size=robot.nv)
        pq, G = pin.neutral(model), np.zeros((model.nv, robot.nv))
        for jid in range(1, model.njoints):
            name, joint = model.names[jid], model.joints[jid]
            if joint.nq == 7:  # the free flyer: derive's q = [p, qx qy qz qw], v = [v_body, w_body] are Pinocchio's
                pq[joint.idx_q:joint.idx_q + 7], G[joint.idx_v:joint.idx_v + 6, :6] = q[:7], np.eye(6)
                continue
            leader, c1, c0 = (mimic[name].joint, mimic[name].multiplier, mimic[name].offset) if name in mimic else \
                (name, 1.0, 0.0)
            pq[joint.idx_q], G[joint.idx_v, vi[leader]] = c0 + c1 * q[qi[leader]], c1
        M = pin.crba(model, data, pq)
        M = np.triu(M) + np.triu(M, 1).T
        rigid_M = ref.crba(q) - np.diag(ref.armature)
        rigid_tau = ref.rnea(q, v, a) - ref.armature * a - ref.viscous * v - ref.friction(v) + ref.viscous * v
        worst["M"] = max(worst["M"], np.abs(G.T @ (M - np.diag(model.armature)) @ G - rigid_M).max() / np.abs(rigid_M).max())
        tau = G.T @ (pin.rnea(model, data, pq, G @ v, G @ a) - model.armature * (G @ a))
        worst["ID"] = max(worst["ID"], np.abs(tau - rigid_tau).max() / np.abs(rigid_tau).max())
        pin.framesForwardKinematics(model, data, pq)
        fk = ref.fk(q)
        for link in robot.frame_names:
            if model.existFrame(link, pin.BODY):
                placed = data.oMf[model.getFrameId(link, pin.BODY)]
                worst["pose"] = max(worst["pose"], np.abs(placed.translation - fk[link][:3, 3]).max(),
                                    np.abs(placed.rotation - fk[link][:3, :3]).max())
    return worst


@pytest.mark.parametrize("key", sorted(ERD_MJCF))
def test_mjcf_written_by_mujoco_from_example_robot_data(mujoco, pin, tmp_path, key, capsys):
    """example-robot-data URDF -> MuJoCo -> mj_saveLastXML -> import-mjcf imports whole (every link a
    body or frame, panda's mimic finger a mimic joint, solo12 floating by its free joint) and matches
    MuJoCo on the same MJCF to 1e-10 (M, ID with the URDF's damping, body poses; reference and the
    derived CasADi model), Pinocchio on the same numbers to 1e-9 (its algorithms on the imported model, and
    its own MJCF parser on the written file), and Pinocchio on the original URDF to TOL_ROUNDED (MuJoCo
    writes 6 digits). --floating on the file without the free joint gives the same robot."""
    import pinocchio
    from derive.description.urdf import example_robot_data_dir

    assert example_robot_data_dir() is not None, "example-robot-data is not installed"
    urdf, free = ERD_MJCF[key]
    path = mujoco_written(mujoco, example_robot_data_dir() / urdf, tmp_path / f"{key}.xml", free)
    errors = compare(mujoco, path, pin)
    robot = parse_robot(*import_mjcf_named(path))
    original = pinocchio.buildModelFromUrdf(str(example_robot_data_dir() / urdf), *(
        [pinocchio.JointModelFreeFlyer()] if free else []))
    same_file = pinocchio_errors(pinocchio, pinocchio.buildModelFromMJCF(str(path)), robot)
    rounded = pinocchio_errors(pinocchio, original, robot)
    print(key, {k: f"{v:.1e}" for k, v in errors.items() if k != "frames"},
          "pin MJCF", {k: f"{v:.1e}" for k, v in same_file.items()},
          "pin URDF", {k: f"{v:.1e}" for k, v in rounded.items()}, file=sys.stderr)
    assert robot.floating == free and errors["frames"] == len(robot.frame_names) - (not free)  # all but world
    assert len(robot.frame_names) - (not free) == mujoco.MjModel.from_xml_path(str(path)).nbody - 1
    for k in ("M", "tau", "pose", "sym M", "sym tau", "sym pose"):
        assert errors[k] <= TOL_MUJOCO, (k, errors)
    for k in ("pin M", "pin tau", "pin pose"):
        assert errors[k] <= TOL_PINOCCHIO, (k, errors)
    assert max(same_file.values()) <= TOL_PINOCCHIO, same_file
    assert max(rounded.values()) <= TOL_ROUNDED, rounded
    if free:
        bare = mujoco_written(mujoco, example_robot_data_dir() / urdf, tmp_path / "bare.xml", False)
        floated = import_mjcf(bare, floating=True)
        entry = import_mjcf(path)
        assert (floated["links"], floated["joints"], floated["frames"]) == (entry["links"], entry["joints"], entry["frames"])


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


REFUSED = {  # connect, weld and tendon equalities (closed chains): tests/test_closed_chain_mujoco.py
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
