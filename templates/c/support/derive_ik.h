/*
 * Levenberg-Marquardt inverse kinematics over n joints: the same for every robot.
 *
 * The generated <robot>_ik_<frame> fills a derive_ik_problem (limits, caps, its fk_jacobian)
 * and passes its number of joints n and a work buffer of DERIVE_IK_WORK_REALS(n) reals from
 * its stack.
 * C99, no allocation, no globals, only <math.h>; static inline (see derive_linalg.h).
 *
 * As derive.ik, method "lm": e = [p_target - p; log(R_target R^T)], E = 1/2 sum w_i e_i^2,
 * step (J^T W J + lambda I) dq = J^T W e by LDL^T; joints pushed past a limit are held on it
 * and the rest re-solved; a step is taken if E decreases (lambda / 10), else lambda * 10; an
 * attempt that stalls restarts from q drawn uniformly within the sampling box (xorshift32 with
 * a fixed seed: the restarts are the same at every call).
 */
#ifndef DERIVE_IK_H
#define DERIVE_IK_H

#include "derive_linalg.h"

#ifndef DERIVE_IK_SUCCESS
#define DERIVE_IK_SUCCESS 0       /* residual within the tolerances, q within the limits */
#define DERIVE_IK_NOT_CONVERGED 1 /* iteration cap reached: q is the best found (unreachable target?) */
#define DERIVE_IK_BAD_INPUT 2     /* a non-finite input, a negative weight or all weights 0: q is mid-range */
#endif

/* Reals of work derive_ik_lm needs for n joints: qc, qt, qbest, dq, g, d, held (7 n), Jc, Jt (2 x 6 n),
 * A0, A (2 n^2). */
#define DERIVE_IK_WORK_REALS(n) (19 * (n) + 2 * (n) * (n))

/* world_T_frame (4x4) and its Jacobian (6 x n, [linear; angular]) at q; p: the robot's parameters. */
typedef void (*derive_fk_jacobian_fn)(const DERIVE_REAL *q, const DERIVE_REAL *p, DERIVE_REAL *T, DERIVE_REAL *J);

typedef struct {
    int max_iterations;                /* LM iterations in all, restarts included */
    int max_attempt;                   /* iterations of one attempt before a restart */
    DERIVE_REAL tol_position;          /* success: position error below (m) */
    DERIVE_REAL tol_rotation;          /* and rotation error below (rad) */
    DERIVE_REAL lambda0;               /* damping at each start */
    DERIVE_REAL lambda_min;            /* smallest damping */
    DERIVE_REAL lambda_stall;          /* damping beyond which an attempt has stalled */
    const DERIVE_REAL *lower;          /* n: joint limits, +-1e30 where none */
    const DERIVE_REAL *upper;          /* n */
    const DERIVE_REAL *sample_lower;   /* n: box of the mid-range start and of the restarts */
    const DERIVE_REAL *sample_upper;   /* n */
    derive_fk_jacobian_fn fk_jacobian;
    const DERIVE_REAL *p;              /* passed to fk_jacobian (NULL for a robot without parameters) */
} derive_ik_problem;

/* e (6) of the pose T (4x4) against the target Tt; returns E = 1/2 sum w_i e_i^2. */
static inline DERIVE_REAL derive_ik_error(const DERIVE_REAL *T, const DERIVE_REAL *Tt, const DERIVE_REAL *w,
                                          DERIVE_REAL *e)
{
    DERIVE_REAL R[9], E = DERIVE_LIT(0.0);
    int i, j, k;
    for (i = 0; i < 3; ++i) {
        for (j = 0; j < 3; ++j) { /* R = Rt R^T */
            R[3 * i + j] = DERIVE_LIT(0.0);
            for (k = 0; k < 3; ++k) R[3 * i + j] += Tt[4 * i + k] * T[4 * j + k];
        }
        e[i] = Tt[4 * i + 3] - T[4 * i + 3];
    }
    derive_so3_log(R, e + 3);
    for (i = 0; i < 6; ++i) E += DERIVE_LIT(0.5) * w[i] * e[i] * e[i];
    return E;
}

