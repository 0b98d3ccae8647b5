"""Rigid contacts: KKT forward dynamics, impulses at touchdown, their derivatives, centroidal terms.

For a contact set with stacked constraint Jacobian J (m x nv) and drift a0(q, v) (m), the contact
forward dynamics solve the KKT system

    [M  J^T] [ qdd  ]   [ tau - h ]
    [J   0 ] [-lambda] = [  -a0    ],     i.e.  M qdd + h = tau + J^T lambda,  J qdd + a0 = 0,

and the impulse dynamics at touchdown, for a restitution coefficient e,

    [M  J^T] [ v+ ]       [  M v-  ]
    [J   0 ] [-Lambda]  = [ -e J v- ],    i.e.  M (v+ - v-) = J^T Lambda,  J v+ = -e J v-.

Conventions are Pinocchio's ``RigidConstraintModel`` with LOCAL_WORLD_ALIGNED, so results compare one
to one with ``constraintDynamics`` and ``impulseDynamics``: a ``point`` contact (CONTACT_3D) holds the
classical acceleration of the frame origin at zero (J: the linear rows of the frame's world-aligned
Jacobian, a0 = those of J'(q, v) v), its force [fx, fy, fz] in world axes; a ``surface`` contact
(CONTACT_6D) holds the frame's spatial acceleration at zero (J: all six rows, a0 = J' v with the
linear part minus w x v, the derivative of the frame's body velocity in world axes), its wrench
[force; torque] at the origin in world axes. lambda is what the ground exerts on the robot.

The KKT matrix is never formed or inverted. M = L^T D L along the tree (LTDL, no fill-in;
:func:`derive.symbolic.ode.ltdl_factor`), W = L^-T J^T, the Schur complement S = W^T D^-1 W = J M^-1 J^T
(m x m, symmetric positive definite when the contact rows are independent), S = L_S D_S L_S^T, and
with u = L^-T (tau - h)

    lambda = -S^-1 (a0 + W^T D^-1 u),   qdd = L^-1 D^-1 (u + W lambda)   (= M^-1 (tau - h + J^T lambda)).

A redundant contact set (dependent rows of J: S singular) is reported, never regularised: ``status``
is 1 where every pivot of D_S exceeds :data:`PIVOT_TOL` times S's diagonal entry, else 0 (then qdd and
lambda solve nothing; an exactly zero pivot is divided as 1 so that no backend raises).

The derivatives follow from the implicit-function theorem on the residual
F(q, v, tau; qdd, lambda) = [ID(q, v, qdd) - J^T lambda - tau; J qdd + a0]: d(qdd, lambda)/dx solves the
same block system with the right-hand side -dF/dx at fixed (qdd, lambda), by the same factors.

The contact-consistent inverse dynamics of a floating base (:attr:`ContactModel.inverse`): for a desired qdd,
the joint torques and the minimum-norm contact forces that the base's six unactuated rows admit,
lambda = J_b (J_b^T J_b)^-1 (ID(q, qd, qdd))_base, tau = ID - J^T lambda on the joints.

Also here: Baumgarte stabilisation of point contacts (:meth:`ContactModel.stabilised`) and the centroidal
terms of legged control, A_G' qd, the CoM acceleration (:func:`momentum_rate`) and the composite inertia
about the CoM (:func:`centroidal_inertia`).
"""

from __future__ import annotations

from functools import cached_property

import casadi as ca

from derive.description.robot import ContactSet
from derive.symbolic.ode import ltdl_factor
from derive.symbolic.spatial import skew

BASE_ROWS = 6
"""A floating base's velocities, the first six of v: the rows of M qdd + h = S^T tau + J^T lambda without torque."""

PIVOT_TOL = 1e-10
"""status = 0 where a pivot of the Schur complement's LDL^T is at most this times its diagonal entry: the
contact rows are dependent to about 1e-5 rad (sin^2 of the angle between a row and the others' span)."""


def reciprocal(y: ca.SX) -> ca.SX:
    """1 / y as one division whose uses stay products: casadi rewrites x * (1 / y) as x / y, a division
    at every use (969 of solo12's contact derivatives' operations were such divisions). (2 / y) * 0.5 is
    the same number exactly (a power of two) and casadi leaves products of it alone."""
    return (2 / y) * 0.5


