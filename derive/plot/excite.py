"""Figure of an excitation trajectory (:class:`derive.solvers.excite.Excitation`): q, qd, qdd and tau over one period."""

from __future__ import annotations

import io
from pathlib import Path

from derive.filesystem import write_atomically
from derive.solvers.excite import Excitation


def render_excitation(ex: Excitation) -> bytes:
    """q, qd, qdd and tau of one period as PNG bytes (a matplotlib Figure on the Agg canvas, no pyplot)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8, 10))
    axes = fig.subplots(4, 1, sharex=True)
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
    png = io.BytesIO()
    fig.savefig(png, format="png", dpi=100)
    return png.getvalue()


def plot_excitation(ex: Excitation, path: str | Path) -> Path:
    """:func:`render_excitation` written to ``path`` atomically (its folder created); returns it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_atomically(path, render_excitation(ex), "excitation plot")
