"""The ``exudyn-train`` simulator plugin: a high-speed car built with exudyn, and its two solvers.

Model (:mod:`.model`): carbody, two bogie frames and four wheelsets as exudyn
rigid bodies (carbody and bogies free in all six motions, wheelsets lateral,
vertical, roll and yaw), two rail masses under each wheelset on a damped
track support; primary suspension per axlebox and secondary suspension per
side with springs and dampers in three directions, traction rods, Maxwell
yaw dampers (damper in series with a stiffness), lateral dampers, anti-roll
bars; wheel-rail contact with Kalker's linear creep coefficients for the
wheel load and the Hertzian contact ellipse, equivalent conicity,
gravitational stiffness and Hertzian vertical contact; creep saturation and
lateral bump stops as options of the time solver. Lateral accelerometers see
g × roll (option ``gravity_roll``).
Parameters (:mod:`.parameters`): vehicle presets (``vehicle:
conventional-hs``, the default, an ICE3/CRH-class car; ``manchester-coach``;
``tgv-articulated``, three carbodies on Jacobs bogies, built on the layout of
:mod:`.layout`), every value with its source; the default identified set is
q = 7 suspension parameters.
Solvers (:mod:`.solvers`): ``solver: time`` integrates the exudyn system
(generalised-alpha, symbolic user functions, no Python on the hot path);
``solver: frequency`` uses exudyn's linearisation (M, K, D) and a batched
frequency response. Modes (:mod:`.modes`): eigenvalues, damping, dominant
body and motion, stability, linear critical speed and its sweep over
conicity and parameters. Contact (:mod:`.contact`): every coordinate of the
linear model on a track segment, and its creep forces against the friction
limit. The class is :class:`.simulator.ExudynTrain`.

Modes of the default car at 300 km/h (``suspid modes``; all damped): carbody
lower sway 0.53 Hz, bounce 0.81 Hz, yaw 0.82 Hz, upper sway 1.04 Hz, pitch
1.07 Hz; bogie bounce 6.3 Hz, roll 8.9 Hz, pitch 10.8 Hz; wheelset lateral
and yaw modes 17-25 Hz (creep damped); wheelsets on the track support (P2)
60-63 Hz, damping ratio 0.31. Linear critical speed 588 km/h at conicity 0.15
(``ExudynTrain().critical_speed()``, ``stability()``).

Default channels (``sensors`` option to change them): carbody vertical and
lateral at floor level (1.2 m above rail) above the front bogie, mid-car and
above the rear bogie; bogie frame vertical and lateral at the frame centre.
``tgv-articulated`` (14 channels): every carbody mid-car, the middle carbody
also above both its pivots, and the two Jacobs bogie frames
(``carbody_<c>_<place>_<direction>``, ``bogie_<b>_<direction>``).
"""

from suspid import hookimpl

from .simulator import ContactOptions, ExudynTrain, Options, SensorOptions, YawDamperOptions

__all__ = ["ContactOptions", "ExudynTrain", "Options", "SensorOptions", "YawDamperOptions"]


@hookimpl
def suspid_register_simulators(register):
    """Register :class:`ExudynTrain` as ``exudyn-train``."""
    register(ExudynTrain)
