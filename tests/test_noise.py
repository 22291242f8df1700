"""Noise model B (paper §2.3, eq. 3): known Gaussian processes give back their mean and covariance."""

import json

import numpy as np
import pytest

from suspid.errors import ConfigError, DataError
from suspid.method.noise import FORMAT_VERSION, NoiseModel, fit_noise_model, noise_samples

N_CH, N_F = 2, 12
FREQS = np.linspace(0.5, 20.0, N_F)


def known_process():
    """Mean (dB) and covariance (dB²) of a GP over (channel, ω): SE in log f, channels correlated."""
    mean = np.vstack([2.0 * np.sin(FREQS / 3), -1.0 + 0.05 * FREQS])
    lf = np.log(FREQS)
    k_f = np.exp(-0.5 * ((lf[:, None] - lf[None, :]) / 0.6) ** 2)
    k_ch = np.array([[1.5 ** 2, 0.6 * 1.5 * 0.8], [0.6 * 1.5 * 0.8, 0.8 ** 2]])
    cov = np.kron(k_ch, k_f) + 0.05 * np.eye(N_CH * N_F)
    return mean, cov


def draw(n, seed):
    mean, cov = known_process()
    z = np.random.default_rng(seed).multivariate_normal(mean.ravel(), cov, size=n)
    return z.reshape(n, N_CH, N_F)


def test_noise_samples_is_eq3_difference():
    rng = np.random.default_rng(0)
    y_mes, y_sim = rng.normal(size=(2, 5, 3, 4))
    np.testing.assert_array_equal(noise_samples(y_mes, y_sim), y_mes - y_sim)
    with pytest.raises(DataError, match="same shape"):
        noise_samples(y_mes, y_sim[:4])


def test_fit_recovers_mean_and_covariance_of_a_known_gp_within_sampling_error():
    mean, cov = known_process()
    v0 = 4000
    model = NoiseModel(variance_fraction=1.0).fit(draw(v0, 1), freqs=FREQS, channels=["cz", "by"])
    sd = np.sqrt(np.diag(cov))
    assert np.max(np.abs(model.mean_.ravel() - mean.ravel()) / (sd / np.sqrt(v0))) < 4.5
    c = model.covariance()
    stderr = np.sqrt((np.outer(np.diag(cov), np.diag(cov)) + cov ** 2) / v0)  # sd of a sample covariance
    assert np.max(np.abs(c - cov) / stderr) < 5.0
    # with every component kept and no shrinkage the model covariance is the sample covariance
    b = draw(v0, 1).reshape(v0, -1)
    np.testing.assert_allclose(c, np.cov(b, rowvar=False), rtol=1e-9, atol=1e-12)


def test_samples_follow_the_fitted_model_and_depend_only_on_the_seed():
    model = NoiseModel(n_components=5, shrinkage=0.2).fit(draw(300, 2))
    paths = model.sample(20000, seed=7)
    assert paths.shape == (20000, N_CH, N_F)
    c = model.covariance()
    sd = np.sqrt(np.diag(c))
    flat = paths.reshape(20000, -1)
    assert np.max(np.abs(flat.mean(axis=0) - model.mean_.ravel()) / (sd / np.sqrt(20000))) < 4.5
    stderr = np.sqrt((np.outer(np.diag(c), np.diag(c)) + c ** 2) / 20000)
    assert np.max(np.abs(np.cov(flat, rowvar=False) - c) / stderr) < 5.0
    np.testing.assert_array_equal(model.sample(4, seed=7), model.sample(4, seed=7))
    assert not np.array_equal(model.sample(4, seed=7), model.sample(4, seed=8))


