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

Modes of the default car at 320 km/h (``suspid modes``; all damped, least
damping ratio 0.125): carbody lateral 0.61 Hz, yaw 0.93 Hz, bounce 1.08 Hz,
roll 1.19 Hz, pitch 1.31 Hz (the plausible range for a passenger carbody is
about 0.5-2 Hz); bogie kinematic (hunting) mode 2.9-3.2 Hz, growing with
speed; bogie frame bounce 7.4 Hz, roll 9.8 Hz, pitch 12.5 Hz, lateral
16.0 Hz; wheelset lateral and yaw modes 7-27 Hz (heavily damped by creep);
wheelsets on the Hertzian contact 185-194 Hz.

Default channels (``sensors`` option to change them): carbody vertical and
lateral at floor level (1.2 m above rail) above the front bogie, mid-car and
above the rear bogie; bogie frame vertical and lateral at the frame centre.
"""

from suspid import hookimpl

from .simulator import ContactOptions, ExudynTrain, Options, SensorOptions

__all__ = ["ContactOptions", "ExudynTrain", "Options", "SensorOptions"]


@hookimpl
def suspid_register_simulators(register):
    """Register :class:`ExudynTrain` as ``exudyn-train``."""
    register(ExudynTrain)
