"""On top: the symbolic model for people (sympy matrices, LaTeX documents, order reduction and linearisation)."""
