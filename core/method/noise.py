"""The additive noise B(ω) of measurement and model uncertainty (paper §2.3, eq. 3).

At the reference date, v0 pairs of measured and simulated spectra give v0
paths of the noise (eq. 3, :func:`noise_samples`)::

    b_i(ω) = y_mes_i(ω) - y_sim_i(ω, w0),   i = 1..v0,   (n_channels, n_freqs) dB each.

B is modelled as a Gaussian process over (channel, ω) on the grid Ω, i.e. a
Gaussian vector of dimension D = n_channels × n_freqs, with the sample mean
and a covariance estimated from the v0 paths. Since v0 (about 100) is far
below D (thousands) the sample covariance C has rank v0 - 1 at most; the model
keeps it in a **low-rank plus diagonal** form:

1. *Karhunen-Loève / principal components.* The centred paths, scaled by
   1/√(v0 - 1), are decomposed by a thin SVD: C = Σ_m λ_m φ_m φ_mᵀ with
   orthonormal φ_m ``(D,)`` and λ_1 >= λ_2 >= ... The first r components are
   kept: ``n_components`` if given, else the fewest that explain
   ``variance_fraction`` of the total variance.
2. *Diagonal remainder.* What the r components leave of each variance,
   d = diag(C) - Σ_{m<=r} λ_m φ_m², is kept as independent noise per
   (channel, ω). The marginal variance of B at every (channel, ω), which is
   all the objectives Ψ_k of eq. 6-7 see, is therefore exactly the sample
   variance whatever r.
3. *Shrinkage* (optional) of the correlations towards zero:
   C_γ = (1 - γ) C_r + γ diag(C), with γ given or ``"auto"``, the
   Schäfer-Strimmer (2005) estimate for the "diagonal, unequal variance"
   target (computed from the v0 × v0 Gram matrix, never forming C).

The model covariance is C_model = (1 - γ) Φ_r Λ_r Φ_rᵀ + diag(diag(C) - (1 - γ) diag(Φ_r Λ_r Φ_rᵀ)),
and a path is drawn as b = μ + Φ_r ((1 - γ) Λ_r)^{1/2} z + d_γ^{1/2} ⊙ e with z,
e standard normal. The model is identified once at the reference date and
reused at later dates: :meth:`NoiseModel.save` / :meth:`NoiseModel.load`
keep it in a ``.npz`` file with a format version, together with the grid
(frequencies, channels) it belongs to.

Beyond the paper, ``noise.floor`` adds an additive sensor-noise floor in
power under the multiplicative (dB) model error, y_mod = 5 log10(10^{(y_sim + m)/5} + N) + e
(:mod:`suspid.method.floor`); the fitted model then carries it as ``floor_``
and every use of y_sim + b goes through :func:`modelled_spectra`. With
``floor: none`` (the default) ``floor_`` is None and nothing changes.

Also beyond the paper, the mean of B may depend on the speed: the model-form
error of a rigid-body model against a vehicle changes with the excitation's
frequencies, which move with the speed. When the reference date runs at
several speeds (``noise.by_speed``, the default, and the segments' speeds given
to :meth:`NoiseModel.fit`), the model keeps one mean per speed group of the
reference date (speeds within :data:`SPEED_TOLERANCE` of each other, at least
two segments) as ``speed_means_``, and the covariance of the paths about their
own group's mean: B(v) = μ_B(v) + e, e the one Gaussian process. A speed the
reference date did not cover takes the mean over all its segments, ``mean_``
(:meth:`NoiseModel.mean_for`), and :meth:`NoiseModel.speed_coverage` says so.
With one speed the mean and covariance are those of all segments, as
without speeds; the speed is kept, so that data at another speed are reported
as not covered by the reference date.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Annotated, Any, Literal, Mapping, Sequence

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from suspid.infra.arrays import CheckedNpz
from suspid.infra.files import atomic_open
from suspid.method.floor import NoiseFloor, estimate_floor, spec_floor
from suspid.options import parse_options
from suspid.errors import ConfigError, DataError

FORMAT = "suspid-noise-model"
FORMAT_VERSION = 3
"""Version 2 adds the floor arrays, version 3 the speed groups; a model is written with the lowest version that
holds what it has (no floor, no speed groups: version 1), and every version is read."""

SPEED_TOLERANCE = 0.03
"""Relative difference of speed within which reference-date segments form one speed group, and within which a
measurement speed takes that group's mean of B."""


