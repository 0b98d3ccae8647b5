"""Motor <-> joint maps of a closed chain: its independent coordinates y (the motors) and the joints o
they drive (models.yaml ``outputs``: a parallel ankle's pitch and roll), for position, velocity and torque.

With q = gamma(y) the closure and G = dq/dy (:mod:`derive.symbolic.closure`), the joints' rates are
od = J yd, J = G's output rows (ny x ny, invertible on the chart: models.yaml's check at the reference).
The loops carry no power, so motor torques tau_y and joint torques tau_o that do the same work at every
motion (tau_o . od = tau_y . yd) satisfy

    tau_y = J^T tau_o              (the motor torques that exert the joint torques tau_o)
    tau_o = J^-T tau_y             (the joint torques the motor torques tau_y exert)
    yd    = J^-1 od

Motor -> joint position is the closure's q at the output rows (its closed form or Newton solve).
Joint -> motor position solves the loops the other way, q = gamma_o(o), the outputs known:

- planar loops: the closed forms of :func:`~derive.symbolic.closed_form.closed_form_closure` with the
  outputs given (the dyads);
- distance loops (rods) whose cycle holds one unknown coordinate, a revolute joint (a parallel ankle:
  the foot's pose known, each crank alone): the rod's residual is f(t) = A cos t + B sin t + C in that
  joint's angle t (the distance between a point turning about an axis and a point off it), with
  A = -f''(0), B = f'(0), C = f(0) + f''(0) (derivatives at t = 0: exact, no rounding of pi), so
      t = c + atan2(sin(s - c), cos(s - c)),   s = atan2(B, A) + sigma atan2(sqrt(A^2 + B^2 - C^2), -C),
  sigma = +-1 the reference's branch and c the reference angle rounded to 1e-3 rad (t within pi of it;
  the square root is the reach: out of it, t is NaN and the status 0);
- otherwise :data:`~derive.symbolic.closure.NEWTON_STEPS` Newton steps on the coordinates not in o.

gamma_o(o_ref) must give the reference configuration to :data:`AGREE_TOL`, else the next method is used.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from derive.symbolic.closed_form import closed_form_closure
from derive.symbolic.closure import ASSEMBLED_TOL, NEWTON_STEPS, ClosedChainModel, ReducedChain

AGREE_TOL = 1e-9
"""gamma_o(o_ref) must give the reference configuration to this, else the closed form is not used."""


@dataclass(frozen=True)
class MotorJointMaps:
    """The six maps as SX expressions. Motor side: of y (and z0 for a Newton closure, the position only),
    with the rate and torque symbols ``yd``, ``tau_y``; joint side: of ``o`` (and ``w0``, the start of the
    coordinates not in o, for a Newton solve), with ``od``, ``tau_o``. p last, as everywhere."""

    o: ca.SX
    od: ca.SX
    tau_o: ca.SX
    w0: ca.SX | None  # the joint -> motor Newton solve's start (None for a closed form)
    method: str  # how joint -> motor position is solved
    joint_position: ca.SX  # o of y (z0)
    joint_velocity: ca.SX  # od = J yd
    joint_torque: ca.SX  # tau_o = J^-T tau_y
    motor_position: ca.SX  # y of o (w0)
    motor_status: ca.SX
    motor_residual: ca.SX
    motor_velocity: ca.SX  # yd = J^-1 od
    motor_torque: ca.SX  # tau_y = J^T tau_o


def motor_joint_maps(ccm: ClosedChainModel, red: ReducedChain, closed_form: bool = True) -> MotorJointMaps:
    """The maps of ``ccm.robot.outputs``; ``red`` = ``ccm.in_y()`` (its closure gives the motor side's q).
    ``closed_form`` False: the Newton solve joint -> motor even where a closed form exists."""
    robot, s = ccm.robot, ccm.sym
    names = list(s.joint_names)
    outputs = list(robot.outputs)
    oi = [names.index(c) for c in outputs]
    o = ca.SX.sym("o", len(oi))
    od = ca.vertcat(*[ca.SX.sym(f"d{c}") for c in outputs])
    tau_o = ca.vertcat(*[ca.SX.sym(f"tau_{c}") for c in outputs])
    J = ccm.projection[oi, :]  # d o / d y (q)

    # motor -> joint, at the closure's q
    J_y = ca.substitute(J, s.q, red.gamma)
    joint_position = red.q[oi]
    joint_velocity = J_y @ ccm.yd
    joint_torque = ca.solve(J_y.T, ccm.tau_y)

    # joint -> motor, at q = gamma_o(o)
    found = inverse_closed_form(ccm, o) if closed_form else None
    w = [i for i in range(ccm.nq) if i not in oi]
    if found is not None:
        gamma_o, method = found
        q_pos, w0 = gamma_o, None
    else:
        w0 = ca.SX.sym("w0", len(w))
        start = ca.DM([round(float(robot.reference_q[i]), 3) for i in w])
        q_pos = ca.SX.zeros(ccm.nq, 1)
        q_pos[oi], q_pos[w] = o, w0
        K_w = ccm.constraint_jacobian[ccm.rows, w]
        step_q = ca.SX(s.q)
        step_q[w] = s.q[w] - ca.solve(K_w, ccm.phi[ccm.rows])
        step = ca.Function("step", [s.q, s.p], [step_q])
        for _ in range(NEWTON_STEPS):
            q_pos = step(q_pos, s.p)
        gamma_o = ca.substitute(q_pos, w0, start)
        method = f"Newton: {NEWTON_STEPS} steps on the coordinates not in outputs"
    residual = ca.mmax(ca.fabs(ca.substitute(ccm.phi, s.q, q_pos)))
    status = 0.5 * (1 + ca.sign(ASSEMBLED_TOL - ca.fmin(residual, 1)))  # as the closure's (NaN: 0)
    J_o = ca.substitute(J, s.q, gamma_o)
    return MotorJointMaps(o=o, od=od, tau_o=tau_o, w0=w0, method=method, joint_position=joint_position,
                          joint_velocity=joint_velocity, joint_torque=joint_torque, motor_position=q_pos[ccm.y],
                          motor_status=status, motor_residual=residual, motor_velocity=ca.solve(J_o, od),
                          motor_torque=J_o.T @ tau_o)


def inverse_closed_form(ccm: ClosedChainModel, o: ca.SX) -> tuple[ca.SX, str] | None:
    """(q = gamma_o(o) as an SX expression of o and p, a one-line description) or None (module docstring)."""
    found = closed_form_closure(ccm.model, o, tuple(ccm.robot.outputs))
    if found is not None:
        return found
    return _rod_closure(ccm, o)


def _rod_closure(ccm: ClosedChainModel, o: ca.SX) -> tuple[ca.SX, str] | None:
    """Distance loops, each with one unknown revolute coordinate in its cycle: a cos t + b sin t + c = 0."""
    robot, s, kin = ccm.robot, ccm.sym, ccm.model.kinematics
    if robot.floating or any(lp.kind != "distance" for lp in robot.loops):
        return None
    if any(j.mimic is not None for j in robot.joints):
        return None
    names = list(s.joint_names)
    known = {c: o[i] for i, c in enumerate(robot.outputs)}
    q_ref = np.array(robot.reference_q, dtype=float)
    p_def = np.array([p.default for p in robot.parameters], dtype=float)
    solved: dict[str, ca.SX] = {}
    t = ca.SX.sym("t")
    for row, lp in enumerate(robot.loops):  # a distance loop has one row
        cycle = set(kin.ancestors[lp.a]) | set(kin.ancestors[lp.b])
        free = [k for k in cycle if k not in known]
        if len(free) != 1 or free[0] in solved or kin.motions[free[0]].kind != "revolute":
            return None
        k = free[0]
        pairs = [(s.q[names.index(c)], x) for c, x in known.items()] + [(s.q[names.index(k)], t)]
        f = ca.substitute([ccm.phi[row]], [ca.vertcat(*[a for a, _ in pairs])], [ca.vertcat(*[b for _, b in pairs])])[0]
        if ca.depends_on(f, s.q):
            return None
        df = ca.jacobian(f, t)
        d2f = ca.jacobian(df, t)
        f0, df0, d2f0 = (ca.substitute(e, t, ca.SX(0)) for e in (f, df, d2f))
        A, B, C = -d2f0, df0, f0 + d2f0
        alpha = ca.atan2(B, A)
        beta = ca.atan2(ca.sqrt(A * A + B * B - C * C), -C)  # acos(-C / rho), rho = sqrt(A^2 + B^2); NaN out of reach
        centre = round(float(q_ref[names.index(k)]), 3)
        at = ca.Function("at", [o, s.p], [alpha, beta])
        o_ref = q_ref[[names.index(c) for c in robot.outputs]]
        a_ref, b_ref = (float(v) for v in at(o_ref, p_def))
        sigma = min((1.0, -1.0), key=lambda sg: abs(math.remainder(a_ref + sg * b_ref - q_ref[names.index(k)], 2 * math.pi)))
        u = alpha + sigma * beta - centre
        solved[k] = centre + ca.atan2(ca.sin(u), ca.cos(u))
    if set(known) | set(solved) != set(names):
        return None
    q = ca.vertcat(*[known[c] if c in known else solved[c] for c in names])
    o_ref = q_ref[[names.index(c) for c in robot.outputs]]
    got = np.array(ca.Function("g", [o, s.p], [q])(o_ref, p_def), dtype=float).ravel()
    if not np.all(np.abs(got - q_ref) <= AGREE_TOL):
        return None
    return q, "closed form: one crank per rod (a cos t + b sin t = c)"
