# Manipulability (lecture eq. 30) of task rows of a Jacobian: the same in every generated
# module. Copied verbatim after the module's imports (math, numpy as np).


def _manipulability(J):
    """mu = [mu1, mu2, mu3] of the task rows J (k x nv), or of each of a batch (..., k, nv), from
    its singular values s: mu1 = smax / smin (inf at a singularity), mu2 = mu1^2, mu3 = prod s =
    sqrt(det(J J^T)). A batch gives (..., 3), bit for bit the matrices' results one by one."""
    s = np.linalg.svd(J, compute_uv=False)
    if s.ndim == 1:
        mu1 = s[0] / s[-1] if s[-1] > 0.0 else math.inf
        return np.array([mu1, mu1 * mu1, float(np.prod(s))])
    with np.errstate(divide="ignore", invalid="ignore"):
        mu1 = np.where(s[..., -1] > 0.0, s[..., 0] / s[..., -1], math.inf)
    return np.stack([mu1, mu1 * mu1, np.prod(s, axis=-1)], axis=-1)
