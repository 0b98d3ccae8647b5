"""Constant angles near a multiple of pi/2: exact to rounding, or rounded by the file's author.

An angle a is read against its nearest multiple of pi/2, k pi/2, by its distance d = |a - k pi/2| (rad):

- d <= EXACT (1e-14): *exact to rounding*. k pi/2 has no exact double; 1.5707963267948966 (the double
  nearest pi/2, d = 6e-17) and a value printed to 15 significant digits (3.14159265358979, d = 3.2e-15)
  both mean it. Taking such an angle as k pi/2 (cos and sin exactly 0 and +-1) moves no result by more
  than 1e-14 relative (|sin d| <= d, 1 - cos d <= d^2 / 2), so derive does it without a word, in the
  importer's composed origins and in the symbolic rotations (:mod:`derive.symbolic.spatial`).
- EXACT < d <= NEAR (1e-4): a right angle rounded by hand or by an exporter (the Kinova Gen3's 1.5708,
  pi/2 + 3.7e-6; ur5's 1.57079632679, pi/2 - 4.9e-12), most likely, but it is what the file says: it
  is kept as written, and the URDF import warns with the list. ``derive import-urdf --snap-angles TOL``
  takes every constant angle with d <= TOL as k pi/2 (the entry's ``source`` records the option).
- d > NEAR: a real angle; never touched.
"""

from __future__ import annotations

import math

EXACT = 1e-14
NEAR = 1e-4
HALF_PI = math.pi / 2


def quarter(angle: float, tol: float) -> int | None:
    """k with |angle - k pi/2| <= tol, or None."""
    k = round(angle / HALF_PI)
    return k if abs(angle - k * HALF_PI) <= tol else None


def right_angle(k: int) -> float:
    """k pi/2 as the nearest double (0.0 for k = 0; 2 * (pi/2) is math.pi exactly)."""
    return float(k * HALF_PI) if k else 0.0


def snapped(angle: float, tol: float = EXACT) -> float:
    """``angle`` if it is farther than ``tol`` from every multiple of pi/2, else that multiple."""
    k = quarter(float(angle), tol)
    return float(angle) if k is None else right_angle(k)


def spelled(angle: float) -> str:
    """An angle near k pi/2 as ``1.5708 (pi/2 + 3.7e-06)``, for warnings."""
    k = quarter(angle, math.inf)
    name = {0: "0", 1: "pi/2", -1: "-pi/2", 2: "pi", -2: "-pi"}.get(k, f"{k} pi/2")
    d = angle - k * HALF_PI
    return f"{angle!r} ({name} {'+' if d >= 0 else '-'} {abs(d):.2g})"
