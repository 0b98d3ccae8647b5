"""derive: symbolic derivation and code generation for robot manipulators."""

from .api import SXModel, SymbolicModel, load
from .model import ModelError, Robot, load_models, load_robot

__all__ = ["load", "SymbolicModel", "SXModel", "ModelError", "Robot", "load_models", "load_robot"]
__version__ = "0.1.0"
