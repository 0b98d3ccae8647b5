"""LaTeX of a robot's equations of motion, for papers (``derive latex ROBOT`` on the command line).

M(q) qdd + C(q, qd) qd + g(q) = tau, written in the lecture's notation: joint
coordinates by name (phi -> \\varphi, theta1 -> \\theta_{1}; other names q_{i}),
derivatives with dots (dphi -> \\dot{\\varphi}, ddtheta1 -> \\ddot{\\theta}_{1}),
parameters with subscripts (m_r -> m_{r}, L1 -> L_{1}). Sums are grouped by
their sin/cos factors (optionally shortened to s_{1}, c_{12} = cos(theta1 +
theta2) with a legend) and broken over lines at + and -; a matrix that does not
fit on the page is written entry by entry (M once per upper-triangle entry, as
it is symmetric). Models with more than two joints come as common
subexpressions t_{k} ("where ..."), as their expanded entries run to pages.

The document is rendered from templates/latex/document.tex.jinja with plain
data prepared here (:func:`document_context`); :func:`compile_pdf` runs pdflatex
where one is installed. :func:`derive.plot.latex.render_png` draws the same lines
with matplotlib's mathtext (no LaTeX install needed: every line is checked by its
parser).
"""

from __future__ import annotations

import re
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import sympy as sp

from derive.codegen.generate import model_hash
from derive.codegen.render import environment
from derive.errors import DeriveError
from derive.inspect.closed_latex import reduced_context, reduced_equations

GREEK = {"alpha", "beta", "gamma", "delta", "epsilon", "zeta", "eta", "theta", "iota", "kappa", "lambda",
         "mu", "nu", "xi", "pi", "rho", "sigma", "tau", "upsilon", "phi", "chi", "psi", "omega",
         "Gamma", "Delta", "Theta", "Lambda", "Xi", "Pi", "Sigma", "Upsilon", "Phi", "Psi", "Omega"}
VARIANTS = {"phi": r"\varphi", "epsilon": r"\varepsilon"}  # the lecture's glyphs
DIGITS = 6  # significant digits of floating-point constants in print


@dataclass(frozen=True)
class Options:
    """What goes into the document and how it is laid out.

    Args:
        short_trig: write sin(theta1 + theta2) as s_{12} (joint indices, 1-based), with a legend.
        cse: common subexpressions t_{k}; None: for models with more than two joints.
        width: characters of visible maths per line before an entry is broken.
        fk, jacobian: frames whose world_T_frame / geometric Jacobian are added.
        energy: add the kinetic and potential energies T and U.
        tree: for a robot with loops, the spanning tree's M, C, g (in q, the loops not imposed) instead
            of the closed chain's reduced equations in y (:mod:`derive.inspect.closed_latex`).
    """

    short_trig: bool = False
    cse: bool | None = None
    width: int = 64
    fk: tuple[str, ...] = ()
    jacobian: tuple[str, ...] = ()
    energy: bool = False
    tree: bool = False


# ---- symbol names ----

def name_latex(name: str) -> str | None:
    """LaTeX of an identifier: theta1 -> \\theta_{1}, m_r -> m_{r}, L_tcp -> L_{\\mathrm{tcp}}; None if not short.

    Short means a Greek name or one letter, then digits or one ``_`` and a subscript.
    """
    m = re.fullmatch(r"([A-Za-z]+?)(?:_([A-Za-z0-9]+)|(\d+))?", name)
    if not m or not (m.group(1) in GREEK or len(m.group(1)) == 1):
        return None
    base = VARIANTS.get(m.group(1), "\\" + m.group(1) if m.group(1) in GREEK else m.group(1))
    sub = m.group(2) or m.group(3)
    if sub is None:
        return base
    sub_tex = sub if sub.isdigit() else name_latex(sub) or r"\mathrm{" + sub + "}"
    return f"{base}_{{{sub_tex}}}"


def symbol_names(m) -> dict[sp.Symbol, str]:
    """LaTeX for every symbol of a SymbolicModel: q, qd (dot), qdd (ddot), tau and parameters."""
    names: dict[sp.Symbol, str] = {}
    for i, (q, qd, qdd, tau) in enumerate(zip(m.q, m.qd, m.qdd, m.tau), 1):
        tex = name_latex(str(q)) or f"q_{{{i}}}"
        base, _, sub = tex.partition("_")
        sub = f"_{sub}" if sub else ""
        names[q] = tex
        names[qd] = rf"\dot{{{base}}}{sub}"
        names[qdd] = rf"\ddot{{{base}}}{sub}"
        names[tau] = rf"\tau_{{{tex}}}" if not sub else rf"\tau{sub}"
    for p in m.params:
        names[p] = name_latex(str(p)) or r"\mathrm{" + escape_text(str(p)) + "}"
    return names


