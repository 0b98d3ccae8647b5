# Levenberg-Marquardt inverse kinematics over n joints (as derive.ik, method "lm", and the C
# derive_ik.h): the same in every generated module, which passes its limits, caps and
# fk_jacobian. Copied verbatim after the module's imports (math, numpy as np). The one generated
# function that loops over a batch in Python (_ik_batch): the solver iterates per state.


def _so3_log(R):
    """w = log(R) (3): angle * axis, the angle from atan2 (exact near 0 and pi)."""
    v = 0.5 * np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    c = 0.5 * (np.trace(R) - 1.0)
    s = math.sqrt(v @ v)
    if s >= 1e-9:
        return math.atan2(s, c) / s * v
    if c > 0.0:
        return v
    k = int(np.argmax(np.diag(R)))   # angle ~ pi: the axis from the largest column of (R + I) / 2
    col = 0.5 * (R[:, k] + np.eye(3)[:, k])
    return math.pi * col / math.sqrt(max(0.5 * (R[k, k] + 1.0), 1e-30))


_IK_TOL_TARGET = 1e-6
"""T is a rigid transform: R R^T = I entry by entry and its last row [0 0 0 1] within this, det R > 0."""


def _ik_target_ok(T):
    """T (4x4) finite and a rigid transform within _IK_TOL_TARGET (as derive_ik_target_ok in C)."""
    if not np.isfinite(T).all():
        return False
    R = T[:3, :3]
    return bool(np.abs(T[3] - [0.0, 0.0, 0.0, 1.0]).max() <= _IK_TOL_TARGET and np.abs(R).max() <= 1.0 + _IK_TOL_TARGET
                and np.abs(R @ R.T - np.eye(3)).max() <= _IK_TOL_TARGET and np.linalg.det(R) > 0.0)


def _ik_lm(fk_jacobian, T, q0, w, *, lower, upper, sample_lower, sample_upper, max_iterations, attempt,
           tol_position, tol_rotation, lambda0, lambda_min, lambda_stall):
    """(q, residual, status) with fk_jacobian(q) = (world_T_frame (4x4), J) reaching T: status 0
    solved, 1 not converged (q the best found), 2 bad input (q mid-range, residual inf): an entry
    of T, q0 or w not finite, T not a rigid transform (_ik_target_ok), a weight < 0 or all 0."""
    n = lower.size
    mid = 0.5 * (sample_lower + sample_upper)
    T = np.asarray(T, dtype=float).reshape(4, 4)
    w = np.ones(6) if w is None else np.asarray(w, dtype=float).reshape(6)
    q0 = None if q0 is None else np.asarray(q0, dtype=float).reshape(n)
    # q0 checked before it is clipped: a limit would clip an infinity to a finite value
    if not (_ik_target_ok(T) and np.isfinite(w).all() and (w >= 0).all() and (w > 0).any()
            and (q0 is None or np.isfinite(q0).all())):
        return mid, np.full(2, np.inf), 2
    qc = mid if q0 is None else np.clip(q0, lower, upper)

    def error(Tq):
        e = np.concatenate([T[:3, 3] - Tq[:3, 3], _so3_log(T[:3, :3] @ Tq[:3, :3].T)])
        return e, 0.5 * float(w @ (e * e))

    def fk_j(q):
        Tq, J = fk_jacobian(q)
        return Tq, np.reshape(J, (6, n))

    def norms(e):
        return np.array([math.sqrt(float(np.sum(e[:3][w[:3] > 0] ** 2))), math.sqrt(float(np.sum(e[3:][w[3:] > 0] ** 2)))])

    Tq, J = fk_j(qc)
    ec, E = error(Tq)
    qbest, ebest, Ebest = qc, ec, E
    lam, tries, status, seed = lambda0, 0, 1, 2463534242
    for _ in range(max_iterations):
        r = norms(ec)
        if r[0] < tol_position and r[1] < tol_rotation:
            qbest, ebest, status = qc, ec, 0
            break
        if tries >= attempt or lam > lambda_stall:  # stalled: restart
            qc = np.empty(n)
            for i in range(n):
                seed ^= (seed << 13) & 0xFFFFFFFF
                seed ^= seed >> 17
                seed ^= (seed << 5) & 0xFFFFFFFF
                qc[i] = sample_lower[i] + (sample_upper[i] - sample_lower[i]) * (seed >> 8) * 5.9604644775390625e-08
            Tq, J = fk_j(qc)
            ec, E = error(Tq)
            lam, tries = lambda0, 0
            continue
        tries += 1
        A0 = J.T @ (w[:, None] * J)
        g = J.T @ (w * ec)
        A = A0 + lam * np.eye(n)
        try:
            L = np.linalg.cholesky(A)
            dq = np.linalg.solve(L.T, np.linalg.solve(L, g))
            step = qc + dq
            held = (step < lower) | (step > upper)  # joints pushed past a limit are held on it
            if held.any():
                d = np.where(held, np.clip(step, lower, upper) - qc, 0.0)
                free = ~held
                dq = d.copy()
                dq[free] = np.linalg.solve(A[np.ix_(free, free)], (g - A @ d)[free]) if free.any() else dq[free]
        except np.linalg.LinAlgError:  # not positive definite in this precision: damp more
            lam *= 10.0
            continue
        qt = np.clip(qc + dq, lower, upper)
        Tt, Jt = fk_j(qt)
        et, Et = error(Tt)
        if Et < E:
            qc, J, ec, E = qt, Jt, et, Et
            lam = max(lam * 0.1, lambda_min)
            if E < Ebest:
                qbest, ebest, Ebest = qc, ec, E
        else:
            lam = min(lam * 10.0, 1e10)
    return qbest, norms(ebest), status


def _ik_batch(solve, n, T, *vectors):
    """A batch of IK problems solved one state after the other by solve(T, *vectors) (the one
    generated function that loops over a batch in Python: the solver iterates per state), or None
    when every input is one state (T 4x4, the vectors 1-D or None). T (..., 4, 4) and the vectors
    (..., k) or None broadcast against each other; returns q (..., n), residual (..., 2) and status
    (...) an int array, each state's entries those solve gives for it alone."""
    T = np.asarray(T, dtype=float)  # checked by the caller (_matrix, _array): (..., 4, 4) and (..., k)
    vectors = [None if v is None else np.asarray(v, dtype=float) for v in vectors]
    if T.ndim <= 2 and all(v is None or v.ndim <= 1 for v in vectors):
        return None
    shape = np.broadcast_shapes(T.shape[:-2], *(v.shape[:-1] for v in vectors if v is not None))
    T = np.broadcast_to(T, shape + (4, 4))
    vectors = [None if v is None else np.broadcast_to(v, shape + v.shape[-1:]) for v in vectors]
    q, residual, status = np.empty(shape + (n,)), np.empty(shape + (2,)), np.empty(shape, dtype=int)
    for i in np.ndindex(shape):
        q[i], residual[i], status[i] = solve(T[i], *(None if v is None else v[i] for v in vectors))
    return q, residual, status
