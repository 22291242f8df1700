"""The objective function J(w) = Σ_k α_k Ψ_k(w) (paper §3.1, eq. 5), with common random numbers.

For a parameter w the simulator gives v spectra y_sim_i(w), one per track
segment; the modelled samples are y_mod_i(w) = y_sim_i(w) + b_i with noise
paths b_i drawn from the noise model B (§2.3), and an :class:`~suspid.interfaces.Objective`
plugin compares them with the measured samples y_mes_i channel by channel
(Ψ_k, eq. 6 or 7). Within one run the paths b_i are drawn **once**, from the
run's seed, and reused for every w (common random numbers): J is then a
deterministic function of w, which the Kriging metamodel of §3.2 needs, and
differences J(w) - J(w') are not blurred by fresh noise.

Weights α_k (eq. 5) are non-negative and sum to 1; by default 1/n as in §3.3.
"""

from __future__ import annotations

from collections import abc
from functools import cached_property
from typing import Mapping, Sequence

import numpy as np

from suspid.errors import ConfigError, DataError
from suspid.interfaces import Objective
from suspid.method.floor import NoiseFloor
from suspid.method.noise import NoiseModel, modelled_spectra


def reference_weights(noise_model: NoiseModel) -> np.ndarray:
    """α_k of eq. 5 from the reference date: ``(n_channels,)`` ∝ 1 / mean over ω of (μ_B² + σ_B²), sum 1.

    B = y_mes - y_sim(w0) at the reference date (eq. 3) measures, per channel, how far the model is from
    the vehicle where the truth is known: a channel the model misses by a lot (large mean μ_B or
    spread σ_B, in dB) is down-weighted, in the spirit of inverse-variance weighting.
    """
    error = np.mean(noise_model.mean_ ** 2 + noise_model.variance_, axis=1)        # (n_channels,) dB²
    alpha = 1.0 / np.maximum(error, 1e-12)
    return alpha / alpha.sum()


def validate_weights(weights: Sequence[float] | Mapping[str, float] | None, channels: Sequence[str],
                     key: str = "objective.weights") -> np.ndarray:
    """The weights α_k of eq. 5 as ``(n_channels,)``, normalised to sum to 1.

    :param weights: ``None`` (equal weights 1/n), a list in channel order, or a
        mapping channel name -> weight (channels not named get 0).
    :param channels: the channel names, in the order of the spectra.
    :param key: the config key named in errors.
    :raises ConfigError: wrong length, unknown channel names, negative or
        non-finite weights, or weights that are all zero.
    """
    channels = [str(c) for c in channels]
    n = len(channels)
    if n == 0:
        raise ConfigError("there are no channels to weight", key=key)
    if weights is None or (isinstance(weights, str) and weights in ("reference", "efficient")):  # set at the reference date
        return np.full(n, 1.0 / n)
    if isinstance(weights, abc.Mapping):
        unknown = [str(name) for name in weights if str(name) not in channels]
        if unknown:
            raise ConfigError(f"unknown channel(s) {', '.join(unknown)}; channels are: {', '.join(channels)}",
                              key=key)
        values = [weights.get(name, 0.0) for name in channels]
    elif isinstance(weights, (str, bytes)) or not isinstance(weights, (abc.Sequence, np.ndarray)):
        raise ConfigError(f"expected a list of {n} weights or a mapping channel -> weight, "
                          f"got {type(weights).__name__}", key=key)
    else:
        values = list(weights)
        if len(values) != n:
            raise ConfigError(f"{len(values)} weights given for {n} channels ({', '.join(channels)})", key=key)
    try:
        alpha = np.array(values, dtype=float)
    except (TypeError, ValueError):
        raise ConfigError(f"weights must be numbers, got {values!r}", key=key) from None
    if not np.all(np.isfinite(alpha)) or np.any(alpha < 0):
        raise ConfigError(f"weights must be finite and non-negative, got {values!r}", key=key)
    total = alpha.sum()
    if total <= 0:
        raise ConfigError("weights are all zero; at least one channel needs a positive weight", key=key)
    return alpha / total


