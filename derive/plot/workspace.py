"""Figure of the configuration space and the workspace side by side (lecture figure 4)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from derive.analysis.workspace import AXIS_NAMES, Workspace
from derive.plot.figure import joint_label, new_figure, save_figure


def plot_workspace(ws: Workspace, path: str | Path) -> Path:
    """Configuration space (left) and workspace (right), as the lecture's figure 4.

    Every sample is coloured by its distance from the base in both panels, so bands
    in the configuration space can be followed into the workspace (the samples the
    Workspace kept; the reach circles and the title cover them all). Planar robots get
    one workspace panel in their plane with the innermost and outermost reach drawn;
    spatial ones get the xy, xz and yz projections of the point cloud.
    """
    robot = ws.robot
    planes = [ws.plane] if len(ws.plane) == 2 else [(0, 1), (0, 2), (1, 2)]
    fig = new_figure(1 + len(planes))
    axes = fig.subplots(1, 1 + len(planes))
    r = ws.reach
    small = len(ws.q) <= 5000
    size = 6 if small else 1.5
    cs = axes[0]
    if robot.nv == 1:
        cs.scatter(ws.q[:, 0], np.zeros(len(ws.q)), c=r, s=size, cmap="viridis")
        cs.set_yticks([])
    else:
        cs.scatter(ws.q[:, 0], ws.q[:, 1], c=r, s=size, cmap="viridis", rasterized=True)
        cs.set_ylabel(joint_label(robot, 1))
    cs.set_xlabel(joint_label(robot, 0))
    extra = f" (projection on the first two of {robot.nv} joints)" if robot.nv > 2 else ""
    cs.set_title(f"configuration space{extra}", fontsize=10)
    for ax, (a, b) in zip(axes[1:], planes):
        sc = ax.scatter(ws.points[:, a], ws.points[:, b], c=r, s=size, cmap="viridis", rasterized=True)
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel(f"{AXIS_NAMES[a]} [m]")
        ax.set_ylabel(f"{AXIS_NAMES[b]} [m]")
        if len(planes) == 1:
            t = np.linspace(0, 2 * np.pi, 400)
            rmin, rmax = ws.reach_range
            for rad, style in ((rmin, "--"), (rmax, "-")):
                ax.plot(ws.base[a] + rad * np.cos(t), ws.base[b] + rad * np.sin(t), style, color="k", lw=0.8)
            ax.set_title(f"workspace of '{ws.frame}': reach {rmin:.3g} .. {rmax:.3g} m", fontsize=10)
        else:
            ax.set_title(f"workspace of '{ws.frame}', {AXIS_NAMES[a]}{AXIS_NAMES[b]} projection", fontsize=10)
    fig.colorbar(sc, ax=list(axes), shrink=0.8, label="distance from base [m]")
    drawn = "" if len(ws.q) == ws.count else f" ({len(ws.q)} of them drawn)"
    fig.suptitle(f"{robot.name}: {ws.count} configurations through FK{drawn}", fontsize=11)
    return save_figure(fig, path)
