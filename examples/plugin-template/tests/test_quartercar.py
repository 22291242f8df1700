"""Run suspid's conformance kit on the plugin, and one physics check."""

import numpy as np

from suspid.testing import check_simulator
from suspid_quartercar import QuarterCar


def test_conformance():
    check_simulator(QuarterCar)


def test_body_resonance_near_closed_form():
    sim = QuarterCar()
    f = np.linspace(0.2, 5, 2000)
    h = np.abs(sim.frequency_response({}, 2 * np.pi * f)[0])
    # sprung mass on the two springs in series: f = sqrt(k_eq / m) / (2 pi)
    k_eq = 1 / (1 / 0.4e6 + 1 / 1.2e6)
    f0 = np.sqrt(k_eq / 10_000) / (2 * np.pi)
    assert abs(f[np.argmax(h / (2 * np.pi * f) ** 2)] - f0) / f0 < 0.05
