"""Independent numeric reference (numpy only): kinematics, RNEA, CRBA, ABA, Christoffel C, energies."""

from derive.reference.rnea import NumericRobot

__all__ = ["NumericRobot"]
