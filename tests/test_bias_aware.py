"""Bias-aware intervals: known answers for the widening of the intervals by the model-error bound."""

import numpy as np
import pytest
from scipy.stats import norm

from suspid.method.identifiability import bias_aware_half_width, bias_bound_for_half_width

LEVEL_2SIGMA = 2 * norm.cdf(2.0) - 1  # 0.9545


def test_without_bias_the_interval_is_the_sampling_one():
    sd = np.array([0.01, 0.03, 0.2])
    assert np.allclose(bias_aware_half_width(sd, np.zeros(3), 2.0), 2.0 * sd, rtol=1e-9)
    assert np.allclose(bias_aware_half_width(sd, np.zeros(3), 1.0), sd, rtol=1e-9)


def test_without_sampling_spread_the_interval_is_the_bias_bound():
    assert np.allclose(bias_aware_half_width(np.zeros(2), np.array([0.04, 0.0]), 2.0), [0.04, 0.0])


def test_a_dominant_bias_adds_the_one_sided_quantile():
    # |N(t, 1)| with t = 30: the lower tail is empty, so c = t + Φ⁻¹(level)
    chi = bias_aware_half_width(np.array([0.001]), np.array([0.03]), 2.0)[0]
    assert chi == pytest.approx(0.03 + 0.001 * norm.ppf(LEVEL_2SIGMA), rel=1e-6)


@pytest.mark.parametrize("t", [0.0, 0.5, 1.0, 2.0, 5.0])
def test_the_level_holds_for_every_bias_within_the_bound(t):
    sd, bound = 0.02, t * 0.02
    chi = bias_aware_half_width(np.array([sd]), np.array([bound]), 2.0)[0]
    for b in np.linspace(-bound, bound, 7):  # closed form of P(|b + sd Z| <= chi)
        cover = norm.cdf((chi - b) / sd) - norm.cdf((-chi - b) / sd)
        assert cover >= LEVEL_2SIGMA - 1e-9
    # ... exactly at the bound (the shortest such interval), and shorter than adding the bound to 2 sd
    assert norm.cdf((chi - bound) / sd) - norm.cdf((-chi - bound) / sd) == pytest.approx(LEVEL_2SIGMA, abs=1e-9)
    assert chi <= bound + 2 * sd + 1e-12


def test_the_bias_bound_for_a_half_width_inverts_it():
    """Known answers: B(χ(σ, B)) = B; a half-width the unbiased interval reaches already needs no bias (the lower
    end of the bracket); without sampling spread the bound is the half-width itself."""
    for s, b in ((0.02, 0.01), (0.05, 0.3), (0.001, 0.05)):
        chi = bias_aware_half_width(np.array([s]), np.array([b]), 2.0)[0]
        assert bias_bound_for_half_width(s, chi, 2.0) == pytest.approx(b, abs=1e-9)
    unbiased = bias_aware_half_width(np.array([0.02]), np.array([0.0]), 2.0)[0]
    assert unbiased == pytest.approx(0.04, rel=1e-9)
    assert bias_bound_for_half_width(0.02, unbiased, 2.0) == 0.0
    assert bias_bound_for_half_width(0.02, 0.03, 2.0) == 0.0            # 2 σ = 0.04 > 0.03
    assert bias_bound_for_half_width(0.02, 0.03, 2.0, lower=0.01) == 0.01
    assert bias_bound_for_half_width(0.0, 0.07, 2.0) == 0.07


def test_quadrature_would_not_hold_the_level():
    # the former rule: sqrt((2 sd)² + B²); with B = 2 sd it holds the truth 79.7 % of the time, not 95.4 %
    sd, bound = 1.0, 2.0
    chi_quad = np.hypot(2 * sd, bound)
    assert norm.cdf(chi_quad - bound) - norm.cdf(-chi_quad - bound) == pytest.approx(0.797, abs=1e-3)
    chi = bias_aware_half_width(np.array([sd]), np.array([bound]), 2.0)[0]
    assert chi > chi_quad


def test_a_component_too_uncertain_under_model_error_is_not_trustworthy():
    from suspid.workflows.analysis import imprecise

    trust = {"trustworthy": {"a": True, "b": True, "c": True}, "reasons": {},
             "bias_bound": np.array([0.01, 0.06, 0.2])}
    sd = np.array([0.01, 0.02, 0.05])
    half = bias_aware_half_width(sd, trust["bias_bound"], 2.0)   # 0.027, 0.094, 0.28
    imprecise(trust, ["a", "b", "c"], np.array([True, True, False]), half, 2 * sd, 0.08)
    assert trust["trustworthy"] == {"a": True, "b": False, "c": True}  # c: not identifiable, flagged already
    assert list(trust["reasons"]) == ["b"] and "± 9.4 %" in trust["reasons"]["b"][0]


def test_reference_weights_down_weight_the_channels_the_model_misses():
    from suspid.method.noise import fit_noise_model
    from suspid.method.objective import reference_weights

    rng = np.random.default_rng(1)
    y_sim0 = rng.normal(0, 1, (40, 3, 50))
    offset = np.array([0.0, 2.0, 0.0])[None, :, None]          # channel 1: the model 2 dB off
    spread = np.array([0.5, 0.5, 1.5])[None, :, None]          # channel 2: 1.5 dB of scatter
    noise = fit_noise_model(y_sim0 + offset + spread * rng.normal(0, 1, y_sim0.shape), y_sim0)
    alpha = reference_weights(noise)
    error = np.array([0.25, 4.25, 2.25])                       # μ² + σ² per channel, dB²
    assert alpha.sum() == pytest.approx(1.0)
    assert alpha == pytest.approx((1 / error) / (1 / error).sum(), rel=0.15)


def test_weights_given_as_an_array_are_still_weights():
    from suspid.method.objective import validate_weights

    assert validate_weights(np.array([1.0, 1.0, 2.0]), ["a", "b", "c"]) == pytest.approx([0.25, 0.25, 0.5])
    assert validate_weights("reference", ["a", "b"]) == pytest.approx([0.5, 0.5])  # replaced from B later


def test_trust_is_yes_only_when_every_required_check_ran_and_none_flags():
    """Three states: a flag from a check that ran is a no; no flag is a yes only when the self-check, the
    adequacy test and the data groups all ran, else not assessed with the checks that did not run."""
    from suspid.workflows.analysis import trust_states

    done = {"self_check": "done", "adequacy": "done", "groups": "done"}
    t = trust_states(["a", "b"], [["groups disagree"], []], done)
    assert t["trustworthy"] == {"a": False, "b": True} and t["not_assessed"] == {}
    assert t["reasons"] == {"a": ["groups disagree"]}
    partial = done | {"self_check": "not run: the reference date's data are not part of this run"}
    t = trust_states(["a", "b"], [["groups disagree"], []], partial)
    assert t["trustworthy"] == {"a": False, "b": None}
    assert t["not_assessed"] == {"b": ["reference-date self-check not run: the reference date's data are not "
                                       "part of this run"]}
    t = trust_states(["a"], [[]], {"self_check": "done", "adequacy": "done"})   # the groups never reported
    assert t["trustworthy"] == {"a": None} and "data groups" in t["not_assessed"]["a"][0]
