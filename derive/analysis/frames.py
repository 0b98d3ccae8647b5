"""World poses and Jacobians of any frame at given q: every link, every named frame and alias.

    world_T_frame(q) (4x4, Trans(p) R) and J(q) (6 x nv, [linear; angular], LOCAL_WORLD_ALIGNED:
    [v; w] = J qd at the frame origin), at the parameters' defaults.

What ``derive fk`` prints. The generated code has per-frame functions for the named frames (or
models.yaml's ``generate: {frames: [...]}``) and every link's pose in ``fk_all``; this evaluates the
same expressions for any frame without generating anything.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from derive.description.robot import Robot
from derive.errors import DeriveError
from derive.symbolic.kinematics import Kinematics
from derive.symbolic.symbols import make_symbols


def frame_poses(robot: Robot, q, frames=None, jacobian: bool = False) -> dict[str, tuple[np.ndarray, np.ndarray | None]]:
    """{frame: (world_T_frame (4x4), J (6 x nv) or None)} at q (nq) for ``frames`` (links, named
    frames or aliases; default every link, then every named frame), in the order asked."""
    q = np.asarray(q, dtype=float)
    if q.shape != (robot.nq,):
        raise DeriveError(f"robot '{robot.name}': q must have nq = {robot.nq} entries, got {q.size}")
    names = tuple(robot.frame_names if frames is None else frames)
    known = robot.frame_names + tuple(robot.frame_aliases)
    for name in names:
        if name not in known:
            raise DeriveError(f"robot '{robot.name}': no frame '{name}' (links and frames: {', '.join(known)})")
    sym = make_symbols(robot)
    kin = Kinematics(robot, sym)
    outputs = [kin.fk(n) for n in names] + ([kin.jacobian(n) for n in names] if jacobian else [])
    values = ca.Function("frames", [sym.q, sym.p], outputs)(q, np.array([p.default for p in robot.parameters]))
    values = [np.array(v) for v in (values if isinstance(values, (list, tuple)) else [values])]
    k = len(names)
    return {n: (values[i], values[k + i] if jacobian else None) for i, n in enumerate(names)}
