/*
 * The mass matrix's factor M = L^T D L along the kinematic tree and its solve, for derive's
 * ODE Jacobians of large robots: the same for every robot.
 *
 * Featherstone's LTDL (Rigid Body Dynamics Algorithms, section 6.5): eliminating from the leaves
 * towards the root creates no fill-in, so only the entries (k, i) with i an ancestor of k (or k
 * itself) are read or written, O(n d^2) for depth d. parents[k] is the index of k's parent
 * coordinate, -1 at the root (a chain: k - 1). C99, no allocation, no globals, only <math.h>
 * (through derive_real.h); static inline, so several robots link into one program.
 */
#ifndef DERIVE_LTDL_H
#define DERIVE_LTDL_H

#include "derive_real.h"

/* restrict in C99; the same promise under C++ (nvcc -x cu, g++, clang++) */
#ifndef DERIVE_RESTRICT
#if defined(__cplusplus) && defined(_MSC_VER)
#define DERIVE_RESTRICT __restrict
#elif defined(__cplusplus)
#define DERIVE_RESTRICT __restrict__
#else
#define DERIVE_RESTRICT restrict
#endif
#endif

/* y -= a x over m entries (x and y two different rows: restrict lets the compiler vectorise) */
static inline DERIVE_FN void derive_row_update(int m, DERIVE_REAL a, const DERIVE_REAL *DERIVE_RESTRICT x,
                                               DERIVE_REAL *DERIVE_RESTRICT y)
{
    int j;
    for (j = 0; j < m; ++j) y[j] -= a * x[j];
}

/*
 * H (n x n, row-major, symmetric positive definite, its lower triangle read) becomes its factor in
 * place: H[k][i] = L_ki for i an ancestor of k (unit diagonal implied), H[k][k] = D_k.
 */
static inline DERIVE_FN void derive_ltdl_factor(int n, const int *parents, DERIVE_REAL *H)
{
    int i, j, k;
    for (k = n - 1; k >= 0; --k) {
        for (i = parents[k]; i >= 0; i = parents[i]) {
            const DERIVE_REAL a = H[n * k + i] / H[n * k + k];
            for (j = i; j >= 0; j = parents[j]) H[n * i + j] -= a * H[n * k + j];
            H[n * k + i] = a;
        }
    }
}

/*
 * B (n x m, row-major) becomes M^-1 B from derive_ltdl_factor's H: L^T y = b from the leaves,
 * z = D^-1 y, then L x = z from the root, each step one row update of all m columns.
 */
static inline DERIVE_FN void derive_ltdl_solve(int n, const int *parents, const DERIVE_REAL *H, int m, DERIVE_REAL *B)
{
    int i, j, k;
    for (k = n - 1; k >= 0; --k) {
        for (i = parents[k]; i >= 0; i = parents[i]) derive_row_update(m, H[n * k + i], B + m * k, B + m * i);
    }
    for (k = 0; k < n; ++k) {
        const DERIVE_REAL d = H[n * k + k];
        for (j = 0; j < m; ++j) B[m * k + j] /= d;
    }
    for (k = 0; k < n; ++k) {
        for (i = parents[k]; i >= 0; i = parents[i]) derive_row_update(m, H[n * k + i], B + m * i, B + m * k);
    }
}

#endif /* DERIVE_LTDL_H */