class KKT:
    """The factored KKT system of one contact set at the symbolic state.

    M = L^T D L along the tree (:func:`~derive.symbolic.ode.ltdl_factor`; a chain or mimic joints: every
    earlier coordinate an ancestor), W = L^-T J^T (m half solves, each filling only the contact's branch
    and its ancestors), S = W^T D^-1 W = J M^-1 J^T, S = L_S D_S L_S^T (:func:`guarded_ldlt`).
    :meth:`solve` returns (a, l) with M a - J^T l = r1, J a = r2 for any number of columns:
    z = D^-1 L^-T r1, l = S^-1 (r2 - W^T z), a = L^-1 (z + D^-1 W l): two half solves per column."""

    def __init__(self, M: ca.SX, J: ca.SX, parents: tuple[int, ...]):
        self.parents = parents
        self.H = ltdl_factor(M, parents)
        self.n = M.shape[0]
        self.inverse = [reciprocal(self.H[k, k]) for k in range(self.n)]  # D^-1: one division per pivot, not per use
        self.W = self.lower_solve(J.T)
        self.DW = self.scaled(self.W)  # D^-1 W
        S = self.W.T @ self.DW
        self.L, self.D_inverse, self.status = guarded_ldlt(S)

    def scaled(self, b: ca.SX) -> ca.SX:
        """D^-1 b."""
        return scale_rows(b, self.inverse)

    def ancestors(self, k: int) -> list[int]:
        out, i = [], self.parents[k]
        while i != -1:
            out.append(i)
            i = self.parents[i]
        return out

    def lower_solve(self, b: ca.SX) -> ca.SX:
        """L^-T b (L^T y = b, leaves first), row by row for all columns."""
        y = [b[k, :] for k in range(self.n)]
        for k in reversed(range(self.n)):
            for i in self.ancestors(k):
                y[i] = y[i] - self.H[k, i] * y[k]
        return ca.vertcat(*y)

    def unit_upper_solve(self, z: ca.SX) -> ca.SX:
        """L^-1 z (L x = z, root first)."""
        x = [z[k, :] for k in range(self.n)]
        for k in range(self.n):
            for i in self.ancestors(k):
                x[k] = x[k] - self.H[k, i] * x[i]
        return ca.vertcat(*x)

    def schur_solve(self, b: ca.SX) -> ca.SX:
        """S^-1 b by S's LDL^T (row by row for all columns)."""
        return ldlt_solve(self.L, self.D_inverse, b)

    def solve(self, r1: ca.SX, r2: ca.SX) -> tuple[ca.SX, ca.SX]:
        """(a, l) of [M J^T; J 0] [a; -l] = [r1; r2]."""
        z = self.scaled(self.lower_solve(r1))  # D^-1 L^-T r1
        l = self.schur_solve(r2 - self.W.T @ z)
        return self.unit_upper_solve(z + self.DW @ l), l

    def mass_inverse(self) -> list[list]:
        """M^-1 = L^-1 D^-1 L^-T entry by entry (n x n, symmetric: each pair once): with V = L^-1 (row k
        nonzero only at k and its ancestors), M^-1[i, j] = sum over the common ancestors-or-selves c of
        V[i, c] V[j, c] / D[c]."""
        n, H = self.n, self.H
        V: list[dict] = []
        for k in range(n):  # L V = I, root first: V[k, c] = -sum_i H[k, i] V[i, c] over k's ancestors i
            acc: dict = {}
            for i in self.ancestors(k):
                for c, v in V[i].items():  # c: i or an ancestor of i, never k
                    acc[c] = acc[c] + H[k, i] * v if c in acc else H[k, i] * v
            V.append({k: ca.SX(1), **{c: -t for c, t in acc.items()}})
        out = [[None] * n for _ in range(n)]
        for i in range(n):
            for j in range(i, n):
                common = sorted(set(V[i]) & set(V[j]))
                out[i][j] = out[j][i] = sum((V[i][c] * (V[j][c] * self.inverse[c]) for c in common), ca.SX(0))
        return out

    def tau_columns(self) -> tuple[ca.SX, ca.SX]:
        """(a, l) of :meth:`solve` for r1 = I (n columns), r2 = 0: the KKT inverse's top-left block
        P = M^-1 - G S^-1 G^T (symmetric, G = M^-1 J^T = L^-1 D^-1 W: each pair of entries computed once)
        and its bottom-left one, -S^-1 G^T. With S = L_S D_S L_S^T and E = L_S^-1 G^T, F = D_S^-1 E:
        P = M^-1 - E^T F and -S^-1 G^T = -L_S^-T F (solo12's 18 columns: about 1.2k operations fewer than by
        :meth:`solve`; with S^-1 the blocks also serve the sparse columns of the derivatives)."""
        n = self.n
        G = self.unit_upper_solve(self.DW)
        E = ldlt_forward(self.L, G.T)
        F = scale_rows(E, self.D_inverse)
        Minv = self.mass_inverse()
        P = [[None] * n for _ in range(n)]
        for a in range(n):
            for b in range(a, n):
                P[a][b] = P[b][a] = Minv[a][b] - ca.dot(E[:, a], F[:, b])
        return ca.vertcat(*(ca.horzcat(*row) for row in P)), -ldlt_back(self.L, F)


