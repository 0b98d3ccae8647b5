"""On top: solvers on the derived model (inverse kinematics, trajectory optimisation, simulation of the generated dynamics)."""