class ObjectiveFunction:
    """J(w) of eq. 5 for one run: measured spectra, fixed noise paths, an objective plugin, weights.

    :param objective: an :class:`~suspid.interfaces.Objective` instance (Ψ_k).
    :param y_mes: ``(v_mes, n_channels, n_freqs)`` measured spectra in dB.
    :param freqs: ``(n_freqs,)`` Hz.
    :param noise_paths: ``(v, n_channels, n_freqs)`` dB, the paths b_i, fixed
        for the run; v is the number of simulated spectra per evaluation. Or
        ``(K, v, n_channels, n_freqs)``: K independent draws of them, J and Ψ then the means over the
        draws of each draw's J and Ψ (the share of J's scatter the draw makes divided by K).
    :param weights: α_k as accepted by :func:`validate_weights` (default 1/n).
    :param channels: channel names, needed when ``weights`` is a mapping.
    :param floor: the noise model's sensor-noise floor, or None (y_mod = y_sim + b_i, eq. 4);
        with one, y_mod follows :func:`~suspid.method.noise.modelled_spectra`.

    The constructor stores; :meth:`evaluate` validates and computes. Build it
    from a noise model with :meth:`from_noise_model`.
    """

    def __init__(self, objective: Objective, y_mes: np.ndarray, freqs: np.ndarray, noise_paths: np.ndarray,
                 weights: Sequence[float] | Mapping[str, float] | None = None,
                 channels: Sequence[str] | None = None, floor: NoiseFloor | None = None) -> None:
        self.objective = objective
        self.floor = floor
        self.y_mes = y_mes
        self.freqs = freqs
        self.noise_paths = noise_paths
        self.weights = weights
        self.channels = channels

    @classmethod
    def from_noise_model(cls, objective: Objective, y_mes: np.ndarray, freqs: np.ndarray,
                         noise_model: NoiseModel, seed: int | np.random.Generator,
                         n_paths: int | None = None,
                         weights: Sequence[float] | Mapping[str, float] | None = None,
                         channels: Sequence[str] | None = None,
                         speeds: Sequence[float] | None = None) -> "ObjectiveFunction":
        """Draw the run's noise paths b_i once from ``noise_model`` with ``seed`` (common random numbers).

        :param n_paths: v, the number of simulated spectra per evaluation;
            default: as many as measured spectra (one per segment).
        :param speeds: ``(v,)`` m/s, the segments' speeds: each path takes μ_B at its speed.
        :raises DataError: the noise model belongs to another grid or other channels.
        """
        y_mes = np.asarray(y_mes, dtype=float)
        if y_mes.ndim != 3:
            raise DataError(f"y_mes must be (n_samples, n_channels, n_freqs), got shape {y_mes.shape}")
        noise_model.check_grid(freqs, channels)
        if noise_model.shape != y_mes.shape[1:]:
            raise DataError(f"the noise model is on a {noise_model.shape} (channels, frequencies) grid, "
                            f"the measured spectra on {y_mes.shape[1:]}")
        paths = noise_model.sample(y_mes.shape[0] if n_paths is None else n_paths, seed, speeds)
        return cls(objective, y_mes, freqs, paths, weights=weights, channels=channels, floor=noise_model.floor_)

    @cached_property
    def alpha(self) -> np.ndarray:
        """α_k ``(n_channels,)``, normalised to sum to 1 (eq. 5)."""
        n_ch = np.shape(self.y_mes)[1]
        channels = self.channels if self.channels is not None else [f"channel {k}" for k in range(n_ch)]
        if len(channels) != n_ch:
            raise DataError(f"{len(channels)} channel names for spectra with {n_ch} channels")
        if isinstance(self.weights, abc.Mapping) and self.channels is None:
            raise ConfigError("weights given by channel name need the channel names", key="objective.weights")
        return validate_weights(self.weights, channels)

    @cached_property
    def noise_variance(self) -> np.ndarray:
        """``(n_channels, n_freqs)`` dB²: the sample variance of the noise paths b_i (ddof = 1), the
        noise model's variance as this run draws it; passed to objectives with ``uses_noise_variance``."""
        paths = np.asarray(self.noise_paths, dtype=float)
        if paths.ndim == 4:                # several draws: each is a sample of B, pooled
            paths = paths.reshape(-1, *paths.shape[2:])
        if paths.shape[0] < 2:
            raise DataError(f"objective '{getattr(self.objective, 'name', '?')}' needs the noise variance, "
                            f"which takes at least 2 noise paths; got {paths.shape[0]}")
        return paths.var(axis=0, ddof=1)

    def evaluate(self, y_sim: np.ndarray) -> tuple[float, np.ndarray]:
        """J and Ψ for simulated spectra (eq. 5).

        :param y_sim: ``(v, n_channels, n_freqs)`` dB, y_sim_i(w) for the segments in order.
        :returns: ``(J, psi)`` with J a float and psi ``(n_channels,)``.
        :raises DataError: ``y_sim`` does not match the noise paths.
        """
        y_sim = np.asarray(y_sim, dtype=float)
        paths = np.asarray(self.noise_paths)
        draws = paths if paths.ndim == 4 else paths[None]
        if y_sim.shape != draws.shape[1:]:
            raise DataError(f"simulated spectra have shape {y_sim.shape}; this objective function holds "
                            f"noise paths of shape {draws.shape[1:]} (v, n_channels, n_freqs)")
        wants_variance = getattr(self.objective, "uses_noise_variance", False)
        extra = {"noise_variance": self.noise_variance} if wants_variance else {}
        psi = np.zeros(self.alpha.shape)
        for b in draws:
            y_mod = modelled_spectra(y_sim, b, self.floor)
            psi_b = np.asarray(self.objective.psi(self.y_mes, y_mod, self.freqs, **extra), dtype=float)
            if psi_b.shape != self.alpha.shape:
                raise DataError(f"objective '{getattr(self.objective, 'name', '?')}' returned psi of shape "
                                f"{psi_b.shape}, expected {self.alpha.shape}")
            psi += psi_b
        psi /= len(draws)
        return float(self.alpha @ psi), psi

    __call__ = evaluate
