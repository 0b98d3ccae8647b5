"""Figure of an optimised trajectory (:class:`derive.solvers.trajopt.TrajoptResult`): q, qd and tau over time."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from derive.plot.figure import figure_bytes, new_figure, write_png
from derive.solvers.trajopt import TrajoptResult


def trajopt_png(result: TrajoptResult, limits: dict | None = None) -> bytes:
    """Joint positions, velocities and torques over time as PNG bytes.

    ``limits`` maps joints to effort limits, drawn dotted in the torque panel.
    """
    r = result
    fig = new_figure(1, height=8, width=8, layout="tight")
    axes = fig.subplots(3, 1, sharex=True)
    for ax, data, label in zip(axes, (r.q, r.qd, r.tau), ("q [rad, m]", "qd [rad/s, m/s]", "tau [Nm, N]")):
        for i, j in enumerate(r.joints):
            ax.plot(r.t, data[:, i], label=j)
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
    colors = [line.get_color() for line in axes[2].lines]
    for color, j in zip(colors, r.joints):
        eff = (limits or {}).get(j)
        if eff is not None and np.isfinite(eff):
            for sign in (-1, 1):
                axes[2].axhline(sign * eff, color=color, linestyle=":", linewidth=0.8)
    axes[0].legend(fontsize="small", ncol=min(len(r.joints), 4))
    axes[-1].set_xlabel("t [s]")
    axes[0].set_title(f"{r.robot}: {r.method}, N = {len(r.t) - 1}, T = {r.duration:.3f} s, "
                      f"IPOPT {r.stats.get('iterations', 0)} it, {r.stats.get('solve_time', 0):.3f} s")
    return figure_bytes(fig, f"trajopt {r.robot}: the figure of the trajectory", dpi=100)


def plot_trajopt(result: TrajoptResult, path: str | Path, limits: dict | None = None) -> Path:
    """:func:`trajopt_png` written to ``path`` (atomically); returns it."""
    return write_png(path, trajopt_png(result, limits))