def short_trig_symbols(exprs: list[sp.Matrix], m) -> tuple[dict, dict[sp.Symbol, str], list[tuple]]:
    """sin/cos of sums of joint angles -> s_{ij}/c_{ij} symbols: (replacements, their LaTeX, legend rows).

    Legend rows are (letter, joint indices, the sin/cos expression).
    """
    index = {q: str(i) for i, q in enumerate(m.q, 1)}
    sep = "," if m.nv > 9 else ""
    atoms = set().union(*(e.atoms(sp.sin, sp.cos) for e in exprs))
    subs, names, legend = {}, {}, []
    for a in sorted(atoms, key=sp.default_sort_key):
        terms = sp.Add.make_args(a.args[0])
        if not all(t in index for t in terms):
            continue
        key = sep.join(sorted((index[t] for t in terms), key=int))
        letter = "s" if isinstance(a, sp.sin) else "c"
        sym = sp.Symbol(f"_{letter}{key}")
        subs[a], names[sym] = sym, f"{letter}_{{{key}}}"
        legend.append((letter, key, a))
    return subs, names, legend


# ---- printing ----

class Printer:
    """sympy -> LaTeX strings with the model's names; sums as signed terms, grouped by trig factors."""

    def __init__(self, names: dict[sp.Symbol, str], trig_symbols: set, group: bool, width: int):
        self.names, self.trig, self.group, self.width = names, trig_symbols, group, width

    def tex(self, e) -> str:
        """LaTeX of e; floats (model numbers that are not short fractions) to DIGITS significant digits."""
        e = sp.sympify(e)
        e = e.xreplace({f: sp.Float(f, DIGITS) for f in e.atoms(sp.Float)})
        return sp.latex(e, symbol_names=self.names, fold_func_brackets=True, full_prec=False)

    def terms(self, e: sp.Expr) -> list[str]:
        """Signed LaTeX terms of e (each starts with '-' or not); grouped by trig factor when asked."""
        e = sp.sympify(e)
        keys = sorted(e.atoms(sp.sin, sp.cos) | (e.free_symbols & self.trig), key=sp.default_sort_key)
        if not self.group or not keys:
            return [self.tex(t) for t in e.as_ordered_terms()]
        parts = sp.collect(sp.expand(e), keys, evaluate=False)
        out: list[str] = []
        for key in sorted(parts, key=lambda k: (k == 1, sp.default_sort_key(k))):
            coef = sp.factor_terms(parts[key])
            if key == 1:
                out += [self.tex(t) for t in coef.as_ordered_terms()]
            else:
                out.append(self.product(coef, self.tex(key)))
        return out

    def grouped(self, coef: sp.Expr, factor: str) -> str:
        """coef * factor with coef as grouped terms, in parentheses if more than one."""
        terms = self.terms(coef)
        if len(terms) == 1:
            return self.product(coef, factor)
        return rf"\left({' '.join(signed(terms))}\right) {factor}"

    def product(self, coef: sp.Expr, factor: str) -> str:
        """coef * factor with coef printed first (in parentheses if a sum)."""
        if coef == 1:
            return factor
        if coef == -1:
            return f"-{factor}"
        if isinstance(coef, sp.Add):
            return rf"\left({self.tex(coef)}\right) {factor}"
        if coef.could_extract_minus_sign():
            return f"-{self.product(-coef, factor)}"
        return f"{self.tex(coef)} {factor}"

    def lines(self, terms: list[str]) -> list[str]:
        """Join signed terms into lines of at most ``width`` visible characters (a long term keeps its own line)."""
        lines: list[str] = []
        for piece in signed(terms or ["0"]):
            if lines and visible(lines[-1]) + visible(piece) <= self.width:
                lines[-1] += " " + piece
            else:
                lines.append(piece)
        return lines


def signed(terms: list[str]) -> list[str]:
    """Signed terms as written after the first: ["a", "-b", "c"] -> ["a", "- b", "+ c"]."""
    return terms[:1] + [f"- {t[1:].lstrip()}" if t.startswith("-") else f"+ {t}" for t in terms[1:]]


def visible(tex: str) -> int:
    """Rough printed width of LaTeX maths: commands count as one glyph, braces and spaces as none."""
    tex = re.sub(r"\\(left|right|frac|dot|ddot|mathrm)\b", "", tex)
    return len(re.sub(r"\\[A-Za-z]+", "x", re.sub(r"[{}\s]", "", tex)))


