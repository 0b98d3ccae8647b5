"""Output languages. Each is one folder here (see :mod:`derive.codegen.backends.base` for the
contract) plus one line in :data:`REGISTRY`; generation renders every registered backend, in
this order, into ``generated/<robot>/<name>/``."""

from __future__ import annotations

import importlib

from derive.codegen.backends.base import Backend

REGISTRY: dict[str, str] = {
    "c": "derive.codegen.backends.c",
    "python": "derive.codegen.backends.python",
    "jax": "derive.codegen.backends.jax",
}
"""Backend name -> the module whose ``BACKEND`` implements it."""


def backends() -> list[Backend]:
    """The registered backends, in registry order."""
    return [importlib.import_module(module).BACKEND for module in REGISTRY.values()]
