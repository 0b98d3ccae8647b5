# Manipulability (lecture eq. 30) of task rows of a Jacobian, batched: the same in every generated
# module. Copied verbatim after the module's imports (jax, jax.numpy as jnp).
# From the singular values s of J, as the numpy module: the eigenvalues of J J^T (eigvalsh) would
# square the condition number, so mu2 = lmax / lmin would lose eps * mu2 relative (1e-7 near a
# singularity of planar_2r), where s loses eps * mu1.


def _manipulability(J):
    """mu = [mu1, mu2, mu3] (..., 3) of the task rows J (..., k, nv) from its singular values s:
    mu1 = smax / smin (inf at a singularity, smin = 0), mu2 = mu1^2, mu3 = prod s = sqrt(det(J J^T)).
    Differentiable where the singular values are distinct and smin > 0."""
    s = jnp.linalg.svd(J, compute_uv=False)
    smin = s[..., -1]
    regular = smin > 0.0
    mu1 = jnp.where(regular, s[..., 0] / jnp.where(regular, smin, 1.0), jnp.inf)
    return jnp.stack([mu1, mu1 * mu1, jnp.prod(s, axis=-1)], axis=-1)
