"""On top: the lecture's kinematic toolkit (rotations, Grübler's DOF, workspace, singularities, manipulability, A* planning). Computes; figures are in :mod:`derive.plot`."""
