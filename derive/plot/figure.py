"""Shared pieces of the figures: a Figure on the Agg canvas, rendering and saving it, axis labels, colours.

Figures are built on :class:`matplotlib.figure.Figure` directly (no pyplot), so no
display is needed and matplotlib's global backend is left alone; matplotlib is
imported inside the functions, only when a figure is drawn. A figure is rendered to
PNG bytes first (:func:`figure_bytes`) and then written all at once
(:func:`derive.filesystem.write_atomically`): a failed drawing or a full disk never
leaves a half-written PNG, and an old one stays as it was.
"""

from __future__ import annotations

import io
import warnings
from pathlib import Path

import numpy as np

from derive.description.robot import Robot
from derive.errors import DeriveError
from derive.filesystem import write_atomically


def new_figure(ncols: int, height: float = 4.6, width: float | None = None, layout: str = "constrained"):
    """A matplotlib Figure on the Agg canvas (no pyplot, no display, no global backend change); ``width``
    defaults to ``height`` per column."""
    from matplotlib.figure import Figure

    return Figure(figsize=(width or height * ncols * 1.02, height), layout=layout)


def figure_bytes(fig, what: str, dpi: int = 110) -> bytes:
    """``fig`` rendered as PNG bytes; ``what`` (e.g. "robot 'pendulum': the simulation figure") names it
    in the DeriveError raised when matplotlib cannot draw it (values near the float range's end)."""
    buffer = io.BytesIO()
    try:
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")  # matplotlib's own warnings of degenerate axes: not the user's concern
            fig.savefig(buffer, format="png", dpi=dpi)
    except (ValueError, OverflowError, ArithmeticError) as exc:
        reason = " ".join(str(exc).split())[:200]
        raise DeriveError(f"{what}: matplotlib cannot draw it ({reason}): the values are too large to plot; "
                          "nothing written") from None
    return buffer.getvalue()


def write_png(path: str | Path, data: bytes) -> Path:
    """Write PNG bytes to ``path`` atomically, creating its folder; returns ``path``."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DeriveError(f"{path}: cannot create its folder ({exc.strerror or exc})") from None
    return write_atomically(path, data, "PNG")


def save_figure(fig, path: str | Path, dpi: int = 110) -> Path:
    """Render ``fig`` and write it as a PNG to ``path`` atomically, creating its folder; returns the path."""
    return write_png(path, figure_bytes(fig, str(path), dpi=dpi))


def joint_label(robot: Robot, i: int) -> str:
    """Axis label of joint coordinate ``i``: its name and unit, e.g. ``theta1 [rad]``."""
    c = robot.coordinates[i]
    return f"{c.name} [{c.unit}]"


def sequence_color(t: float):
    """The colour of step ``t`` in [0, 1] of a sequence (viridis without its darkest and brightest tenth)."""
    from matplotlib import colormaps

    return colormaps["viridis"](0.1 + 0.8 * t)
