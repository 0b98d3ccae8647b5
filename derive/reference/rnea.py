"""Numeric rigid-body dynamics of a fixed-base tree, written from Featherstone's textbook.

This is the independent reference the symbolic pipeline is checked against: it
uses numpy only, and reads the model through :mod:`derive.description.model` and
:mod:`derive.description.expr` (input parsing), nothing else of ``derive``.

Conventions
-----------
- Spatial vectors inside the algorithms are Featherstone's ``[angular; linear]``,
  expressed in the body frame at the body origin; the motion transform from
  frame A to frame B, whose pose in A is ``(R, r)``, is
  ``B_X_A = [[R^T, 0], [-R^T r^, R^T]]`` and forces transform with ``X^T``.
- Bodies are the moving joints, in ``robot.moving_joints`` order; body i's
  frame is the child link frame of joint i, and its coordinates are the
  consecutive slice ``dofs[i]`` of q. Links hanging off a body through
  fixed joints are merged rigidly into it (their frames keep their own poses);
  links fixed to the root are part of the world and carry no dynamics.
- Every joint type is one :class:`JointModel` (Featherstone, section 4.4): the
  joint transform X_J(q), the motion subspace S(q) (6 x DOF, child frame) and
  the bias c_J = Sdot qd. Multi-DOF joints are single bodies with a 6 x 2 or
  6 x 3 S here, not chains of massless bodies as on the symbolic side.
- Gravity enters as the base acceleration ``a_0 = -[0; gravity]``.
- Outputs meant for comparison (Jacobians) use Pinocchio's ``[linear; angular]``.
- Every q-dependent quantity is computed with numpy ufuncs and plain transposes
  (no abs, no conjugation), so complex q works and complex-step derivatives
  ``f'(q) e = Im f(q + i h e) / h`` are exact to machine precision.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from derive.description import expr
from derive.description.robot import Origin, Robot

COMPLEX_STEP = 1e-30


# --------------------------------------------------------------------------- small algebra


def skew(v: np.ndarray) -> np.ndarray:
    """v^ such that v^ w = v x w."""
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]], dtype=np.result_type(v, float))


def rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """URDF's R = Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


def rotation(axis: np.ndarray, angle) -> np.ndarray:
    """Rodrigues: exp(angle [axis]x) = 1 + sin(angle) K + (1 - cos(angle)) K^2 for a unit axis."""
    k = skew(axis)
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)


def homogeneous(rot: np.ndarray, pos: np.ndarray) -> np.ndarray:
    t = np.zeros((4, 4), dtype=np.result_type(rot, pos))
    t[:3, :3], t[:3, 3], t[3, 3] = rot, pos, 1
    return t


def motion_transform(pose: np.ndarray) -> np.ndarray:
    """B_X_A = [[E, 0], [-E r^, E]], E = R^T, for the pose (R, r) of frame B in frame A."""
    e = pose[:3, :3].T
    x = np.zeros((6, 6), dtype=pose.dtype)
    x[:3, :3] = x[3:, 3:] = e
    x[3:, :3] = -e @ skew(pose[:3, 3])
    return x


def crm(v: np.ndarray) -> np.ndarray:
    """Motion cross product v x = [[w^, 0], [v^, w^]] for v = [w; v]."""
    out = np.zeros((6, 6), dtype=v.dtype)
    out[:3, :3] = out[3:, 3:] = skew(v[:3])
    out[3:, :3] = skew(v[3:])
    return out


def crf(v: np.ndarray) -> np.ndarray:
    """Force cross product v x* = -(v x)^T."""
    return -crm(v).T


def spatial_inertia(mass: float, com: np.ndarray, inertia_com: np.ndarray) -> np.ndarray:
    """I_O = [[I_c + m c^ c^T, m c^], [m c^T, m 1]]: body inertia about the frame origin."""
    c = skew(com)
    return np.block([[inertia_com + mass * c @ c.T, mass * c], [mass * c.T, mass * np.eye(3)]])


# --------------------------------------------------------------------------- joint models


