"""Commands that show the symbolic model: ``derive eom`` and ``derive latex``."""

from __future__ import annotations

import sympy as sp

from derive.inspect import latex
from derive.inspect.sympy_model import load


def cmd_eom(args) -> int:
    m = load(args.robot_name, args.models, method="newton-euler")
    quantities = {"M(q)": m.mass_matrix, "C(q, qd)": m.coriolis_matrix, "g(q)": m.gravity_vector}
    if m.nv <= 2:
        for label, value in quantities.items():
            print(f"{label} =\n{sp.pretty(value)}\n")
        return 0
    # written out, 3+ joints run to megabytes: print with common subexpressions instead
    subs, reduced = sp.cse(list(quantities.values()), symbols=sp.numbered_symbols("t"), optimizations="basic")
    print(f"# {m.robot.name}: {len(subs)} common subexpressions t_k, then M, C, g (newton-euler route)")
    for sym, value in subs:
        print(f"{sym} = {value}")
    for label, value in zip(quantities, reduced):
        print(f"\n{label} =\n{value}")
    return 0



def add_parser(sub) -> None:
    e = sub.add_parser("eom", help="print M, C and g of a robot (sympy)")
    e.add_argument("robot_name")
    e.set_defaults(func=cmd_eom)
    latex.add_parser(sub)  # moves here with the latex command
