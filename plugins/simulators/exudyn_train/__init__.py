"""The ``exudyn-train`` simulator plugin: a high-speed car built with exudyn, and its two solvers.

Model (:mod:`.model`): carbody, two bogie frames and four wheelsets as exudyn
rigid bodies with lateral, vertical, roll, pitch and yaw motion (31 degrees
of freedom); primary suspension per axlebox and secondary suspension per side
with springs and dampers in three directions, yaw dampers, lateral dampers,
anti-roll bars; wheel-rail contact with linearised Kalker creep, equivalent
conicity, gravitational stiffness and Hertzian vertical contact; creep
saturation and lateral bump stops as options of the time solver.
Parameters (:mod:`.parameters`): every value with its source; the default
identified set is q = 7 suspension parameters.
Solvers (:mod:`.solvers`): ``solver: time`` integrates the exudyn system
(generalised-alpha, symbolic user functions, no Python on the hot path);
``solver: frequency`` uses exudyn's linearisation (M, K, D) and a batched
frequency response. Modes (:mod:`.modes`): eigenvalues, damping, dominant
body and motion, stability. The class is :class:`.simulator.ExudynTrain`.
"""

from suspid import hookimpl

from .simulator import ContactOptions, ExudynTrain, Options, SensorOptions

__all__ = ["ContactOptions", "ExudynTrain", "Options", "SensorOptions"]


@hookimpl
def suspid_register_simulators(register):
    """Register :class:`ExudynTrain` as ``exudyn-train``."""
    register(ExudynTrain)
