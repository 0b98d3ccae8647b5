"""On top: running the generated code from Python (the compiled C behind a Python API).

``derive.compiled(robot)`` (:mod:`derive.runtime.loader`) builds a robot's generated C into a
cached shared library (:mod:`derive.runtime.build`) and calls it through ctypes, one state or a
whole batch per call; ``derive.compiled(robot, device="cuda")`` builds the same C as CUDA batch
kernels (:mod:`derive.runtime.cuda`) and runs them on device arrays
(:mod:`derive.runtime.cuda_arrays`). ``derive.generated(robot)`` (:mod:`derive.runtime.python`)
imports its generated Python instead (no compiler needed).
"""

from derive.runtime.loader import compiled
from derive.runtime.python import generated

__all__ = ["compiled", "generated"]
