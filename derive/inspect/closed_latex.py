"""The reduced equations of a small closed chain as named sympy definitions, for ``derive latex``.

A closed chain's M_y and h_y written out in y run to pages (the closure z = gamma(y) inside every
entry). The document instead gives them as a short chain of named definitions, each an expression of
the ones before it (the four-bar's fits on one page):

    psi(q) = 0                     the loops in world axes: p_a - p_b in the loop's plane (planar),
                                   p_a - p_b (point), (|p_a - p_b|^2 - L^2) / (2 L) (distance);
                                   the same G and Gdot yd as the generated phi (K differs by an
                                   invertible factor on the loops, which G = [I; -K_z^-1 K_y] drops)
    w_k, z = gamma(y)              the closure's closed form after common subexpressions w_k
                                   (angles within (-pi, pi]), where one exists
    Delta = det K_z,  G_i          G = [I; -adj(K_z) K_y / Delta]
    qd = G yd,  kappa = Kdot qd,   beta_i = [-adj(K_z) kappa / Delta]_i  (Gdot yd)
    M_y = G^T M G,                 h_y = G^T (C qd + g + M Gdot yd)

with M, C, g the tree's (the document's sections above, here written out in q). :func:`evaluate`
runs the chain numerically (tests compare it with the generated functions).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
import sympy as sp

from derive.description.robot import loop_basis
from derive.errors import DeriveError
from derive.inspect.tosympy import to_sympy
from derive.symbolic.closed_form import closed_form_closure

MAX_DEPENDENT = 3
"""Most dependent coordinates written out: K_z's adjugate and determinant grow as n!; the four-bar,
slider-crank and five-bar have 2."""


@dataclass(frozen=True)
class Definition:
    symbol: sp.Symbol | None  # None: a line of the reduced equations themselves (M_y, h_y entries)
    expr: sp.Expr
    lhs: str  # LaTeX of the left-hand side


@dataclass(frozen=True)
class Reduced:
    """The chain of definitions, in order, by section; ``names`` the LaTeX of every new symbol."""

    closure: str  # how gamma is written
    loops: list[Definition]
    closure_lines: list[Definition]
    projection: list[Definition]
    rates: list[Definition]
    mass: list[Definition]
    bias: list[Definition]
    names: dict
    y: list[sp.Symbol]
    z: list[sp.Symbol]


def _simplify(e: sp.Expr) -> sp.Expr:
    return sp.trigsimp(sp.expand(e))


_X = sp.Wild("X")


def _tidy(e: sp.Expr) -> sp.Expr:
    """A sum with sin^2 written as 1 - cos^2 and expanded (products, not powers of sums), where that is
    shorter: the closure's |rotated vector|^2 = b^2 cos^2 + b^2 sin^2 becomes b^2 (sympy's trigsimp on
    the whole closure takes minutes)."""
    t = sp.expand(sp.expand(e, multinomial=False).replace(sp.sin(_X) ** 2, 1 - sp.cos(_X) ** 2), multinomial=False)
    return t if sp.count_ops(t) < sp.count_ops(e) else e


def reduced_equations(m) -> Reduced:
    """The definitions of a SymbolicModel ``m`` of a robot with loops (module docstring)."""
    robot = m.robot
    s, kin = m.sx.sym, m.sx.kinematics
    names = list(s.joint_names)
    nz = len(robot.dependent)
    if nz > MAX_DEPENDENT:
        raise DeriveError(f"robot '{robot.name}': the reduced equations are written out for at most {MAX_DEPENDENT} "
                          f"dependent coordinates (this one has {nz}: {', '.join(robot.dependent)})")
    q = list(m.q)
    yi = [names.index(c) for c in robot.independent]
    zi = [names.index(c) for c in robot.dependent]
    y_syms, z_syms = [q[i] for i in yi], [q[i] for i in zi]
    tex: dict = {}

    def sym(e: ca.SX) -> sp.Matrix:
        (out,) = to_sympy([e], [(s.q, q), (s.p, list(m.params))] if s.p.numel() else [(s.q, q)])
        return out

    # psi in world axes
    rows: list[sp.Expr] = []
    for lp in robot.loops:
        d = sym(kin.pose(lp.a).p - kin.pose(lp.b).p)
        if lp.kind == "planar" and not lp.rotation:
            u, v = (sp.Matrix([sp.nsimplify(c) for c in x]) for x in loop_basis(_world_normal(m, lp)))
            rows += [(u.T * d)[0], (v.T * d)[0]]
        elif lp.kind == "point":
            rows += list(d)
        elif lp.kind == "distance":
            L = sym(s.value(lp.length))[0] if not isinstance(lp.length, (int, float)) else sp.nsimplify(lp.length)
            rows.append(((d.T * d)[0] - L ** 2) / (2 * L))
        else:
            raise DeriveError(f"robot '{robot.name}': the reduced equations are written for planar, point and distance "
                              f"loops only (a {lp.kind} loop here)")
    psi = sp.Matrix([_simplify(rows[i]) for i in robot.loop_rows])  # the same rows as phi's, the kept ones
    if psi.rows != nz:
        raise DeriveError(f"robot '{robot.name}': the loops in world axes give {psi.rows} rows for {nz} dependent "
                          "coordinates")
    loops = [Definition(None, psi[i], rf"\psi_{{{i + 1}}}") for i in range(nz)]

    # the closure
    ysx = ca.SX.sym("y", len(yi))
    found = closed_form_closure(m.sx, ysx, centred=False)
    closure_lines: list[Definition] = []
    if found is not None:
        gamma_sx, method = found
        (gamma,) = to_sympy([gamma_sx], [(ysx, y_syms), (s.p, list(m.params))] if s.p.numel() else [(ysx, y_syms)])
        w_syms = sp.numbered_symbols("_w", start=1)
        reps, out = _inline(*sp.cse([gamma[i].replace(lambda x: x.is_Add, _tidy) for i in zi], symbols=w_syms,
                                    order="none"))
        for k, (w, e) in enumerate(reps, 1):
            tex[w] = f"w_{{{k}}}"
            closure_lines.append(Definition(w, e, tex[w]))
        for zs, e in zip(z_syms, out):
            closure_lines.append(Definition(zs, e, ""))
        closure = method.replace("closed form: ", "closed form (") + ")"
    else:
        closure = r"no closed form: Newton's method on $\psi = 0$ from the reference configuration"

    # G, Delta
    K = psi.jacobian(q)
    K_y, K_z = K[:, yi], K[:, zi]
    det = sp.Symbol("_Delta")
    tex[det] = r"\Delta"
    adj = K_z.adjugate()
    projection = [Definition(det, _simplify(K_z.det()), r"\Delta")]
    Gz = -(adj * K_y)
    G_syms = sp.zeros(len(q), len(yi))
    for a, i in enumerate(yi):
        G_syms[i, a] = 1
    for b, i in enumerate(zi):
        for a in range(len(yi)):
            g = sp.Symbol(f"_G{i}_{a}")
            tex[g] = f"G_{{{i + 1}{a + 1}}}" if len(yi) > 1 else f"G_{{{i + 1}}}"
            projection.append(Definition(g, _simplify(Gz[b, a]) / det, tex[g]))
            G_syms[i, a] = g

    # rates: qd_z = G yd, kappa = Kdot qd, gamma = -adj kappa / Delta
    qd, yd = list(m.qd), [m.qd[i] for i in yi]
    rates = [Definition(m.qd[i], sum((G_syms[i, a] * yd[a] for a in range(len(yi))), sp.Integer(0)), "") for i in zi]
    kappa_expr = (K * sp.Matrix(qd)).jacobian(q) * sp.Matrix(qd)
    kap = []
    for b in range(nz):
        k = sp.Symbol(f"_kappa{b}")
        tex[k] = rf"\kappa_{{{b + 1}}}"
        rates.append(Definition(k, _simplify(kappa_expr[b]), tex[k]))
        kap.append(k)
    gam = sp.zeros(len(q), 1)
    gv = -(adj * sp.Matrix(kap))
    for b, i in enumerate(zi):
        g = sp.Symbol(f"_beta{i}")
        tex[g] = rf"\beta_{{{i + 1}}}"
        rates.append(Definition(g, sp.expand(gv[b]) / det, tex[g]))
        gam[i] = g

    # M_y = G^T M G, h_y = G^T (C qd + g + M gamma)
    M = m.mass_matrix.applyfunc(_simplify)
    My = G_syms.T * M * G_syms
    h = G_syms.T * (m.coriolis_matrix.applyfunc(_simplify) * sp.Matrix(qd) + m.gravity_vector.applyfunc(_simplify)
                    + M * gam)
    ny = len(yi)
    mass = [Definition(None, sp.expand(My[a, b]), f"M_{{y,{a + 1}{b + 1}}}" if ny > 1 else "M_{y}")
            for a in range(ny) for b in range(a, ny)]
    bias = [Definition(None, sp.expand(h[a]), f"h_{{y,{a + 1}}}" if ny > 1 else "h_{y}") for a in range(ny)]
    return Reduced(closure=closure, loops=loops, closure_lines=closure_lines, projection=projection, rates=rates,
                   mass=mass, bias=bias, names=tex, y=y_syms, z=z_syms)


def _inline(reps: list, out: list) -> tuple[list, list]:
    """sympy's cse with the temporaries that save nothing put back: one operation or less (-w_3, a^2,
    sin q_1) or used once. The rest renamed in order (w_1, w_2, ...)."""
    reps, out = list(reps), list(out)
    while True:
        uses = {w: sum(e.count(w) for _, e in reps) + sum(e.count(w) for e in out) for w, _ in reps}
        drop = next(((w, e) for w, e in reps if sp.count_ops(e) <= 1 or uses[w] <= 1), None)
        if drop is None:
            break
        reps.remove(drop)
        reps = [(w, e.xreplace({drop[0]: drop[1]})) for w, e in reps]
        out = [e.xreplace({drop[0]: drop[1]}) for e in out]
    new = {w: sp.Symbol(f"_w{k}") for k, (w, _) in enumerate(reps, 1)}
    return [(new[w], e.xreplace(new)) for w, e in reps], [e.xreplace(new) for e in out]


def _world_normal(m, lp) -> np.ndarray:
    """A planar loop's normal in world axes at the reference configuration (constant: the mechanism is planar)."""
    s = m.sx.sym
    f = ca.Function("n", [s.q, s.p], [m.sx.kinematics.pose(lp.a).R @ ca.DM(list(lp.axis))])
    p = [x.default for x in m.robot.parameters]
    n = np.array(f(m.robot.reference_q, p), dtype=float).ravel()
    return np.round(n / np.linalg.norm(n), 12)


