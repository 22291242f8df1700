"""The statistics of suspid.method.localisation with known answers: the smooth-gain basis the calibration
profiles out, and the cluster-robust standard deviation that carries model-form misfit into the interval."""

from __future__ import annotations

import math

import numpy as np

from suspid.method.calibration import octave_clusters
from suspid.method.localisation import (cluster_sd, consistent_channels, fit_column, smooth_gain_basis,
                                        without_smooth_gains)

FREQS = np.geomspace(0.5, 16.0, 120)        # 5 octaves


def test_smooth_gain_basis_is_a_partition_of_unity_with_knots_every_so_many_octaves():
    B = smooth_gain_basis(FREQS, 1.0)
    assert B.shape == (120, 5 + 3)                                  # 5 one-octave intervals, cubic: 8 B-splines
    assert np.allclose(B.sum(axis=1), 1.0) and (B >= 0).all()      # a flat gain is in the span
    assert smooth_gain_basis(FREQS, 2.0).shape[1] == 3 + 3


def test_without_smooth_gains_removes_a_smooth_gain_and_keeps_a_resonance():
    rng = np.random.default_rng(0)
    x = np.log2(FREQS)
    smooth = 1.5 * np.sin(2 * np.pi * x / 5.0) + 0.7          # a gain varying over several octaves, dB
    r = FREQS / 4.0                                             # a resonance at 4 Hz whose damping drops 20 %:
    level = lambda zeta: 10 * np.log10(1.0 / ((1 - r ** 2) ** 2 + (2 * zeta * r) ** 2))  # noqa: E731
    feature = level(0.08) - level(0.1)                          # a peak a fraction of an octave wide
    weights = np.ones((2, FREQS.size)) * rng.uniform(0.5, 2.0, (2, FREQS.size))
    B = smooth_gain_basis(FREQS, 1.0)
    out = without_smooth_gains(np.stack([smooth, smooth + feature]), weights, B)
    assert np.abs(out[0]).max() < 0.05 * np.abs(smooth).max()      # the smooth gain is (nearly) all removed
    kept = np.sum(out[1] * feature) / np.sum(feature * feature)
    # what a gain cannot mimic is left for the model parameters: a third of a damping change with one-octave
    # knots, more with wider ones (a gain and a resonance's change are confounded at the scale of the knots)
    wider = without_smooth_gains(feature[None], weights[:1], smooth_gain_basis(FREQS, 2.0))[0]
    assert 0.25 < kept < np.sum(wider * feature) / np.sum(feature * feature) < 1.0
    # trailing axes (a Jacobian's parameters) are stripped column by column
    both = without_smooth_gains(np.stack([smooth, feature], axis=-1)[None], weights[:1], B)
    assert np.allclose(both[0, :, 0], without_smooth_gains(smooth[None], weights[:1], B)[0])
    assert np.allclose(both[0, :, 1], without_smooth_gains(feature[None], weights[:1], B)[0])


def test_cluster_sd_is_the_channels_disagreement_when_each_channel_is_one_cluster():
    """With one cluster per channel, var θ = Σ_k (I_k / I)² (θ_k − θ)²: θ_k each channel's own estimate, I_k its
    information, θ and I the pooled ones (the closed form of the cluster-robust sandwich)."""
    rng = np.random.default_rng(1)
    K, n = 4, 60
    column = rng.normal(size=(K, n))
    var = rng.uniform(0.5, 2.0, (K, n))
    slopes = np.array([-0.7, -0.6, -0.2, -0.5])                  # the channels see the change differently
    delta = column * slopes[:, None] + 0.05 * rng.normal(size=(K, n))
    theta, _, _ = fit_column(column, delta, var)
    e = delta - column * theta
    info = np.sum(column ** 2 / var, axis=1)
    own = np.array([fit_column(column[k], delta[k], var[k])[0] for k in range(K)])
    expected = math.sqrt(np.sum((info / info.sum()) ** 2 * (own - theta) ** 2))
    one_per_channel = np.repeat(np.arange(K)[:, None], n, axis=1)
    assert math.isclose(cluster_sd(column, var, e, one_per_channel), expected, rel_tol=1e-10)
    # channels that agree leave only their noise: far below the disagreeing channels' figure
    agree = column * -0.5 + 0.05 * rng.normal(size=(K, n))
    t2, sd2, _ = fit_column(column, agree, var)
    assert cluster_sd(column, var, agree - column * t2, one_per_channel) < 0.2 * expected
    # octave bands within channels are finer clusters
    clusters = octave_clusters(np.geomspace(0.5, 16.0, n), K, 1.0)
    assert clusters.max() + 1 == K * 6 and cluster_sd(column, var, e, clusters) > 0


def test_consistent_channels_drops_the_discordant_channels_one_at_a_time():
    sd = np.array([0.03, 0.02, 0.03, 0.02, 0.05, np.inf, 0.04])
    agree = np.array([-0.70, -0.68, -0.66, -0.69, -0.72, 3.0, -0.67])       # the 6th channel sees nothing
    assert consistent_channels(agree, sd).all()
    two_off = agree.copy()
    two_off[[1, 3]] = [-0.10, -0.25]              # two channels whose model responds otherwise than the vehicle
    keep = consistent_channels(two_off, sd)
    assert keep.tolist() == [True, False, True, False, True, True, True]
    # never fewer than three seen channels: with no majority nothing more is dropped
    assert consistent_channels(np.array([-0.7, -0.1, -0.4]), np.array([0.01, 0.01, 0.01])).all()