class NoiseOptions(BaseModel):
    """The ``noise:`` section: how many Karhunen-Loève components to keep, and shrinkage."""

    model_config = ConfigDict(extra="forbid")

    n_components: int | None = Field(default=None, ge=1,
                                     description="components kept; default: by variance_fraction")
    variance_fraction: float = Field(default=0.99, gt=0.0, le=1.0,
                                     description="fraction of the total variance the kept components explain")
    shrinkage: Annotated[float, Field(ge=0.0, le=1.0)] | Literal["auto"] = Field(
        default=0.0, description="γ in [0, 1] towards the diagonal, or 'auto' (Schäfer-Strimmer)")
    floor: Literal["none", "auto", "spec"] = Field(
        default="none", description="additive sensor-noise floor in power: none, auto (estimated from the "
        "reference date) or spec (from sensor_noise_density)")
    sensor_noise_density: Annotated[float, Field(gt=0.0)] | dict[str, Annotated[float, Field(gt=0.0)]] | None = \
        Field(default=None, description="sensor noise density, (m/s²)²/Hz one-sided, for all channels or "
              "per channel name (floor: spec)")
    floor_octaves: float = Field(default=0.5, ge=0.0, le=4.0,
                                 description="width (octaves) of the window over which the floor is smoothed")
    by_speed: bool = Field(default=True, description="one mean of B per speed group of the reference date "
                           "(when it runs at several speeds), the covariance about each group's mean")

    @model_validator(mode="after")
    def _spec_needs_density(self) -> "NoiseOptions":
        if self.floor == "spec" and self.sensor_noise_density is None:
            raise ValueError("floor: spec needs sensor_noise_density ((m/s²)²/Hz, one-sided)")
        return self


def modelled_spectra(y_sim: np.ndarray, b: np.ndarray, floor: NoiseFloor | None = None) -> np.ndarray:
    """y_mod = y_sim + b (eq. 4), or with a noise floor 5 log10(10^{(y_sim + m)/5} + N) + b - m.

    :param y_sim: ``(v, n_channels, n_freqs)`` dB; ``b``: the same shape (or broadcastable), dB.
    """
    return y_sim + b if floor is None else floor.effective(y_sim) + b


def noise_samples(y_mes: np.ndarray, y_sim: np.ndarray) -> np.ndarray:
    """Noise paths b_i = y_mes_i - y_sim_i(w0) (eq. 3).

    :param y_mes: ``(v0, n_channels, n_freqs)`` dB, measured at the reference date.
    :param y_sim: ``(v0, n_channels, n_freqs)`` dB, simulated at w0 on the same
        segments, in the same order.
    :returns: ``(v0, n_channels, n_freqs)`` dB.
    :raises DataError: shapes differ or values are not finite.
    """
    y_mes = np.asarray(y_mes, dtype=float)
    y_sim = np.asarray(y_sim, dtype=float)
    if y_mes.ndim != 3 or y_mes.shape != y_sim.shape:
        raise DataError(f"measured spectra {y_mes.shape} and simulated spectra {y_sim.shape} must have the "
                        f"same shape (v0, n_channels, n_freqs), one pair per segment")
    b = y_mes - y_sim
    if not np.all(np.isfinite(b)):
        raise DataError("measured or simulated spectra contain NaN or infinite values")
    return b


def speed_groups(speeds: Sequence[float], tolerance: float = SPEED_TOLERANCE) -> tuple[np.ndarray, np.ndarray]:
    """Group segment speeds: sorted, a new group where a speed exceeds the group's first by more than
    ``tolerance`` of it.

    :param speeds: ``(v,)`` m/s, one per segment.
    :returns: the groups' mean speeds ``(S,)`` m/s (ascending) and each segment's group ``(v,)``.
    """
    v = np.asarray(speeds, dtype=float)
    order = np.argsort(v, kind="stable")
    group_of = np.empty(v.size, dtype=int)
    g, first = -1, -np.inf
    for i in order:
        if v[i] > first * (1.0 + tolerance):
            g, first = g + 1, v[i]
        group_of[i] = g
    return np.array([v[group_of == k].mean() for k in range(g + 1)]), group_of


