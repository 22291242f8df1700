"""The compiled log-KDE kernel against the numpy reference and a direct log-sum-exp, to 1e-12."""

import math

import numpy as np
import pytest

import suspid.method.kde as kde
from suspid.plugins.objectives.likelihood import LikelihoodObjective

numba = pytest.importorskip("numba")

RTOL = 1e-12


def direct_log_kde(points, centres, h):
    """log p by a plain loop: largest exponent out, exact sum (math.fsum) of the rest, per point."""
    out = np.empty(points.shape)
    n = centres.shape[1]
    for r in range(points.shape[0]):
        for i, x in enumerate(points[r]):
            u = [((x - c) / h[r]) ** 2 / 2.0 for c in centres[r]]
            low = min(u)
            out[r, i] = -low + math.log(math.fsum(math.exp(low - v) for v in u)) \
                - math.log(n * math.sqrt(2.0 * math.pi) * h[r])
    return out


def assert_close(actual, expected):
    """Relative 1e-12 (and 1e-12 absolute where log p passes through 0), nothing NaN or infinite."""
    assert np.isfinite(actual).all()
    np.testing.assert_allclose(actual, expected, rtol=RTOL, atol=RTOL)


def cases():
    """(name, points, centres, h): ordinary data and the extreme ones."""
    rng = np.random.default_rng(11)
    out = []
    points, centres = rng.normal(0.5, 3.0, (40, 37)), rng.normal(0.0, 2.8, (40, 100))
    out.append(("ordinary, m not a multiple of 8", points, centres, kde.bandwidths(centres, "silverman", 1e-3)))
    points, centres = rng.normal(-60.0, 3.0, (30, 100)), rng.normal(-60.0, 2.8, (30, 100))
    out.append(("benchmark shape, levels far from 0 dB", points, centres,
                kde.bandwidths(centres, "silverman", 1e-3)))
    points, centres = rng.normal(0.0, 1.0, (6, 9)), rng.normal(0.0, 1.0, (6, 15))
    h = kde.bandwidths(centres, "silverman", 1e-3)
    points[0, 1] = 40.0                     # ~60 h from every centre: plain exp sum < 1e-250
    points[1, 3] = 1.0e4                    # far beyond the numpy path's 100 √2 h
    points[2, :] = -3.0e3                   # a whole row of far points
    centres[3, 0], points[3, 0] = 5.0e3, 5.0e3 + 0.3 * h[3]  # far outlier centre with a point next to it
    points[4, 2] = centres[4].max() + 33.0 * h[4]  # plain sum ~1e-237: just before the switch at 1e-250
    points[4, 3] = centres[4].min() - 34.5 * h[4]  # just past it: shifted sum
    out.append(("far outliers: underflow and shifted log-sum-exp", points, centres, h))
    centres = np.full((3, 12), 2.0)
    points = np.array([[2.0] * 5, [2.0, 2.0005, 1.999, 2.01, 2.0], [1.0, 3.0, 2.0, 2.0, 2.0]])
    out.append(("identical centres, h at its 1e-3 floor", points, centres,
                kde.bandwidths(centres, "silverman", 1e-3)))
    points = np.full((4, 20), -7.25)
    centres = rng.normal(-7.0, 1.0, (4, 20))
    centres[:, :10] = -7.25
    out.append(("identical points, half the centres on them", points, centres,
                kde.bandwidths(centres, "silverman", 1e-3)))
    centres = rng.normal(0.0, 2.0, (50, 2))
    points = rng.normal(0.0, 2.0, (50, 1))
    out.append(("v = 1 measured point, 2 centres", points, centres, kde.bandwidths(centres, "scott", 1e-3)))
    centres = rng.normal(0.0, 2.0, (5, 1))
    out.append(("one centre", rng.normal(0.0, 2.0, (5, 3)), centres, np.full(5, 0.8)))
    points, centres = rng.normal(0.0, 1.0, (4, 64)), rng.normal(0.0, 1.0, (4, 30))
    out.append(("bandwidths from 1e-3 to 1e3", points, centres, np.array([1e-3, 0.05, 30.0, 1e3])))
    return out