def escape_text(text: str) -> str:
    """Plain text for LaTeX (descriptions, sources)."""
    out = text.replace("\\", r"\textbackslash{}")
    for ch in "&%$#_{}":
        out = out.replace(ch, "\\" + ch)
    return out.replace("~", r"\textasciitilde{}").replace("^", r"\textasciicircum{}")


# ---- the document ----

def _index(i: int, j: int | None, big: bool) -> str:
    return f"{i + 1}" if j is None else (f"{i + 1},{j + 1}" if big else f"{i + 1}{j + 1}")


def _block(title: str, symbol: str, mat: sp.Matrix, pr: Printer, symmetric: bool = False, skip_last_row=False,
           entry: str | None = None) -> dict:
    """Plain data for one matrix: its entries (``entry``_{ij} = lines) and, if it fits, the bmatrix form."""
    rows, cols = mat.shape
    rows -= int(skip_last_row)
    big = max(rows, cols) > 9
    vector = cols == 1
    entries, cells = [], []
    for i in range(rows):
        row = []
        for j in range(cols):
            lines = pr.lines(pr.terms(mat[i, j]))
            row.append(lines)
            if mat[i, j] != 0 and not (symmetric and j < i):
                entries.append({"lhs": f"{entry or symbol}_{{{_index(i, None if vector else j, big)}}}",
                                "lines": lines})
        cells.append(row)
    fits = (all(len(c) == 1 for row in cells for c in row)
            and max(sum(visible(c[0]) + 3 for c in row) for row in cells) <= pr.width)
    if skip_last_row:  # the constant row of a homogeneous transform
        cells.append([["0"]] * (cols - 1) + [["1"]])
    matrix = r" \\ ".join(" & ".join(c[0] for c in row) for row in cells) if fits else ""
    note = ("symmetric; " if symmetric else "") + "entries not listed are zero" + (
        ", the last row is (0, 0, 0, 1)" if skip_last_row else "")
    scalar = fits and rows == cols == 1
    if scalar:
        matrix = cells[0][0][0]
    return {"title": title, "symbol": symbol, "as_matrix": fits, "scalar": scalar, "matrix": matrix,
            "entries": entries, "note": note, "empty": not entries}


def document_context(m, options: Options = Options()) -> dict:
    """Everything the template needs, as plain data (strings, lists, booleans)."""
    robot = m.robot
    if robot.closed and not options.tree:
        return reduced_document_context(m, options)
    for frame in options.fk + options.jacobian:
        if frame not in m.frames:
            raise DeriveError(f"robot '{robot.name}': no frame '{frame}' (known: {', '.join(m.frames)})")
    mats: list[tuple[str, str, sp.Matrix, dict]] = [
        ("Mass matrix", "M", m.mass_matrix, {"symmetric": True}),
        ("Coriolis matrix", "C", m.coriolis_matrix, {}),
        ("Gravity vector", "g", m.gravity_vector, {}),
    ]
    if options.energy:
        mats += [("Kinetic energy", "T", sp.Matrix([m.kinetic_energy]), {}),
                 ("Potential energy", "U", sp.Matrix([m.potential_energy]), {})]
    for frame in options.fk:
        mats.append((f"Pose of frame {frame}", rf"{{}}^{{0}}T_{{\mathrm{{{escape_text(frame)}}}}}", m.fk(frame),
                     {"skip_last_row": True, "entry": "T"}))
    for frame in options.jacobian:
        mats.append((f"Geometric Jacobian of frame {frame}", rf"J_{{\mathrm{{{escape_text(frame)}}}}}",
                     m.jacobian(frame), {"entry": "J"}))
    names = symbol_names(m)
    exprs = [x[2] for x in mats]
    legend = []
    trig: set = set()
    if options.short_trig:
        subs, trig_names, legend_raw = short_trig_symbols(exprs, m)
        exprs = [e.xreplace(subs) for e in exprs]
        names.update(trig_names)
        trig = set(trig_names)
        legend = [{"lhs": f"{letter}_{{{key}}}", "rhs": sp.latex(a, symbol_names=names, fold_func_brackets=True)}
                  for letter, key, a in legend_raw]
    use_cse = (m.nv > 2) if options.cse is None else options.cse
    temporaries = []
    if use_cse:
        cse_syms = sp.numbered_symbols("_t", start=1)
        reps, exprs = sp.cse(exprs, symbols=cse_syms, order="none")
        for k, (sym, _) in enumerate(reps, 1):
            names[sym] = f"t_{{{k}}}"
    pr = Printer(names, trig, group=not use_cse, width=options.width)
    blocks = [_block(title, symbol, e, pr, **kw) for (title, symbol, _, kw), e in zip(mats, exprs)]
    if use_cse:
        temporaries = [{"lhs": names[s], "lines": pr.lines(pr.terms(e))} for s, e in reps]
    eom = [] if use_cse else _eom_rows(m, exprs[0], exprs[1], exprs[2], pr)
    q = ", ".join(names[s] for s in m.q)
    return {
        "robot": robot.name,
        "robot_text": escape_text(robot.name),
        "model_hash": model_hash(robot)[:16],
        "description": escape_text(robot.description),
        "source": escape_text(robot.source),
        "method": "Euler-Lagrange" if m.method == "lagrange" else "recursive Newton-Euler",
        "coordinates": rf"q = \left({q}\right)",
        "parameters": ", ".join(names[p] for p in m.params),
        "has_parameters": bool(len(m.params)),
        "eom": eom,
        "has_eom": bool(eom),
        "blocks": blocks,
        "legend": legend,
        "has_legend": bool(legend),
        "temporaries": temporaries,
        "has_temporaries": bool(temporaries),
    }


