"""The paper's §2 control: constraint elimination -> inverse dynamics -> computed torque.

The readable numpy path (:mod:`.elimination`, :mod:`.inverse_dynamics`, :mod:`.controller`) is the
reference; the compiled kernels beside it (``*_kernels.py``) compute the same numbers and are tested
equal to it. :mod:`.adaptation` holds the expert's adaptive gains on its torques (the knee law, the learned
strength estimator).
"""

from agents.control.controller import STANCE_MODES, ComputedTorqueController, Gains
from agents.control.elimination import ProjectedDynamics, eliminate_constraints
from agents.control.inverse_dynamics import DISTRIBUTIONS, IDResult, InverseDynamics, friction_pyramid
from agents.control.nominal import NominalModel
from agents.control.verify import IDCheck, verify_inverse_dynamics

__all__ = [
    "DISTRIBUTIONS",
    "STANCE_MODES",
    "ComputedTorqueController",
    "Gains",
    "IDCheck",
    "IDResult",
    "InverseDynamics",
    "NominalModel",
    "ProjectedDynamics",
    "eliminate_constraints",
    "friction_pyramid",
    "verify_inverse_dynamics",
]