RESIDUAL_RTOL = 1e-10
"""The diagonal remainder d_γ = variance − (1−γ) Σ λ_m φ_m² of a point is zero where it is below this fraction of
the point's variance. With γ = 0 and every mode kept the remainder is exactly 0, computed as a difference that
leaves rounding (about v ε of the variance); its square root would draw the paths' independent part at 1e-8 of
their size, in other last bits on every processor (the cross-machine differences of the noise paths). A true
remainder below 1e-10 of the variance adds at most 1e-5 of the point's standard deviation."""


def _auto_shrinkage(z: np.ndarray) -> float:
    """Schäfer-Strimmer intensity for the diagonal target, from centred paths ``z`` ``(v, D)``.

    γ* = Σ_{i≠j} Var(r_ij) / Σ_{i≠j} r_ij² with r the sample correlations; the
    sums over D² pairs are computed through the v × v Gram matrix.
    """
    v = z.shape[0]
    sd = np.sqrt((z * z).sum(axis=0) / (v - 1))
    zs = np.divide(z, sd, out=np.zeros_like(z), where=sd > 0)  # standardised; constant variables drop out
    row_sq = (zs * zs).sum(axis=1)                    # Σ_i z_ki²
    sum_w2_all = float(row_sq @ row_sq)               # Σ_k Σ_{i,j} (z_ki z_kj)²
    sum_w2_diag = float((zs ** 4).sum())
    gram = zs @ zs.T
    mean_w = (zs * zs).sum(axis=0) / v                # w̄_ii
    sum_wbar2_off = (float((gram * gram).sum()) / v ** 2) - float(mean_w @ mean_w)
    var_sum = v / (v - 1) ** 3 * ((sum_w2_all - sum_w2_diag) - v * sum_wbar2_off)
    r2_sum = (v / (v - 1)) ** 2 * sum_wbar2_off
    if r2_sum <= 0:
        return 1.0
    return float(np.clip(var_sum / r2_sum, 0.0, 1.0))