def test_truncation_keeps_the_marginal_variances_and_the_leading_eigenpairs():
    b = draw(60, 3)
    sample_cov = np.cov(b.reshape(60, -1), rowvar=False)
    model = NoiseModel(n_components=3).fit(b)
    c = model.covariance()
    np.testing.assert_allclose(np.diag(c), np.diag(sample_cov), rtol=1e-10)
    lam, vec = np.linalg.eigh(sample_cov)
    best = (vec[:, -3:] * lam[-3:]) @ vec[:, -3:].T  # best rank-3 approximation
    off = ~np.eye(c.shape[0], dtype=bool)
    np.testing.assert_allclose(c[off], best[off], atol=1e-10)
    np.testing.assert_allclose(model.eigenvalues_, lam[::-1][:3], rtol=1e-10)


def test_variance_fraction_keeps_the_fewest_components_that_reach_it():
    b = draw(80, 4)
    lam = np.linalg.eigvalsh(np.cov(b.reshape(80, -1), rowvar=False))[::-1]
    expected = int(np.argmax(np.cumsum(lam) / lam.sum() >= 0.9)) + 1
    model = NoiseModel(variance_fraction=0.9).fit(b)
    assert model.components_.shape == (expected, N_CH * N_F)
    assert model.explained_variance_ratio_.sum() >= 0.9 > model.explained_variance_ratio_[:-1].sum()
    np.testing.assert_allclose(model.components_ @ model.components_.T, np.eye(expected), atol=1e-10)


def test_fixed_shrinkage_scales_the_correlations_only():
    b = draw(50, 5)
    sample_cov = np.cov(b.reshape(50, -1), rowvar=False)
    c = NoiseModel(variance_fraction=1.0, shrinkage=0.3).fit(b).covariance()
    off = ~np.eye(c.shape[0], dtype=bool)
    np.testing.assert_allclose(c[off], 0.7 * sample_cov[off], atol=1e-10)
    np.testing.assert_allclose(np.diag(c), np.diag(sample_cov), rtol=1e-10)


def test_auto_shrinkage_matches_a_direct_schafer_strimmer_computation():
    b = draw(40, 6).reshape(40, -1)
    v = b.shape[0]
    x = (b - b.mean(axis=0)) / b.std(axis=0, ddof=1)
    w = x[:, :, None] * x[:, None, :]                # (v, D, D)
    w_bar = w.mean(axis=0)
    var_r = v / (v - 1) ** 3 * ((w - w_bar) ** 2).sum(axis=0)
    r = v / (v - 1) * w_bar
    off = ~np.eye(r.shape[0], dtype=bool)
    expected = np.clip(var_r[off].sum() / (r[off] ** 2).sum(), 0, 1)
    model = NoiseModel(shrinkage="auto").fit(b.reshape(40, N_CH, N_F))
    assert model.shrinkage_ == pytest.approx(expected, rel=1e-9)
    iid = np.random.default_rng(0).normal(size=(40, N_CH, N_F))  # no correlation to keep
    assert NoiseModel(shrinkage="auto").fit(iid).shrinkage_ > 0.9


def test_save_and_load_round_trip(tmp_path):
    model = NoiseModel(n_components=4, shrinkage=0.1).fit(draw(50, 8), freqs=FREQS, channels=["cz", "by"])
    path = model.save(tmp_path / "noise.npz")
    again = NoiseModel.load(path)
    for name in ("mean_", "components_", "eigenvalues_", "variance_", "residual_variance_", "freqs_"):
        np.testing.assert_array_equal(getattr(again, name), getattr(model, name))
    assert again.channels_ == ("cz", "by") and again.shrinkage_ == 0.1 and again.n_samples_ == 50
    np.testing.assert_array_equal(again.sample(3, seed=1), model.sample(3, seed=1))
    again.check_grid(FREQS, ["cz", "by"])
    with pytest.raises(DataError, match="other frequencies"):
        again.check_grid(FREQS * 1.01)
    with pytest.raises(DataError, match="channels"):
        again.check_grid(channels=["cz", "bz"])


