"""A robot's equations of motion drawn to a PNG with matplotlib's mathtext (no LaTeX install needed).

The lines are those of the LaTeX document of :func:`derive.inspect.latex.document_context`;
mathtext's parser checks every line of maths. mathtext has no environments, so
matrices come entry by entry.
"""

from __future__ import annotations

import io
from pathlib import Path

from derive.errors import DeriveError
from derive.plot.figure import write_png

PNG_MAX_LINES = 400  # beyond this the PNG is cut (the .tex holds everything)


def mathtext_lines(context: dict) -> list[tuple[str, str]]:
    """The document as (kind, text) lines for mathtext: 'head', 'text' or 'math' (without $)."""
    if context.get("reduced"):  # a closed chain's reduced equations: its sections' rows
        out = [("head", f"{context['robot']}: reduced equations ({context['method']})"),
               ("math", r"M_y(y)\,\ddot{y} + h_y(y, \dot{y}) = \tau_y"), ("math", context["coordinates"]),
               ("math", context["closed_coordinates"])]
        for sec in context["sections"]:
            out.append(("head", sec["title"]))
            for e in sec["rows"]:
                out.append(("math", f"{e['lhs']} = {e['lines'][0]}"))
                out.extend(("math", rf"\qquad {line}") for line in e["lines"][1:])
        return out
    out: list[tuple[str, str]] = [("head", f"{context['robot']}: equations of motion ({context['method']})"),
                                  ("math", r"M(q)\,\ddot{q} + C(q, \dot{q})\,\dot{q} + g(q) = \tau"),
                                  ("math", context["coordinates"])]

    def entry(lhs: str, lines: list[str]) -> None:
        out.append(("math", f"{lhs} = {lines[0]}" if lhs else lines[0]))
        out.extend(("math", rf"\qquad {line}") for line in lines[1:])

    for row in context["eom"]:
        entry("", row["lines"])
    for b in context["blocks"]:
        out.append(("head", b["title"]))
        for e in b["entries"] or [{"lhs": b["symbol"], "lines": ["0"]}]:
            entry(e["lhs"], e["lines"])
    if context["legend"]:
        out.append(("head", "where"))
        out.extend(("math", f"{line['lhs']} = {line['rhs']}") for line in context["legend"])
    if context["temporaries"]:
        out.append(("head", "with the common subexpressions"))
        for t in context["temporaries"]:
            entry(t["lhs"], t["lines"])
    return out


def equations_png(context: dict, dpi: int = 110) -> bytes:
    """The document's lines (a :func:`derive.inspect.latex.document_context`) drawn with mathtext, as PNG bytes.

    At most PNG_MAX_LINES lines are drawn; the .tex holds the rest. A line mathtext
    cannot parse is a DeriveError naming the robot.
    """
    from matplotlib.figure import Figure

    lines = mathtext_lines(context)
    if len(lines) > PNG_MAX_LINES:
        lines = lines[:PNG_MAX_LINES] + [("text", f"... {len(lines) - PNG_MAX_LINES} more lines in the .tex")]
    step = 0.42  # inches per line: room for \frac
    fig = Figure(figsize=(11, step * (len(lines) + 1)))
    for k, (kind, text) in enumerate(lines):
        y = 1 - (k + 0.8) / (len(lines) + 1)
        if kind == "math":
            fig.text(0.03, y, f"${text}$", fontsize=12, va="center")
        else:
            fig.text(0.01, y, text, fontsize=12, va="center", weight="bold" if kind == "head" else "normal")
    buffer = io.BytesIO()
    try:
        fig.savefig(buffer, format="png", dpi=dpi)
    except ValueError as exc:  # mathtext parse errors surface at draw time
        reason = " ".join(str(exc).split())[:300]
        raise DeriveError(f"robot '{context['robot']}': mathtext cannot render the equations: {reason}") from None
    return buffer.getvalue()


def render_png(context: dict, path: str | Path, dpi: int = 110) -> Path:
    """:func:`equations_png` written to ``path`` (atomically, creating its folder); returns it."""
    return write_png(path, equations_png(context, dpi))
