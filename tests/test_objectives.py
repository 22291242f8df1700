"""Objectives Ψ_k (eq. 6-8) and J (eq. 5) against independent references."""

import statistics

import numpy as np
import pytest
import yaml
from scipy.stats import gaussian_kde

import suspid.registry as registry
from suspid.config import Config, validate_options
from suspid.errors import ConfigError, DataError
from suspid.method.kde import bandwidths, frequency_mean, log_kde, overlap_coefficient
from suspid.method.noise import NoiseModel
from suspid.method.objective import ObjectiveFunction, validate_weights
from suspid.plugins.objectives.likelihood import LikelihoodObjective
from suspid.plugins.objectives.overlap import OverlapObjective
from suspid.testing import check_objective

FREQS = np.array([0.5, 0.8, 1.5, 4.0, 9.0])  # non-uniform on purpose (Hz)


def scipy_likelihood_psi(y_mes, y_mod, freqs, bw_method):
    """Eq. 6 by a direct loop with scipy.stats.gaussian_kde (the independent reference)."""
    n_ch, n_f = y_mes.shape[1:]
    values = np.empty((n_ch, n_f))
    for k in range(n_ch):
        for j in range(n_f):
            values[k, j] = gaussian_kde(y_mod[:, k, j], bw_method=bw_method).logpdf(y_mes[:, k, j]).sum()
    return np.trapezoid(values, freqs, axis=1) / (freqs[-1] - freqs[0])


def test_registry_finds_both_objectives():
    registry.reset()
    assert registry.get("objective", "likelihood") is LikelihoodObjective
    assert registry.get("objective", "overlap") is OverlapObjective
    assert {"likelihood", "overlap"} <= set(registry.names("objective"))
    rows, failures = registry.plugins()
    assert not [f for f in failures if f.name in ("likelihood", "overlap")]


@pytest.mark.parametrize("name", ["likelihood", "overlap"])
def test_conformance_kit(name):
    check_objective(registry.get("objective", name))


@pytest.mark.parametrize("name, options", [("likelihood", {"bandwidth": "scott"}),
                                           ("overlap", {"bandwidth": 0.5, "grid_size": 512})])
def test_a_yaml_config_selects_and_configures_either(name, options):
    text = yaml.safe_dump({"objective": {"plugin": name, "options": options, "weights": [1, 3]}})
    config = Config.model_validate(yaml.safe_load(text))
    cls = registry.get("objective", config.objective.plugin)
    validated = validate_options(cls, config.objective.options, file="run.yaml", key="objective.options")
    objective = cls(**validated)
    rng = np.random.default_rng(0)
    psi = objective.psi(rng.normal(size=(20, 2, 5)), rng.normal(size=(20, 2, 5)), FREQS)
    assert psi.shape == (2,) and np.all(np.isfinite(psi))
    np.testing.assert_allclose(validate_weights(config.objective.weights, ["a", "b"]), [0.25, 0.75])
    with pytest.raises(ConfigError, match="objective.options.grid_sise"):
        validate_options(cls, {"grid_sise": 3}, file="run.yaml", key="objective.options")


@pytest.mark.parametrize("bw", ["silverman", "scott", 0.4])
def test_likelihood_matches_scipy_gaussian_kde(bw):
    rng = np.random.default_rng(5)
    y_mes = rng.normal(0.0, 2.0, size=(7, 2, FREQS.size))
    y_mod = rng.normal(0.5, 3.0, size=(12, 2, FREQS.size))
    psi = LikelihoodObjective(bandwidth=bw).psi(y_mes, y_mod, FREQS)
    np.testing.assert_allclose(psi, scipy_likelihood_psi(y_mes, y_mod, FREQS, bw), rtol=1e-8)


def test_likelihood_far_points_use_logsumexp_and_stay_exact():
    """A measured point 60 bandwidths from every modelled one underflows exp; far data leave the fast path."""
    rng = np.random.default_rng(6)
    y_mod = rng.normal(0.0, 1.0, size=(15, 1, FREQS.size))
    y_mes = rng.normal(0.0, 1.0, size=(4, 1, FREQS.size))
    y_mes[0, 0, 1] = 40.0          # ~60 h away: exp underflows to 0
    y_mes[1, 0, 3] = 1.0e4         # far beyond 100 √2 h: the whole row is recomputed
    psi = LikelihoodObjective().psi(y_mes, y_mod, FREQS)
    assert np.isfinite(psi).all()
    np.testing.assert_allclose(psi, scipy_likelihood_psi(y_mes, y_mod, FREQS, "silverman"), rtol=1e-8)