class NoiseModel:
    """Gaussian model of the noise B over (channel, ω) (paper §2.3), low rank plus diagonal.

    ``NoiseModel(**options)`` stores :class:`NoiseOptions`; :meth:`fit` does the
    work and sets the fitted attributes:

    - ``mean_`` ``(n_channels, n_freqs)`` dB, the mean function of B;
    - ``components_`` ``(r, D)`` orthonormal Karhunen-Loève modes φ_m (D = n_channels·n_freqs);
    - ``eigenvalues_`` ``(r,)`` dB², their variances λ_m (before shrinkage);
    - ``variance_`` ``(n_channels, n_freqs)`` dB², the sample variance of B at each point;
    - ``residual_variance_`` ``(n_channels, n_freqs)`` dB², the diagonal remainder d_γ;
    - ``shrinkage_`` γ, ``n_samples_`` v0, ``explained_variance_ratio_`` ``(r,)``;
    - ``freqs_`` ``(n_freqs,)`` Hz and ``channels_`` when given to :meth:`fit`;
    - ``floor_`` the :class:`~suspid.method.floor.NoiseFloor` (set by :func:`fit_noise_model`), or None;
    - ``speeds_`` ``(S,)`` m/s, ``speed_counts_`` ``(S,)`` and ``speed_means_`` ``(S, n_channels, n_freqs)`` dB:
      the reference date's speed groups (at least two segments each), their segments and their means of B;
      None without speeds or with ``by_speed: false``.
    """

    floor_: NoiseFloor | None = None
    speeds_: np.ndarray | None = None
    speed_counts_: np.ndarray | None = None
    speed_means_: np.ndarray | None = None

    def __init__(self, **options: Any) -> None:
        self.options = options

    # -- fitting -----------------------------------------------------------------
    def fit(self, b: np.ndarray, freqs: np.ndarray | None = None,
            channels: Sequence[str] | None = None, speeds: Sequence[float] | None = None) -> "NoiseModel":
        """Estimate mean and covariance from noise paths (eq. 3); returns ``self``.

        :param b: ``(v0, n_channels, n_freqs)`` dB, see :func:`noise_samples`; v0 >= 2.
        :param freqs: ``(n_freqs,)`` Hz, the grid Ω, stored to check later reuse.
        :param channels: channel names, stored to check later reuse.
        :param speeds: ``(v0,)`` m/s, each path's segment speed: with ``by_speed``, one mean per speed group
            and the covariance about the group means (segments of a group of one keep the overall mean).
        :raises DataError: wrong shape, fewer than 2 paths, non-finite values.
        :raises ConfigError: invalid options.
        """
        opt = parse_options(NoiseOptions, self.options, "noise")
        b = np.asarray(b, dtype=float)
        if b.ndim != 3 or b.shape[0] < 2:
            raise DataError(f"noise paths must be (v0, n_channels, n_freqs) with v0 >= 2, got shape {b.shape}")
        if not np.all(np.isfinite(b)):
            raise DataError("noise paths contain NaN or infinite values")
        v0, n_ch, n_f = b.shape
        self._set_grid(freqs, channels, n_ch, n_f)
        mean = b.mean(axis=0)
        centre, dof = self._fit_speed_groups(b, speeds if opt.by_speed else None)
        z = (b - mean - centre).reshape(v0, -1)
        scaled = z / math.sqrt(dof)
        _, s, vt = np.linalg.svd(scaled, full_matrices=False)
        lam = s * s
        total = float(lam.sum())
        keep = lam > total * 1e-12 if total > 0 else np.zeros_like(lam, dtype=bool)
        lam, vt = lam[keep], vt[keep]
        if opt.n_components is not None:
            r = min(opt.n_components, lam.size)
        else:
            cumulative = np.cumsum(lam) / total if total > 0 else np.ones(0)
            r = int(np.searchsorted(cumulative, opt.variance_fraction * (1 - 1e-12)) + 1) if lam.size else 0
            r = min(r, lam.size)
        gamma = _auto_shrinkage(z) if opt.shrinkage == "auto" else float(opt.shrinkage)
        variance = (scaled * scaled).sum(axis=0)
        explained = ((1 - gamma) * lam[:r]) @ (vt[:r] ** 2)
        self.mean_ = mean
        self.components_ = vt[:r].copy()
        self.eigenvalues_ = lam[:r].copy()
        self.variance_ = variance.reshape(n_ch, n_f)
        residual = variance - explained   # where the kept modes explain all of it: rounding, set to 0 (RESIDUAL_RTOL)
        self.residual_variance_ = np.where(residual > RESIDUAL_RTOL * variance, residual, 0.0).reshape(n_ch, n_f)
        self.shrinkage_ = gamma
        self.n_samples_ = v0
        self.explained_variance_ratio_ = lam[:r] / total if total > 0 else lam[:r]
        self.floor_ = None
        return self

    def _fit_speed_groups(self, b: np.ndarray, speeds: Sequence[float] | None) -> tuple[np.ndarray, int]:
        """Set the speed groups; returns each path's centre relative to the overall mean ``(v0, K, F)`` and the
        degrees of freedom of the covariance (v0 minus the means estimated)."""
        self.speeds_ = self.speed_counts_ = self.speed_means_ = None
        v0 = b.shape[0]
        centre = np.zeros_like(b)
        if speeds is None:
            return centre, v0 - 1
        speeds = np.asarray(speeds, dtype=float)
        if speeds.shape != (v0,):
            raise DataError(f"{speeds.size} segment speeds for {v0} noise paths")
        centres, group_of = speed_groups(speeds)
        kept = [g for g in range(centres.size) if np.sum(group_of == g) >= 2]
        if not kept:
            return centre, v0 - 1
        mean = b.mean(axis=0)
        means = np.array([b[group_of == g].mean(axis=0) for g in kept])
        self.speeds_ = centres[kept]
        self.speed_counts_ = np.array([np.sum(group_of == g) for g in kept])
        self.speed_means_ = means
        if len(kept) < 2:
            return centre, v0 - 1        # one speed: the covariance about the overall mean, as without speeds
        for i, g in enumerate(kept):
            centre[group_of == g] = means[i] - mean
        return centre, v0 - len(kept) - int(np.any(~np.isin(group_of, kept)))

    def speed_group_of(self, speeds: Sequence[float]) -> np.ndarray:
        """Each speed's group in ``speeds_`` (within :data:`SPEED_TOLERANCE`), -1 where none; ``(n,)``."""
        v = np.atleast_1d(np.asarray(speeds, dtype=float))
        if self.speeds_ is None:
            return np.full(v.size, -1)
        rel = np.abs(v[:, None] / self.speeds_[None] - 1.0)
        best = np.argmin(rel, axis=1)
        return np.where(rel[np.arange(v.size), best] <= SPEED_TOLERANCE, best, -1)

    def mean_for(self, speeds: Sequence[float]) -> np.ndarray:
        """μ_B at each speed ``(n, n_channels, n_freqs)`` dB: the mean of the reference date's speed group within
        :data:`SPEED_TOLERANCE`, else (no such group, or no speed groups) the overall mean ``mean_``."""
        self._check_fitted()
        g = self.speed_group_of(speeds)
        out = np.repeat(self.mean_[None], g.size, axis=0)
        if self.speed_means_ is not None:
            out[g >= 0] = self.speed_means_[g[g >= 0]]
        return out

    def reference_counts(self, speeds: Sequence[float]) -> np.ndarray:
        """The reference-date segments behind :meth:`mean_for` at each speed ``(n,)``: its group's, else v0."""
        g = self.speed_group_of(speeds)
        counts = np.full(g.size, self.n_samples_)
        if self.speed_counts_ is not None:
            counts[g >= 0] = self.speed_counts_[g[g >= 0]]
        return counts

    def speed_coverage(self, speeds: Sequence[float]) -> list[dict[str, Any]]:
        """Per speed (m/s): which mean of B it takes (``speed_group`` or ``pooled``) and from how many
        reference-date segments; ``covered`` is False where the reference date's speeds are known and none is
        within :data:`SPEED_TOLERANCE` of this one (its mean is then the pooled one, of other speeds)."""
        g = self.speed_group_of(speeds)
        counts = self.reference_counts(speeds)
        out = []
        for v, gi, n in zip(np.atleast_1d(np.asarray(speeds, dtype=float)), g, counts):
            out.append({"speed_kmh": round(float(v) * 3.6, 3), "mean": "speed_group" if gi >= 0 else "pooled",
                        "reference_segments": int(n),
                        "covered": bool(gi >= 0 or self.speeds_ is None)})
        return out

    def effective(self, y_sim: np.ndarray) -> np.ndarray:
        """What stands for y_sim in y_mod = y_sim + b: ``y_sim`` itself without a floor, else
        :meth:`NoiseFloor.effective`."""
        return y_sim if self.floor_ is None else self.floor_.effective(y_sim)

    def _set_grid(self, freqs, channels, n_ch: int, n_f: int) -> None:
        self.freqs_ = None if freqs is None else np.asarray(freqs, dtype=float)
        self.channels_ = None if channels is None else tuple(str(c) for c in channels)
        if self.freqs_ is not None and self.freqs_.shape != (n_f,):
            raise DataError(f"freqs has shape {self.freqs_.shape}, the noise paths have {n_f} frequencies")
        if self.channels_ is not None and len(self.channels_) != n_ch:
            raise DataError(f"{len(self.channels_)} channel names for noise paths with {n_ch} channels")

    def _check_fitted(self) -> None:
        if not hasattr(self, "mean_"):
            raise DataError("the noise model is not fitted: call fit(b) or NoiseModel.load(path) first")

    # -- using -------------------------------------------------------------------
    @property
    def shape(self) -> tuple[int, int]:
        """``(n_channels, n_freqs)`` of one path."""
        self._check_fitted()
        return self.mean_.shape

    def covariance(self) -> np.ndarray:
        """The model covariance C_model ``(D, D)`` dB² (dense: for checks on small grids)."""
        self._check_fitted()
        low_rank = (self.components_.T * ((1 - self.shrinkage_) * self.eigenvalues_)) @ self.components_
        return low_rank + np.diag(self.residual_variance_.ravel())

    def sample(self, n: int, seed: int | np.random.Generator | None,
               speeds: Sequence[float] | None = None) -> np.ndarray:
        """``n`` paths of B drawn from the fitted Gaussian model.

        :param n: number of paths (>= 1).
        :param seed: an int seed or a ``numpy.random.Generator``; the same seed
            gives the same paths (draws: KL coefficients first, then the diagonal part).
        :param speeds: ``(n,)`` m/s, each path's segment speed: its mean is :meth:`mean_for` that speed
            (default: ``mean_`` for all).
        :returns: ``(n, n_channels, n_freqs)`` dB.
        """
        self._check_fitted()
        if int(n) != n or n < 1:
            raise DataError(f"number of noise paths must be a positive integer, got {n!r}")
        rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
        n = int(n)
        coefficients = rng.standard_normal((n, self.eigenvalues_.size))
        coefficients *= np.sqrt((1 - self.shrinkage_) * self.eigenvalues_)
        independent = rng.standard_normal((n, self.mean_.size)) * np.sqrt(self.residual_variance_.ravel())
        paths = coefficients @ self.components_ + independent
        if speeds is not None and len(speeds) != n:
            raise DataError(f"{len(speeds)} speeds for {n} noise paths")
        mean = self.mean_ if speeds is None else self.mean_for(speeds)
        return paths.reshape((n,) + self.mean_.shape) + mean

    def check_grid(self, freqs: np.ndarray | None = None, channels: Sequence[str] | None = None) -> None:
        """Raise :class:`DataError` unless the model belongs to this grid Ω and these channels.

        A model identified at the reference date can only be reused on the same grid.
        """
        self._check_fitted()
        if freqs is not None:
            freqs = np.asarray(freqs, dtype=float)
            if freqs.shape != (self.mean_.shape[1],) or (
                    self.freqs_ is not None and not np.allclose(freqs, self.freqs_, rtol=1e-9, atol=0)):
                raise DataError(f"the noise model was identified on {self.mean_.shape[1]} other frequencies; "
                                f"recompute it for this grid (spectra: section)")
        if channels is not None:
            channels = tuple(str(c) for c in channels)
            if len(channels) != self.mean_.shape[0] or (self.channels_ is not None and channels != self.channels_):
                raise DataError(f"the noise model has channels {list(self.channels_ or [])} "
                                f"({self.mean_.shape[0]}), the data {list(channels)}")

    # -- files -------------------------------------------------------------------
    _ARRAYS = ("mean", "components", "eigenvalues", "variance", "residual_variance", "explained_variance_ratio")

    def save(self, path: str | Path) -> Path:
        """Write the fitted model to ``path`` (a ``.npz`` file, format version :data:`FORMAT_VERSION`).

        :returns: the path written.
        """
        self._check_fitted()
        path = Path(path)
        arrays = {name: getattr(self, name + "_") for name in self._ARRAYS}
        floor = self.floor_
        version = 1
        exclude = {"floor", "sensor_noise_density", "floor_octaves", "by_speed"}
        if floor is not None:
            arrays |= {"floor_power": floor.power, "floor_gain_db": floor.gain_db}
            version, exclude = 2, exclude - {"floor", "sensor_noise_density", "floor_octaves"}
        if self.speed_means_ is not None:
            arrays |= {"speeds": self.speeds_, "speed_counts": self.speed_counts_, "speed_means": self.speed_means_}
            version, exclude = 3, exclude - {"by_speed"}
        meta = {"format": FORMAT, "format_version": version,
                "shrinkage": self.shrinkage_,
                "n_samples": self.n_samples_,
                "options": parse_options(NoiseOptions, self.options, "noise").model_dump(exclude=exclude),
                "channels": list(self.channels_) if self.channels_ is not None else None}
        try:
            with atomic_open(path, "wb", fsync=True) as fh:  # a later date needs this file: never truncated
                np.savez(fh, meta=np.array(json.dumps(meta)),
                         freqs=self.freqs_ if self.freqs_ is not None else np.zeros(0), **arrays)
        except OSError as exc:
            raise DataError(f"cannot write noise model {path}: {exc.strerror or exc}") from None
        return path

    @classmethod
    def load(cls, path: str | Path) -> "NoiseModel":
        """Read a model written by :meth:`save`.

        :raises DataError: missing file, not a suspid noise model, another
            format version, or inconsistent arrays; the message names the file.
        """
        path = Path(path)
        with CheckedNpz(path, "noise model file") as npz:   # every array's size checked before it is read
            missing = [key for key in ("meta", "freqs", *cls._ARRAYS) if key not in npz.files]
            if missing:
                raise DataError(f"noise model file {path} is not a suspid noise model (missing {', '.join(missing)})")
            meta = npz.load("meta")
            cls._expect_shapes(npz, meta)
            content = {"meta": meta} | {key: npz.load(key) for key in npz.files if key != "meta"}
        try:
            return cls._from_content(content, path)
        except DataError:
            raise
        except (ConfigError, KeyError, TypeError, ValueError, AttributeError, IndexError) as exc:
            # a header or an array edited or written by other code: whatever the decoding meets
            what = exc.detail if isinstance(exc, ConfigError) else f"{type(exc).__name__}: {exc}"
            where = f" at '{exc.key}'" if isinstance(exc, ConfigError) and exc.key else ""
            raise DataError(f"noise model file {path} has a damaged header{where} ({what})") from None

    @classmethod
    def _expect_shapes(cls, npz: CheckedNpz, meta: np.ndarray) -> None:
        """Each array's declared shape against the model's grid, before any is read: (channels, frequencies)
        from the header's channels and the ``freqs`` array (else from ``mean``'s own shape), r components."""
        m = npz.members
        grid = m["mean"].shape
        try:
            channels = json.loads(str(meta)).get("channels") if meta.ndim == 0 else None
        except (json.JSONDecodeError, AttributeError):
            channels = None     # the header's own check (_from_content) names what is wrong with it
        n_c = len(channels) if isinstance(channels, list) else (grid[0] if len(grid) == 2 else None)
        n_f = m["freqs"].shape[0] if len(m["freqs"].shape) == 1 and m["freqs"].shape[0] else (
            grid[1] if len(grid) == 2 else None)
        if n_c is None or n_f is None:
            raise DataError(f"noise model file {npz.path}: array 'mean' declares shape {grid}, expected "
                            f"(channels, frequencies)")
        shape, axes = (n_c, n_f), "channels x frequencies of the model's grid"
        for name in ("mean", "variance", "residual_variance", "floor_power", "floor_gain_db"):
            if name in m:
                npz.expect(name, shape, axes)
        r = m["eigenvalues"].shape[0] if len(m["eigenvalues"].shape) == 1 else 0
        npz.expect("eigenvalues", (r,), "one per component")
        npz.expect("explained_variance_ratio", (r,), "one per component")
        npz.expect("components", (r, n_c * n_f), "components x (channels x frequencies)")
        if "speeds" in m and len(m["speeds"].shape) == 1:
            n_s = m["speeds"].shape[0]
            npz.expect("speed_counts", (n_s,), "one per speed group")
            npz.expect("speed_means", (n_s, *shape), "speed groups x channels x frequencies")

    @classmethod
    def _from_content(cls, content: Mapping[str, np.ndarray], path: Path) -> "NoiseModel":
        """The model from the arrays of its file (:meth:`load`); any decoding error is the caller's to name."""
        try:
            meta = json.loads(str(content["meta"]))
        except json.JSONDecodeError:
            raise DataError(f"noise model file {path} has a corrupt header") from None
        if not isinstance(meta, dict) or meta.get("format") != FORMAT:
            raise DataError(f"noise model file {path} is not a suspid noise model")
        if meta.get("format_version") not in range(1, FORMAT_VERSION + 1):
            raise DataError(f"noise model file {path} has format version {meta.get('format_version')}; "
                            f"this suspid reads versions 1 to {FORMAT_VERSION}: identify the noise model again")
        options = parse_options(NoiseOptions, meta.get("options") or {}, "options").model_dump(
            exclude_unset=True)   # checked as a config's noise: section is (n_components >= 1, ...)
        model = cls(**options)
        for name in cls._ARRAYS:
            setattr(model, name + "_", np.asarray(content[name], dtype=float))
        model.shrinkage_ = float(meta["shrinkage"])
        model.n_samples_ = int(meta["n_samples"])
        freqs = content["freqs"]
        model.freqs_ = np.asarray(freqs, dtype=float) if freqs.size else None
        model.channels_ = tuple(str(c) for c in meta["channels"]) if meta.get("channels") is not None else None
        model.floor_ = None
        if "floor_power" in content and "floor_gain_db" in content:
            model.floor_ = NoiseFloor(np.asarray(content["floor_power"], dtype=float),
                                      np.asarray(content["floor_gain_db"], dtype=float))
        if all(k in content for k in ("speeds", "speed_counts", "speed_means")):
            model.speeds_ = np.asarray(content["speeds"], dtype=float)
            model.speed_counts_ = np.asarray(content["speed_counts"], dtype=int)
            model.speed_means_ = np.asarray(content["speed_means"], dtype=float)
        model._check_consistent(path)
        return model

    def _check_consistent(self, path: Path) -> None:
        grid = self.mean_.shape
        r = self.eigenvalues_.shape[0] if self.eigenvalues_.ndim == 1 else -1
        ok = (len(grid) == 2 and self.variance_.shape == grid and self.residual_variance_.shape == grid
              and self.components_.shape == (r, grid[0] * grid[1])
              and self.explained_variance_ratio_.shape == (r,)
              and (self.freqs_ is None or self.freqs_.shape == (grid[1],))
              and (self.channels_ is None or len(self.channels_) == grid[0])
              and 0.0 <= self.shrinkage_ <= 1.0
              and all(np.all(np.isfinite(getattr(self, n + "_"))) for n in self._ARRAYS)
              and all(np.all(getattr(self, n + "_") >= 0) for n in ("eigenvalues", "variance", "residual_variance"))
              and (self.floor_ is None or (self.floor_.power.shape == grid and self.floor_.gain_db.shape == grid
                                           and np.all(self.floor_.power >= 0)
                                           and np.all(np.isfinite(self.floor_.power))
                                           and np.all(np.isfinite(self.floor_.gain_db))))
              and (self.speed_means_ is None or (self.speed_means_.shape == (self.speeds_.size,) + grid
                                                 and self.speed_counts_.shape == self.speeds_.shape
                                                 and np.all(self.speeds_ > 0) and np.all(self.speed_counts_ >= 2)
                                                 and np.all(np.isfinite(self.speed_means_)))))
        if not ok:
            raise DataError(f"noise model file {path} is inconsistent (array shapes or values do not match, "
                            f"or a negative variance)")