def test_bad_files_are_clear_errors(tmp_path):
    model = NoiseModel().fit(draw(20, 9))
    with pytest.raises(DataError, match="not found"):
        NoiseModel.load(tmp_path / "missing.npz")
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"this is not a zip file")
    with pytest.raises(DataError, match="junk.npz is not a readable"):
        NoiseModel.load(junk)
    good = model.save(tmp_path / "good.npz")
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(good.read_bytes()[:200])
    with pytest.raises(DataError, match="truncated.npz"):
        NoiseModel.load(truncated)
    other = tmp_path / "other.npz"
    np.savez(other, x=np.zeros(3))
    with pytest.raises(DataError, match="not a suspid noise model"):
        NoiseModel.load(other)
    with np.load(good) as data:
        content = dict(data)
    meta = json.loads(str(content["meta"]))
    meta["format_version"] = FORMAT_VERSION + 1
    newer = tmp_path / "newer.npz"
    np.savez(newer, **{**content, "meta": np.array(json.dumps(meta))})
    with pytest.raises(DataError, match="format version"):
        NoiseModel.load(newer)
    broken = tmp_path / "broken.npz"
    np.savez(broken, **{**content, "components": content["components"][:, :5]})
    with pytest.raises(DataError, match=r"broken.npz: array 'components' declares shape \(11, 5\) float64 \(440 B\), "
                                        r"expected shape \(11, 24\)"):
        NoiseModel.load(broken)     # refused on its declared shape, before it is read


def test_invalid_inputs():
    with pytest.raises(ConfigError, match="noise.shrinkage"):
        NoiseModel(shrinkage=1.5).fit(draw(10, 0))
    with pytest.raises(DataError, match="v0 >= 2"):
        NoiseModel().fit(draw(1, 0))
    with pytest.raises(DataError, match="not fitted"):
        NoiseModel().sample(2, seed=0)
    y = draw(10, 0)
    model = fit_noise_model(y + 1.0, y, {"n_components": 2})
    np.testing.assert_allclose(model.mean_, 1.0)
    assert model.sample(3, seed=0) == pytest.approx(np.ones((3, N_CH, N_F)))  # zero variance: b = 1 dB


def test_speed_groups_keep_a_mean_per_speed_and_the_covariance_about_it(tmp_path):
    """Reference paths at 200 and 300 km/h whose means differ by 1.5 dB: a mean per speed, the within-group
    variance (not inflated by the speeds' difference), saved and loaded; another speed takes the pooled mean."""
    v200, v300 = 200 / 3.6, 300 / 3.6
    b = draw(80, 11)
    b[:40] += 1.5
    speeds = [v200] * 40 + [v300 * 1.01] * 20 + [v300] * 20        # 1 % apart: one group
    model = NoiseModel().fit(b, freqs=FREQS, speeds=speeds)
    np.testing.assert_allclose(model.speeds_, [v200, v300 * 1.005])
    np.testing.assert_array_equal(model.speed_counts_, [40, 40])
    np.testing.assert_allclose(model.speed_means_, [b[:40].mean(axis=0), b[40:].mean(axis=0)])
    within = np.concatenate([b[:40] - b[:40].mean(axis=0), b[40:] - b[40:].mean(axis=0)])
    np.testing.assert_allclose(model.variance_, (within ** 2).sum(axis=0) / (80 - 2))
    assert np.mean(model.variance_) < 0.8 * np.mean(NoiseModel().fit(b).variance_)   # pooled: + (1.5/2)² dB²
    np.testing.assert_allclose(model.mean_for([v300, v200, 250 / 3.6]),
                               [model.speed_means_[1], model.speed_means_[0], b.mean(axis=0)])
    np.testing.assert_array_equal(model.reference_counts([v300, 250 / 3.6]), [40, 80])
    assert [c["covered"] for c in model.speed_coverage([v200, 250 / 3.6])] == [True, False]
    again = NoiseModel.load(model.save(tmp_path / "noise.npz"))
    np.testing.assert_array_equal(again.speed_means_, model.speed_means_)
    np.testing.assert_array_equal(again.sample(4, 3, [v200, v300, v200, v300]),
                                  model.sample(4, 3, [v200, v300, v200, v300]))
    pooled = NoiseModel(by_speed=False).fit(b, speeds=speeds)
    assert pooled.speeds_ is None and np.allclose(pooled.mean_for([v200]), b.mean(axis=0))


