"""Figure of a simulated run (:func:`derive.solvers.simulate.simulate`): q(t), qd(t) and the energy drift."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from derive.plot.figure import save_figure
from derive.solvers.simulate import Trajectory


def plot_simulation(traj: Trajectory, path: str | Path) -> Path:
    """q(t), qd(t) and the relative energy drift, one panel each (matplotlib Agg), to ``path``; returns it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
    for k, name in enumerate(traj.joints):
        axes[0].plot(traj.t, traj.q[:, k], label=name)
        axes[1].plot(traj.t, traj.qd[:, k], label=f"d{name}")
    axes[2].plot(traj.t, (traj.balance - traj.balance[0]) / traj.energy_scale)
    axes[0].set_ylabel("q")
    axes[1].set_ylabel("qd")
    axes[2].set_ylabel("energy drift (rel.)")
    axes[2].set_xlabel("t [s]")
    for ax in axes[:2]:
        ax.legend(loc="upper right", fontsize="small", ncol=min(len(traj.joints), 4))
    for ax in axes:
        ax.grid(True, alpha=0.3)
    fig.suptitle(f"{traj.robot}: {traj.method}, tau = {np.array2string(traj.tau, precision=3)}")
    fig.tight_layout()
    save_figure(fig, path, dpi=100)
    plt.close(fig)
    return Path(path)