def reduced_document_context(m, options: Options) -> dict:
    """The reduced equations of a closed chain (:func:`derive.inspect.closed_latex.reduced_equations`)."""
    robot = m.robot
    if options.fk or options.jacobian or options.energy or options.short_trig or options.cse:
        raise DeriveError(f"robot '{robot.name}': --fk, --jacobian, --energy, --short-trig and --cse are for the "
                          "spanning tree's document of a closed chain (add --tree)")
    red = reduced_equations(m)
    names = symbol_names(m) | red.names
    pr = Printer(names, set(), group=True, width=options.width)
    q = ", ".join(names[s] for s in m.q)
    return {
        "robot": robot.name, "robot_text": escape_text(robot.name), "model_hash": model_hash(robot)[:16],
        "description": escape_text(robot.description), "source": escape_text(robot.source),
        "method": "recursive Newton-Euler" if m.method != "lagrange" else "Euler-Lagrange",
        "coordinates": rf"q = \left({q}\right)", "parameters": ", ".join(names[p] for p in m.params),
        "has_parameters": bool(len(m.params)), "eom": [], "has_eom": False, "blocks": [], "legend": [],
        "has_legend": False, "temporaries": [], "has_temporaries": False,
        **reduced_context(m, red, names, pr)}


def _eom_rows(m, M: sp.Matrix, C: sp.Matrix, g: sp.Matrix, pr: Printer) -> list[dict]:
    """Row i of M qdd + C qd + g = tau as grouped terms: (M_ij) qdd_j ..., then C qd, then g."""
    rows = []
    Cqd = C * m.qd
    for i in range(m.nv):
        terms = [pr.grouped(M[i, j], pr.names[m.qdd[j]]) for j in range(m.nv) if M[i, j] != 0]
        terms += pr.terms(sp.factor_terms(sp.expand(Cqd[i]))) if Cqd[i] != 0 else []
        terms += pr.terms(g[i]) if g[i] != 0 else []
        lines = pr.lines(terms)
        lines[-1] += rf" = {pr.names[m.tau[i]]}"
        rows.append({"lines": lines})
    return rows


def latex_document(m, options: Options = Options()) -> str:
    """A standalone LaTeX document (article, amsmath) with the model's equations."""
    return render_tex(document_context(m, options))


def render_tex(context: dict) -> str:
    """The .tex text of a :func:`document_context` (templates/latex/document.tex.jinja)."""
    template = "latex/reduced.tex.jinja" if context.get("reduced") else "latex/document.tex.jinja"
    return environment().get_template(template).render(context)


def compile_pdf(tex: str | Path) -> Path:
    """pdflatex the .tex beside itself; raises DeriveError if pdflatex is missing or fails."""
    exe = shutil.which("pdflatex")
    tex = Path(tex).resolve()
    if exe is None:
        raise DeriveError(f"pdflatex not found: {tex} is written, render it with --png (mathtext) instead")
    run = subprocess.run([exe, "-interaction=nonstopmode", "-halt-on-error", tex.name], cwd=tex.parent,
                         capture_output=True, text=True)
    if run.returncode != 0:
        raise DeriveError(f"pdflatex failed on {tex} (see {tex.with_suffix('.log')})")
    return tex.with_suffix(".pdf")
