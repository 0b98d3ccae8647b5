"""Independent numeric reference (numpy only), fixed or floating base: kinematics, frame accelerations,
RNEA and ABA (with external wrenches), CRBA, Coriolis matrices, energies, COM and centroidal map."""

from derive.reference.rnea import NumericRobot

__all__ = ["NumericRobot"]