def test_log_kde_is_a_gaussian_mixture():
    points = np.array([[-1.0, 0.0, 2.5]])
    centres = np.array([[0.0, 1.0]])
    h = np.array([0.7])
    expected = np.log(0.5 * sum(np.exp(-0.5 * ((points[0] - c) / 0.7) ** 2) / (0.7 * np.sqrt(2 * np.pi))
                                for c in centres[0]))
    np.testing.assert_allclose(log_kde(points, centres, h)[0], expected, rtol=1e-13)


def test_overlap_of_two_normal_samples_against_the_closed_form():
    """n = 5000 each, N(0, 1) vs N(0.8, 1.5²): mean over 10 seeds within 0.01 of Inman-Bradley."""
    exact = statistics.NormalDist(0.0, 1.0).overlap(statistics.NormalDist(0.8, 1.5))
    rng = np.random.default_rng(2026)
    # the 10 seeds as 10 channels of one call
    y_mes = rng.normal(0.0, 1.0, size=(5000, 10, 1))
    y_mod = rng.normal(0.8, 1.5, size=(5000, 10, 1))
    psi = OverlapObjective().psi(y_mes, y_mod, np.array([5.0]))
    assert abs(psi.mean() - exact) < 0.01
    assert 0.004 < psi.std() < 0.02  # the seed-to-seed scatter, about 0.009


def test_overlap_binning_accuracy_against_direct_quadrature():
    """The documented accuracy: |error| < 5e-4 (about 2e-4) for v = 100 and grid_size 256."""
    rng = np.random.default_rng(8)
    a = rng.normal(0.0, 1.0, size=(6, 100))
    b = rng.normal(0.0, 1.0, size=(6, 100)) * rng.uniform(0.5, 2.0, (6, 1)) + rng.uniform(-2, 2, (6, 1))
    h_a, h_b = bandwidths(a, "silverman", 1e-3), bandwidths(b, "silverman", 1e-3)
    got = overlap_coefficient(a, b, h_a, h_b, grid_size=256)
    for r in range(6):
        lo, hi = min(a[r].min(), b[r].min()) - 9, max(a[r].max(), b[r].max()) + 9
        u = np.linspace(lo, hi, 20001)
        p_a = gaussian_kde(a[r], bw_method=h_a[r] / a[r].std(ddof=1))(u)
        p_b = gaussian_kde(b[r], bw_method=h_b[r] / b[r].std(ddof=1))(u)
        assert got[r] == pytest.approx(np.trapezoid(np.minimum(p_a, p_b), u), abs=5e-4)
    assert overlap_coefficient(a, a, h_a, h_a) == pytest.approx(np.ones(6), abs=1e-12)


def test_frequency_integral_is_the_trapezoidal_mean_over_omega():
    rng = np.random.default_rng(9)
    y_mes = rng.normal(size=(30, 2, FREQS.size))
    y_mod = rng.normal(0.3, 1.2, size=(30, 2, FREQS.size))
    for objective in (LikelihoodObjective(), OverlapObjective()):
        per_freq = np.column_stack([objective.psi(y_mes[:, :, [j]], y_mod[:, :, [j]], FREQS[[j]])
                                    for j in range(FREQS.size)])
        expected = np.trapezoid(per_freq, FREQS, axis=1) / (FREQS[-1] - FREQS[0])
        np.testing.assert_allclose(objective.psi(y_mes, y_mod, FREQS), expected, rtol=1e-12)
    assert frequency_mean(np.array([[1.0, 3.0, 7.0]]), np.array([0.0, 1.0, 3.0]))[0] == pytest.approx(4.0)


def test_constant_samples_do_not_give_nan():
    """Zero variance: h is floored at min_bandwidth_db (1e-3 dB)."""
    const = np.full((10, 1, 3), 2.0)
    spread = np.random.default_rng(1).normal(2.0, 1.0, size=(10, 1, 3))
    freqs = np.array([1.0, 2.0, 3.0])
    assert OverlapObjective().psi(const, const, freqs)[0] == pytest.approx(1.0)
    assert 0.0 <= OverlapObjective().psi(spread, const, freqs)[0] < 0.1
    lik = LikelihoodObjective().psi(const, const, freqs)[0]
    assert lik == pytest.approx(10 * -np.log(np.sqrt(2 * np.pi) * 1e-3), rel=1e-12)
    assert np.isfinite(LikelihoodObjective().psi(spread, const, freqs)).all()


