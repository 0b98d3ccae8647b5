"""A Pinocchio model built directly from a derive Robot (no URDF), and a NumericRobot-like wrapper.

Used by the tests (tests/pin_model.py re-exports it) and by ``derive bench pinocchio-cpp``; it needs
pinocchio, so :mod:`derive.reference` itself does not import it.

- Floating base: a ``JointModelFreeFlyer`` named ``root_joint`` (Pinocchio's q = [p, quaternion
  x y z w], v = [linear, angular] in the root frame), the root link's mass on it.
- revolute / prismatic: RX/RY/RZ, PX/PY/PZ about a coordinate axis, else the Unaligned models;
  continuous: the same revolute models (one angle in q, as derive has it; Pinocchio's own
  unbounded joints hold (cos, sin) in q instead);
  helical: ``JointModelHelicalUnaligned``; spherical: ``JointModelSphericalZYX``; universal:
  ``JointModelUniversal``; cylindrical (no Pinocchio model): a revolute then a prismatic joint
  about the same axis, with a massless body between them (the same motion, Rot(a, q1) Trans(a q2)).
- Links through fixed joints are merged into the joint they hang from (``appendBodyToJoint`` with
  their placement), as Pinocchio's URDF parser does; with a fixed base the root link and the links
  fixed to it are the universe, whose inertia no algorithm uses (nothing is appended to it).
- Every link becomes a BODY frame and every named frame an OP_FRAME, so all of
  ``robot.frame_names`` can be queried by name.
- A mimic joint (``joint.mimic``) is first added as an ordinary joint of its own type, then, once
  the model is complete, turned into a ``JointModelMimic`` of its leader by Pinocchio's
  ``transformJointIntoMimic(model, leader, mimic, multiplier, offset)`` (what its URDF parser does
  with ``mimic=True``): it keeps its type, body and frames and loses its entries of q and v.
  Pinocchio needs the leader to come before the mimic joint in the tree's order. A helical mimic
  joint is refused: Pinocchio 4.1 crashes (segmentation fault) on a mimic
  ``JointModelHelicalUnaligned``, and a mimic ``JointModelHX`` (helical about x) has the pitch's
  translation left out of its Jacobian and rnea (they disagree with Pinocchio's own fk and crba). ``aba``,
  ``computeKineticEnergy`` and ``computePotentialEnergy`` refuse such a model, so
  :class:`PinRobot` answers those from Pinocchio's ``crba``, ``rnea`` and ``centerOfMass``; its
  ``crba`` is only right on a fresh Data there (:meth:`PinRobot.crba`), and its
  ``computeCoriolisMatrix`` disagrees with its ``rnea`` (:meth:`PinRobot.coriolis_matrix` refuses).
- Parameter expressions are evaluated at the defaults (or ``params``) by derive.description.expr.

Joints are added in ``robot.joints`` order, so Pinocchio's q and v are ours entry for entry (mimic
joints have none in either).
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

try:
    import pinocchio as pin
except ImportError:  # importable without it (derive bench imports every benchmark module); building a model needs it
    pin = None

from derive.description import expr
from derive.description.robot import FREE_FLYER, Robot


def _rpy(r: float, p: float, y: float) -> np.ndarray:
    return pin.rpy.rpyToMatrix(r, p, y)


def _axis_model(kind: str, axis: np.ndarray):
    """RX/RY/RZ or PX/PY/PZ where the axis is a (positive) coordinate axis, else the Unaligned model."""
    for k, unit in enumerate(np.eye(3)):
        if np.array_equal(axis, unit):
            return getattr(pin, f"JointModel{'R' if kind == 'revolute' else 'P'}{'XYZ'[k]}")()
    return pin.JointModelRevoluteUnaligned(axis) if kind == "revolute" else pin.JointModelPrismaticUnaligned(axis)


def build_model(robot: Robot, params: Mapping[str, float] | None = None) -> pin.Model:
    env = dict(robot.parameter_defaults) | {k: float(v) for k, v in (params or {}).items()}

    def num(value) -> float:
        return float(expr.evaluate(value, env))

    def vec(values) -> np.ndarray:
        return np.array([num(v) for v in values], dtype=float)

    def se3(origin) -> pin.SE3:
        return pin.SE3(_rpy(*vec(origin.rpy)), vec(origin.xyz))

    model = pin.Model()
    model.name = robot.name
    model.gravity = pin.Motion(np.concatenate([vec(robot.gravity), np.zeros(3)]))
    placed: dict[str, tuple[int, pin.SE3]] = {robot.root: (0, pin.SE3.Identity())}
    if robot.floating:
        root = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), FREE_FLYER)
        placed[robot.root] = (root, pin.SE3.Identity())
    for joint in robot.joints:
        parent, at = placed[joint.parent]
        placement = at * se3(joint.origin)
        if joint.dof == 0:
            placed[joint.child] = (parent, placement)
            continue
        axis = np.array(joint.axis, dtype=float)
        if joint.type in ("revolute", "prismatic"):
            chain = [_axis_model(joint.type, axis)]
        elif joint.type == "continuous":  # as revolute (one angle, not Pinocchio's (cos, sin) of RUBX..)
            chain = [_axis_model("revolute", axis)]
        elif joint.type == "helical":
            if joint.mimic is not None:
                raise ValueError(f"pin_model: mimic joint '{joint.name}' is helical: Pinocchio 4.1 gets helical mimic "
                                 "joints wrong (a segmentation fault when unaligned, else the pitch left out of J and rnea)")
            chain = [pin.JointModelHelicalUnaligned(axis, num(joint.pitch))]
        elif joint.type == "spherical":
            chain = [pin.JointModelSphericalZYX()]
        elif joint.type == "universal":
            chain = [pin.JointModelUniversal(axis, np.array(joint.axis2, dtype=float))]
        elif joint.type == "cylindrical":
            chain = [pin.JointModelRevoluteUnaligned(axis), pin.JointModelPrismaticUnaligned(axis)]
        else:
            raise ValueError(f"pin_model: joint type {joint.type!r} not handled")
        jid = parent
        for k, jmodel in enumerate(chain):
            name = joint.name if k == 0 else f"{joint.name}__{k}"
            jid = model.addJoint(jid, jmodel, placement if k == 0 else pin.SE3.Identity(), name)
        placed[joint.child] = (jid, pin.SE3.Identity())

    for link in robot.links:
        jid, at = placed[link.name]
        if jid == 0:
            continue
        rot = _rpy(*vec(link.inertia_rpy))
        inertia = rot @ np.array([[num(x) for x in row] for row in link.inertia]) @ rot.T
        model.appendBodyToJoint(jid, pin.Inertia(num(link.mass), vec(link.com), inertia), at)

    for name in [robot.root] + [j.child for j in robot.joints]:
        jid, at = placed[name]
        model.addFrame(pin.Frame(name, jid, at, pin.FrameType.BODY), False)
    for frame in robot.frames:
        jid, at = placed[frame.link]
        model.addFrame(pin.Frame(frame.name, jid, at * se3(frame.origin), pin.FrameType.OP_FRAME), False)

    for joint in robot.joints:
        if joint.mimic is None:
            continue
        leader, follower = model.getJointId(joint.mimic.joint), model.getJointId(joint.name)
        if not leader < follower:
            raise ValueError(f"pin_model: mimic joint '{joint.name}' comes before its leader '{joint.mimic.joint}' "
                             "(Pinocchio needs the leader first)")
        name, gravity = model.name, model.gravity
        model = pin.transformJointIntoMimic(model, leader, follower, float(joint.mimic.multiplier), float(joint.mimic.offset))
        model.name, model.gravity = name, gravity
    return model


class PinRobot:
    """Pinocchio on a derive Robot, with NumericRobot's interface and conventions (q, v in our order,
    Jacobians and frame accelerations LOCAL_WORLD_ALIGNED [linear; angular], wrenches per frame)."""

    def __init__(self, robot: Robot, params: Mapping[str, float] | None = None):
        self.robot = robot
        self.model = build_model(robot, params)
        self.data = self.model.createData()
        assert (self.model.nq, self.model.nv) == (robot.nq, robot.nv), (self.model.nq, self.model.nv)
        # q and v entry for entry: Pinocchio's joints in our order, each at the next free index
        names = ([FREE_FLYER] if robot.floating else []) + [j.name for j in robot.moving_joints]
        ours = [n for n in self.model.names[1:] if "__" not in n]
        assert ours == names, (ours, names)
        self.mimic = any(j.mimic is not None for j in robot.joints)
        mimics = {j.name for j in robot.joints if j.mimic is not None}
        nq = nv = 0
        for name, jmodel in zip(self.model.names[1:], self.model.joints[1:]):
            if name in mimics:  # the leader's indexes, no entries of its own
                assert jmodel.shortname() == "JointModelMimic" and (jmodel.nq, jmodel.nv) == (0, 0), (name, jmodel)
                continue
            assert (jmodel.idx_q, jmodel.idx_v) == (nq, nv)
            nq, nv = nq + jmodel.nq, nv + jmodel.nv
        self.frame_ids = {name: self.model.getFrameId(name) for name in robot.frame_names}
        assert len(set(self.frame_ids.values())) == len(self.frame_ids)

    def frame_id(self, name: str) -> int:
        return self.frame_ids[self.robot.frame_name(name)]  # an alias: the frame it names

    def _kinematics(self, q, v=None, a=None) -> None:
        if v is None:
            pin.forwardKinematics(self.model, self.data, q)
        else:
            pin.forwardKinematics(self.model, self.data, q, v, np.zeros(self.model.nv) if a is None else a)
        pin.updateFramePlacements(self.model, self.data)

    def pose(self, q, name: str) -> np.ndarray:
        self._kinematics(q)
        return self.data.oMf[self.frame_id(name)].homogeneous.copy()

    frame_pose = pose

    def jacobian(self, q, name: str) -> np.ndarray:
        return pin.computeFrameJacobian(self.model, self.data, q, self.frame_id(name), pin.LOCAL_WORLD_ALIGNED).copy()

    def crba(self, q) -> np.ndarray:
        """Pinocchio's M (its upper triangle, mirrored). With mimic joints on a fresh Data: Pinocchio 4.1's
        crba then adds onto entries a previous crba left in the Data (the coupling of a joint below a
        mimic joint with its support's coordinates), so only a first call is right."""
        data = self.model.createData() if self.mimic else self.data
        m = np.array(pin.crba(self.model, data, q))
        return np.triu(m) + np.triu(m, 1).T

    def gravity(self, q) -> np.ndarray:
        return np.array(pin.computeGeneralizedGravity(self.model, self.data, q))

    def fext(self, q, wrenches: Mapping[str, np.ndarray]):
        """Frame wrenches [force; torque] at the frame origin, world axes -> per-joint forces, joint frame."""
        self._kinematics(q)
        out = [pin.Force.Zero() for _ in range(self.model.njoints)]
        for name, wrench in wrenches.items():
            fid = self.frame_id(name)
            jid = self.model.frames[fid].parentJoint
            p = self.data.oMf[fid].translation
            force, torque = np.asarray(wrench[:3], float), np.asarray(wrench[3:], float)
            at_world_origin = pin.Force(force, torque + np.cross(p, force))
            out[jid] = out[jid] + self.data.oMi[jid].actInv(at_world_origin)
        vec = pin.StdVec_Force()
        for f in out:
            vec.append(f)
        return vec

    def rnea(self, q, v, a, wrenches=None) -> np.ndarray:
        if wrenches:
            return np.array(pin.rnea(self.model, self.data, q, v, a, self.fext(q, wrenches)))
        return np.array(pin.rnea(self.model, self.data, q, v, a))

    def rnea_derivatives(self, q, v, a) -> np.ndarray:
        """[dtau/dq, dtau/dv] (nv x 2 nv) by computeRNEADerivatives: dq in the tangent space, which is
        the coordinates' own derivative where nq = nv (no free flyer, no continuous joints)."""
        dq, dv, _ = pin.computeRNEADerivatives(self.model, self.data, q, v, a)
        return np.hstack([np.array(dq), np.array(dv)])

    def aba_derivatives(self, q, v, tau) -> tuple[np.ndarray, np.ndarray]:
        """computeABADerivatives: ([dqdd/dq, dqdd/dv] (nv x 2 nv, tangent space), M^-1 (symmetrised))."""
        pin.computeABADerivatives(self.model, self.data, q, v, tau)
        minv = np.array(self.data.Minv)
        return np.hstack([np.array(self.data.ddq_dq), np.array(self.data.ddq_dv)]), np.triu(minv) + np.triu(minv, 1).T

    def aba(self, q, v, tau, wrenches=None) -> np.ndarray:
        """Pinocchio's ABA; with mimic joints (which it refuses) M^-1 (tau - rnea(q, v, 0, fext))."""
        if self.mimic:
            return np.linalg.solve(self.crba(q), tau - self.rnea(q, v, np.zeros(self.model.nv), wrenches))
        if wrenches:
            return np.array(pin.aba(self.model, self.data, q, v, tau, self.fext(q, wrenches)))
        return np.array(pin.aba(self.model, self.data, q, v, tau))

    def frame_acceleration(self, q, v, a, name: str) -> np.ndarray:
        self._kinematics(q, v, a)
        acc = pin.getFrameClassicalAcceleration(self.model, self.data, self.frame_id(name), pin.LOCAL_WORLD_ALIGNED)
        return np.concatenate([acc.linear, acc.angular])

    def jdot_v(self, q, v, name: str) -> np.ndarray:
        return self.frame_acceleration(q, v, np.zeros(self.model.nv), name)

    def com(self, q) -> np.ndarray:
        return np.array(pin.centerOfMass(self.model, self.data, q))

    def com_jacobian(self, q) -> np.ndarray:
        return np.array(pin.jacobianCenterOfMass(self.model, self.data, q))

    def centroidal_map(self, q) -> np.ndarray:
        return np.array(pin.computeCentroidalMap(self.model, self.data, q))

    def coriolis_matrix(self, q, v) -> np.ndarray:
        """Pinocchio's computeCoriolisMatrix; not for mimic joints: Pinocchio 4.1's C v then differs from
        its own rnea(q, v, 0) - g."""
        if self.mimic:
            raise NotImplementedError("Pinocchio 4.1's Coriolis matrix disagrees with its rnea on mimic joints")
        return np.array(pin.computeCoriolisMatrix(self.model, self.data, q, v))

    def kinetic_energy(self, q, v) -> float:
        """Pinocchio's; with mimic joints (which it refuses) 1/2 v^T M v."""
        if self.mimic:
            return float(0.5 * v @ self.crba(q) @ v)
        return float(pin.computeKineticEnergy(self.model, self.data, q, v))

    def potential_energy(self, q) -> float:
        """Pinocchio's; with mimic joints (which it refuses) -m gravity . com."""
        if self.mimic:
            mass = sum(inertia.mass for inertia in self.model.inertias[1:])
            return float(-mass * (self.model.gravity.linear @ self.com(q)))
        return float(pin.computePotentialEnergy(self.model, self.data, q))
