"""A legged robot's MPC problem on derive's exported CasADi functions, acados-style (no acados needed).

Run from anywhere (outputs go to OUT_DIR, default ./contact_mpc_out/):

    .venv/bin/python examples/contact_mpc.py [OUT_DIR]

1. A small floating biped (pelvis, two 3-joint legs, point feet) with ``contacts:``, its stance the two feet.
2. ``derive export-casadi`` in Python: its contact dynamics with Baumgarte stabilisation and the feet's poses as
   serialised casadi.Function files (what acados' and CasADi's OCP builders load), read back with
   casadi.Function.load as an MPC stack would.
3. A multiple-shooting OCP: x = (q, v), u = the six joint torques, the dynamics qdd = contact_dynamics(q, v, tau)
   with the feet held at their anchors, semi-implicit Euler with the base quaternion's kinematics, the normal
   forces pushing (lam_z >= 0); the pelvis lowers by 4 cm in 0.2 s. Solved by IPOPT.
4. The check: the feet stay at their anchors, the forces push, the pelvis reaches its target.
"""

from __future__ import annotations

import sys
from pathlib import Path

import casadi as ca
import numpy as np

from derive.codegen.casadi_export import export_casadi
from derive.description.model import parse_models

BIPED = """
robots:
  biped:
    base: floating
    links:
      - {name: pelvis, mass: 5.0, com: [0.0, 0.0, 0.02], inertia: [0.1, 0.2, 0.3]}
      - {name: l_hip, mass: 1.0, com: [0.0, 0.0, -0.05], inertia: [0.01, 0.02, 0.015]}
      - {name: l_thigh, mass: 1.5, com: [0.0, 0.0, -0.15], inertia: [0.02, 0.02, 0.01]}
      - {name: l_shin, mass: 0.8, com: [0.0, 0.0, -0.15], inertia: [0.01, 0.012, 0.005]}
      - {name: r_hip, mass: 1.0, com: [0.0, 0.0, -0.05], inertia: [0.01, 0.02, 0.015]}
      - {name: r_thigh, mass: 1.5, com: [0.0, 0.0, -0.15], inertia: [0.02, 0.02, 0.01]}
      - {name: r_shin, mass: 0.8, com: [0.0, 0.0, -0.15], inertia: [0.01, 0.012, 0.005]}
    joints:
      - {name: l_hip_roll, type: revolute, parent: pelvis, child: l_hip, axis: [1, 0, 0], origin: {xyz: [0, 0.1, -0.05]}}
      - {name: l_hip_pitch, type: revolute, parent: l_hip, child: l_thigh, axis: [0, 1, 0], origin: {xyz: [0, 0, -0.1]}}
      - {name: l_knee, type: revolute, parent: l_thigh, child: l_shin, axis: [0, 1, 0], origin: {xyz: [0, 0, -0.3]}}
      - {name: r_hip_roll, type: revolute, parent: pelvis, child: r_hip, axis: [1, 0, 0], origin: {xyz: [0, -0.1, -0.05]}}
      - {name: r_hip_pitch, type: revolute, parent: r_hip, child: r_thigh, axis: [0, 1, 0], origin: {xyz: [0, 0, -0.1]}}
      - {name: r_knee, type: revolute, parent: r_thigh, child: r_shin, axis: [0, 1, 0], origin: {xyz: [0, 0, -0.3]}}
    frames:
      - {name: l_foot, link: l_shin, xyz: [0, 0, -0.3]}
      - {name: r_foot, link: r_shin, xyz: [0, 0, -0.3]}
    contacts: [{frame: l_foot}, {frame: r_foot}]
    contact_sets: {stance: [l_foot, r_foot]}
    generate: {frames: [l_foot, r_foot], quantities: [contact_dynamics_baumgarte, fk]}
"""

N, DT = 10, 0.02            # nodes, step (s)
DROP = 0.04                 # the pelvis lowers by this (m)
GAINS = [100.0, 20.0]       # Baumgarte kp, kd: the feet are pulled back to their anchors


def quaternion_rate(quat, w):
    """d/dt of the unit quaternion (x, y, z, w) for the angular velocity w in the base frame: 1/2 quat (x) (w, 0)."""
    x, y, z, s = quat[0], quat[1], quat[2], quat[3]
    return 0.5 * ca.vertcat(s * w[0] + y * w[2] - z * w[1], s * w[1] + z * w[0] - x * w[2],
                            s * w[2] + x * w[1] - y * w[0], -(x * w[0] + y * w[1] + z * w[2]))


