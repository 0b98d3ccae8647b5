/*
 * Manipulability (lecture eq. 30) of task rows of a Jacobian: the same for every robot.
 *
 * C99, no allocation, no globals, only <math.h>; static inline (see derive_linalg.h).
 */
#ifndef DERIVE_MANIPULABILITY_H
#define DERIVE_MANIPULABILITY_H

#include "derive_linalg.h"

/*
 * mu = [mu1, mu2, mu3] (3) of B = the k rows `rows` (k, 0-based, ascending) of J (6 x n,
 * row-major), from its singular values s_i: mu1 = smax / smin, mu2 = mu1^2, mu3 = prod s_i
 * = sqrt(det(B B^T)); mu1 = mu2 = +inf at a singularity (IEEE division).
 * Work: B (k * n reals) and s (k reals), owned by the caller.
 */
static inline DERIVE_FN void derive_manipulability(int k, int n, const int *rows, const DERIVE_REAL *J,
                                         DERIVE_REAL *B, DERIVE_REAL *s, DERIVE_REAL *mu)
{
    DERIVE_REAL smax = DERIVE_LIT(0.0), smin = DERIVE_LIT(0.0), prod = DERIVE_LIT(1.0);
    int i, c;
    for (i = 0; i < k; ++i) {
        for (c = 0; c < n; ++c) B[n * i + c] = J[n * rows[i] + c];
    }
    derive_singular_values(k, n, B, s);
    for (i = 0; i < k; ++i) {
        if (i == 0 || s[i] > smax) smax = s[i];
        if (i == 0 || s[i] < smin) smin = s[i];
        prod *= s[i];
    }
    mu[0] = smax / smin;
    mu[1] = mu[0] * mu[0];
    mu[2] = prod;
}

#endif /* DERIVE_MANIPULABILITY_H */