class JointModel:
    """One joint type: X_J(q) as the child's pose in the joint frame, S(q) and c_J(q, qd) in the child frame.

    ``v_J = S(q) qd`` is the child's spatial velocity relative to the joint frame and
    ``c_J = Sdot qd`` (Featherstone's eq. 4.43; nonzero only where S depends on q).

    - revolute ``a``: T = Rot(a, q); S = [a; 0].
    - prismatic ``a``: T = Trans(a q); S = [0; a].
    - helical ``a``, pitch h: T = Rot(a, q) Trans(h a q); S = [a; h a].
    - cylindrical ``a``: T = Rot(a, q1) Trans(a q2); S = [[a, 0]; [0, a]].
    - universal ``a1``, ``a2``: T = Rot(a1, q1) Rot(a2, q2);
      S = [[Rot(a2, q2)^T a1, a2]; 0], c_J = [qd1 qd2 (Rot(a2, q2)^T a1) x a2; 0].
    - spherical, ZYX Euler (a, b, c): T = Rz(a) Ry(b) Rx(c); the body rates
      w = [[-sb, 0, 1], [cb sc, cc, 0], [cb cc, -sc, 0]] [da; db; dc] (s = sin, c = cos),
      singular where cb = 0.
    """

    def __init__(self, kind: str, axis: np.ndarray, axis2: np.ndarray | None = None, pitch: float = 0.0):
        self.kind, self.axis, self.axis2, self.pitch = kind, axis, axis2, pitch

    def transform(self, q) -> np.ndarray:
        a = self.axis
        if self.kind == "revolute":
            return homogeneous(rotation(a, q[0]), np.zeros(3))
        if self.kind == "prismatic":
            return homogeneous(np.eye(3), a * q[0])
        if self.kind == "helical":
            return homogeneous(rotation(a, q[0]), a * (self.pitch * q[0]))
        if self.kind == "cylindrical":
            return homogeneous(rotation(a, q[0]), a * q[1])
        if self.kind == "universal":
            return homogeneous(rotation(a, q[0]) @ rotation(self.axis2, q[1]), np.zeros(3))
        ex, ey, ez = np.eye(3)
        return homogeneous(rotation(ez, q[0]) @ rotation(ey, q[1]) @ rotation(ex, q[2]), np.zeros(3))

    def subspace(self, q) -> np.ndarray:
        a, z = self.axis, np.zeros(3)
        if self.kind == "revolute":
            cols = [np.concatenate([a, z])]
        elif self.kind == "prismatic":
            cols = [np.concatenate([z, a])]
        elif self.kind == "helical":
            cols = [np.concatenate([a, self.pitch * a])]
        elif self.kind == "cylindrical":
            cols = [np.concatenate([a, z]), np.concatenate([z, a])]
        elif self.kind == "universal":
            cols = [np.concatenate([rotation(self.axis2, q[1]).T @ a, z]), np.concatenate([self.axis2, z])]
        else:
            sb, cb, sc, cc = np.sin(q[1]), np.cos(q[1]), np.sin(q[2]), np.cos(q[2])
            w = np.array([[-sb, 0.0, 1.0], [cb * sc, cc, 0.0], [cb * cc, -sc, 0.0]])
            return np.vstack([w, np.zeros((3, 3))])
        return np.column_stack(cols)

    def bias(self, q, qd) -> np.ndarray:
        if self.kind == "universal":
            s1 = rotation(self.axis2, q[1]).T @ self.axis
            return np.concatenate([qd[0] * qd[1] * np.cross(s1, self.axis2), np.zeros(3)])
        if self.kind == "spherical":
            sb, cb, sc, cc = np.sin(q[1]), np.cos(q[1]), np.sin(q[2]), np.cos(q[2])
            da, db, dc = qd
            dcol0 = np.array([-cb * db, -sb * sc * db + cb * cc * dc, -sb * cc * db - cb * sc * dc])
            dcol1 = np.array([0.0, -sc * dc, -cc * dc])
            return np.concatenate([dcol0 * da + dcol1 * db, np.zeros(3)])
        return np.zeros(6, dtype=np.result_type(q, qd, float))


