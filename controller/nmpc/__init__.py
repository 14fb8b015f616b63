"""The NMPC (paper §III-B): the optimal control problem, its solvers, and the controller
that calls them every control period.

`problem` writes the OCP once (`NmpcConfig`, the paper's Table "NMPC parameters"); `reference`,
`segment_slots`, `slack_reference` and `obstacle` build its parameters; `rti` (SQP and the
real-time iteration), `hpipm_qp` and `ipopt` solve it; `codegen_cache` compiles and caches
the generated C; `controller` is the per-step controller; `bench` a small closed loop to
measure it.
"""

from .controller import METHODS, NmpcController, NmpcStep
from .problem import NmpcConfig

__all__ = ["METHODS", "NmpcConfig", "NmpcController", "NmpcStep"]
