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
 *
 * Inputs are checked before anything else (DERIVE_IK_BAD_INPUT, q mid-range, residual not NaN):
 * every entry of T, q0 and w finite; T a rigid transform, its rotation block R with R R^T = I
 * entry by entry within DERIVE_IK_TOL_TARGET (1e-6; 1e-4 with DERIVE_FLOAT) and det R > 0 (so
 * det R = +1 to within a few times that), its last row [0 0 0 1] within the same; w >= 0, not all 0.
 *
 * -ffast-math / -Ofast / -ffinite-math-only: supported. Those let the compiler assume that no
 * value is NaN or infinite and delete isfinite(), isnan(), x != x and x - x == 0 (and compare
 * a NaN as "less than" anything), which used to turn an all-NaN target into a "success". Here
 * finiteness is read from the bits (derive_ik_finite: integer operations on the IEEE 754
 * exponent, through a union, well defined in C99), which no floating-point option may remove,
 * and a SUCCESS is only returned with a q and residual whose bits are finite.
 */
#ifndef DERIVE_IK_H
#define DERIVE_IK_H

#include "derive_linalg.h"

#ifndef DERIVE_IK_SUCCESS
#define DERIVE_IK_SUCCESS 0       /* residual within the tolerances, q within the limits */
#define DERIVE_IK_NOT_CONVERGED 1 /* iteration cap reached: q is the best found (unreachable target?) */
#define DERIVE_IK_BAD_INPUT 2     /* a non-finite input, T not a rigid transform, a negative weight or all weights 0: q is mid-range */
#endif

/* Tolerance of the check that T is a rigid transform (R R^T = I, det R > 0, last row [0 0 0 1]). */
#ifndef DERIVE_IK_TOL_TARGET
#ifdef DERIVE_FLOAT
#define DERIVE_IK_TOL_TARGET DERIVE_LIT(1e-4)
#else
#define DERIVE_IK_TOL_TARGET DERIVE_LIT(1e-6)
#endif
#endif

/* The residual reported with DERIVE_IK_BAD_INPUT: +infinity, or under -ffinite-math-only (where
 * infinity is off limits) a huge finite value. */
#if defined(__FINITE_MATH_ONLY__) && __FINITE_MATH_ONLY__
#define DERIVE_IK_NO_RESIDUAL DERIVE_LIT(1e30)
#else
#define DERIVE_IK_NO_RESIDUAL ((DERIVE_REAL)HUGE_VAL)
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

/*
 * 1 if x is finite (neither NaN nor +-infinity), else 0, from its bits: an IEEE 754 binary32 or
 * binary64 value (float, double) is not finite exactly when its exponent bits are all ones. The
 * test is integer arithmetic on the bytes of x (read through a union of x and unsigned char[],
 * well defined in C99), so -ffast-math and -ffinite-math-only cannot remove it as they remove
 * isfinite() or x - x == 0. The byte order of floats is taken to be that of integers. A
 * DERIVE_REAL of another size (long double) falls back to x - x == 0, which fast-math may remove.
 */
static inline DERIVE_FN int derive_ik_finite(DERIVE_REAL x)
{
    union { DERIVE_REAL x; unsigned char b[sizeof(DERIVE_REAL)]; } u;
    union { unsigned short s; unsigned char b[sizeof(unsigned short)]; } order;
    const int size = (int)sizeof(DERIVE_REAL);
    unsigned int top;
    if ((size != 4 && size != 8) || (unsigned char)-1 != 255U) return x - x == DERIVE_LIT(0.0);
    u.x = x;
    order.s = 1U;
    /* the 16 most significant bits of x: sign, exponent, leading bits of the significand */
    top = order.b[0] ? ((unsigned int)u.b[size - 1] << 8) | u.b[size - 2] : ((unsigned int)u.b[0] << 8) | u.b[1];
    return size == 4 ? (top & 0x7F80U) != 0x7F80U : (top & 0x7FF0U) != 0x7FF0U;
}

/* 1 if every entry of T (4x4) is finite and T is a rigid transform within DERIVE_IK_TOL_TARGET: its
 * rotation block R with R R^T = I entry by entry and det R > 0, its last row [0 0 0 1]. */
