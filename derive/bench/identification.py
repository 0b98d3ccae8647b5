"""``derive bench identification``: excitation and identification figures (issue "Real actuators and identification").

- ``derive excite panda``: the optimised trajectory's cond(W_b) against that of the random Fourier
  trajectory of the same period, harmonics and samples it starts from (within the same limits).
- Round trip on the panda: data simulated along the optimised excitation with the inverse dynamics
  of a perturbed panda (masses +-20 %, centres of mass ~1 cm, armature, viscous and Coulomb friction
  on every joint), identified from the nominal model; without noise, the error of the base
  parameters; with 1 % torque noise, the rms error of the identified model's torques on a held-out
  motion against the noise level.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from derive.description.model import load_models
from derive.description.robot import Actuator
from derive.solvers.excite import excite, fourier_basis, random_coefficients
from derive.solvers.identify import Measurements, identify, regressor_along, torques_along
from derive.symbolic.base_parameters import base_parameters
from derive.symbolic.dynamics import NewtonEuler
from derive.symbolic.regressor import Regressor
from derive.symbolic.symbols import make_symbols


def perturbed(robot, seed: int = 5, armature: float = 0.1, viscous: float = 0.5, coulomb: float = 1.0):
    """The robot with masses (+-20 %) and centres of mass (~1 cm) perturbed and the same actuator on every joint."""
    rng = np.random.default_rng(seed)
    links = tuple(dataclasses.replace(link, mass=float(link.mass) * rng.uniform(0.8, 1.2),
                                      com=tuple(float(c) + rng.normal() * 0.01 for c in link.com))
                  for link in robot.links)
    act = Actuator(armature=armature, viscous=viscous, coulomb=coulomb)
    joints = tuple(dataclasses.replace(j, actuator=act) if j.dof else j for j in robot.joints)
    return dataclasses.replace(robot, links=links, joints=joints)


def bench_identification(args) -> str:
    start = time.perf_counter()
    nominal = load_models()["panda"]
    reg = Regressor(NewtonEuler(nominal, make_symbols(nominal)))
    bp = base_parameters(nominal, regressor=reg)
    s = reg.sym
    Yb = reg.matrix[:, list(bp.columns)]
    samples, harmonics, iterations = (40, 3, 40) if args.quick else (100, 5, 200)
    t0 = time.perf_counter()
    ex = excite(nominal, Yb, s.q, s.qd, s.qdd, NewtonEuler(nominal, s).inverse_dynamics(), period=10.0,
                harmonics=harmonics, samples=samples, max_iterations=iterations,
                log=lambda m: print(m, flush=True))
    excite_s = time.perf_counter() - t0
    true = perturbed(nominal)
    pi_true = np.asarray(Regressor(NewtonEuler(true, make_symbols(true))).values())
    pib_true = bp.K @ pi_true
    Y = regressor_along(reg, nominal)

    # one period of the excitation at 10x the optimiser's sampling (the controller's rate)
    t = np.linspace(0.0, ex.period, 10 * samples, endpoint=False)
    P, V, A = fourier_basis(t, ex.period, ex.harmonics)
    P0, _, _ = fourier_basis(ex.t, ex.period, ex.harmonics)
    theta = np.linalg.lstsq(P0, ex.q, rcond=None)[0]  # the coefficients back from the samples (exact)
    q, qd, qdd = P @ theta, V @ theta, A @ theta
    tau = torques_along(true, q, qd, qdd)
    clean = identify(Y, bp, np.asarray(reg.values()), Measurements(t, q, qd, qdd, tau),
                     bodies=len(reg.bodies))
    err_clean = float(np.abs(clean.base_values - pib_true).max() / np.abs(pib_true).max())
    rng = np.random.default_rng(1)
    noise = 0.01 * np.sqrt(np.mean(tau ** 2, axis=0))
    noisy = identify(Y, bp, np.asarray(reg.values()),
                     Measurements(t, q, qd, qdd, tau + rng.normal(size=tau.shape) * noise), bodies=len(reg.bodies))
    # held out: the random Fourier trajectory the optimiser started from, at the same rate
    lo, hi = (np.array(b) for b in nominal.joint_box())
    vmax = np.array([c.limits.velocity or np.inf for c in nominal.coordinates])
    x0 = random_coefficients(np.random.default_rng(7), nominal.nv, 1 + 2 * ex.harmonics, ex.harmonics, ex.period,
                             lo, hi, vmax, 2 * vmax, P, V, A).reshape(nominal.nv, -1).T
    q2, qd2, qdd2 = P @ x0, V @ x0, A @ x0
    Y2 = Y(q2, qd2, qdd2).reshape(-1, len(reg.names))[:, list(bp.columns)]
    pred = (Y2 @ noisy.base_values).reshape(-1, nominal.nv)
    held = np.sqrt(np.mean((pred - torques_along(true, q2, qd2, qdd2)) ** 2, axis=0))
    lines = ["## Identification: excitation and round trip (panda)", "",
             f"`derive excite panda` ({harmonics} harmonics, period {ex.period:g} s, {samples} samples, "
             f"{ex.iterations} SLSQP iterations, {excite_s:.0f} s): "
             f"**cond(W_b) = {ex.condition:.4g}** against {ex.random_condition:.4g} for the random Fourier trajectory "
             f"of the same length it starts from (both within the limits; worst use of a limit "
             f"{ex.worst_limit:.3f}, within every limit: {'yes' if ex.limits_ok else 'NO'}). "
             f"{len(bp.names)} base parameters of {len(reg.names)} standard ones.", "",
             "Round trip: torques of a perturbed panda (masses +-20 %, centres of mass ~1 cm, armature 0.1, viscous "
             "0.5 and Coulomb 1.0 friction on every joint) along one period of that excitation at "
             f"{10 * samples / ex.period:g} Hz, identified from the nominal model:", "",
             "| data | base parameters: max error / max value | residual rms / torque rms (worst joint) |",
             "|---|---|---|",
             f"| no noise | {err_clean:.2e} | {np.max(clean.residual_rms / clean.tau_rms):.1e} |",
             f"| 1 % torque noise | {np.abs(noisy.base_values - pib_true).max() / np.abs(pib_true).max():.2e} | "
             f"{np.max(noisy.residual_rms / noisy.tau_rms):.1e} |", "",
             "Held-out motion (the random Fourier trajectory, not used to identify): rms torque error of the "
             "identified model per joint against the noise level (1 % of each joint's rms torque): "
             + ", ".join(f"{c.name} {h:.3g} / {n:.3g}" for c, h, n in zip(nominal.coordinates, held, noise))
             + f"; within the noise on every joint: {'yes' if np.all(held <= noise) else 'NO'}.", "",
             f"Bench time {time.perf_counter() - start:.0f} s."]
    return "\n".join(lines)


def benchmarks() -> dict:
    return {"identification": bench_identification}
