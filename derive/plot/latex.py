"""A robot's equations of motion drawn to a PNG with matplotlib's mathtext (no LaTeX install needed).

The lines are those of the LaTeX document of :func:`derive.inspect.latex.document_context`;
mathtext's parser checks every line of maths. mathtext has no environments, so
matrices come entry by entry.
"""

from __future__ import annotations

from pathlib import Path

from derive.errors import DeriveError

PNG_MAX_LINES = 400  # beyond this the PNG is cut (the .tex holds everything)


def mathtext_lines(context: dict) -> list[tuple[str, str]]:
    """The document as (kind, text) lines for mathtext: 'head', 'text' or 'math' (without $)."""
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


def render_png(context: dict, path: str | Path, dpi: int = 110) -> Path:
    """Draw the document's lines (a :func:`derive.inspect.latex.document_context`) with mathtext to ``path``.

    At most PNG_MAX_LINES lines are drawn; the .tex holds the rest. A line mathtext
    cannot parse is a DeriveError naming the robot.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lines = mathtext_lines(context)
    if len(lines) > PNG_MAX_LINES:
        lines = lines[:PNG_MAX_LINES] + [("text", f"... {len(lines) - PNG_MAX_LINES} more lines in the .tex")]
    step = 0.42  # inches per line: room for \frac
    fig = plt.figure(figsize=(11, step * (len(lines) + 1)))
    for k, (kind, text) in enumerate(lines):
        y = 1 - (k + 0.8) / (len(lines) + 1)
        if kind == "math":
            fig.text(0.03, y, f"${text}$", fontsize=12, va="center")
        else:
            fig.text(0.01, y, text, fontsize=12, va="center", weight="bold" if kind == "head" else "normal")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        fig.savefig(path, dpi=dpi)
    except ValueError as exc:  # mathtext parse errors surface at draw time
        raise DeriveError(f"robot '{context['robot']}': mathtext cannot render the equations: {exc}") from None
    finally:
        plt.close(fig)
    return path