def scale_rows(b: ca.SX, factors: list) -> ca.SX:
    """Row k of ``b`` times ``factors[k]``: a diagonal matrix's product, for all columns."""
    return ca.vertcat(*(b[k, :] * f for k, f in enumerate(factors)))


def ldlt_forward(L: list, b: ca.SX) -> ca.SX:
    """L^-1 b for :func:`guarded_ldlt`'s unit lower L, row by row for all columns."""
    y = [None] * len(L)
    for i in range(len(L)):
        y[i] = b[i, :] - sum((L[i][k] * y[k] for k in range(i)), ca.SX(0))
    return ca.vertcat(*y)


def ldlt_back(L: list, z: ca.SX) -> ca.SX:
    """L^-T z for :func:`guarded_ldlt`'s unit lower L, row by row for all columns."""
    n = len(L)
    x = [None] * n
    for i in reversed(range(n)):
        x[i] = z[i, :] - sum((L[k][i] * x[k] for k in range(i + 1, n)), ca.SX(0))
    return ca.vertcat(*x)


def ldlt_solve(L: list, D_inverse: list, b: ca.SX) -> ca.SX:
    """A^-1 b for A = L D L^T (:func:`guarded_ldlt`'s L, the reciprocals of its D), row by row for all columns."""
    return ldlt_back(L, scale_rows(ldlt_forward(L, b), D_inverse))


def guarded_ldlt(S: ca.SX) -> tuple[list, list, ca.SX]:
    """S = L D L^T as (L, the reciprocals of D, status), each exactly zero pivot replaced by 1 (so that no
    backend divides by zero); status 1 where every pivot exceeds :data:`PIVOT_TOL` S_kk, else 0 (fmax of
    indicators in pivot order: the first failing pivot is finite, those after it may not be)."""
    n = S.shape[0]
    L = [[None] * n for _ in range(n)]
    D, D_inverse = [None] * n, [None] * n
    failed = ca.SX(0)
    for j in range(n):
        d = S[j, j] - sum((L[j][k] * L[j][k] * D[k] for k in range(j)), ca.SX(0))
        failed = ca.fmax(failed, 0.5 * (1 + ca.sign(PIVOT_TOL * S[j, j] - d)))
        D[j] = d + (1 - ca.sign(ca.fabs(d)))  # d itself unless exactly 0 (then 1): no division by zero
        D_inverse[j] = reciprocal(D[j])
        for i in range(j + 1, n):
            L[i][j] = (S[i, j] - sum((L[i][k] * L[j][k] * D[k] for k in range(j)), ca.SX(0))) * D_inverse[j]
    return L, D_inverse, 1 - failed


