"""The combination of the sources of bias shared by the full and the linearised model-error checks
(:func:`suspid.workflows.trust.combine_sources`): known answers."""

import numpy as np
import pytest
from scipy.stats import norm

from suspid.method.identifiability import bias_aware_half_width
from suspid.workflows.trust import BiasSources, combine_sources, model_spread, transfer_term

LEVEL_2SIGMA = 2 * norm.cdf(2.0) - 1  # 0.9545


@pytest.mark.parametrize("rho, expected", [(0.0, np.hypot(0.03, 0.04)), (1.0, 0.07), (-1.0, 0.01),
                                           (0.5, np.sqrt(0.03 ** 2 + 0.04 ** 2 + 0.03 * 0.04))])
def test_two_correlated_model_parameters_move_w_opt_with_their_correlation(rho, expected):
    # G: +0.3 and +0.2 of the interval per unit of t; Σ_t: standard deviations 0.1 and 0.2, correlation rho
    G = np.array([[0.3, 0.2], [0.3, -0.2]])
    cov = np.array([[0.01, rho * 0.02], [rho * 0.02, 0.04]])
    spread = model_spread(G, cov)
    assert spread[0] == pytest.approx(expected, abs=1e-12)
    # the second component feels the second parameter the other way: the correlation then cancels
    assert spread[1] == pytest.approx(np.sqrt(0.03 ** 2 + 0.04 ** 2 - 0.03 * 0.04 * 2 * rho), abs=1e-12)


def test_a_flat_component_does_not_count():
    assert model_spread(np.array([[np.nan, 1.0]]), np.diag([1.0, 0.0]))[0] == 0.0


def _sources(sc, gh, shift, spread, residual=0.0):
    return BiasSources(*(np.atleast_1d(np.asarray(v, float)) for v in (sc, gh, shift, spread, residual)))


def test_corrected_the_model_shift_is_the_correction_and_the_rest_adds_in_quadrature():
    sd = np.array([0.01, 0.02])
    src = _sources([0.03, -0.01], [0.04, 0.0], [0.05, -0.02], [0.0, 0.0], [0.0, 0.01])
    bound, correction = combine_sources(sd, src, True, 2.0)
    assert np.allclose(correction, [0.05, -0.02])
    # no spread: the bound is the self-check and the groups in quadrature (3-4-5), plus the residual
    assert np.allclose(bound, [0.05, 0.01 + 0.01], atol=1e-9)


def test_uncorrected_every_source_is_a_worst_case():
    sd = np.array([0.01])
    bound, correction = combine_sources(sd, _sources(-0.03, 0.04, -0.05, 0.0), False, 2.0)
    assert correction is None and bound[0] == pytest.approx(0.03 + 0.04 + 0.05, abs=1e-9)


def test_the_model_spread_adds_to_the_sampling_spread_in_quadrature():
    # without sampling spread the bound is the interval itself: 2 sigma of the model spread (3-4-5 over 2 sources)
    G, cov = np.array([[0.3, 0.2]]), np.diag([0.01, 0.04])
    src = _sources(0.0, 0.0, 0.0, model_spread(G, cov))
    bound, _ = combine_sources(np.zeros(1), src, True, 2.0)
    assert bound[0] == pytest.approx(2 * 0.05, rel=1e-9)
    # with it, the interval is that of sqrt(sd² + spread²)
    sd = np.array([0.012])
    bound, _ = combine_sources(sd, src, True, 2.0)
    assert bias_aware_half_width(sd, bound, 2.0)[0] == pytest.approx(2 * np.hypot(0.012, 0.05), rel=1e-6)


def test_the_combined_interval_holds_its_level_when_the_sources_are_what_they_claim():
    """Monte Carlo over draws of the model parameters (correlated, 0.6) and the sampling: the corrected estimate's
    bias-aware interval holds the truth at its nominal level, for a fixed bias of the self-check within its bound."""
    rng = np.random.default_rng(3)
    G = np.array([[0.25, -0.15]])
    cov = np.array([[0.04, 0.6 * 0.2 * 0.1], [0.6 * 0.2 * 0.1, 0.01]])
    sd, sc = np.array([0.015]), np.array([0.02])
    bound, _ = combine_sources(sd, _sources(sc, 0.0, 0.0, model_spread(G, cov)), True, 2.0)
    half = bias_aware_half_width(sd, bound, 2.0)[0]
    n = 200_000
    dt = rng.multivariate_normal(np.zeros(2), cov, size=n)
    for b in (-sc[0], 0.0, sc[0]):                        # the self-check's bias, sign unknown
        err = b + (dt @ G.T)[:, 0] + sd[0] * rng.standard_normal(n)
        cover = np.mean(np.abs(err) <= half)
        assert cover >= LEVEL_2SIGMA - 0.005, (b, cover)
    # ... and not wastefully wide: at the bound's end the level is met, not exceeded by much
    err = sc[0] + (dt @ G.T)[:, 0] + sd[0] * rng.standard_normal(n)
    assert np.mean(np.abs(err) <= half) == pytest.approx(LEVEL_2SIGMA, abs=0.005)