def test_one_reference_speed_changes_nothing_but_records_it(tmp_path):
    b = draw(30, 12)
    plain = NoiseModel().fit(b)
    one = NoiseModel().fit(b, speeds=[300 / 3.6] * 30)
    for name in ("mean_", "components_", "eigenvalues_", "variance_", "residual_variance_"):
        np.testing.assert_array_equal(getattr(one, name), getattr(plain, name))
    np.testing.assert_array_equal(one.sample(5, 7, [300 / 3.6] * 5), plain.sample(5, 7))
    assert one.speed_coverage([200 / 3.6]) == [{"speed_kmh": 200.0, "mean": "pooled", "reference_segments": 30,
                                                "covered": False}]
    assert json.loads(str(np.load(plain.save(tmp_path / "plain.npz"))["meta"]))["format_version"] == 1


def _edited(tmp_path, meta=None, **arrays):
    """A saved model with its header entries ``meta`` (None: removed) and arrays replaced."""
    good = NoiseModel().fit(draw(20, 9)).save(tmp_path / "good.npz")
    with np.load(good) as data:
        content = dict(data)
    header = json.loads(str(content["meta"]))
    for key, value in (meta or {}).items():
        node, *path = key.split(".")
        target = header if not path else header[node]
        name = path[-1] if path else node
        if value is None:
            del target[name]
        else:
            target[name] = value
    path = tmp_path / "edited.npz"
    np.savez(path, **{**content, "meta": np.array(json.dumps(header))})
    with np.load(path) as data:
        content = dict(data)
    for name, edit in arrays.items():
        content[name] = edit(content[name])
    np.savez(path, **content)
    return path


# a damaged noise model file: (edit, words of the one-line DataError that names the file)
DAMAGED_NOISE_MODELS = {
    "header_without_shrinkage": (dict(meta={"shrinkage": None}), "damaged header (KeyError: 'shrinkage')"),
    "shrinkage_is_text": (dict(meta={"shrinkage": "auto?"}), "damaged header (ValueError"),
    "shrinkage_is_a_list": (dict(meta={"shrinkage": [0.1]}), "damaged header (TypeError"),
    "n_samples_is_null": (dict(meta={"n_samples": "many"}), "damaged header (ValueError"),
    "channels_is_a_number": (dict(meta={"channels": 7}), "damaged header (TypeError"),
    "n_components_zero": (dict(meta={"options.n_components": 0}), "damaged header at 'options.n_components'"),
    "options_not_a_mapping": (dict(meta={"options": [1, 2]}), "damaged header at 'options'"),
    "negative_residual_variance": (dict(residual_variance=lambda a: -a), "negative variance"),
    "negative_eigenvalues": (dict(eigenvalues=lambda a: -a), "negative variance"),
}


@pytest.mark.parametrize("name", sorted(DAMAGED_NOISE_MODELS))
def test_a_damaged_noise_model_is_a_data_error_naming_the_file(tmp_path, name):
    """Each was a KeyError, TypeError or ValueError (exit 1, "a bug"), a ConfigError naming a key of no config,
    or NaN in Y_mod later on (negative variances)."""
    edit, words = DAMAGED_NOISE_MODELS[name]
    path = _edited(tmp_path, **edit)
    with pytest.raises(DataError) as err:
        NoiseModel.load(path)
    msg = str(err.value)
    assert msg.startswith(f"noise model file {path} ") and words in msg and "\n" not in msg, msg
