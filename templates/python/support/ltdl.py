# The mass matrix's factor M = L^T D L along the kinematic tree and its solve (Featherstone's LTDL:
# no fill-in), for the ODE Jacobians of large robots: the same in every generated module. Copied
# verbatim after the module's imports (math, numpy as np). Element by element the arithmetic of
# the C code's derive_ltdl.h, on one matrix (n, n) or a batch (..., n, n) alike, so a batch gives
# bit for bit the results state by state.


def _ltdl_up(parents):
    """Per coordinate k: k and its ancestors, from k to the root."""
    up = []
    for k, parent in enumerate(parents):
        up.append([k] + (up[parent] if parent >= 0 else []))
    return up


def _ltdl_factor(H, parents):
    """H (..., n, n), symmetric positive definite, becomes its factor in place: H[..., k, i] = L_ki
    for i an ancestor of k, H[..., k, k] = D_k (only those entries are read or written)."""
    up = _ltdl_up(parents)
    for k in reversed(range(len(parents))):
        for i in up[k][1:]:
            a = H[..., k, i] / H[..., k, k]
            H[..., i, up[i]] -= a[..., None] * H[..., k, up[i]]
            H[..., k, i] = a
    return H


def _ltdl_solve(H, B, parents):
    """B (..., n, m) becomes M^-1 B in place from _ltdl_factor's H: L^T y = b from the leaves,
    z = D^-1 y, then L x = z from the root, one row of all m columns at a time."""
    up = _ltdl_up(parents)
    n = len(parents)
    for k in reversed(range(n)):
        for i in up[k][1:]:
            B[..., i, :] -= H[..., k, i, None] * B[..., k, :]
    for k in range(n):
        B[..., k, :] /= H[..., k, k, None]
    for k in range(n):
        for i in up[k][1:]:
            B[..., k, :] -= H[..., k, i, None] * B[..., i, :]
    return B