class ContactModel:
    """The contact functions of one robot (:class:`~derive.symbolic.model.SXModel`) for one contact set."""

    def __init__(self, model, stance: ContactSet):
        self.model, self.stance = model, stance
        self.robot, self.sym = model.robot, model.sym
        self.ne, self.wb = model.newton_euler, model.whole_body

    @property
    def rows(self) -> int:
        return sum(self.robot.contact(f).rows for f in self.stance.frames)

    @cached_property
    def _starts(self) -> list[int]:
        """Each contact's first row in the set's rows."""
        out, at = [], 0
        for f in self.stance.frames:
            out.append(at)
            at += self.robot.contact(f).rows
        return out

    def _rows(self, frame: str) -> slice:
        return slice(0, self.robot.contact(frame).rows)

    @cached_property
    def jacobian(self) -> ca.SX:
        """J (m x nv): the contacts' rows of their frames' world-aligned Jacobians, in the set's order."""
        return ca.vertcat(*(self.model.jacobian(f)[self._rows(f), :] for f in self.stance.frames))

    def drift(self, v: ca.SX | None = None) -> ca.SX:
        """a0 = J'(q, v) v (m): a point's classical acceleration at qdd = 0, a surface's spatial one
        ([classical linear - w x v; angular]), world-aligned. ``v``: the velocity (default the symbol qd)."""
        out = self.acceleration()
        return out if v is None else ca.substitute(out, self.sym.qd, v)

    def wrenches(self, l: ca.SX) -> list:
        """The contact forces ``l`` (m, world-aligned: [f] per point, [f; torque] per surface, at each
        frame's origin) as the RNEA's external wrenches: (body, force, torque about its origin), body
        coordinates; ID with them is ID - J^T l."""
        out = []
        for f, at in zip(self.stance.frames, self._starts):
            body, _, r = self.wb.placement_in_body(f)
            force = self.ne.world_to_body(body, l[at:at + 3])
            torque = ca.cross(r, force)
            if self.robot.contact(f).rows == 6:
                torque = torque + self.ne.world_to_body(body, l[at + 3:at + 6])
            out.append((body, force, torque))
        return out

    def acceleration(self, qdd: ca.SX | None = None) -> ca.SX:
        """J qdd + a0 (m): the contacts' accelerations as :meth:`drift` has them, at the accelerations
        ``qdd`` (default zero: the drift), from the RNEA's forward pass without gravity."""
        parts = []
        for f in self.stance.frames:
            a = self.wb.jdot_qd(f) if qdd is None else self.wb.frame_acceleration(f, qdd)
            if self.robot.contact(f).kind == "surface":
                twist = self.model.jacobian(f) @ self.sym.qd
                a = ca.vertcat(a[0:3] - ca.cross(twist[3:6], twist[0:3]), a[3:6])
            parts.append(a[self._rows(f)])
        return ca.vertcat(*parts)

    @cached_property
    def kkt(self) -> KKT:
        n = self.sym.nv
        return KKT(self.ne.mass_matrix, self.jacobian, self.ne.dof_parents or tuple(range(-1, n - 1)))

    @cached_property
    def bias(self) -> ca.SX:
        """h = C qd + g plus the smooth friction (the model's bias) by the RNEA whose forward pass runs without
        gravity (split), the pass :meth:`drift` takes its accelerations from: one pass for both."""
        return self.ne.inverse_dynamics(ca.SX.zeros(self.sym.nv, 1), smooth=True, split=True)

    @cached_property
    def forward(self) -> tuple[ca.SX, ca.SX, ca.SX]:
        """(qdd, lambda, status) at (q, qd, tau)."""
        k = self.kkt
        qdd, lam = k.solve(self.sym.tau - self.bias, -self.drift())
        return qdd, lam, k.status

    @property
    def points_only(self) -> bool:
        """Whether every contact of the set is a point (what :meth:`stabilised` handles)."""
        return all(self.robot.contact(f).kind == "point" for f in self.stance.frames)

    def stabilised(self, anchor: ca.SX, gains: ca.SX) -> tuple[ca.SX, ca.SX, ca.SX]:
        """(qdd, lambda, status) with Baumgarte stabilisation of a set of point contacts: the constraint
        J qdd + a0 = -kp (p - anchor) - kd J qd, p the contact points stacked (world), ``anchor`` where they
        are held (3 per point), ``gains`` = [kp, kd] (Pinocchio's BaumgarteCorrectorParameters Kp, Kd with
        joint2_placement at the anchor)."""
        if not self.points_only:
            raise ValueError("Baumgarte stabilisation of surface contacts is not derived (it needs log6)")
        s, k = self.sym, self.kkt
        p = ca.vertcat(*(self.model.fk(f)[0:3, 3] for f in self.stance.frames))
        a0 = self.drift() + gains[0] * (p - anchor) + gains[1] * (self.jacobian @ s.qd)
        qdd, lam = k.solve(s.tau - self.bias, -a0)
        return qdd, lam, k.status

    @cached_property
    def forward_derivatives(self) -> tuple[ca.SX, ca.SX]:
        """(dqdd, dlambda), each with columns [d/dq (nq), d/dqd (nv), d/dtau (nv)]: by the implicit-function
        theorem on F = [ID(q, qd, a) - J^T l - tau; J a + a0] at (a, l) = the solution; a floating base's
        quaternion columns in closed form (:meth:`_quaternion_terms`)."""
        s, k = self.sym, self.kkt
        qdd, lam, _ = self.forward
        a = ca.SX.sym("a", s.nv)
        l = ca.SX.sym("l", self.rows)
        x = self._differentiated
        # F1 = ID(q, qd, a) - J^T l with the contact forces carried by the RNEA's backward pass, and
        # F2 = J a + a0 as the contacts' accelerations at a from its forward pass (split: without
        # gravity); one Jacobian of both, so that their derivatives share the passes
        F1 = self.ne.inverse_dynamics(a, smooth=True, split=True, external=self.wrenches(l))
        F2 = self.acceleration(a)
        dF = ca.substitute(ca.jacobian(ca.vertcat(F1, F2), x), ca.vertcat(a, l), ca.vertcat(qdd, lam))
        n, m = s.nv, self.rows
        P, dl_tau = k.tau_columns()  # d/dtau: the KKT inverse's left blocks, the symmetric one once per pair
        S_inverse = ldlt_solve(k.L, k.D_inverse, ca.SX.eye(m))
        da, dl = [], []
        for c in range(dF.shape[1]):
            r1, r2 = -dF[:n, c], -dF[n:, c]
            if sum(not dF[i, c].is_zero() for i in range(n + m)) <= m:
                # a sparse column (a leg joint's: the base's rows, its leg's, its foot's) by the KKT inverse's
                # blocks [P, -dl_tau^T; dl_tau, S^-1], which d/dtau computes anyway: fewer operations than the
                # factored solve's fill-in (at most m nonzeros: solo12 71 721 to 67 935, anymal 74 490 to 70 884,
                # talos_reduced's two soles 270 440 to 268 648; a looser bound made talos_reduced's larger)
                da.append(P @ r1 - dl_tau.T @ r2)
                dl.append(dl_tau @ r1 + S_inverse @ r2)
            else:
                a_c, l_c = k.solve(r1, r2)
                da.append(a_c)
                dl.append(l_c)
        if self.robot.floating:
            # M (a + [u; 0]) - J^T (l - w) = M a - J^T l + dF1 and J (a + [u; 0]) = J a + J[:, :3] u: the column
            # of d/dq_k is (a, l) = (-[u; 0], -w) plus the KKT inverse's blocks on [0; J[:, :3] u]. J[:, :3] (the
            # base's own velocity, in its frame) is R on each contact's three linear rows and 0 on a surface's
            # angular ones, so those blocks' columns at the linear rows are summed over the contacts first
            D1 = sum((dl_tau[at:at + 3, :] for at in self._starts), ca.SX.zeros(3, n))
            D2 = sum((S_inverse[:, at:at + 3] for at in self._starts), ca.SX.zeros(m, 3))
            zeros = ca.SX.zeros(n - 3, 1)
            R = self.ne.base_rotation
            for j, (u, w) in zip(range(3, 7), self._quaternion_terms(lam)):
                r2 = R @ u
                da.insert(j, -ca.vertcat(u, zeros) - D1.T @ r2)
                dl.insert(j, D2 @ r2 - w)
        return ca.horzcat(*da, P), ca.horzcat(*dl, dl_tau)

    @property
    def _differentiated(self) -> ca.SX:
        """The entries of (q, qd) whose columns the derivatives take by AD: all but a floating base's quaternion."""
        s = self.sym
        return ca.vertcat(s.q[0:3], s.q[7:], s.qd) if self.robot.floating else ca.vertcat(s.q, s.qd)

    def _quaternion_terms(self, l: ca.SX) -> list[tuple[ca.SX, ca.SX]]:
        """Per entry q_k of a floating base's quaternion (k = 3..6), what it changes in the residual at the
        solution with contact forces ``l``, as (u, w): dF1/dq_k = M[:, :3] u - J^T w, dF2/dq_k = 0.

        The columns are those of the functions of the rotation the quaternion stands for, R(quat / |quat|), at
        a unit quaternion: dR_k = dR/dq_k - q_k sum_j q_j dR/dq_j, zero along the quaternion itself (where
        R(quat)'s own formula would give something else: it is a rotation only on the unit sphere), so that
        d/dq T is the tangent-space derivative (Pinocchio's) for T = d(q (+) dv)/d dv. Each dR_k = B R with
        B skew, a rotation of the whole robot, which the RNEA, M and the body-frame Jacobians do not see (the
        base's velocity is in its own frame). It rotates gravity into the base, R^T g, which enters as the
        base's acceleration -R^T g: u = -dR_k^T g. It rotates each world-aligned contact force into its
        body, R^T l_c: w = R dR_k^T l_c per three rows (J^T = J_b^T R^T). It rotates the contacts' world-aligned
        accelerations and velocities, which the solution holds at zero: dF2 = B F2 = 0."""
        s, ne = self.sym, self.ne
        R, quat = ne.base_rotation, s.q[3:7]
        dR = [ca.reshape(ca.jacobian(ca.vec(R), s.q[k]), 3, 3) for k in range(3, 7)]
        radial = sum((quat[j] * dR[j] for j in range(4)), ca.SX.zeros(3, 3))
        out = []
        for j in range(4):
            dR_j = dR[j] - quat[j] * radial
            A = R @ dR_j.T
            w = [A @ l[at + o:at + o + 3] for f, at in zip(self.stance.frames, self._starts)
                 for o in range(0, self.robot.contact(f).rows, 3)]
            out.append((-dR_j.T @ ne.gravity, ca.vertcat(*w)))
        return out

    @property
    def base_determined(self) -> bool:
        """Whether the set has the contact-consistent inverse dynamics (:attr:`inverse`): a floating base and
        at least 6 contact rows (with fewer, J_b^T lambda = the base rows cannot hold for a general qdd)."""
        return self.robot.floating and self.rows >= BASE_ROWS

    @cached_property
    def inverse(self) -> tuple[ca.SX, ca.SX, ca.SX]:
        """(tau, lambda, status) at (q, qd, qdd) for a floating base: M qdd + h = S^T tau + J^T lambda with
        S^T tau zero on the base's six rows. With r = ID(q, qd, qdd) (RNEA) and J_b = J[:, :6] (m x 6) the base
        rows ask J_b^T lambda = r_b (6 equations, m >= 6 unknowns); lambda is their minimum-norm solution
        lambda = J_b (J_b^T J_b)^-1 r_b (numpy's lstsq), the 6 x 6 normal matrix by :func:`guarded_ldlt` (status
        0 where J_b has rank < 6: the stance cannot push the base in some direction), and
        tau = r - J^T lambda with its six base entries exactly 0 (they are 0 up to rounding)."""
        if not self.base_determined:
            raise ValueError("contact-consistent inverse dynamics needs a floating base and at least 6 contact rows")
        r = self.ne.inverse_dynamics(smooth=True)  # with the friction contact_dynamics' bias h has
        Jb = self.jacobian[:, :BASE_ROWS]
        L, D_inverse, status = guarded_ldlt(Jb.T @ Jb)
        lam = Jb @ ldlt_solve(L, D_inverse, r[:BASE_ROWS])
        tau = r - self.jacobian.T @ lam
        return ca.vertcat(ca.SX.zeros(BASE_ROWS, 1), tau[BASE_ROWS:]), lam, status

    def impulse(self, e: ca.SX) -> tuple[ca.SX, ca.SX, ca.SX]:
        """(v+, Lambda, status) for the velocity before impact qd and restitution e:
        Lambda = -(1 + e) S^-1 J qd, v+ = qd + M^-1 J^T Lambda."""
        k, s = self.kkt, self.sym
        v_plus, imp = k.solve(ca.SX.zeros(s.nv, 1), -(1 + e) * (self.jacobian @ s.qd))
        return s.qd + v_plus, imp, k.status

    def impulse_derivatives(self, e: ca.SX) -> tuple[ca.SX, ca.SX]:
        """(dv+, dLambda), columns [d/dq (nq), d/d(v-) (nv)]: the implicit-function theorem on
        F = [M (w - v-) - J^T l; J (w + e v-)] at (w, l) = (v+, Lambda)."""
        s, k = self.sym, self.kkt
        v_plus, imp, _ = self.impulse(e)
        w = ca.SX.sym("w", s.nv)
        l = ca.SX.sym("l", self.rows)
        x = self._differentiated
        F1 = self.ne.mass_matrix @ (w - s.qd) - self.jacobian.T @ l
        F2 = self.jacobian @ (w + e * s.qd)
        dF = ca.substitute(ca.vertcat(ca.jacobian(F1, x), ca.jacobian(F2, x)), ca.vertcat(w, l), ca.vertcat(v_plus, imp))
        n = s.nv
        dv, dl = k.solve(-dF[:n, :], -dF[n:, :])
        if not self.robot.floating:
            return dv, dl
        # M is the base frame's and dF2 = 0 at the solution (:meth:`_quaternion_terms`): with dF1 = -J^T w_k the
        # column of d/dq_k is (0, -w_k)
        terms = self._quaternion_terms(imp)
        return (ca.horzcat(dv[:, 0:3], ca.SX.zeros(n, 4), dv[:, 3:]),
                ca.horzcat(dl[:, 0:3], *(-w for _, w in terms), dl[:, 3:]))


