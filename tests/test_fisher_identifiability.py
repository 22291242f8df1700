"""Identifiability from the Jacobian's Fisher information (what a gradient-based run's analysis reports)."""

from __future__ import annotations

import sys

import numpy as np
import pytest

import suspid
from conftest import TEMPLATE_SRC
from suspid import hookimpl, registry
from suspid.method.floor import NoiseFloor
from suspid.method.jacobian import fisher_identifiability, fisher_information
from suspid.method.noise import NoiseModel


def _noise_model(seed: int = 0) -> NoiseModel:
    rng = np.random.default_rng(seed)
    # paths with a smooth gain shared by every frequency of a segment (correlated) and white scatter
    b = 0.5 * rng.standard_normal((400, 3, 20)) + rng.standard_normal((400, 1, 1)) * np.linspace(0.5, 2.0, 20)
    return NoiseModel().fit(b)


def test_fisher_information_is_that_of_the_dense_covariance():
    model = _noise_model()
    rng = np.random.default_rng(1)
    jac, y = rng.standard_normal((5, 3, 20, 4)), rng.standard_normal((5, 3, 20))
    inv = np.linalg.inv(model.covariance())
    dense = sum(g.T @ inv @ g for g in jac.reshape(5, -1, 4))
    np.testing.assert_allclose(fisher_information(y, jac, model, rel_floor=0.0), dense, rtol=1e-9,
                               atol=1e-9 * np.abs(dense).max())
    # a parameter that moves the spectra as the shared gain does: 60 readings of each segment count as about one
    # (the gain's coefficient has unit variance: 5 segments give an information near 5), not as 60 independent
    along = np.broadcast_to(np.linspace(0.5, 2.0, 20), (5, 3, 20))[..., None]
    independent = np.sum(along[..., 0] ** 2 / model.variance_[None])
    assert 2.0 < fisher_information(y, along, model)[0, 0] < 12.0 < 0.2 * independent
    # a sensor floor 40 dB above the spectra: the modelled spectra do not move, no information is left
    model.floor_ = NoiseFloor(power=np.full((3, 20), 10.0 ** (40 / 5)), gain_db=np.zeros((3, 20)))
    assert fisher_information(y, jac, model).max() < 1e-6 * np.abs(dense).max()


def test_fisher_identifiability_known_answers():
    names = ["strong", "none", "twin_a", "twin_b"]
    rng = np.random.default_rng(2)
    a, b = rng.standard_normal(400), rng.standard_normal(400)
    G = np.stack([3 * a, np.zeros(400), b, b + 1e-9 * a], axis=1)       # unit noise: F = Gᵀ G
    verdict = fisher_identifiability(G.T @ G, names, n_sigmas=2.0, max_width=0.5)
    assert verdict.identifiable.tolist() == [True, False, False, False]
    np.testing.assert_allclose(verdict.sd_alone[0], 1 / (3 * np.linalg.norm(a)), rtol=1e-12)
    assert "no influence on the spectra" in verdict.reasons[1][0] and np.isinf(verdict.sd_alone[1])
    assert "flat direction" in verdict.reasons[2][0] and "twin_b" in verdict.reasons[2][0]
    assert verdict.partner[2][0] == "twin_b" and verdict.partner[2][1] < -0.99


def _register_seat_car():
    """The template's quarter car declaring one more parameter, a seat mass its two channels do not see."""
    sys.path.insert(0, str(TEMPLATE_SRC))
    try:
        from suspid_quartercar import QuarterCar
    finally:
        sys.path.remove(str(TEMPLATE_SRC))
    from suspid.interfaces import Parameter

    class SeatQuarterCar(QuarterCar):
        name = "quarter-car-seat"

        def parameters(self):
            return super().parameters() + [Parameter("m_seat", "kg", 80.0, 50.0, 120.0, "a seat, not sensed")]

        def simulate(self, w, segments):
            return super().simulate({k: v for k, v in w.items() if k != "m_seat"}, segments)

    class Plugin:
        @hookimpl
        def suspid_register_simulators(self, register):
            register(SeatQuarterCar)

    registry.add_plugin(Plugin(), "quarter-car-seat")


@pytest.mark.slow
def test_after_gauss_newton_a_parameter_without_influence_is_not_identifiable(tmp_path):
    """A whole gauss-newton run (finite-difference Jacobians of the template's quarter car): the seat mass
    moves no channel and is flagged, the two suspension rates are identified (the metamodel's Sobol indices on
    the run's 10 points are no basis for it: with other sizes of this run they put the seat mass's total
    index at 0.99, or a suspension rate's below the 'no influence' threshold)."""
    _register_seat_car()
    cfg = {"name": "seat", "seed": 3,
           "simulator": {"plugin": "quarter-car-seat", "options": {"fs_hz": 100.0}},
           "parameters": {"k_secondary": {}, "c_secondary": {}, "m_seat": {}},
           "data": {"track": {"n_segments": 8, "length_m": 800.0},
                    "w_ref": {"k_secondary": 0.5e6, "c_secondary": 20e3, "m_seat": 60.0}},
           "spectra": {"f_min_hz": 0.5, "f_max_hz": 20.0, "n_freqs": 60},
           "optimizer": {"plugin": "gauss-newton"}, "identifiability": {"n_redraws": 6},
           "output": {"dir": str(tmp_path / "run")}}
    r = suspid.identify(cfg).to_dict()
    assert r["identifiability_method"]["kind"] == "fisher"
    assert r["identifiable"] == {"k_secondary": True, "c_secondary": True, "m_seat": False}
    assert "no influence on the spectra" in r["non_identifiable_reasons"]["m_seat"][0]
    assert r["identifiability_method"]["sd_alone_percent"]["k_secondary"] < 5.0
    assert r["errors_percent"]["k_secondary"] < 5.0
