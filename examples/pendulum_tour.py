"""From models.yaml to the pendulum's equations, a simulation and firmware C, as a new user would.

Run from the project root (or anywhere; outputs go to ./pendulum_tour_out/):

    .venv/bin/python examples/pendulum_tour.py [OUT_DIR]

1. derive.load("pendulum"): the lecture's Example 5 model, M, C, g as sympy.
2. Its equations in LaTeX (.tex and a mathtext .png): eq. 18 in dot notation.
3. Example 7: linearised about phi = 0, a phi'' + b phi = 0 and z' = [z1, -b/a z0].
4. Ten seconds of RK4 with the generated code, a plot, a CSV and the energy drift.
5. The generated C (generated/pendulum/c/): compiled with a small main() calling
   pendulum_rk4_step if a C compiler is installed, and checked against step 4.

The generated code is read from ./generated (what `derive generate` writes) when it holds
the pendulum, else from the project's generated/ beside this example.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import sympy as sp

import derive
from derive.codegen.generate import default_output
from derive.inspect.latex import Options, document_context, render_tex
from derive.inspect.linearize import linearize
from derive.plot.latex import render_png
from derive.plot.simulate import plot_simulation
from derive.solvers.simulate import simulate, summary, write_csv

out = Path(sys.argv[1] if len(sys.argv) > 1 else "pendulum_tour_out")
out.mkdir(parents=True, exist_ok=True)
generated = default_output()
if not (generated / "pendulum").is_dir():
    generated = Path(__file__).resolve().parents[1] / "generated"

# ---- 1. the model ----
m = derive.load("pendulum")
print("1. pendulum from models.yaml:", m.robot.description)
print("   M(q) =", m.mass_matrix[0, 0])
print("   g(q) =", m.gravity_vector[0])
print("   equation of motion:", sp.Eq(m.equations_of_motion[0] + m.tau[0], m.tau[0]))

# ---- 2. LaTeX ----
context = document_context(m, Options(energy=True))
(out / "pendulum.tex").write_text(render_tex(context))
render_png(context, out / "pendulum_equations.png")
print(f"\n2. LaTeX: {out / 'pendulum.tex'} (and {out / 'pendulum_equations.png'}):")
print("   " + context["eom"][0]["lines"][0])

# ---- 3. order reduction (Example 7) ----
lin = linearize(m, [0])
a, b = lin.M[0, 0], lin.K[0, 0]
z0, z1 = sp.symbols("z0 z1")
print("\n3. small angles: a phi'' + b phi = 0 with")
print("   a =", a)
print("   b =", b)
print("   z' =", list(lin.A * sp.Matrix([z0, z1])))

# ---- 4. simulation ----
traj = simulate(m.robot, q0=[1.0], t_end=10.0, dt=1e-3, generated=generated)
write_csv(traj, out / "pendulum.csv")
plot_simulation(traj, out / "pendulum_simulation.png")
print("\n4.", summary(traj).replace("\n", "\n   "))
print(f"   wrote {out / 'pendulum.csv'} and {out / 'pendulum_simulation.png'}")

# ---- 5. the generated C ----
c_dir = generated / "pendulum" / "c"
print(f"\n5. generated C: {c_dir / 'pendulum_rk4_step.c'} (and {len(list(c_dir.glob('*.c'))) - 1} other .c files)")
cc = shutil.which("cc") or shutil.which("gcc")
if cc is None:
    print("   no C compiler found: skipping the firmware-side check")
    sys.exit(0)
main_c = out / "main.c"
main_c.write_text("""#include <stdio.h>
#include "pendulum.h"

int main(void)
{
    DERIVE_REAL x[2] = {1.0, 0.0}, u[1] = {0.0}, dt[1] = {1e-3}, x_next[2];
    const DERIVE_REAL p[PENDULUM_NP] = {PENDULUM_DEFAULT_m_r, PENDULUM_DEFAULT_m_s, PENDULUM_DEFAULT_I_r,
                                        PENDULUM_DEFAULT_I_s, PENDULUM_DEFAULT_l, PENDULUM_DEFAULT_g};
    int k;
    for (k = 0; k < 10000; ++k) {  /* 10 s: predict the state as firmware would */
        pendulum_rk4_step(x, u, dt, p, x_next);
        x[0] = x_next[0];
        x[1] = x_next[1];
    }
    printf("%.17g %.17g\\n", x[0], x[1]);
    return 0;
}
""")
exe = out / "pendulum_predict"
subprocess.run([cc, "-std=c99", "-O2", "-I", str(c_dir), "-o", str(exe), str(main_c), *map(str, sorted(c_dir.glob("*.c"))),
                "-lm"], check=True)
x_c = np.array(subprocess.run([str(exe)], check=True, capture_output=True, text=True).stdout.split(), dtype=float)
x_py = np.concatenate([traj.q[-1], traj.qd[-1]])
print(f"   compiled {exe}: x(10 s) = {x_c}, Python {x_py}, max difference {np.abs(x_c - x_py).max():.1e}")
