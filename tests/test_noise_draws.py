"""J averaged over several draws of the noise paths (``objective.noise_draws``).

Known answers: the averaged J and Ψ are the means of the one-draw J and Ψ over the draws; with K draws the
run's first draw is the one-draw run's paths (the paper's J is unchanged, and so is its data identity);
a bad K is one line naming the key.
"""

from __future__ import annotations

import numpy as np
import pytest

from suspid import registry
from suspid.config import load_config
from suspid.errors import ConfigError
from suspid.infra.ledger import Ledger
from suspid.method.objective import ObjectiveFunction
from suspid.workflows.evaluation import j_of_spectra
from suspid.workflows.problem import build_problem


def _small(seed: int = 3, **objective) -> dict:
    return {"name": "draws", "seed": seed,
            "simulator": {"plugin": "exudyn-train", "options": {"solver": "frequency", "fs_hz": 50.0}},
            "parameters": {"k_sec_z": {}, "c_sec_z": {}},
            "data": {"track": {"n_segments": 4, "length_m": 500.0}, "w_ref": {"k_sec_z": 380.0e3}},
            "spectra": {"f_min_hz": 0.5, "f_max_hz": 10.0, "n_freqs": 30},
            "objective": {"plugin": "overlap", **objective}}


@pytest.mark.parametrize("plugin", ["overlap", "likelihood"])
def test_the_average_over_draws_is_the_mean_of_each_draws_j(plugin):
    rng = np.random.default_rng(0)
    v, n_ch, n_f, K = 8, 2, 12, 3
    y_mes = rng.normal(size=(v, n_ch, n_f))
    y_sim = rng.normal(size=(v, n_ch, n_f))
    paths = rng.normal(scale=0.5, size=(K, v, n_ch, n_f))
    freqs = np.linspace(1.0, 5.0, n_f)
    objective = registry.get("objective", plugin)()
    one = [ObjectiveFunction(objective, y_mes, freqs, b).evaluate(y_sim) for b in paths]
    J, psi = ObjectiveFunction(objective, y_mes, freqs, paths).evaluate(y_sim)
    assert J == pytest.approx(np.mean([j for j, _ in one]), rel=1e-12)
    np.testing.assert_allclose(psi, np.mean([p for _, p in one], axis=0), rtol=1e-12)
    # a single draw given as (1, v, ...) is the one-draw J
    assert ObjectiveFunction(objective, y_mes, freqs, paths[:1]).evaluate(y_sim)[0] == pytest.approx(one[0][0])


def test_noise_variance_pools_the_draws():
    rng = np.random.default_rng(1)
    paths = rng.normal(size=(4, 5, 2, 3))
    fn = ObjectiveFunction(registry.get("objective", "overlap")(), paths[0], np.arange(1.0, 4.0), paths)
    np.testing.assert_allclose(fn.noise_variance, paths.reshape(20, 2, 3).var(axis=0, ddof=1))


def test_k_draws_keep_the_first_draw_and_average_j(tmp_path):
    one = build_problem(load_config(_small()), Ledger(tmp_path / "one.sqlite"))
    three = build_problem(load_config(_small(noise_draws=3)), Ledger(tmp_path / "three.sqlite"))
    assert one.b_more is None and one.noise_paths is one.b
    np.testing.assert_array_equal(three.b, one.b)                 # the paper's draw is the first
    np.testing.assert_array_equal(three.y_mes, one.y_mes)
    assert three.b_more.shape == (2, *one.b.shape)
    assert not np.allclose(three.b_more[0], three.b) and not np.allclose(three.b_more[0], three.b_more[1])
    assert three.data_identity != one.data_identity
    y = one.y_mes - 1.0                                           # any spectra of the right shape
    expected = np.mean([j_of_spectra(one, y, b=b)[0] for b in three.noise_paths])
    assert j_of_spectra(three, y)[0] == pytest.approx(expected, rel=1e-12)
    assert j_of_spectra(one, y)[0] == pytest.approx(j_of_spectra(one, y, b=one.b)[0], rel=1e-12)


@pytest.mark.parametrize("bad", [0, 65, "many"])
def test_a_bad_number_of_draws_is_refused_naming_the_key(bad):
    with pytest.raises(ConfigError, match="noise_draws"):
        load_config(_small(noise_draws=bad))