# --------------------------------------------------------------------------- the robot


class NumericRobot:
    """A :class:`~derive.model.Robot` evaluated at fixed parameters, with numpy kinematics and dynamics.

    Args:
        robot: the parsed model.
        params: parameter name -> value, overriding ``robot.parameter_defaults``.
    """

    def __init__(self, robot: Robot, params: Mapping[str, float] | None = None):
        env = dict(robot.parameter_defaults)
        unknown = set(params or {}) - set(env)
        if unknown:
            raise ValueError(f"robot '{robot.name}' has no parameter(s) {', '.join(sorted(unknown))}")
        env.update({k: float(v) for k, v in (params or {}).items()})
        self.robot, self.params = robot, env

        def num(value) -> float:
            return float(expr.evaluate(value, env))

        def vec(values) -> np.ndarray:
            return np.array([num(v) for v in values], dtype=float)

        def pose(origin: Origin) -> np.ndarray:
            return homogeneous(rpy_matrix(*vec(origin.rpy)), vec(origin.xyz))

        self.gravity_vector = vec(robot.gravity)
        self.nq = self.nv = robot.nv
        self.joint_names = tuple(c.name for c in robot.coordinates)  # one per entry of q

        # Walk the tree: each link sits on a body (-1 = world) at a constant pose in that body's frame.
        self.parent: list[int] = []  # lambda(i)
        self.tree_pose: list[np.ndarray] = []  # joint frame i (before motion) in body lambda(i)
        self.joint_model: list[JointModel] = []
        self.dofs: list[slice] = []  # body i's entries of q
        placed = {robot.root: (-1, np.eye(4))}
        for joint in robot.joints:
            body, at = placed[joint.parent]
            joint_pose = at @ pose(joint.origin)
            if joint.dof == 0:
                placed[joint.child] = (body, joint_pose)
                continue
            self.parent.append(body)
            self.tree_pose.append(joint_pose)
            self.joint_model.append(JointModel(
                joint.type, np.array(joint.axis, dtype=float),
                None if joint.axis2 is None else np.array(joint.axis2, dtype=float),
                0.0 if joint.pitch is None else num(joint.pitch)))
            start = self.dofs[-1].stop if self.dofs else 0
            self.dofs.append(slice(start, start + joint.dof))
            placed[joint.child] = (len(self.parent) - 1, np.eye(4))
        n = self.nb = len(self.parent)
        self.support = []  # bodies from the root down to i, inclusive
        for i in range(n):
            chain, k = [], i
            while k >= 0:
                chain.append(k)
                k = self.parent[k]
            self.support.append(chain[::-1])

        # Inertias, merged per body; point masses kept per link for the potential energy.
        self.inertia = [np.zeros((6, 6)) for _ in range(n)]
        self.masses: list[tuple[int, float, np.ndarray]] = []  # (body, mass, COM in body frame) per moving link
        for link in robot.links:
            if link.name == robot.root:
                continue
            body, at = placed[link.name]
            mass = num(link.mass)
            rot = at[:3, :3] @ rpy_matrix(*vec(link.inertia_rpy))
            inertia_com = rot @ np.array([[num(x) for x in row] for row in link.inertia]) @ rot.T
            com = at[:3, :3] @ vec(link.com) + at[:3, 3]
            if body >= 0:  # links fixed to the root are world, as in Pinocchio
                self.masses.append((body, mass, com))
                self.inertia[body] = self.inertia[body] + spatial_inertia(mass, com, inertia_com)

        # Every placeable frame: (body, constant pose in the body frame).
        self.frames: dict[str, tuple[int, np.ndarray]] = {}
        for name in [robot.root] + [j.child for j in robot.joints]:
            self.frames[name] = placed[name]
        for frame in robot.frames:
            body, at = placed[frame.link]
            self.frames[frame.name] = (body, at @ pose(frame.origin))

    # ------------------------------------------------------------------ kinematics

    def joint_pose(self, i: int, qi) -> np.ndarray:
        """Pose of body i in body lambda(i): T_tree_i * T_J(q_i), q_i = q[dofs[i]] (see :class:`JointModel`)."""
        return self.tree_pose[i] @ self.joint_model[i].transform(qi)

    def subspace(self, i: int, q) -> np.ndarray:
        """S_i(q_i), 6 x DOF_i, body i's frame."""
        return self.joint_model[i].subspace(q[self.dofs[i]])

    def body_transforms(self, q) -> list[np.ndarray]:
        """X_i = i_X_lambda(i)(q_i), the motion transform from the parent body to body i."""
        return [motion_transform(self.joint_pose(i, q[self.dofs[i]])) for i in range(self.nb)]

    def body_poses(self, q) -> list[np.ndarray]:
        """World pose of every body: T_i = T_lambda(i) * T_tree_i * T_J(q_i)."""
        poses: list[np.ndarray] = []
        for i in range(self.nb):
            local = self.joint_pose(i, q[self.dofs[i]])
            poses.append(local if self.parent[i] < 0 else poses[self.parent[i]] @ local)
        return poses

    def fk(self, q) -> dict[str, np.ndarray]:
        """World pose (4x4) of every name in ``robot.frame_names``: T = T_body(q) * T_body_frame."""
        q = np.asarray(q)
        poses = self.body_poses(q)
        return {name: (at.copy() if body < 0 else poses[body] @ at) for name, (body, at) in self.frames.items()}

    def frame_pose(self, q, name: str) -> np.ndarray:
        """World pose (4x4) of one frame."""
        body, at = self.frames[name]
        return at.copy() if body < 0 else self.body_poses(np.asarray(q))[body] @ at

    def jacobian(self, q, name: str) -> np.ndarray:
        """Geometric Jacobian (6, nv), ``[v; w] = J qd``, LOCAL_WORLD_ALIGNED as in Pinocchio.

        v is the velocity of the frame origin p, w the angular velocity, both in world
        axes. The columns of a supporting body j (origin o_j, rotation R_j) are its
        S_j = [s_w; s_v] turned to world axes and moved to p:
        ``[R_j s_v + (R_j s_w) x (p - o_j); R_j s_w]`` (revolute: ``[a x (p - o_j); a]``,
        prismatic: ``[a; 0]``); other columns are zero.
        """
        q = np.asarray(q)
        body, at = self.frames[name]
        jac = np.zeros((6, self.nv), dtype=np.result_type(q, float))
        if body < 0:
            return jac
        poses = self.body_poses(q)
        p = (poses[body] @ at)[:3, 3]
        for j in self.support[body]:
            rot, s = poses[j][:3, :3], self.subspace(j, q)
            w = rot @ s[:3]
            jac[3:, self.dofs[j]] = w
            jac[:3, self.dofs[j]] = rot @ s[3:] + np.cross(w.T, p - poses[j][:3, 3]).T
        return jac

    # ------------------------------------------------------------------ dynamics

    def _base_acceleration(self, dtype) -> np.ndarray:
        return np.concatenate([np.zeros(3), -self.gravity_vector]).astype(dtype)

    def _velocities(self, q, qd, xs) -> tuple[list, list, list]:
        """Body velocities v_i = X_i v_lambda + v_J, joint velocities v_J = S_i qd_i and the S_i."""
        v, vj, ss = [], [], []
        for i in range(self.nb):
            ss.append(self.subspace(i, q))
            vj.append(ss[i] @ qd[self.dofs[i]])
            v.append(vj[i] if self.parent[i] < 0 else xs[i] @ v[self.parent[i]] + vj[i])
        return v, vj, ss

    def rnea(self, q, qd, qdd) -> np.ndarray:
        """Inverse dynamics tau = M(q) qdd + C(q, qd) qd + g(q) (Featherstone, Table 5.1).

        Forward: v_i = X_i v_lambda + S_i qd_i, a_i = X_i a_lambda + S_i qdd_i + c_J + v_i x S_i qd_i,
        with v_0 = 0 and a_0 = -[0; gravity]. Backward: f_i = I_i a_i + v_i x* I_i v_i,
        tau_i = S_i^T f_i, f_lambda += X_i^T f_i.
        """
        q, qd, qdd = np.asarray(q), np.asarray(qd), np.asarray(qdd)
        dtype = np.result_type(q, qd, qdd, float)
        xs = self.body_transforms(q)
        v, vj, ss = self._velocities(q, qd, xs)
        a, f = [], []
        a0 = self._base_acceleration(dtype)
        for i in range(self.nb):
            lam, dof = self.parent[i], self.dofs[i]
            c_j = self.joint_model[i].bias(q[dof], qd[dof])
            a.append(xs[i] @ (a0 if lam < 0 else a[lam]) + ss[i] @ qdd[dof] + c_j + crm(v[i]) @ vj[i])
            f.append(self.inertia[i] @ a[i] + crf(v[i]) @ (self.inertia[i] @ v[i]))
        tau = np.zeros(self.nv, dtype)
        for i in reversed(range(self.nb)):
            tau[self.dofs[i]] = ss[i].T @ f[i]
            if self.parent[i] >= 0:
                f[self.parent[i]] = f[self.parent[i]] + xs[i].T @ f[i]
        return tau

    def gravity(self, q) -> np.ndarray:
        """Generalized gravity g(q) = rnea(q, 0, 0)."""
        zero = np.zeros(self.nv)
        return self.rnea(q, zero, zero)

    def crba(self, q) -> np.ndarray:
        """Joint-space inertia M(q) by the composite rigid body algorithm (Featherstone, Table 6.2).

        I^c_i = I_i + sum over children j of X_j^T I^c_j X_j; M_ii = S_i^T I^c_i S_i and,
        walking F = I^c_i S_i up the support (F <- X_j^T F), M_ij = M_ji^T = F^T S_j (blocks
        of DOF_i x DOF_j).
        """
        q = np.asarray(q)
        dtype = np.result_type(q, float)
        xs = self.body_transforms(q)
        ss = [self.subspace(i, q) for i in range(self.nb)]
        ic = [inertia.astype(dtype) for inertia in self.inertia]
        for i in reversed(range(self.nb)):
            if self.parent[i] >= 0:
                ic[self.parent[i]] = ic[self.parent[i]] + xs[i].T @ ic[i] @ xs[i]
        m = np.zeros((self.nv, self.nv), dtype)
        for i in range(self.nb):
            di = self.dofs[i]
            force = ic[i] @ ss[i]
            m[di, di] = ss[i].T @ force
            j = i
            while self.parent[j] >= 0:
                force = xs[j].T @ force
                j = self.parent[j]
                m[di, self.dofs[j]] = force.T @ ss[j]
                m[self.dofs[j], di] = m[di, self.dofs[j]].T
        return m

    mass_matrix = crba

    def aba(self, q, qd, tau) -> np.ndarray:
        """Forward dynamics qdd = M^-1 (tau - C qd - g) by the articulated body algorithm (Featherstone, Table 7.1).

        Pass 1: v_i, c_i = c_J + v_i x S_i qd_i, I^A_i = I_i, p^A_i = v_i x* I_i v_i.
        Pass 2 (leaves to root): U_i = I^A_i S_i, D_i = S_i^T U_i, u_i = tau_i - S_i^T p^A_i;
        I^a_i = I^A_i - U_i D_i^-1 U_i^T, I^A_lambda += X_i^T I^a_i X_i,
        p^A_lambda += X_i^T (p^A_i + I^a_i c_i + U_i D_i^-1 u_i).
        Pass 3: a'_i = X_i a_lambda + c_i, qdd_i = D_i^-1 (u_i - U_i^T a'_i), a_i = a'_i + S_i qdd_i,
        a_0 = -[0; gravity].
        """
        q, qd, tau = np.asarray(q), np.asarray(qd), np.asarray(tau)
        dtype = np.result_type(q, qd, tau, float)
        xs = self.body_transforms(q)
        n = self.nb
        v, vj, ss = self._velocities(q, qd, xs)
        c, ia, pa = [None] * n, [None] * n, [None] * n
        for i in range(n):
            dof = self.dofs[i]
            c[i] = self.joint_model[i].bias(q[dof], qd[dof]) + crm(v[i]) @ vj[i]
            ia[i] = self.inertia[i].astype(dtype)
            pa[i] = crf(v[i]) @ (self.inertia[i] @ v[i])
        u_mat, d, u = [None] * n, [None] * n, [None] * n
        for i in reversed(range(n)):
            u_mat[i] = ia[i] @ ss[i]
            d[i] = ss[i].T @ u_mat[i]
            u[i] = tau[self.dofs[i]] - ss[i].T @ pa[i]
            lam = self.parent[i]
            if lam >= 0:
                d_inv_ut = np.linalg.solve(d[i], u_mat[i].T)
                i_art = ia[i] - u_mat[i] @ d_inv_ut
                p_art = pa[i] + i_art @ c[i] + u_mat[i] @ np.linalg.solve(d[i], u[i])
                ia[lam] = ia[lam] + xs[i].T @ i_art @ xs[i]
                pa[lam] = pa[lam] + xs[i].T @ p_art
        a = [None] * n
        qdd = np.zeros(self.nv, dtype)
        a0 = self._base_acceleration(dtype)
        for i in range(n):
            lam = self.parent[i]
            a_prime = xs[i] @ (a0 if lam < 0 else a[lam]) + c[i]
            qdd[self.dofs[i]] = np.linalg.solve(d[i], u[i] - u_mat[i].T @ a_prime)
            a[i] = a_prime + ss[i] @ qdd[self.dofs[i]]
        return qdd

    def mass_matrix_partials(self, q) -> np.ndarray:
        """dM/dq (nv, nv, nv), [k] = dM/dq_k = Im M(q + i h e_k) / h by complex step (h = 1e-30); q real."""
        q = np.asarray(q, dtype=float)
        return np.array([self.crba(q + 1j * COMPLEX_STEP * e).imag / COMPLEX_STEP for e in np.eye(self.nv)])

    def coriolis_matrix(self, q, qd) -> np.ndarray:
        """Christoffel C(q, qd): C_ij = sum_k 1/2 (dM_ij/dq_k + dM_ik/dq_j - dM_jk/dq_i) qd_k.

        With this choice C qd is the Coriolis and centrifugal torque and Mdot - 2C is skew.
        dM/dq comes from :meth:`mass_matrix_partials` (complex step, exact to rounding).
        """
        dm = self.mass_matrix_partials(q)  # dm[k, i, j] = dM_ij / dq_k
        qd = np.asarray(qd, dtype=float)
        return 0.5 * (np.einsum("kij,k->ij", dm, qd) + np.einsum("jik,k->ij", dm, qd) - np.einsum("ijk,k->ij", dm, qd))

    def kinetic_energy(self, q, qd):
        """T = 1/2 sum_i v_i^T I_i v_i over the body spatial velocities (= 1/2 qd^T M qd)."""
        q, qd = np.asarray(q), np.asarray(qd)
        v, _, _ = self._velocities(q, qd, self.body_transforms(q))
        return sum(0.5 * v[i] @ self.inertia[i] @ v[i] for i in range(self.nb))

    def potential_energy(self, q):
        """U = -sum_l m_l gravity . p_com_l over the links that move (world COM positions).

        Zero when every COM is at the world origin. The root link and links fixed to
        it are world and do not count (as in Pinocchio's computePotentialEnergy).
        """
        poses = self.body_poses(np.asarray(q))
        energy = 0
        for body, mass, com in self.masses:
            p = poses[body][:3, :3] @ com + poses[body][:3, 3]
            energy = energy - mass * (self.gravity_vector @ p)
        return energy
