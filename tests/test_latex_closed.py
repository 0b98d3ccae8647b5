"""``derive latex`` of a closed chain: the reduced equations as a chain of named definitions
(derive/inspect/closed_latex.py). The chain evaluated numerically equals the generated closure,
mass_matrix_y and bias_y; the four-bar's document fits on one page."""

from __future__ import annotations

import re

import numpy as np
import pytest

import derive
from derive.cli import main
from derive.inspect.closed_latex import evaluate, reduced_equations
from derive.inspect.latex import Options, document_context, render_tex
from derive.plot.latex import mathtext_lines
from test_codegen import load_python
from test_latex import check_structure

PAGE_ROWS = 40
"""Display rows that fit one A4 page at 11 pt with 2 cm margins beside the title, the text lines and the
section heads (about 55 lines of text in all)."""


@pytest.fixture(scope="module")
def fourbar():
    return derive.load("fourbar", method="newton-euler")


@pytest.mark.parametrize("name", ["fourbar", "slider_crank"])
def test_printed_chain_equals_the_generated_functions(name, fourbar):
    """q (the printed closed form), M_y and h_y from the printed definitions (sympy, 30 digits) at 2 seeded
    states near the reference: the generated closure, mass_matrix_y and bias_y to 1e-12."""
    m = fourbar if name == "fourbar" else derive.load(name, method="newton-euler")
    red = reduced_equations(m)
    py = load_python(name)
    names = [c.name for c in m.robot.coordinates]
    y_ref = np.array([m.robot.reference_q[names.index(c)] for c in m.robot.independent])
    rng = np.random.default_rng(21)
    for _ in range(2):
        y, yd = y_ref + rng.uniform(-0.1, 0.1, y_ref.size), rng.normal(size=y_ref.size)
        q, M_y, h_y = evaluate(red, m, y, yd)
        assert np.abs(q - py.closure(y)[0]).max() <= 1e-12
        assert np.abs(M_y - py.mass_matrix_y(y)).max() <= 1e-12 * np.abs(M_y).max()
        assert np.abs(h_y - py.bias_y(y, yd)).max() <= 1e-12 * max(1.0, np.abs(h_y).max())


def test_fourbar_document_fits_one_page(fourbar):
    """The sections in order, every definition used after it is made, 28 display rows (<= PAGE_ROWS) and
    no row wider than 80 visible characters; the tree's t_k are not in it."""
    context = document_context(fourbar, Options())
    tex = render_tex(context)
    check_structure(tex)
    assert [s["title"] for s in context["sections"]] == ["Loop closure", "Closed form", "Velocity map",
                                                        "Acceleration bias", "Reduced mass matrix", "Reduced bias"]
    assert context["n_lines"] <= PAGE_ROWS and len(tex) <= 5000, (context["n_lines"], len(tex))
    rows = [r for s in context["sections"] for r in s["rows"]]
    assert [r["lhs"] for r in rows][:2] == [r"\psi_{1}", r"\psi_{2}"]
    assert [r["lhs"] for r in rows][-2:] == ["M_{y}", "h_{y}"]
    from derive.inspect.latex import visible
    assert max(visible(line) for r in rows for line in r["lines"]) <= 80
    assert r"\Delta &= b c \sin{\left(q_{2} + q_{1} - q_{3} \right)}" in tex  # det K_z = b c sin(transmission angle)
    assert r"G_{3} &= \frac{a b}{\Delta} \sin {q_{2}}" in tex
    defined = [r["lhs"] for r in rows]
    for k, r in enumerate(rows):  # w_k, G_i, beta_i, kappa_i: used only after their definition
        for used in set(re.findall(r"(?:w|G|\\beta|\\kappa)_\{\d+\}", " ".join(r["lines"]))):
            assert used in defined[:k], f"{used} used in {r['lhs']} before it is defined"
    assert "t_{" not in tex
    assert len(mathtext_lines(context)) > 30  # --png draws the same rows


def test_cli_prints_the_reduced_document_and_the_tree_on_request(capsys):
    assert main(["latex", "slider_crank"]) == 0
    out = capsys.readouterr().out
    assert r"\section*{Reduced equations of slider\_crank }" in out and r"\psi_{1}" in out
    assert main(["latex", "slider_crank", "--tree"]) == 0
    out = capsys.readouterr().out
    assert r"\section*{Equations of motion of slider\_crank }" in out and r"\psi" not in out
    assert main(["latex", "slider_crank", "--energy"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("derive: error: robot 'slider_crank': --fk, --jacobian, --energy") and "--tree" in err[-1]