def test_the_ends_give_the_slope_and_the_searches_scatter():
    from suspid.workflows.nuisance import sensitivity_of_ends

    lo, hi = np.array([-0.5, -0.2]), np.array([0.5, 0.6])
    # component 0: linear in both parameters (slopes 0.1 and -0.05); component 1: both ends of the first move
    # the same way by 0.02 (a search's scatter), the second linear
    s_lo = np.array([[-0.05, 0.02], [0.01, 0.0]])
    s_hi = np.array([[0.05, 0.02], [-0.03, 0.0]])
    G, noise = sensitivity_of_ends(lo, hi, s_lo, s_hi)
    assert np.allclose(G[0], [0.1, -0.05]) and noise[0] == pytest.approx(0.0, abs=1e-12)
    assert np.allclose(G[1], [0.0, 0.0])
    assert noise[1] == pytest.approx(np.sqrt((0.02 ** 2 + 0.02 ** 2) / 2), rel=1e-9)   # two degrees of freedom


def test_the_calibrated_shifts_transfer_error_is_one_more_source_in_quadrature():
    # self-check 0.03 and groups 0.04 (3-4-5), shift 0.24 with transfer_error 0.25: 0.06; no spread, no residual
    src = _sources([0.03], [0.04], [-0.24], [0.0])
    bound, correction = combine_sources(np.zeros(1), src, True, 2.0, transfer_error=0.25)
    assert correction[0] == pytest.approx(-0.24)              # the correction itself is unchanged
    assert bound[0] == pytest.approx(np.sqrt(0.05 ** 2 + 0.06 ** 2), abs=1e-9)
    assert transfer_term(src, 0.25)[0] == pytest.approx(0.06)
    assert transfer_term(src, 0.25, correct=False)[0] == 0.0
    # 0 takes the shift as exact (the rule before), and the uncorrected worst case does not count it twice
    assert combine_sources(np.zeros(1), src, True, 2.0, transfer_error=0.0)[0][0] == pytest.approx(0.05, abs=1e-9)
    assert combine_sources(np.zeros(1), src, False, 2.0, transfer_error=0.25)[0][0] == pytest.approx(
        0.03 + 0.04 + 0.24, abs=1e-9)


def test_a_shift_that_misses_its_w_dependence_is_covered_at_the_level():
    """Monte Carlo: the calibrated model's shift s is right at w0 and wrong at w_opt by e, |e| <= ρ |s| (sign
    unknown): with transfer_error ρ the corrected estimate's interval holds the truth at its level; without it,
    not (the same draws)."""
    rng = np.random.default_rng(5)
    sd, s, rho = np.array([0.01]), -0.05, 0.25
    n = 200_000
    for e in (-rho * abs(s), rho * abs(s)):
        err = e + sd[0] * rng.standard_normal(n)            # the corrected estimate's error
        with_ = bias_aware_half_width(sd, combine_sources(sd, _sources(0.0, 0.0, s, 0.0), True, 2.0,
                                                          transfer_error=rho)[0], 2.0)[0]
        without = bias_aware_half_width(sd, combine_sources(sd, _sources(0.0, 0.0, s, 0.0), True, 2.0)[0], 2.0)[0]
        assert np.mean(np.abs(err) <= with_) >= LEVEL_2SIGMA - 0.005
        assert np.mean(np.abs(err) <= without) < 0.9


def test_the_calibrated_shift_averages_over_distinct_path_draws_the_first_the_checks_own():
    from suspid.workflows.linearised import correction_draws
    draws = correction_draws(8)
    assert draws[0] == "nuisance" and len(set(draws)) == 8
    assert correction_draws(1) == ["nuisance"]
