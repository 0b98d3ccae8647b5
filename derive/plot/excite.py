"""Figure of an excitation trajectory (:class:`derive.solvers.excite.Excitation`): q, qd, qdd and tau over one period."""

from __future__ import annotations

from pathlib import Path

from derive.plot.figure import save_figure
from derive.solvers.excite import Excitation


def plot_excitation(ex: Excitation, path: str | Path) -> Path:
    """q, qd, qdd and tau of one period (matplotlib, Agg) to ``path``; returns it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(4, 1, sharex=True, figsize=(8, 10))
    for ax, data, label in zip(axes, (ex.q, ex.qd, ex.qdd, ex.tau),
                               ("q [rad, m]", "qd [rad/s, m/s]", "qdd [rad/s^2, m/s^2]", "tau [Nm, N]")):
        for i, j in enumerate(ex.joints):
            ax.plot(ex.t, data[:, i], label=j)
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize="small", ncol=min(len(ex.joints), 4))
    axes[-1].set_xlabel("t [s]")
    axes[0].set_title(f"{ex.robot}: excitation, T = {ex.period:g} s, {ex.harmonics} harmonics, "
                      f"cond(W_b) = {ex.condition:.3g} (random start {ex.random_condition:.3g})")
    fig.tight_layout()
    save_figure(fig, path, dpi=100)
    plt.close(fig)
    return Path(path)