def rotation(quat):
    x, y, z, s = quat[0], quat[1], quat[2], quat[3]
    return ca.vertcat(ca.horzcat(1 - 2 * (y * y + z * z), 2 * (x * y - s * z), 2 * (x * z + s * y)),
                      ca.horzcat(2 * (x * y + s * z), 1 - 2 * (x * x + z * z), 2 * (y * z - s * x)),
                      ca.horzcat(2 * (x * z - s * y), 2 * (y * z + s * x), 1 - 2 * (x * x + y * y)))


def step(q, v_next, dt):
    """q (+) dt v_next: the base position by R v, the quaternion by its rate (renormalised), the joints by their rates."""
    quat = q[3:7] + dt * quaternion_rate(q[3:7], v_next[3:6])
    return ca.vertcat(q[0:3] + dt * rotation(q[3:7]) @ v_next[0:3], quat / ca.norm_2(quat), q[7:] + dt * v_next[6:])


def main(out: Path) -> int:
    robot = parse_models(BIPED)["biped"]
    written, _ = export_casadi(robot, out)
    print(f"exported {len(written)} CasADi functions to {out}/: {', '.join(p.name for p in written)}")
    dynamics = ca.Function.load(str(out / "biped_contact_dynamics_baumgarte_stance.casadi"))
    feet = [ca.Function.load(str(out / f"biped_fk_{f}.casadi")) for f in ("l_foot", "r_foot")]
    nq, nv = robot.nq, robot.nv

    bend = [0.0, -0.4, 0.8]  # hip roll, hip pitch, knee: a crouch
    q0 = np.r_[0, 0, 0, 0, 0, 0, 1, bend, bend]
    anchor = np.concatenate([np.asarray(f(q0))[0:3, 3] for f in feet])
    z0 = q0[2]

    opti = ca.Opti()
    X = opti.variable(nq + nv, N + 1)
    U = opti.variable(nv - 6, N)
    opti.subject_to(X[:, 0] == np.r_[q0, np.zeros(nv)])
    cost = 0
    for k in range(N):
        q, v = X[:nq, k], X[nq:, k]
        tau = ca.vertcat(ca.DM.zeros(6), U[:, k])
        qdd, lam, _ = dynamics(q, v, tau, anchor, GAINS)
        v_next = v + DT * qdd
        opti.subject_to(X[:, k + 1] == ca.vertcat(step(q, v_next, DT), v_next))
        opti.subject_to(ca.vertcat(lam[2], lam[5]) >= 0)  # the ground pushes
        cost += 1e3 * (X[2, k + 1] - (z0 - DROP)) ** 2 + 1e-4 * ca.sumsqr(U[:, k]) + 1e-2 * ca.sumsqr(v_next)
    opti.minimize(cost)
    opti.set_initial(X, np.tile(np.r_[q0, np.zeros(nv)], (N + 1, 1)).T)
    opti.set_initial(U, np.zeros((nv - 6, N)))
    opti.solver("ipopt", {"print_time": False}, {"print_level": 0, "sb": "yes", "max_iter": 200})
    sol = opti.solve()

    x, u = sol.value(X), sol.value(U)
    drift = max(np.abs(np.concatenate([np.asarray(f(x[:nq, k]))[0:3, 3] for f in feet]) - anchor).max()
                for k in range(N + 1))
    forces = np.array([np.asarray(dynamics(x[:nq, k], x[nq:, k], np.r_[np.zeros(6), u[:, k]], anchor, GAINS)[1]).ravel()
                       for k in range(N)])
    print(f"pelvis height {z0:.3f} -> {x[2, -1]:.3f} m (target {z0 - DROP:.3f}); feet off their anchors by at most "
          f"{drift:.2e} m; normal forces {forces[:, [2, 5]].min():.1f} .. {forces[:, [2, 5]].max():.1f} N")
    ok = drift < 2e-3 and forces[:, [2, 5]].min() >= -1e-6 and abs(x[2, -1] - (z0 - DROP)) < 0.01
    print("solved: the feet held, the ground pushing, the pelvis lowered" if ok else "check failed")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("contact_mpc_out")))
