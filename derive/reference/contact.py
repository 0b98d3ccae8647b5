"""Contact and impulse dynamics and the centroidal momentum rate, numpy on :class:`NumericRobot`.

The independent check of :mod:`derive.symbolic.contact`: the KKT systems are assembled from the
reference's M (:meth:`~NumericRobot.crba`), h (:meth:`~NumericRobot.rnea` at qdd = 0), J
(:meth:`~NumericRobot.jacobian`) and J'v (:meth:`~NumericRobot.jdot_v`) and solved densely by
``numpy.linalg.solve``, which is all a reference needs:

    [M J^T; J 0] [qdd; -lambda] = [tau - h; -a0],     [M J^T; J 0] [v+; -Lambda] = [M v-; -e J v-],

with a point contact's three linear rows (classical acceleration) and a surface contact's six rows,
its drift the spatial acceleration (linear part: classical minus w x v), Pinocchio's
CONTACT_3D / CONTACT_6D conventions with LOCAL_WORLD_ALIGNED.
"""

from __future__ import annotations

from typing import Iterable

import numpy as np

from derive.reference.rnea import NumericRobot


def contact_rows(nr: NumericRobot, q, qd, contacts: Iterable[tuple[str, str]]) -> tuple[np.ndarray, np.ndarray]:
    """(J, a0) stacked over ``contacts`` = (frame, kind) pairs, kind "point" or "surface"."""
    Js, drifts = [], []
    for frame, kind in contacts:
        J = nr.jacobian(q, frame)
        a = nr.jdot_v(q, qd, frame)
        if kind == "surface":
            v = J @ qd
            a = np.concatenate([a[:3] - np.cross(v[3:], v[:3]), a[3:]])
        rows = slice(0, 3) if kind == "point" else slice(0, 6)
        Js.append(J[rows])
        drifts.append(a[rows])
    return np.vstack(Js), np.concatenate(drifts)


def _kkt(M: np.ndarray, J: np.ndarray) -> np.ndarray:
    m = J.shape[0]
    return np.block([[M, J.T], [J, np.zeros((m, m))]])


def contact_dynamics(nr: NumericRobot, q, qd, tau, contacts) -> tuple[np.ndarray, np.ndarray]:
    """(qdd, lambda) with M qdd + h = tau + J^T lambda and J qdd + a0 = 0."""
    q, qd, tau = (np.asarray(x, dtype=float) for x in (q, qd, tau))
    M = nr.crba(q)
    h = nr.rnea(q, qd, np.zeros(nr.nv))
    J, a0 = contact_rows(nr, q, qd, contacts)
    x = np.linalg.solve(_kkt(M, J), np.concatenate([tau - h, -a0]))
    return x[:nr.nv], -x[nr.nv:]


def impulse_dynamics(nr: NumericRobot, q, v_minus, e: float, contacts) -> tuple[np.ndarray, np.ndarray]:
    """(v+, Lambda) with M (v+ - v-) = J^T Lambda and J v+ = -e J v-."""
    q, v_minus = np.asarray(q, dtype=float), np.asarray(v_minus, dtype=float)
    M = nr.crba(q)
    J, _ = contact_rows(nr, q, v_minus, contacts)
    x = np.linalg.solve(_kkt(M, J), np.concatenate([M @ v_minus, -e * (J @ v_minus)]))
    return x[:nr.nv], -x[nr.nv:]


def centroidal_momentum_rate(nr: NumericRobot, q, qd, qdd) -> np.ndarray:
    """dh_G/dt = A_G qdd + A_G' qd (6: [linear; angular about the COM], world axes) of a floating base,
    from the RNEA: without gravity, the free flyer's row [force; torque] (root frame, at the root origin)
    is the rate of the whole robot's momentum; turned to world axes and moved to the COM c,
    n_G = R n + (p_root - c) x (R f)."""
    if not nr.robot.floating:
        raise ValueError("centroidal_momentum_rate: a floating base only (the free flyer's row of the RNEA)")
    q = np.asarray(q, dtype=float)
    tau = nr.rnea(q, qd, qdd) - nr.gravity(q)
    pose = nr.body_poses(q)[0]
    R, p = pose[:3, :3], pose[:3, 3]
    f, n = R @ tau[0:3], R @ tau[3:6]
    return np.concatenate([f, n + np.cross(p - nr.com(q), f)])