@pytest.mark.parametrize("name, points, centres, h", cases(), ids=[c[0] for c in cases()])
def test_kernel_equals_numpy_reference_and_direct_sum(name, points, centres, h):
    fused = kde.log_kde(points, centres, h, method="numba")
    assert_close(fused, kde.log_kde(points, centres, h, method="numpy"))
    assert_close(fused, direct_log_kde(points, centres, h))


def test_kernel_on_a_benchmark_sized_block():
    """8 channels × 50 frequencies, v = 100: every log p and every per-row sum within 1e-12."""
    rng = np.random.default_rng(12)
    points = rng.normal(0.5, 3.0, (400, 100))
    centres = rng.normal(0.0, 2.8, (400, 100)) + rng.normal(0.0, 1.0, (400, 100))
    h = kde.bandwidths(centres, "silverman", 1e-3)
    fused = kde.log_kde(points, centres, h, method="numba")
    reference = kde.log_kde(points, centres, h, method="numpy")
    assert_close(fused, reference)
    np.testing.assert_allclose(fused.sum(axis=1), reference.sum(axis=1), rtol=RTOL)


def test_inline_exp_is_within_two_ulp_of_the_correctly_rounded_value():
    @numba.njit
    def exp_neg_all(u):
        out = np.empty_like(u)
        for i in range(u.size):
            out[i] = kde._exp_neg(u[i])
        return out

    rng = np.random.default_rng(13)
    u = np.concatenate([rng.uniform(0.0, 1.0, 100_000), rng.uniform(0.0, 708.0, 100_000),
                        np.exp(rng.uniform(-40.0, math.log(708.0), 100_000)), np.arange(0.0, 708.0, 0.5),
                        np.arange(1, 1022) * math.log(2.0) / 2.0, [0.0, 5e-324, 1e-300, 708.0]])
    got = exp_neg_all(u)
    want = np.array([math.exp(-v) for v in u])
    ulp = np.spacing(want)
    assert np.max(np.abs(got - want) / ulp) <= 2.0
    assert exp_neg_all(np.array([0.0]))[0] == 1.0
    clamped = exp_neg_all(np.array([708.5, 745.2, 1e6, 1e300, np.inf]))
    assert np.all(clamped == got[-1])              # u clamped at 708
    assert got[-1] == pytest.approx(math.exp(-708.0), rel=1e-15)  # a normal double, negligible next to 1e-250


def test_likelihood_psi_is_the_same_with_either_kernel():
    rng = np.random.default_rng(14)
    freqs = np.linspace(0.5, 20.0, 40)
    y_mes = rng.normal(-20.0, 3.0, (100, 3, freqs.size))
    y_mod = rng.normal(-20.5, 2.8, (100, 3, freqs.size))
    y_mes[3, 1, 7] = 60.0                   # one far measured point
    fused = LikelihoodObjective().psi(y_mes, y_mod, freqs)
    reference = LikelihoodObjective(kernel="numpy").psi(y_mes, y_mod, freqs)
    np.testing.assert_allclose(fused, reference, rtol=RTOL)


def test_without_numba_auto_falls_back_to_numpy(monkeypatch):
    rng = np.random.default_rng(15)
    points, centres = rng.normal(size=(3, 5)), rng.normal(size=(3, 6))
    h = kde.bandwidths(centres, "silverman", 1e-3)
    monkeypatch.setattr(kde, "HAVE_NUMBA", False)
    np.testing.assert_array_equal(kde.log_kde(points, centres, h), kde.log_kde_numpy(points, centres, h))
    with pytest.raises(ValueError, match="needs the numba package"):
        kde.log_kde(points, centres, h, method="numba")
    with pytest.raises(ValueError, match="'auto', 'numba' or 'numpy'"):
        kde.log_kde(points, centres, h, method="scipy")


def test_kernel_checks_shapes_and_accepts_no_points():
    """The compiled loops do not check bounds, so the wrapper does."""
    rng = np.random.default_rng(16)
    points, centres, h = rng.normal(size=(3, 5)), rng.normal(size=(3, 6)), np.ones(3)
    for bad in ((points, centres[:2], h), (points, centres, h[:2]), (points[0], centres, h),
                (points, centres[:, :0], h)):
        with pytest.raises(ValueError, match="log_kde needs points"):
            kde.log_kde(*bad, method="numba")
    assert kde.log_kde(points[:, :0], centres, h, method="numba").shape == (3, 0)
