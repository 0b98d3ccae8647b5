"""Figure of manipulability ellipses along the arm and mu3 over the workspace (lecture figure 9)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from derive.analysis.manipulability import Manipulability, default_poses
from derive.analysis.singularity import ROW_NAMES
from derive.analysis.workspace import Arm, workspace
from derive.errors import DeriveError
from derive.plot.figure import new_figure, save_figure, sequence_color


def _ellipse(S: np.ndarray, n: int = 100) -> np.ndarray:
    """2 x n boundary of {x : x^T S^+ x <= 1} for a 2 x 2 PSD S (a segment when S is singular)."""
    w, V = np.linalg.eigh(S)
    t = np.linspace(0, 2 * np.pi, n)
    return V @ (np.sqrt(np.clip(w, 0, None))[:, None] * np.vstack([np.cos(t), np.sin(t)]))


def plot_manipulability(man: Manipulability, path: str | Path, poses=None, samples: int = 40000) -> Path:
    """Ellipsoids along the arm (left, as figure 9) and mu3 over the workspace (right).

    Position tasks only (ellipses in metres). A 2-D task is drawn in its plane; a 3-D one
    as the ellipsoids' projections on the x-z plane (side view), P (J J^T) P^T.
    """
    tj, robot = man.tj, man.robot
    if any(r > 2 for r in tj.rows):
        raise DeriveError(f"robot '{robot.name}': plots need a position task, got rows {tj.row_names}")
    plane = tj.rows if tj.k == 2 else ((0, 2) if tj.k == 3 else None)
    if plane is None:
        raise DeriveError(f"robot '{robot.name}': a 1-D task ({tj.row_names}) has no ellipses to draw")
    sel = [tj.rows.index(r) for r in plane]
    poses = default_poses(robot) if poses is None else np.atleast_2d(poses)
    arm = Arm(robot, man.frame)
    skel = arm.skeleton(poses)
    fig = new_figure(2, height=5.0)
    ax, ax2 = fig.subplots(1, 2)
    reach = np.abs(skel[..., list(plane)]).max()
    infos = [man.at(q) for q in poses]
    smax = max(i.semi_axes[0] for i in infos)
    scale = 0.25 * reach / smax if smax > 0 else 1.0
    colors = [sequence_color(i / max(len(poses) - 1, 1)) for i in range(len(poses))]
    for info, sk, color in zip(infos, skel, colors):
        A = tj(info.q) @ tj(info.q).T
        S = A[np.ix_(sel, sel)]
        tip = sk[-1, list(plane)]
        ax.plot(sk[:, plane[0]], sk[:, plane[1]], "-o", color=color, lw=2, ms=3)
        e = tip[:, None] + scale * _ellipse(S)
        ax.fill(e[0], e[1], color=color, alpha=0.25)
        ax.plot(e[0], e[1], color=color, lw=1)
        mu1 = "inf" if not np.isfinite(info.mu[0]) else f"{info.mu[0]:.3g}"
        ax.annotate(f"mu1 {mu1}\nmu3 {info.mu[2]:.3g}", tip, textcoords="offset points", xytext=(6, 6),
                    fontsize=7, color=color)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel(f"{ROW_NAMES[plane[0]]} [m]")
    ax.set_ylabel(f"{ROW_NAMES[plane[1]]} [m]")
    proj = "" if tj.k == 2 else ", x-z projection"
    ax.set_title(f"manipulability ellipses of '{man.frame}' (x{scale:.2g}{proj})", fontsize=10)
    ws = workspace(robot, man.frame, samples, "random", 0, arm=arm)
    mu3 = man.batch(ws.q)[:, 2]
    sc = ax2.scatter(ws.points[:, plane[0]], ws.points[:, plane[1]], c=mu3, s=1.5, cmap="magma", rasterized=True)
    ax2.set_aspect("equal", adjustable="datalim")
    ax2.set_xlabel(f"{ROW_NAMES[plane[0]]} [m]")
    ax2.set_ylabel(f"{ROW_NAMES[plane[1]]} [m]")
    ax2.set_title("mu3 = sqrt(det(J J^T)) over the workspace" + (" (max over overlaps hidden)" if tj.k == 3 else ""),
                  fontsize=10)
    fig.colorbar(sc, ax=ax2, shrink=0.8, label="mu3")
    fig.suptitle(f"{robot.name}: task rows {tj.row_names}", fontsize=11)
    return save_figure(fig, path)
