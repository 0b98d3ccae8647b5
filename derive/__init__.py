"""derive: symbolic derivation and code generation for robot manipulators."""

from derive.description.model import load_models, load_robot
from derive.description.robot import ModelError, Robot
from derive.inspect.sympy_model import SymbolicModel, load
from derive.runtime import compiled, generated
from derive.symbolic.model import SXModel

__all__ = ["load", "compiled", "generated", "SymbolicModel", "SXModel", "ModelError", "Robot", "load_models", "load_robot"]
__version__ = "0.1.0"