def reference_paths(model: "NoiseModel", y_mes: np.ndarray, y_sim: np.ndarray) -> np.ndarray:
    """The reference date's noise paths ``(v0, n_channels, n_freqs)`` dB the Gaussian part of ``model`` was fitted
    on: b_i = y_mes_i − y_sim_i(w0) (eq. 3), or with ``model``'s floor the paths m + e_i under it."""
    return noise_samples(y_mes, y_sim) if model.floor_ is None else model.floor_.paths(y_mes, y_sim)


def refit_gaussian(model: "NoiseModel", paths: np.ndarray, freqs: np.ndarray | None = None,
                   channels: Sequence[str] | None = None, speeds: Sequence[float] | None = None) -> "NoiseModel":
    """A noise model with ``model``'s options and floor, its mean and covariance fitted again on ``paths``
    ``(v0, n_channels, n_freqs)`` dB (e.g. a bootstrap resample of :func:`reference_paths`)."""
    refit = NoiseModel(**model.options).fit(paths, freqs=freqs, channels=channels, speeds=speeds)
    refit.floor_ = model.floor_
    return refit


def bootstrap_refit(model: "NoiseModel", paths: np.ndarray, speeds: Sequence[float], rng: np.random.Generator,
                    freqs: np.ndarray | None = None, channels: Sequence[str] | None = None) -> "NoiseModel":
    """One bootstrap replicate of the reference date's noise model: :func:`refit_gaussian` on the paths
    ``(v0, n_channels, n_freqs)`` dB of v0 reference segments drawn with replacement (``speeds (v0,)`` m/s,
    each segment's speed), so that an interval or a test carries B's own estimation error."""
    i0 = rng.integers(0, len(speeds), len(speeds))
    return refit_gaussian(model, paths[i0], freqs, channels, [speeds[i] for i in i0])


