/*
 * Small dense linear algebra for derive's generated solvers: the same for every robot.
 *
 * C99, no allocation, no globals, only <math.h> (through derive_real.h). Every routine works
 * in buffers its caller owns (sizes in the arguments). The functions are static inline so that
 * several robots' generated code links into one program without duplicate symbols, and so
 * that the compiler can specialise them to the caller's constant sizes.
 */
#ifndef DERIVE_LINALG_H
#define DERIVE_LINALG_H

#include "derive_real.h"

/*
 * A x = b for symmetric positive definite A (n x n, row-major) by LDL^T in place: A's lower
 * triangle becomes L (unit diagonal implied) and its diagonal D; b becomes x.
 * Returns 0 (A and b partly overwritten) if a pivot is not positive, else 1.
 */
static inline DERIVE_FN int derive_ldlt_solve(int n, DERIVE_REAL *A, DERIVE_REAL *b)
{
    int i, j, k;
    for (j = 0; j < n; ++j) {
        DERIVE_REAL d = A[n * j + j];
        for (k = 0; k < j; ++k) d -= A[n * j + k] * A[n * j + k] * A[n * k + k];
        if (!(d > DERIVE_LIT(0.0))) return 0;
        A[n * j + j] = d;
        for (i = j + 1; i < n; ++i) {
            DERIVE_REAL s = A[n * i + j];
            for (k = 0; k < j; ++k) s -= A[n * i + k] * A[n * j + k] * A[n * k + k];
            A[n * i + j] = s / d;
        }
    }
    for (i = 0; i < n; ++i) {
        for (k = 0; k < i; ++k) b[i] -= A[n * i + k] * b[k];
    }
    for (i = 0; i < n; ++i) b[i] /= A[n * i + i];
    for (i = n - 1; i >= 0; --i) {
        for (k = i + 1; k < n; ++k) b[i] -= A[n * k + i] * b[k];
    }
    return 1;
}

/*
 * w = log(R) (3), the SO(3) logarithm of a rotation matrix R (3x3, row-major): angle * axis,
 * the angle from atan2(sin, cos) (exact near 0 and pi); near pi the axis comes from the
 * largest column of (R + I) / 2.
 */
static inline DERIVE_FN void derive_so3_log(const DERIVE_REAL *R, DERIVE_REAL *w)
{
    DERIVE_REAL v[3], c, s;
    int i, k;
    v[0] = DERIVE_LIT(0.5) * (R[7] - R[5]);
    v[1] = DERIVE_LIT(0.5) * (R[2] - R[6]);
    v[2] = DERIVE_LIT(0.5) * (R[3] - R[1]);
    c = DERIVE_LIT(0.5) * (R[0] + R[4] + R[8] - DERIVE_LIT(1.0));
    s = DERIVE_SQRT(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    if (s >= DERIVE_LIT(1e-9)) { /* angle / sin(angle) * v */
        const DERIVE_REAL f = DERIVE_ATAN2(s, c) / s;
        for (i = 0; i < 3; ++i) w[i] = f * v[i];
    } else if (c > DERIVE_LIT(0.0)) { /* angle ~ 0 */
        for (i = 0; i < 3; ++i) w[i] = v[i];
    } else { /* angle ~ pi */
        k = (R[0] >= R[4] && R[0] >= R[8]) ? 0 : (R[4] >= R[8] ? 1 : 2);
        s = DERIVE_SQRT(DERIVE_FMAX(DERIVE_LIT(0.5) * (R[4 * k] + DERIVE_LIT(1.0)), DERIVE_LIT(1e-30)));
        for (i = 0; i < 3; ++i) {
            w[i] = DERIVE_LIT(3.141592653589793) * DERIVE_LIT(0.5) * (R[3 * i + k] + (i == k ? DERIVE_LIT(1.0) : DERIVE_LIT(0.0))) / s;
        }
    }
}

/*
 * Singular values s (k, unordered) of B (k x n, row-major, k <= n) by one-sided Jacobi
 * (Hestenes): rotate pairs of rows of B (overwritten) until all are orthogonal; the row norms
 * are then the s_i = sqrt(l_i), l_i the eigenvalues of B B^T, with high relative accuracy.
 */
static inline DERIVE_FN void derive_singular_values(int k, int n, DERIVE_REAL *B, DERIVE_REAL *s)
{
#ifdef DERIVE_FLOAT
    const DERIVE_REAL tol = DERIVE_LIT(1e-7);
#else
    const DERIVE_REAL tol = DERIVE_LIT(1e-15);
#endif
    int i, j, c, sweep, rotated;
    for (sweep = 0; sweep < 60; ++sweep) {
        rotated = 0;
        for (i = 0; i < k - 1; ++i) {
            for (j = i + 1; j < k; ++j) {
                DERIVE_REAL a = DERIVE_LIT(0.0), b = DERIVE_LIT(0.0), g = DERIVE_LIT(0.0), zeta, t, cs, sn;
                for (c = 0; c < n; ++c) {
                    a += B[n * i + c] * B[n * i + c];
                    b += B[n * j + c] * B[n * j + c];
                    g += B[n * i + c] * B[n * j + c];
                }
                if (DERIVE_FABS(g) <= tol * DERIVE_SQRT(a * b)) continue;
                /* t = tan of the angle that makes rows i and j orthogonal, the smaller root */
                zeta = (b - a) / (DERIVE_LIT(2.0) * g);
                t = (zeta >= DERIVE_LIT(0.0) ? DERIVE_LIT(1.0) : DERIVE_LIT(-1.0))
                    / (DERIVE_FABS(zeta) + DERIVE_SQRT(DERIVE_LIT(1.0) + zeta * zeta));
                cs = DERIVE_LIT(1.0) / DERIVE_SQRT(DERIVE_LIT(1.0) + t * t);
                sn = cs * t;
                if (sn == DERIVE_LIT(0.0)) continue; /* below rounding: nothing left to rotate */
                rotated = 1;
                for (c = 0; c < n; ++c) {
                    const DERIVE_REAL x = B[n * i + c], y = B[n * j + c];
                    B[n * i + c] = cs * x - sn * y;
                    B[n * j + c] = sn * x + cs * y;
                }
            }
        }
        if (!rotated) break;
    }
    for (i = 0; i < k; ++i) {
        DERIVE_REAL ss = DERIVE_LIT(0.0);
        for (c = 0; c < n; ++c) ss += B[n * i + c] * B[n * i + c];
        s[i] = DERIVE_SQRT(ss);
    }
}

#endif /* DERIVE_LINALG_H */
