"""Figure of a simulated run (:func:`derive.solvers.simulate.simulate`): q(t), qd(t) and the energy drift."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from derive.plot.figure import figure_bytes, new_figure, write_png
from derive.solvers.simulate import Trajectory

MAX_DRAWN = 20_000
"""Samples drawn per curve: a longer run is drawn at every k-th sample (the figure is 800 pixels wide)."""


def simulation_png(traj: Trajectory) -> bytes:
    """q(t), qd(t) and the relative energy drift, one panel each, as PNG bytes."""
    stride = max(1, -(-len(traj.t) // MAX_DRAWN))
    pick = slice(None, None, stride)
    t = traj.t[pick]
    fig = new_figure(1, height=8, width=8, layout="tight")
    axes = fig.subplots(3, 1, sharex=True)
    for k, name in enumerate(traj.joints):
        axes[0].plot(t, traj.q[pick, k], label=name)
        axes[1].plot(t, traj.qd[pick, k], label=f"d{name}")
    axes[2].plot(t, ((traj.balance - traj.balance[0]) / traj.energy_scale)[pick])
    axes[0].set_ylabel("q")
    axes[1].set_ylabel("qd")
    axes[2].set_ylabel("energy drift (rel.)")
    axes[2].set_xlabel("t [s]")
    for ax in axes[:2]:
        ax.legend(loc="upper right", fontsize="small", ncol=min(len(traj.joints), 4))
    for ax in axes:
        ax.grid(True, alpha=0.3)
    fig.suptitle(f"{traj.robot}: {traj.method}, tau = {np.array2string(traj.tau, precision=3)}")
    return figure_bytes(fig, f"robot '{traj.robot}': the figure of the simulation", dpi=100)


def plot_simulation(traj: Trajectory, path: str | Path) -> Path:
    """:func:`simulation_png` written to ``path`` (atomically); returns it."""
    return write_png(path, simulation_png(traj))
