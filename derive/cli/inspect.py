"""Commands that show the symbolic model: ``derive eom`` and ``derive latex``."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import sympy as sp

from derive.cli.common import check_count, integer, path_arg, png_path
from derive.description.model import load_robot
from derive.errors import DeriveError
from derive.filesystem import write_atomically
from derive.inspect.latex import Options, compile_pdf, document_context, render_tex
from derive.inspect.sympy_model import load
from derive.plot.figure import write_png
from derive.plot.latex import equations_png

MIN_WIDTH = 10
"""Narrowest ``latex --width``: below it every term would sit on a line of its own whatever the width."""
MAX_WIDTH = 10_000
"""Widest ``latex --width``: far beyond any page; a line is never longer than that."""


def cmd_eom(args) -> int:
    """Print M, C, g: written out up to two joints, else after common subexpressions t_k.

    sympy's cse with its default (no) optimisations and order "none", as ``derive latex`` runs it: with
    optimizations="basic" a 7-joint arm took more than 600 s, now 6 s (panda) and 3.5 s (ur5). What
    is left is announced on stderr before it starts (one line), the time when done."""
    robot = load_robot(args.robot_name, args.models)
    print(f"deriving {robot.name} ({robot.nv} joints, newton-euler) ...", file=sys.stderr, flush=True)
    start = time.perf_counter()
    m = load(args.robot_name, args.models, method="newton-euler")
    quantities = {"M(q)": m.mass_matrix, "C(q, qd)": m.coriolis_matrix, "g(q)": m.gravity_vector}
    if m.nv <= 2:
        for label, value in quantities.items():
            print(f"{label} =\n{sp.pretty(value)}\n")
        return 0
    # written out, 3+ joints run to megabytes: print with common subexpressions instead
    subs, reduced = sp.cse(list(quantities.values()), symbols=sp.numbered_symbols("t"), order="none")
    print(f"# {m.robot.name}: {len(subs)} common subexpressions t_k, then M, C, g (newton-euler route)")
    for sym, value in subs:
        print(f"{sym} = {value}")
    for label, value in zip(quantities, reduced):
        print(f"\n{label} =\n{value}")
    print(f"derived {robot.name} in {time.perf_counter() - start:.1f} s (`derive latex {robot.name}` writes it as a "
          "LaTeX document)", file=sys.stderr)
    return 0


def cmd_latex(args) -> int:
    """Write (or print) the LaTeX document; --png draws it with mathtext, --pdf runs pdflatex on --out."""
    if args.pdf and not args.out:
        raise DeriveError("latex: --pdf needs --out FILE.tex")
    # every option is checked (cheaply, before the derivation) before anything is printed
    robot = load_robot(args.robot_name, args.models)
    if args.width < MIN_WIDTH:
        raise DeriveError(f"robot '{robot.name}': --width must be at least {MIN_WIDTH} characters, got {args.width}")
    check_count(args.width, "--width", MIN_WIDTH, MAX_WIDTH, "characters per line", f"robot '{robot.name}'")
    frames = robot.frame_names + tuple(robot.frame_aliases)
    for frame in args.fk + args.jacobian:
        if frame not in frames:
            raise DeriveError(f"robot '{robot.name}': no frame '{frame}' (known: {', '.join(frames)})")
    print(f"deriving {robot.name} ({args.method}) ...", file=sys.stderr, flush=True)
    m = load(args.robot_name, args.models, method=args.method)
    options = Options(short_trig=args.short_trig, cse=args.cse, width=args.width, fk=tuple(args.fk),
                      jacobian=tuple(args.jacobian), energy=args.energy, tree=args.tree)
    context = document_context(m, options)
    text = render_tex(context)
    png = equations_png(context) if args.png else None  # drawn before anything is written
    if args.out:
        out = Path(args.out)
        try:
            out.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise DeriveError(f"latex --out {out}: cannot create its folder ({exc.strerror or exc})") from None
        write_atomically(out, text, "LaTeX document")
        print(f"wrote {out}", file=sys.stderr)
        if args.pdf:
            print(f"wrote {compile_pdf(out)}", file=sys.stderr)
    else:
        sys.stdout.write(text)
    if png is not None:
        print(f"wrote {write_png(args.png, png)}", file=sys.stderr)
    return 0


def add_parser(sub) -> None:
    e = sub.add_parser("eom", help="print M, C and g of a robot (sympy)",
                       description="Print M(q), C(q, qd) and g(q) as sympy expressions: written out up to two joints, "
                                   "else after common subexpressions t_k (seconds for a 7-joint arm). `derive latex "
                                   "ROBOT` writes them as a LaTeX document.")
    e.add_argument("robot_name")
    e.set_defaults(func=cmd_eom)

    p = sub.add_parser("latex", help="write a robot's M, C, g (and FK/Jacobian) as a LaTeX document; a closed "
                                     "chain's reduced equations in y")
    p.add_argument("robot_name")
    p.add_argument("--out", type=path_arg, help="write the .tex here (default: print it)")
    p.add_argument("--png", type=png_path, help="also draw the equations to this .png file (matplotlib mathtext)")
    p.add_argument("--pdf", action="store_true", help="also run pdflatex on --out (needs a LaTeX install)")
    p.add_argument("--method", choices=("lagrange", "newton-euler"), default="newton-euler",
                   help="derivation route (identical equations; default newton-euler, shorter before simplification)")
    p.add_argument("--short-trig", action="store_true", help="write sin(theta1 + theta2) as s_{12}, with a legend")
    p.add_argument("--cse", action=argparse.BooleanOptionalAction, default=None,
                   help="common subexpressions t_k (default: for models with more than two joints)")
    p.add_argument("--fk", action="append", default=[], metavar="FRAME", help="add world_T_FRAME (repeatable)")
    p.add_argument("--jacobian", action="append", default=[], metavar="FRAME", help="add FRAME's Jacobian (repeatable)")
    p.add_argument("--energy", action="store_true", help="add the kinetic and potential energies")
    p.add_argument("--tree", action="store_true",
                   help="a closed chain: the spanning tree's M, C, g in q (the loops not imposed) instead of the "
                        "reduced equations in y")
    p.add_argument("--width", type=integer, default=64,
                   help=f"visible characters per line ({MIN_WIDTH} .. {MAX_WIDTH}, default 64)")
    p.set_defaults(func=cmd_latex)
