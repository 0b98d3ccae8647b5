"""The tests' Pinocchio model of a derive Robot: :mod:`derive.reference.pinocchio_model` (moved there so that
``derive bench pinocchio-cpp`` can use it too)."""

from derive.reference.pinocchio_model import PinRobot, build_model  # noqa: F401