/* position and rotation error: norms of the weighted rows of e */
static inline void derive_ik_norms(const DERIVE_REAL *e, const DERIVE_REAL *w, DERIVE_REAL *residual)
{
    DERIVE_REAL a = DERIVE_LIT(0.0), b = DERIVE_LIT(0.0);
    int i;
    for (i = 0; i < 3; ++i) {
        if (w[i] > DERIVE_LIT(0.0)) a += e[i] * e[i];
        if (w[3 + i] > DERIVE_LIT(0.0)) b += e[3 + i] * e[3 + i];
    }
    residual[0] = DERIVE_SQRT(a);
    residual[1] = DERIVE_SQRT(b);
}

/*
 * q (n joints; a parameter, not a field of prob, so that the compiler specialises the loops to a
 * caller's constant) within [lower, upper] with world_T_frame(q) = T (4x4), from q0 (n, clipped into the
 * limits; NULL: mid-range) with weights w (6; NULL: all 1). residual = [position error,
 * rotation error] of the weighted rows at the returned q, the best found.
 * Returns DERIVE_IK_SUCCESS, DERIVE_IK_NOT_CONVERGED or DERIVE_IK_BAD_INPUT.
 */
static inline int derive_ik_lm(const int n, const derive_ik_problem *prob, DERIVE_REAL *work, const DERIVE_REAL *T,
                               const DERIVE_REAL *q0, const DERIVE_REAL *w, DERIVE_REAL *q, DERIVE_REAL *residual)
{
    const DERIVE_REAL *lower = prob->lower, *upper = prob->upper;
    const DERIVE_REAL *sample_lower = prob->sample_lower, *sample_upper = prob->sample_upper;
    DERIVE_REAL *qc = work, *qt = qc + n, *qbest = qt + n, *dq = qbest + n, *g = dq + n, *d = g + n;
    DERIVE_REAL *held = d + n, *Jc = held + n, *Jt = Jc + 6 * n, *A0 = Jt + 6 * n, *A = A0 + n * n;
    DERIVE_REAL wt[6], Tc[16], Tt[16], ec[6], et[6], ebest[6], r[2];
    DERIVE_REAL E, Et, Ebest, lambda = prob->lambda0;
    unsigned long seed = 2463534242UL; /* xorshift32 state: restarts are the same at every call */
    int i, j, k, it, attempt = 0, any_held, status = DERIVE_IK_NOT_CONVERGED;

    for (i = 0; i < 6; ++i) wt[i] = w ? w[i] : DERIVE_LIT(1.0);
    for (i = 0; i < n; ++i) { /* start: q0 clipped into the limits, or mid-range */
        qc[i] = q0 ? q0[i] : DERIVE_LIT(0.5) * (sample_lower[i] + sample_upper[i]);
        qc[i] = DERIVE_FMIN(DERIVE_FMAX(qc[i], lower[i]), upper[i]);
        q[i] = qc[i];
    }
    for (i = 0, k = 1; i < 16; ++i) k = k && T[i] - T[i] == DERIVE_LIT(0.0);
    for (i = 0, E = DERIVE_LIT(0.0); i < 6; ++i) {
        k = k && wt[i] >= DERIVE_LIT(0.0) && wt[i] - wt[i] == DERIVE_LIT(0.0);
        E += wt[i];
    }
    k = k && E > DERIVE_LIT(0.0);
    for (i = 0; i < n; ++i) k = k && qc[i] - qc[i] == DERIVE_LIT(0.0);
    if (!k) { /* NaN or infinity, a negative weight, or all weights zero */
        for (i = 0; i < n; ++i) q[i] = DERIVE_LIT(0.5) * (sample_lower[i] + sample_upper[i]);
        residual[0] = residual[1] = (DERIVE_REAL)HUGE_VAL;
        return DERIVE_IK_BAD_INPUT;
    }
    prob->fk_jacobian(qc, prob->p, Tc, Jc);
    E = derive_ik_error(Tc, T, wt, ec);
    Ebest = E;
    for (i = 0; i < n; ++i) qbest[i] = qc[i];
    for (i = 0; i < 6; ++i) ebest[i] = ec[i];

    for (it = 0; it < prob->max_iterations; ++it) {
        derive_ik_norms(ec, wt, r);
        if (r[0] < prob->tol_position && r[1] < prob->tol_rotation) {
            for (i = 0; i < n; ++i) qbest[i] = qc[i];
            for (i = 0; i < 6; ++i) ebest[i] = ec[i];
            status = DERIVE_IK_SUCCESS;
            break;
        }
        if (attempt >= prob->max_attempt || lambda > prob->lambda_stall) { /* stalled: restart */
            for (i = 0; i < n; ++i) {
                seed ^= (seed << 13) & 0xFFFFFFFFUL;
                seed ^= seed >> 17;
                seed ^= (seed << 5) & 0xFFFFFFFFUL;
                qc[i] = sample_lower[i] + (sample_upper[i] - sample_lower[i])
                        * (DERIVE_REAL)(seed >> 8) * DERIVE_LIT(5.9604644775390625e-08);
            }
            prob->fk_jacobian(qc, prob->p, Tc, Jc);
            E = derive_ik_error(Tc, T, wt, ec);
            lambda = prob->lambda0;
            attempt = 0;
            continue;
        }
        ++attempt;
        /* A0 = J^T W J, g = J^T W e */
        for (i = 0; i < n; ++i) {
            g[i] = DERIVE_LIT(0.0);
            for (k = 0; k < 6; ++k) g[i] += Jc[n * k + i] * wt[k] * ec[k];
            for (j = 0; j <= i; ++j) {
                DERIVE_REAL s = DERIVE_LIT(0.0);
                for (k = 0; k < 6; ++k) s += Jc[n * k + i] * wt[k] * Jc[n * k + j];
                A0[n * i + j] = s;
                A0[n * j + i] = s;
            }
        }
        for (i = 0; i < n * n; ++i) A[i] = A0[i];
        for (i = 0; i < n; ++i) {
            A[n * i + i] += lambda;
            dq[i] = g[i];
        }
        k = derive_ldlt_solve(n, A, dq);
        any_held = 0;
        for (i = 0; k && i < n; ++i) { /* joints the step pushes past a limit are held on it */
            const DERIVE_REAL qi = qc[i] + dq[i];
            held[i] = (qi < lower[i] || qi > upper[i]) ? DERIVE_LIT(1.0) : DERIVE_LIT(0.0);
            d[i] = held[i] * (DERIVE_FMIN(DERIVE_FMAX(qi, lower[i]), upper[i]) - qc[i]);
            any_held = any_held || held[i] > DERIVE_LIT(0.0);
        }
        if (k && any_held) { /* re-solve for the free joints */
            for (i = 0; i < n; ++i) {
                dq[i] = g[i];
                for (j = 0; j < n; ++j) {
                    dq[i] -= (A0[n * i + j] + (i == j ? lambda : DERIVE_LIT(0.0))) * d[j];
                    A[n * i + j] = (held[i] > DERIVE_LIT(0.0) || held[j] > DERIVE_LIT(0.0))
                        ? (i == j ? DERIVE_LIT(1.0) : DERIVE_LIT(0.0))
                        : A0[n * i + j] + (i == j ? lambda : DERIVE_LIT(0.0));
                }
                if (held[i] > DERIVE_LIT(0.0)) dq[i] = d[i];
            }
            k = derive_ldlt_solve(n, A, dq);
        }
        if (!k) { /* not positive definite in this precision: damp more */
            lambda *= DERIVE_LIT(10.0);
            continue;
        }
        for (i = 0; i < n; ++i) qt[i] = DERIVE_FMIN(DERIVE_FMAX(qc[i] + dq[i], lower[i]), upper[i]);
        prob->fk_jacobian(qt, prob->p, Tt, Jt);
        Et = derive_ik_error(Tt, T, wt, et);
        if (Et < E) { /* accept */
            E = Et;
            for (i = 0; i < n; ++i) qc[i] = qt[i];
            for (i = 0; i < 16; ++i) Tc[i] = Tt[i];
            for (i = 0; i < 6 * n; ++i) Jc[i] = Jt[i];
            for (i = 0; i < 6; ++i) ec[i] = et[i];
            lambda = DERIVE_FMAX(lambda * DERIVE_LIT(0.1), prob->lambda_min);
            if (E < Ebest) {
                Ebest = E;
                for (i = 0; i < n; ++i) qbest[i] = qc[i];
                for (i = 0; i < 6; ++i) ebest[i] = ec[i];
            }
        } else {
            lambda = DERIVE_FMIN(lambda * DERIVE_LIT(10.0), DERIVE_LIT(1e10));
        }
    }
    for (i = 0; i < n; ++i) q[i] = qbest[i];
    derive_ik_norms(ebest, wt, residual);
    return status;
}

#endif /* DERIVE_IK_H */