static inline DERIVE_FN int derive_ik_target_ok(const DERIVE_REAL *T)
{
    const DERIVE_REAL tol = DERIVE_IK_TOL_TARGET;
    DERIVE_REAL d;
    int i, j, k;
    for (i = 0; i < 16; ++i) {
        if (!derive_ik_finite(T[i])) return 0;
    }
    for (i = 0; i < 4; ++i) {
        if (!(DERIVE_FABS(T[12 + i] - (i == 3 ? DERIVE_LIT(1.0) : DERIVE_LIT(0.0))) <= tol)) return 0;
    }
    for (i = 0; i < 3; ++i) { /* |R_ij| <= 1 first: no product below can overflow */
        for (j = 0; j < 3; ++j) {
            if (!(DERIVE_FABS(T[4 * i + j]) <= DERIVE_LIT(1.0) + tol)) return 0;
        }
    }
    for (i = 0; i < 3; ++i) { /* R R^T = I */
        for (j = 0; j <= i; ++j) {
            d = i == j ? DERIVE_LIT(-1.0) : DERIVE_LIT(0.0);
            for (k = 0; k < 3; ++k) d += T[4 * i + k] * T[4 * j + k];
            if (!(DERIVE_FABS(d) <= tol)) return 0;
        }
    }
    d = T[0] * (T[5] * T[10] - T[6] * T[9]) - T[1] * (T[4] * T[10] - T[6] * T[8])
        + T[2] * (T[4] * T[9] - T[5] * T[8]);
    return d > DERIVE_LIT(0.0);
}

/* e (6) of the pose T (4x4) against the target Tt; returns E = 1/2 sum w_i e_i^2. */
static inline DERIVE_FN DERIVE_REAL derive_ik_error(const DERIVE_REAL *T, const DERIVE_REAL *Tt, const DERIVE_REAL *w,
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
static inline DERIVE_FN void derive_ik_norms(const DERIVE_REAL *e, const DERIVE_REAL *w, DERIVE_REAL *residual)
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
static inline DERIVE_FN int derive_ik_lm(const int n, const derive_ik_problem *prob, DERIVE_REAL *work, const DERIVE_REAL *T,
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

    /* inputs first, q0 before it is clipped (fmin and fmax drop a NaN, a limit clips an infinity) */
    for (i = 0; i < 6; ++i) wt[i] = w ? w[i] : DERIVE_LIT(1.0);
    k = derive_ik_target_ok(T);
    for (i = 0; i < 6; ++i) k = k && derive_ik_finite(wt[i]) && wt[i] >= DERIVE_LIT(0.0);
    k = k && (wt[0] > DERIVE_LIT(0.0) || wt[1] > DERIVE_LIT(0.0) || wt[2] > DERIVE_LIT(0.0)
              || wt[3] > DERIVE_LIT(0.0) || wt[4] > DERIVE_LIT(0.0) || wt[5] > DERIVE_LIT(0.0));
    for (i = 0; k && q0 && i < n; ++i) k = derive_ik_finite(q0[i]);
    if (!k) { /* NaN or infinity, T not a rigid transform, a negative weight, or all weights zero */
        for (i = 0; i < n; ++i) q[i] = DERIVE_LIT(0.5) * (sample_lower[i] + sample_upper[i]);
        residual[0] = residual[1] = DERIVE_IK_NO_RESIDUAL;
        return DERIVE_IK_BAD_INPUT;
    }
    for (i = 0; i < n; ++i) { /* start: q0 clipped into the limits, or mid-range */
        qc[i] = q0 ? q0[i] : DERIVE_LIT(0.5) * (sample_lower[i] + sample_upper[i]);
        qc[i] = DERIVE_FMIN(DERIVE_FMAX(qc[i], lower[i]), upper[i]);
        q[i] = qc[i];
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
    /* never a success with a NaN or infinite q or residual (compiled with -ffast-math, a NaN
     * compares below any tolerance) */
    k = derive_ik_finite(residual[0]) && derive_ik_finite(residual[1]);
    for (i = 0; i < n; ++i) k = k && derive_ik_finite(q[i]);
    if (!k) status = DERIVE_IK_NOT_CONVERGED;
    return status;
}

#endif /* DERIVE_IK_H */
