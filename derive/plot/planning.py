"""Figure of a planned joint path in the configuration space and in the workspace (lecture Example 4)."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np

from derive.analysis.planning import Circle, PlanResult
from derive.analysis.workspace import Arm
from derive.description.robot import Robot
from derive.plot.figure import joint_label, new_figure, save_figure, sequence_color


def plot_plan(robot: Robot, result: PlanResult, start, goal, obstacles, path: str | Path, frame: str = "tcp",
              arm: Arm | None = None) -> Path:
    """The path in the configuration space (left; obstacle nodes dark) and in the workspace (right)."""
    from matplotlib.patches import Circle as CirclePatch
    from matplotlib.patches import Rectangle

    arm = arm or Arm(robot, frame)
    fig = new_figure(2, height=5.0)
    cs, ws = fig.subplots(1, 2)
    if robot.nv >= 2 and result.free is not None:
        occ = result.free if robot.nv == 2 else result.free.all(axis=tuple(range(2, robot.nv)))
        a0, a1 = result.axes[0], result.axes[1]
        cs.imshow(~occ.T, origin="lower", extent=(a0[0], a0[-1], a1[0], a1[-1]), cmap="Greys", alpha=0.6,
                  aspect="auto", interpolation="nearest")
        cs.set_ylabel(joint_label(robot, 1))
        if robot.nv > 2:
            cs.set_title("configuration space (dark: blocked for every other joint value)", fontsize=10)
    cs.set_xlabel(joint_label(robot, 0))
    if result.success:
        cs.plot(result.path[:, 0], result.path[:, 1] if robot.nv > 1 else 0 * result.path[:, 0], "-", color="C0", lw=2)
    cs.plot(start[0], start[1] if robot.nv > 1 else 0, "o", color="C2", label="start")
    cs.plot(goal[0], goal[1] if robot.nv > 1 else 0, "*", color="C3", ms=12, label="goal")
    cs.legend(loc="upper right", fontsize=8)
    if robot.nv == 2:
        cs.set_title("configuration space (dark: collision)", fontsize=10)
    for i, ob in enumerate(obstacles):
        if isinstance(ob, Circle):
            ws.add_patch(CirclePatch(ob.center[:2], ob.radius, color="0.4", alpha=0.7))
        else:
            ws.add_patch(Rectangle(ob.lower[:2], ob.upper[0] - ob.lower[0], ob.upper[1] - ob.lower[1], color="0.4", alpha=0.7))
    shown = result.path if result.success else np.vstack([start, goal])
    pick = np.unique(np.linspace(0, len(shown) - 1, min(len(shown), 8)).round().astype(int))
    sk = arm.skeleton(shown)
    for k, i in enumerate(pick):
        ws.plot(sk[i, :, 0], sk[i, :, 1], "-o", color=sequence_color(k / max(len(pick) - 1, 1)), lw=2, ms=3, alpha=0.9)
    if result.success:
        tcp = arm.skeleton(_densify(result.path))[:, -1, :]
        ws.plot(tcp[:, 0], tcp[:, 1], "--", color="C0", lw=1, label=f"path of '{frame}'")
        ws.legend(loc="upper right", fontsize=8)
    ws.set_aspect("equal", adjustable="datalim")
    ws.set_xlabel("x [m]")
    ws.set_ylabel("y [m]")
    ws.set_title("workspace (x-y), arm at waypoints" if result.success else "workspace: NO PATH", fontsize=10)
    fig.suptitle(textwrap.fill(f"{robot.name}: A* in configuration space, {result.message}", 140), fontsize=10)
    return save_figure(fig, path)


def _densify(path: np.ndarray, per_step: int = 8) -> np.ndarray:
    """``per_step`` evenly spaced points on every segment of a joint path (the last waypoint once)."""
    t = np.linspace(0, 1, per_step, endpoint=False)
    return np.vstack([a + t[:, None] * (b - a) for a, b in zip(path[:-1], path[1:])] + [path[-1:]])
