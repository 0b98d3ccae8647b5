"""Shared pieces of the figures: a Figure on the Agg canvas, saving it, axis labels, colours.

Figures are built on :class:`matplotlib.figure.Figure` directly (no pyplot), so no
display is needed and matplotlib's global backend is left alone; matplotlib is
imported inside the functions, only when a figure is drawn.
"""

from __future__ import annotations

from pathlib import Path

from derive.description.robot import Robot


def new_figure(ncols: int, height: float = 4.6):
    """A matplotlib Figure on the Agg canvas (no pyplot, no display, no global backend change)."""
    from matplotlib.figure import Figure

    return Figure(figsize=(height * ncols * 1.02, height), layout="constrained")


def save_figure(fig, path: str | Path, dpi: int = 110) -> Path:
    """Write ``fig`` as a PNG to ``path``, creating its folder; returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    return path


def joint_label(robot: Robot, i: int) -> str:
    """Axis label of joint coordinate ``i``: its name and unit, e.g. ``theta1 [rad]``."""
    c = robot.coordinates[i]
    return f"{c.name} [{c.unit}]"


def sequence_color(t: float):
    """The colour of step ``t`` in [0, 1] of a sequence (viridis without its darkest and brightest tenth)."""
    from matplotlib import colormaps

    return colormaps["viridis"](0.1 + 0.8 * t)