def evaluate(red: Reduced, m, y, yd) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(q, M_y, h_y) from the chain of definitions at y, yd (parameters at their defaults)."""
    values = {p: x.default for p, x in zip(m.params, m.robot.parameters)}
    values |= dict(zip(red.y, map(float, y)))
    values |= {m.qd[list(m.q).index(s)]: float(v) for s, v in zip(red.y, yd)}
    for d in red.closure_lines + red.projection + red.rates:
        values[d.symbol] = complex(d.expr.xreplace(values).evalf(30)).real if d.symbol is not None else None
    num = lambda e: float(sp.N(e.xreplace(values), 30))  # noqa: E731
    ny = len(red.y)
    My = np.zeros((ny, ny))
    k = 0
    for a in range(ny):
        for b in range(a, ny):
            My[a, b] = My[b, a] = num(red.mass[k].expr)
            k += 1
    h = np.array([num(d.expr) for d in red.bias])
    q = np.array([values[s] for s in m.q], dtype=float)
    return q, My, h


def reduced_context(m, red: Reduced, names: dict, printer) -> dict:
    """The template's data for the reduced equations: sections of (lhs, lines) with the document's
    ``printer`` (:class:`derive.inspect.latex.Printer`) and symbol ``names`` (the model's and red's)."""
    robot = m.robot

    def rows(defs: list[Definition]) -> list[dict]:
        return [{"lhs": d.lhs or names[d.symbol], "lines": printer.lines(printer.terms(d.expr))} for d in defs]

    y = ", ".join(names[s] for s in red.y)
    z = ", ".join(names[s] for s in red.z)
    ny = len(red.y)
    sections = [
        {"title": "Loop closure", "text": r"The loops in world axes, $\psi(q) = 0$ (the kept rows; the same $G$ and "
                                          r"$\dot{G}\dot{y}$ as the loops' own residuals):", "rows": rows(red.loops)}]
    if red.closure_lines:
        sections.append({"title": "Closed form", "text": rf"$z = \gamma(y)$ by the {escape(red.closure)}, on the "
                                                           "reference configuration's assembly branch:",
                         "rows": rows(red.closure_lines)})
    else:
        sections[0]["text"] += rf" $z = \gamma(y)$: {escape(red.closure)}."
    G = r"\begin{bmatrix} I \\ -K_z^{-1} K_y \end{bmatrix}"
    sections += [
        {"title": "Velocity map", "text": rf"$\dot{{q}} = G \dot{{y}}$, $G = {G}$, $K = \partial\psi/\partial q$, "
                                          r"$\Delta = \det K_z$:", "rows": rows(red.projection) + rows(
                                              [d for d in red.rates if d.lhs == ""])},
        {"title": "Acceleration bias", "text": r"$\dot{G}\dot{y} = -K_z^{-1} \kappa$ on $z$ (0 on $y$), "
                                               r"$\kappa = \dot{K}\dot{q}$:",
         "rows": rows([d for d in red.rates if d.lhs != ""])},
        {"title": "Reduced mass matrix" + (" (symmetric)" if ny > 1 else ""), "text": r"$M_y = G^T M G$:",
         "rows": rows(red.mass)},
        {"title": "Reduced bias", "text": r"$h_y = G^T (C \dot{q} + g + M \dot{G}\dot{y})$:", "rows": rows(red.bias)},
    ]
    return {"reduced": True, "sections": sections,
            "closed_coordinates": rf"y = \left({y}\right),\ z = \left({z}\right)",
            "n_lines": sum(len(r["lines"]) for sec in sections for r in sec["rows"])}


def escape(text: str) -> str:
    return text.replace("_", r"\_")
