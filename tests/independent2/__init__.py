"""A second independent vehicle model ("real train") that writes measured-data files for suspid.

Time-domain, nonlinear, one parameter per suspension element; written apart
from suspid's ``exudyn-train`` and from ``tests/independent`` (numpy, scipy,
numba). See :mod:`.vehicle` (the model), :mod:`.kernel` (its compiled
equations and integrator), :mod:`.measure` (track, integration, measurement
chain, files) and :mod:`.protocol` (configs for suspid).
"""

from .measure import Instrument, RecordingCar, generate_date, generate_two_dates, simulate_segments
from .vehicle import CHANNELS, ELEMENTS, KINDS, OWN, build, eigenfrequencies, parameters

__all__ = ["CHANNELS", "ELEMENTS", "Instrument", "KINDS", "OWN", "RecordingCar", "build", "eigenfrequencies",
           "generate_date", "generate_two_dates", "parameters", "simulate_segments"]
