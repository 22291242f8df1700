"""Baseline objectives `mean-spectrum` and `wasserstein` against closed forms and scipy."""

import numpy as np
import pytest
from scipy.stats import wasserstein_distance

import suspid.registry as registry
from suspid.method.objective import ObjectiveFunction
from suspid.plugins.objectives.mean_spectrum import MeanSpectrumObjective
from suspid.plugins.objectives.wasserstein import WassersteinObjective, wasserstein_rows
from suspid.testing import check_objective

FREQS = np.array([0.5, 0.8, 1.5, 4.0, 9.0])  # Hz, non-uniform on purpose


@pytest.mark.parametrize("name, cls", [("mean-spectrum", MeanSpectrumObjective),
                                       ("wasserstein", WassersteinObjective)])
def test_registered_and_conformant(name, cls):
    registry.reset()
    assert registry.get("objective", name) is cls
    check_objective(cls)


def test_identical_samples_give_the_maximum_zero():
    rng = np.random.default_rng(0)
    y = rng.normal(0, 2, (30, 2, FREQS.size))
    for obj in (MeanSpectrumObjective(), WassersteinObjective()):
        np.testing.assert_allclose(obj.psi(y, y[::-1], FREQS), [0.0, 0.0], atol=1e-12)


def test_mean_spectrum_of_a_shift_is_minus_d2_over_the_noise_variance():
    """Through J (eq. 5): y_mes = s + b, y_sim = s + d, the run's paths b: Ψ_k = -d²/σ² with σ² = var(b)."""
    rng = np.random.default_rng(1)
    v, d = 40, 1.5
    s = rng.normal(-40, 5, (v, 2, FREQS.size))
    b = rng.normal(0, 1, (v, 2, FREQS.size)) * np.array([1.0, 3.0])[None, :, None]
    fn = ObjectiveFunction(MeanSpectrumObjective(), s + b, FREQS, b, weights=[0.25, 0.75])
    sigma2 = b.var(axis=0, ddof=1)
    expected = -np.trapezoid(d ** 2 / sigma2, FREQS, axis=1) / (FREQS[-1] - FREQS[0])
    J, psi = fn.evaluate(s + d)
    np.testing.assert_allclose(psi, expected, rtol=1e-12)
    assert J == pytest.approx(0.25 * expected[0] + 0.75 * expected[1], rel=1e-12)
    assert fn.evaluate(s)[0] == pytest.approx(0.0, abs=1e-12)  # the maximum
    # called by hand without a noise variance: weights 1/dB², Ψ = -d²
    np.testing.assert_allclose(MeanSpectrumObjective().psi(s, s + d, FREQS), [-d ** 2] * 2, rtol=1e-12)


def test_wasserstein_rows_match_scipy():
    rng = np.random.default_rng(2)
    for n_x, n_y in [(40, 50), (7, 7), (12, 30), (1, 5)]:
        x = rng.normal(0, 2, (50, n_x))
        y = rng.standard_t(3, (50, n_y)) + 0.7
        y[0, : min(3, n_y)] = x[0, 0]  # ties between the samples
        ref = np.array([wasserstein_distance(a, b) for a, b in zip(x, y)])
        np.testing.assert_allclose(wasserstein_rows(x, y), ref, rtol=0, atol=1e-12)


def test_wasserstein_psi_matches_scipy_and_a_shift_costs_its_size():
    rng = np.random.default_rng(3)
    y_mes, y_mod = rng.normal(0, 2, (25, 2, FREQS.size)), rng.normal(1, 3, (31, 2, FREQS.size))
    per_freq = np.array([[wasserstein_distance(y_mes[:, k, j], y_mod[:, k, j]) for j in range(FREQS.size)]
                         for k in range(2)])
    expected = -np.trapezoid(per_freq, FREQS, axis=1) / (FREQS[-1] - FREQS[0])
    np.testing.assert_allclose(WassersteinObjective().psi(y_mes, y_mod, FREQS), expected, atol=1e-12)
    np.testing.assert_allclose(WassersteinObjective().psi(y_mes, y_mes - 2.5, FREQS), [-2.5, -2.5], rtol=1e-12)


def resonance_db(w: float, freqs: np.ndarray) -> np.ndarray:
    """|H|² in dB of a damped oscillator with natural frequency ``w`` (Hz) and damping ratio 0.1."""
    r = freqs / w
    return -10 * np.log10((1 - r ** 2) ** 2 + (0.2 * r) ** 2)


@pytest.mark.parametrize("cls", [MeanSpectrumObjective, WassersteinObjective])
def test_j_is_largest_at_the_true_parameter(cls):
    """A one-parameter spectrum model with independent measurement noise and run noise paths:
    on a grid of ±20 % in steps of 2 %, J peaks at the true natural frequency."""
    rng = np.random.default_rng(4)
    freqs = np.linspace(0.5, 6.0, 60)
    v, w_true = 60, 2.0
    track = rng.normal(0, 2, (v, 1, 1))  # segment-to-segment level, common to all frequencies
    y_mes = resonance_db(w_true, freqs)[None, None, :] + track + rng.normal(0, 1, (v, 1, freqs.size))
    fn = ObjectiveFunction(cls(), y_mes, freqs, rng.normal(0, 1, (v, 1, freqs.size)))
    grid = w_true * np.linspace(0.8, 1.2, 21)
    J = [fn.evaluate(resonance_db(w, freqs)[None, None, :] + track)[0] for w in grid]
    assert grid[int(np.argmax(J))] == pytest.approx(w_true)