def momentum_rate(model, qdd: ca.SX) -> ca.SX:
    """dh_G/dt = A_G qdd + A_G' qd (6): the rate of the centroidal momentum [linear; angular about the centre
    of mass c], world axes, from the RNEA's forward pass without gravity (body i: angular velocity w,
    angular acceleration dw, classical acceleration a of its origin p, body axes, rotation R): per body
    with mass m, first moment h and inertia I_o about its origin,

        f_i = m a + dw x h + w x (w x h),   n_i = h x a + I_o dw + w x (I_o w)   (about its origin),
        dh_G/dt = sum_i [R f_i; R n_i + (p - c) x R f_i],

    O(n) where differentiating A_G(q) qd along dq/dt costs several times the operations."""
    wb, ne, kin = model.whole_body, model.newton_euler, model.kinematics
    w, dw, a = ne.forward(model.sym.qd, qdd, gravity=False)
    c = wb.com
    linear, angular = ca.SX.zeros(3, 1), ca.SX.zeros(3, 1)
    for frame, m, h, I_o in wb.bodies:
        body = ne.where[frame][0]
        pose = kin.pose(frame)
        wi, dwi, ai = w[body], dw[body], a[body]
        f = pose.R @ (m * ai + ca.cross(dwi, h) + ca.cross(wi, ca.cross(wi, h)))
        n = pose.R @ (ca.cross(h, ai) + I_o @ dwi + ca.cross(wi, I_o @ wi))
        linear += f
        angular += n + ca.cross(pose.p - c, f)
    return ca.vertcat(linear, angular)


