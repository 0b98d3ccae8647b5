"""Inertia tensors: Steiner's parallel-axis theorem, rotation, physical validity.

    I_O = I_C + m (|d|^2 E - d d^T)          (Steiner; scalar form I = I_s + m l^2, eq. 8)
    I_A = A_R_B I_B A_R_B^T                  (the same body, axes of frame B -> frame A)

I_C is the inertia about the centre of mass C, d the vector from the new point O
to C (its sign does not matter), m the mass. Tensors are 3x3 numpy arrays or
sympy Matrices (the result follows the argument); the validity check is numeric.

A physical inertia about the COM is symmetric positive semi-definite and its
principal moments satisfy the triangle inequality I1 + I2 >= I3 (equality only
for bodies flat in a plane; point masses and thin rods are the degenerate
cases URDF allows). ``inertia_problem`` is the check model validation can call.
"""

from __future__ import annotations

import numpy as np

from derive.errors import DeriveError


def _is_sympy(*xs) -> bool:
    # by module name, so that model validation can use this file without importing sympy
    return any(type(x).__module__.startswith("sympy") for x in xs)


def steiner(inertia, mass, d):
    """Inertia about a point (or axis) offset by ``d`` from the COM: I_C + m (|d|^2 E - d d^T).

    ``inertia`` 3x3 and ``d`` a 3-vector, or both scalars: I about a parallel axis at
    distance d, I_s + m d^2 (the lecture's eq. 8).
    """
    if np.ndim(d) == 0 and not (_is_sympy(d) and hasattr(d, "shape")):  # a scalar, not a sympy Matrix
        return inertia + mass * d**2
    if _is_sympy(inertia, mass, d) or isinstance(d, (list, tuple)) and _is_sympy(*d):
        import sympy as sp

        d = sp.Matrix(3, 1, list(d))
        return sp.Matrix(inertia) + mass * (d.dot(d) * sp.eye(3) - d * d.T)
    d = np.asarray(d, dtype=float).reshape(3)
    return np.asarray(inertia, dtype=float) + mass * ((d @ d) * np.eye(3) - np.outer(d, d))


def inertia_about_com(inertia_o, mass, d):
    """Inverse of ``steiner``: I_C = I_O - m (|d|^2 E - d d^T), d from O to the COM."""
    return steiner(inertia_o, -mass, d)


def rotate_inertia(R, inertia):
    """R I R^T: the tensor expressed in frame B re-expressed in frame A, R = A_R_B."""
    if _is_sympy(R, inertia):
        import sympy as sp

        R = sp.Matrix(R)
        return R * sp.Matrix(inertia) * R.T
    R = np.asarray(R, dtype=float)
    return R @ np.asarray(inertia, dtype=float) @ R.T


def principal_moments(inertia) -> tuple[np.ndarray, np.ndarray]:
    """(moments ascending, axes as columns) with I = axes diag(moments) axes^T."""
    return np.linalg.eigh(np.asarray(inertia, dtype=float))


def inertia_problem(inertia, mass: float | None = None, *, strict: bool = False, rtol: float = 1e-9) -> str | None:
    """Why a 3x3 inertia about the COM is not physical, or None if it is.

    Checks, with tolerances relative to the trace (the tensor's scale, so 1e-6 kg m^2
    links are judged as strictly as 10 kg m^2 ones):
    - finite and symmetric;
    - positive semi-definite (``strict``: positive definite, i.e. a solid body);
    - principal moments I1 <= I2 <= I3 with I1 + I2 >= I3 (triangle inequality);
    - with ``mass``: mass >= 0 (> 0 if ``strict``), and a massless body has no inertia.
    """
    m = np.asarray(inertia, dtype=float)
    if m.shape != (3, 3):
        return f"expected a 3x3 matrix, got shape {m.shape}"
    if not np.isfinite(m).all():
        return "has non-finite entries"
    if mass is not None:
        if not np.isfinite(mass) or mass < 0 or (strict and mass == 0):
            return f"mass must be {'> 0' if strict else '>= 0'}, got {mass}"
    scale = abs(np.trace(m))
    if scale == 0:
        if strict or np.abs(m).max() > 0:
            return "is zero" if strict else "has a zero trace but nonzero entries: not positive semi-definite"
        return None
    if mass == 0:
        return "a massless body must have zero inertia"
    tol = rtol * scale
    asym = np.abs(m - m.T).max()
    if asym > tol:
        return f"not symmetric (|I - I^T| = {asym:.3g})"
    eig = np.linalg.eigvalsh((m + m.T) / 2)
    moments = ", ".join(f"{e:.6g}" for e in eig)
    if eig[0] < -tol or (strict and eig[0] <= tol):
        return f"not positive {'definite' if strict else 'semi-definite'} (principal moments {moments})"
    if eig[0] + eig[1] < eig[2] - tol:
        return f"breaks the triangle inequality: {eig[0]:.6g} + {eig[1]:.6g} < {eig[2]:.6g}"
    return None


def check_inertia(inertia, mass: float | None = None, *, strict: bool = False, what: str = "inertia") -> None:
    """Raise DeriveError('<what>: <problem>') if ``inertia_problem`` finds one."""
    problem = inertia_problem(inertia, mass, strict=strict)
    if problem:
        raise DeriveError(f"{what}: {problem}")


def nearest_physical(inertia, mass: float) -> np.ndarray:
    """A physical inertia about the COM near ``inertia`` (what ``import-urdf --fix-inertia`` writes).

    A massless body gets zero inertia. Otherwise, in the principal axes of the symmetric part:
    negative moments become 0, then if the triangle inequality I1 + I2 >= I3 fails, the two smaller
    moments are raised by the same amount until it holds with equality (a flat body keeps its largest
    moment: ixx = 0.002 with the other moments 0 becomes the disk 0.001, 0.001, 0.002). A physical
    tensor is returned unchanged.
    """
    m = np.asarray(inertia, dtype=float)
    if inertia_problem(m, mass) is None:
        return m
    if mass == 0:
        return np.zeros((3, 3))
    eig, axes = np.linalg.eigh((m + m.T) / 2)
    e = np.maximum(eig, 0.0)
    short = e[2] - e[0] - e[1]
    if short > 0:
        e[0] += short / 2
        e[1] += short / 2
    out = axes @ np.diag(e) @ axes.T
    return (out + out.T) / 2
