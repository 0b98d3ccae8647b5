"""Cross-check of examples/irb140_dh.yaml against robotics-toolbox (Peter Corke's models.DH.IRB140).

robotics-toolbox is no dependency of derive (its install is ~500 MB with its data), so this runs in
a venv of its own, on the numpy module derive generated:

    derive --models examples/irb140_dh.yaml generate --out /tmp/irb140
    python -m venv /tmp/rtb && /tmp/rtb/bin/pip install roboticstoolbox-python pyyaml
    /tmp/rtb/bin/python bench/rtb_irb140.py /tmp/irb140/irb140/python/irb140.py

rtb's IRB140 takes the masses, centres of mass and inertias of the models.yaml file (its own are
different), with no motor inertia, friction or gear: then FK, the Jacobian (rtb's jacob0: world
frame, [v; w] at the tool, as derive's jacobian_tcp), M, g, C qd and the inverse dynamics compare
at 200 seeded states. The section "robotics-toolbox cross-check (IRB140, DH)" of bench/results.md
is replaced with the figures.
"""

from __future__ import annotations

import importlib.util
import math
import re
import sys
from importlib.metadata import version
from pathlib import Path

import numpy as np
import roboticstoolbox as rtb
import yaml

ROOT = Path(__file__).resolve().parent.parent
TITLE = "## robotics-toolbox cross-check (IRB140, DH)"


def rpy_matrix(rpy) -> np.ndarray:
    """URDF's Rz(yaw) Ry(pitch) Rx(roll)."""
    r, p, y = rpy
    rx = np.array([[1, 0, 0], [0, math.cos(r), -math.sin(r)], [0, math.sin(r), math.cos(r)]])
    ry = np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])
    rz = np.array([[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]])
    return rz @ ry @ rx


def main(module_path: str) -> None:
    spec = importlib.util.spec_from_file_location("irb140", module_path)
    gen = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(gen)
    rows = yaml.safe_load((ROOT / "examples" / "irb140_dh.yaml").read_text())["robots"]["irb140"]["dh"]["rows"]
    robot = rtb.models.DH.IRB140()
    for link, row in zip(robot.links, rows):
        link.m = row.get("mass", 0.0)
        link.r = row.get("com", [0.0, 0.0, 0.0])
        rot = rpy_matrix(row.get("inertia_rpy", [0.0, 0.0, 0.0]))
        link.I = rot @ np.diag(row.get("inertia", [0.0, 0.0, 0.0])) @ rot.T
        link.Jm, link.B, link.Tc, link.G = 0.0, 0.0, [0.0, 0.0], 1.0
    robot.gravity = [0.0, 0.0, -9.81]
    rng = np.random.default_rng(0)
    worst: dict[str, float] = {}
    for _ in range(200):
        q, qd, qdd = rng.uniform(-math.pi, math.pi, 6), rng.normal(size=6), rng.normal(size=6)
        pairs = {"fk_tcp": (gen.fk_tcp(q), robot.fkine(q).A), "jacobian_tcp": (gen.jacobian_tcp(q), robot.jacob0(q)),
                 "mass_matrix": (gen.mass_matrix(q), robot.inertia(q)), "gravity": (gen.gravity(q), robot.gravload(q)),
                 "coriolis_matrix qd": (gen.coriolis_matrix(q, qd) @ qd, robot.coriolis(q, qd) @ qd),
                 "inverse_dynamics": (gen.inverse_dynamics(q, qd, qdd), robot.rne(q, qd, qdd))}
        for name, (ours, theirs) in pairs.items():
            err = np.abs(np.asarray(ours) - np.asarray(theirs)).max() / max(1.0, np.abs(theirs).max())
            worst[name] = max(worst.get(name, 0.0), err)
    lines = [TITLE, "", f"robotics-toolbox {version('roboticstoolbox-python')} `models.DH.IRB140` with the mass "
             "properties of examples/irb140_dh.yaml (no motor inertia, friction or gear) against derive's generated "
             "numpy module, 200 seeded states (q uniform in [-pi, pi]); largest |derive - rtb| / max(1, |rtb|). "
             "The forward dynamics and the ODE are not generated (massless wrist: M(q) singular). "
             "Written by `bench/rtb_irb140.py` (its docstring says how to run it).", "",
             "| quantity (rtb) | max relative error |", "|---|---|"]
    names = {"fk_tcp": "fkine", "jacobian_tcp": "jacob0", "mass_matrix": "inertia", "gravity": "gravload",
             "coriolis_matrix qd": "coriolis @ qd", "inverse_dynamics": "rne"}
    lines += [f"| {name} ({names[name]}) | {err:.1e} |" for name, err in worst.items()]
    section = "\n".join(lines) + "\n"
    results = ROOT / "bench" / "results.md"
    text = results.read_text()
    pattern = re.compile(re.escape(TITLE) + r"\n.*?(?=\n## |\Z)", re.S)
    text = pattern.sub(section.rstrip("\n"), text) if pattern.search(text) else text.rstrip("\n") + "\n\n" + section
    results.write_text(text)
    print(section)


if __name__ == "__main__":
    main(sys.argv[1])