def fit_noise_model(y_mes: np.ndarray, y_sim: np.ndarray, options: NoiseOptions | Mapping[str, Any] | None = None,
                    freqs: np.ndarray | None = None, channels: Sequence[str] | None = None,
                    speeds: Sequence[float] | None = None) -> NoiseModel:
    """Eq. 3 then the Gaussian model: the noise model of a reference date in one call.

    With ``floor: auto`` or ``spec`` the floor N and gain m are fitted first and
    the Gaussian model is fitted to the paths b_i = m + e_i (:mod:`suspid.method.floor`).

    :param y_mes: ``(v0, n_channels, n_freqs)`` dB measured spectra.
    :param y_sim: ``(v0, n_channels, n_freqs)`` dB spectra simulated at w0.
    :param speeds: ``(v0,)`` m/s, the reference segments' speeds (for the speed groups, see :meth:`NoiseModel.fit`).
    """
    opt = parse_options(NoiseOptions, options, "noise")
    b = noise_samples(y_mes, y_sim)
    floor = None
    if opt.floor == "auto":
        floor = estimate_floor(y_mes, y_sim, freqs, opt.floor_octaves)
    elif opt.floor == "spec":
        floor = spec_floor(y_mes, y_sim, opt.sensor_noise_density, channels)
    if floor is not None:
        b = floor.paths(y_mes, y_sim)
    model = NoiseModel(**opt.model_dump()).fit(b, freqs=freqs, channels=channels, speeds=speeds)
    model.floor_ = floor
    return model
