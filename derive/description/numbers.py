"""The numbers a robot model may hold, and how the readers (models.yaml, URDF) read them.

One rule for every number of a model (masses, inertias, lengths, angles, axes, limits, gravity,
mimic multipliers and offsets, actuator values, parameter defaults, locks), whichever reader it
comes from:

    x == 0   or   MIN_MAGNITUDE <= |x| <= MAX_MAGNITUDE,   x finite.

- MAX_MAGNITUDE (1e12 in SI units): products of larger numbers overflow in the dynamics.
- MIN_MAGNITUDE (FLT_MIN = 2^-126 ~ 1.18e-38, the smallest normal float): the generated C also
  builds in single precision (``-DDERIVE_FLOAT``), where a nonzero constant below it is not a
  normal float, and one below FLT_TRUE_MIN (~1.4e-45) does not compile at all ("floating constant
  truncated to zero"). A models file with such a number is refused (it is the user's own file);
  the URDF reader flushes it to 0 with a warning (exporters write rounding residue such as iCub's
  rpy 5.8e-66: physically zero).

URDF numbers are read as urdfdom reads them (``std::istringstream`` in the classic "C" locale):
an optional sign, ASCII decimal digits with an optional point, an optional exponent; vectors
separated by spaces. Nothing more: no ``1_0`` (Python's digit grouping), no Arabic-Indic or
full-width digits, no hexadecimal, no ``inf``/``nan`` as values.
"""

from __future__ import annotations

import math
import re

MAX_MAGNITUDE = 1e12
"""Largest magnitude of a model's number (mass, length, inertia, gravity, ...) in SI units."""
MIN_MAGNITUDE = 2.0**-126
"""Smallest magnitude of a nonzero number of a model: FLT_MIN, the smallest normal float."""

_DECIMAL = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_SEPARATORS = re.compile(r"[ \t\n\r]+")  # XML's white space (attribute values arrive with spaces)


def decimal(text: str) -> float | None:
    """The value of one C-locale decimal number (``-1.5``, ``.5``, ``2.``, ``1e-3``, ``+4E+02``), else None.

    What urdfdom's strtod-like reading accepts, nothing more: ASCII digits only (``str.isdigit``
    would take Arabic-Indic and full-width digits, ``float`` also ``1_0``, ``inf``, ``nan`` and
    surrounding Unicode spaces). Overflowing text (``1e999``) gives inf, for the bounds to refuse.
    """
    if not isinstance(text, str) or not _DECIMAL.fullmatch(text):
        return None
    return float(text)


def decimals(text: str) -> list[str]:
    """The space-separated tokens of a URDF vector attribute (``"0 0 1"``)."""
    return [t for t in _SEPARATORS.split(text.strip(" \t\n\r")) if t]


def magnitude_problem(x: float) -> str | None:
    """Why ``x`` may not be a number of a model (see the module docstring), or None."""
    try:
        x = float(x)
    except OverflowError:  # an int beyond float's range
        return f"an integer of {len(str(abs(x)))} digits is larger than {MAX_MAGNITUDE:g} in magnitude"
    if not math.isfinite(x):
        return f"must be finite, got {x}"
    if abs(x) > MAX_MAGNITUDE:
        return (f"{x:g} is larger than {MAX_MAGNITUDE:g} in magnitude: products of such numbers overflow in the "
                "dynamics")
    if x != 0 and abs(x) < MIN_MAGNITUDE:
        return (f"{x:g} is not 0 but smaller than {MIN_MAGNITUDE:.3g} in magnitude (the smallest normal float: the "
                "generated code must build in single precision too); write 0")
    return None


AXIS_RATIO = 2.0**-63
"""Smallest nonzero |component| of a joint axis relative to its largest (~1.08e-19): the rotation about a
unit axis k holds the products k_i k_j, and those of two such components are still normal floats."""


def axis_component_problem(v) -> tuple[int, str] | None:
    """(index, why) of a nonzero component of the axis ``v`` below AXIS_RATIO of its largest, or None.

    Such a component turns the axis by less than 1e-19 rad (double precision sees 1.1e-16), but its
    square is no normal float: the single-precision build would not compile ("floating constant truncated
    to zero"). The models file refuses it; the URDF reader reads it as 0 with a warning.
    """
    largest = max((abs(float(a)) for a in v), default=0.0)
    for i, a in enumerate(v):
        if a != 0 and abs(a) < AXIS_RATIO * largest:
            return i, (f"{float(a):g} is not 0 but below {AXIS_RATIO:.3g} of the axis's largest component "
                       f"({largest:g}): a turn of the axis by less than 1e-19 rad, whose square is no normal "
                       "float (the generated code must build in single precision too); write 0")
    return None


def tiny(x: float) -> bool:
    """Nonzero, finite and below MIN_MAGNITUDE in magnitude: what the URDF reader flushes to 0."""
    return x != 0 and math.isfinite(x) and abs(x) < MIN_MAGNITUDE


def unit_vector(v) -> tuple[float, ...] | None:
    """``v`` (finite numbers) divided by its length, or None for the zero vector.

    Robust for any finite components: the vector is first scaled by the power of two nearest its
    largest component (exact, so the result is bit-identical to v / |v| wherever |v|^2 neither
    overflows nor underflows), then normalised. A vector of length exactly 1 is returned as given.
    """
    v = [float(a) for a in v]
    largest = max((abs(a) for a in v), default=0.0)
    if largest == 0 or not math.isfinite(largest):
        return None
    exponent = math.frexp(largest)[1]
    w = [math.ldexp(a, -exponent) for a in v]
    norm = math.sqrt(sum(a * a for a in w))
    if math.ldexp(norm, exponent) == 1.0:
        return tuple(v)
    return tuple(a / norm for a in w)
