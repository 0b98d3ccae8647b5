"""Figures (matplotlib, imported lazily): the domain packages compute, these modules draw."""
