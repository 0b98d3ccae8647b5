"""derive: symbolic derivation and code generation for robot manipulators.

The names below are imported on first use (PEP 562), so that ``import derive`` and the command
line start without sympy and CasADi (``derive --version`` in 0.3 s instead of 1.7 s of CPU); each
command imports what it needs.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

__all__ = ["load", "compiled", "generated", "SymbolicModel", "SXModel", "ModelError", "Robot", "load_models", "load_robot"]
__version__ = "0.1.0"

_WHERE = {
    "load_models": "derive.description.model", "load_robot": "derive.description.model",
    "ModelError": "derive.description.robot", "Robot": "derive.description.robot",
    "SymbolicModel": "derive.inspect.sympy_model", "load": "derive.inspect.sympy_model",
    "compiled": "derive.runtime", "generated": "derive.runtime",
    "SXModel": "derive.symbolic.model",
}

if TYPE_CHECKING:  # for type checkers and editors: the names as if imported here
    from derive.description.model import load_models, load_robot
    from derive.description.robot import ModelError, Robot
    from derive.inspect.sympy_model import SymbolicModel, load
    from derive.runtime import compiled, generated
    from derive.symbolic.model import SXModel


def __getattr__(name: str):
    if name not in _WHERE:
        raise AttributeError(f"module 'derive' has no attribute {name!r}")
    value = getattr(importlib.import_module(_WHERE[name]), name)
    globals()[name] = value  # once: later lookups find it without this function
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
