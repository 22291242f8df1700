"""Built-in effects: the catalogue of what rigid-body models miss (``docs/diagnose.md``, "The catalogue").

Each class declares one effect: its parameters with units and bounds, its
signature (channels, band, speed dependence) and what a diagnosis fits. The
simulators implement them (the exudyn model: :mod:`suspid.plugins.simulators.exudyn_train.effects`).

| name | shows in | band | speed | main parameter |
| --- | --- | --- | --- | --- |
| ``carbody-bending`` | carbody vertical, strongest mid-car | 5-20 Hz | none | ``frequency_hz`` |
| ``wheel-polygon`` | axlebox, bogie vertical | k v / (π D) | ∝ v | ``order`` |
| ``yaw-damper-series-stiffness`` | bogie and carbody lateral | hunting family | kinematic | ``stiffness_n_per_m`` |
| ``sensor-tilt`` | lateral channels | any | none | ``angle_deg`` |
| ``conicity-change`` | bogie and carbody lateral | Klingel family | kinematic | ``conicity`` |
| ``track-flexibility`` | axlebox, bogie vertical | P2 resonance 30-120 Hz | none | ``frequency_hz`` |
"""

from suspid import hookimpl

from .catalogue import (CarbodyBending, ConicityChange, SensorTilt, TrackFlexibility, WheelPolygon,
                        YawDamperSeriesStiffness, beam_mode_shape, klingel_hz)

EFFECTS = (CarbodyBending, WheelPolygon, YawDamperSeriesStiffness, SensorTilt, ConicityChange, TrackFlexibility)
"""Every built-in effect class."""

__all__ = ["EFFECTS", "CarbodyBending", "ConicityChange", "SensorTilt", "TrackFlexibility", "WheelPolygon",
           "YawDamperSeriesStiffness", "beam_mode_shape", "klingel_hz"]


@hookimpl
def suspid_register_effects(register):
    """Register the built-in effects of :data:`EFFECTS`."""
    for cls in EFFECTS:
        register(cls)