def centroidal_map_dot_qd(model) -> ca.SX:
    """A_G'(q, qd) qd (6): the centroidal momentum's rate at qdd = 0 (Pinocchio's
    computeCentroidalMomentumTimeVariation's dhg at a = 0), by :func:`momentum_rate`."""
    return momentum_rate(model, ca.SX.zeros(model.sym.nv, 1))


def com_acceleration(model) -> ca.SX:
    """c'' (3): the centre of mass's acceleration, world coordinates: the linear momentum's rate over the mass."""
    return momentum_rate(model, model.sym.qdd)[0:3] / model.whole_body.mass


def centroidal_inertia(model) -> ca.SX:
    """I_G(q) (3x3): the composite rotational inertia of the robot locked at q, about the centre of mass c, world
    axes: the single-rigid-body model's inertia (with the total mass; Pinocchio's ccrba, data.Ig's rotational
    block). Per body (mass m, first moment h, inertia I_o about its origin p, rotation R), moved from p to c
    with d = p - c and h_w = R h: R I_o R^T - [h_w]x [d]x - [d]x [h_w]x - m [d]x [d]x."""
    wb, kin = model.whole_body, model.kinematics
    c = wb.com
    total = ca.SX.zeros(3, 3)
    for frame, m, h, I_o in wb.bodies:
        pose = kin.pose(frame)
        d, h_w = skew(pose.p - c), skew(pose.R @ h)
        total += pose.R @ I_o @ pose.R.T - h_w @ d - d @ h_w - m * (d @ d)
    return total
