"""Figure of an optimised trajectory (:class:`derive.solvers.trajopt.TrajoptResult`): q, qd and tau over time."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from derive.plot.figure import save_figure
from derive.solvers.trajopt import TrajoptResult


def plot_trajopt(result: TrajoptResult, path: str | Path, limits: dict | None = None) -> Path:
    """Joint positions, velocities and torques over time (matplotlib, Agg) to ``path``; returns it.

    ``limits`` maps joints to effort limits, drawn dotted in the torque panel.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    r = result
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(8, 8))
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
    fig.tight_layout()
    save_figure(fig, path, dpi=100)
    plt.close(fig)
    return Path(path)
