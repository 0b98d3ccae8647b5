# The mass matrix's factor M = L^T D L along the kinematic tree and its solve (Featherstone's LTDL:
# no fill-in), for the ODE Jacobians of large robots: the same in every generated module, and the
# same steps as the numpy module's, written functionally (.at[...]) so that jit, vmap and grad
# trace them. Copied verbatim after the module's imports (jax, jax.numpy as jnp, numpy as np).


def _ltdl_up(parents):
    """Per coordinate k: k and its ancestors, from k to the root."""
    up = []
    for k, parent in enumerate(parents):
        up.append([k] + (up[parent] if parent >= 0 else []))
    return up


def _ltdl_factor(H, parents):
    """The factor of H (..., n, n), symmetric positive definite: L_ki at [..., k, i] for i an
    ancestor of k, D_k at [..., k, k] (only those entries are read; the others are left as they are).
    Row i is updated whole, its other entries times 0 (same shapes at every step: eager JAX compiles
    an indexing once per shape, and row i's ancestors as a list index compiled one per row)."""
    up = _ltdl_up(parents)
    n = len(parents)
    ancestors = np.zeros((n, n))
    for i in range(n):
        ancestors[i, up[i]] = 1.0
    for k in reversed(range(n)):
        for i in up[k][1:]:
            a = H[..., k, i] / H[..., k, k]
            H = H.at[..., i, :].add(-(a[..., None] * H[..., k, :]) * ancestors[i])
            H = H.at[..., k, i].set(a)
    return H


def _ltdl_solve(H, B, parents):
    """M^-1 B for B (..., n, m) from _ltdl_factor's H: L^T y = b from the leaves, z = D^-1 y,
    then L x = z from the root, one row of all m columns at a time."""
    up = _ltdl_up(parents)
    n = len(parents)
    B = jnp.broadcast_to(B, jnp.broadcast_shapes(B.shape[:-2], H.shape[:-2]) + B.shape[-2:])
    for k in reversed(range(n)):
        for i in up[k][1:]:
            B = B.at[..., i, :].add(-(H[..., k, i, None] * B[..., k, :]))
    B = B / jnp.diagonal(H, axis1=-2, axis2=-1)[..., None]
    for k in range(n):
        for i in up[k][1:]:
            B = B.at[..., k, :].add(-(H[..., k, i, None] * B[..., i, :]))
    return B