def test_bad_inputs_are_clear_errors():
    rng = np.random.default_rng(0)
    y = rng.normal(size=(10, 2, 5))
    with pytest.raises(DataError, match="same channels"):
        OverlapObjective().psi(y, y[:, :1], FREQS)
    with pytest.raises(DataError, match="strictly increasing"):
        LikelihoodObjective().psi(y, y, FREQS[::-1])
    bad = y.copy()
    bad[0, 0, 0] = np.nan
    with pytest.raises(DataError, match="y_mod contains NaN"):
        LikelihoodObjective().psi(y, bad, FREQS)
    with pytest.raises(ConfigError, match="objective.options.grid_size"):
        OverlapObjective(grid_size=8).psi(y, y, FREQS)
    with pytest.raises(ConfigError, match="objective.options.bandwidth"):
        LikelihoodObjective(bandwidth="silvermann").psi(y, y, FREQS)


# -- J (eq. 5) ---------------------------------------------------------------------
def test_weights_default_list_mapping_and_errors():
    channels = ["carbody_z", "carbody_y", "bogie_y"]
    np.testing.assert_allclose(validate_weights(None, channels), [1 / 3] * 3)
    np.testing.assert_allclose(validate_weights([2, 1, 1], channels), [0.5, 0.25, 0.25])
    np.testing.assert_allclose(validate_weights({"bogie_y": 3.0, "carbody_z": 1.0}, channels), [0.25, 0, 0.75])
    for bad, message in (([1, 1], "2 weights given for 3 channels"), ({"bogie_z": 1}, "unknown channel"),
                         ([1, -1, 1], "non-negative"), ([0, 0, 0], "all zero"), ([1, np.nan, 1], "finite"),
                         ("1,1,1", "expected a list")):
        with pytest.raises(ConfigError, match=message):
            validate_weights(bad, channels)


def resonance_db(freqs, f_n, zeta=0.15):
    """10 log10 |H| of a base-excited oscillator (amplitude in the paper's dB)."""
    r = freqs / f_n
    return 10 * np.log10(np.sqrt((1 + (2 * zeta * r) ** 2) / ((1 - r ** 2) ** 2 + (2 * zeta * r) ** 2)))


def synthetic_case(v=100, seed=0):
    """y_sim_i(w) for w = carbody natural frequency (Hz), and a fitted noise model."""
    freqs = np.geomspace(0.3, 20.0, 80)
    rng = np.random.default_rng(seed)
    level = rng.normal(0.0, 1.5, size=(v, 2, 1)) - 10.0 * np.log10(1 + freqs / 3.0)  # track excitation
    b0 = rng.normal(0.0, 1.0, size=(60, 2, freqs.size)) + rng.normal(0.0, 0.7, size=(60, 2, 1))
    noise = NoiseModel(variance_fraction=0.95).fit(b0, freqs=freqs, channels=["cz", "cy"])

    def y_sim(f_n):
        shape = np.stack([resonance_db(freqs, f_n), resonance_db(freqs, 1.6 * f_n, 0.25)])
        return level + shape

    return freqs, noise, y_sim


@pytest.mark.parametrize("name", ["likelihood", "overlap"])
def test_j_is_largest_at_the_true_parameter(name):
    freqs, noise, y_sim = synthetic_case()
    w_true = 1.2
    y_mes = y_sim(w_true) + noise.sample(100, seed=99)  # eq. 10, paths independent of the run's
    j_of = ObjectiveFunction.from_noise_model(registry.get("objective", name)(), y_mes, freqs, noise, seed=1,
                                              channels=["cz", "cy"])
    grid = np.round(np.arange(0.8, 1.65, 0.05), 2)
    values = [j_of(y_sim(w))[0] for w in grid]
    assert grid[int(np.argmax(values))] == pytest.approx(w_true)
    assert values[0] < max(values) and values[-1] < max(values)


def test_j_is_deterministic_with_common_random_numbers():
    freqs, noise, y_sim = synthetic_case(v=40)
    y_mes = y_sim(1.2) + noise.sample(40, seed=5)
    make = lambda seed: ObjectiveFunction.from_noise_model(OverlapObjective(), y_mes, freqs, noise, seed=seed,
                                                           weights={"cz": 3.0, "cy": 1.0}, channels=["cz", "cy"])
    j1, j2, j3 = make(7), make(7), make(8)
    first, psi = j1(y_sim(1.0))
    assert j1(y_sim(1.0))[0] == first            # same run, same w: bit-identical
    assert j2(y_sim(1.0))[0] == first            # same seed, new instance
    assert j3(y_sim(1.0))[0] != first            # another seed draws other paths
    assert first == pytest.approx(0.75 * psi[0] + 0.25 * psi[1], rel=1e-15)
    with pytest.raises(DataError, match="noise paths of shape"):
        j1(y_sim(1.0)[:10])
    with pytest.raises(DataError, match="other frequencies"):
        ObjectiveFunction.from_noise_model(OverlapObjective(), y_mes, freqs * 2, noise, seed=1)
