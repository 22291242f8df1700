"""Fitting candidate explanations: a registered effect's parameters, or the generic bump.

Overview: ``docs/diagnose.md``, "How it works", step 3.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
from scipy.optimize import minimize

from suspid.config import Config, validate_options
from suspid.errors import ConfigError, SimulatorError
from suspid.infra.files import canonical
from suspid.sections import DiagnoseOptions
from suspid.workflows.tasks import simulate_spectra

from .cells import CellGrid
from .locate import DiscrepancyMap
from .null import NullCalibration


@dataclass
class Candidate:
    """One ranked explanation: an effect with fitted parameters, or the generic bump."""

    effect: str
    status: str
    n_parameters: int = 0
    parameters: dict[str, Any] = field(default_factory=dict)
    D: float = math.inf
    delta_D: float = -math.inf
    delta_D_flagged: float = -math.inf
    explained: float = 0.0
    score: float = -math.inf
    delta_J: float | None = None
    evaluations: int = 0
    signature: dict[str, Any] | None = None
    y_sim: np.ndarray | None = None
    evidence: dict[str, Any] = field(default_factory=dict)
    own: np.ndarray | None = None                  # (n_cells,) bool: its cells (signature + changed), see name.py
    reason: str | None = None

    def as_dict(self) -> dict[str, Any]:
        def num(x):
            return None if x is None or not math.isfinite(x) else round(float(x), 6)

        return {"effect": self.effect, "status": self.status, "score": num(self.score),
                "parameters": canonical(self.parameters), "n_parameters": self.n_parameters,
                "D": num(self.D), "delta_D": num(self.delta_D), "delta_D_flagged": num(self.delta_D_flagged),
                "explained": num(self.explained), "delta_J": num(self.delta_J), "evaluations": self.evaluations,
                "signature": self.signature, "evidence": canonical(self.evidence), "rejected_because": self.reason}


class Discrepancy:
    """The fit criterion D = Σ (m / σ)² over every (speed group, channel, frequency bin), and over the bins
    of the flagged cells; m the group mean of y_mes - y_sim - μ_B (dB; μ_B of the group's speed,
    ``null.noise_mean``), σ its null sd (``null.bin_sd``); y_sim passes through the noise model's sensor-noise
    floor when it has one.

    ``D0`` and ``D0_flagged`` are the base model's (``y_base``).
    """

    def __init__(self, grid: CellGrid, null: NullCalibration, y_mes: np.ndarray, noise_model,
                 flagged: np.ndarray, y_base: np.ndarray) -> None:
        self.grid = grid
        self.effective = noise_model.effective
        self.target = grid.group_means(y_mes) - null.noise_mean                  # m = target - mean(y_sim)
        self.scale = null.bin_sd
        self.flagged = grid.cell_to_bins(flagged.astype(float)) > 0
        self.base_means = grid.group_means(self.effective(y_base))
        self.D0, self.D0_flagged = self.of_means(self.target - self.base_means)

    @property
    def n_terms(self) -> int:
        return int(self.target.size)

    def of_means(self, m: np.ndarray) -> tuple[float, float]:
        z2 = (m / self.scale) ** 2
        return float(z2.sum()), float(z2[self.flagged].sum())

    def __call__(self, y_sim: np.ndarray) -> tuple[float, float]:
        return self.of_means(self.target - self.grid.group_means(self.effective(y_sim)))

    def within(self, bins: np.ndarray, means: np.ndarray) -> float:
        """D over the bins ``bins`` ``(G, K, F)`` bool, for model group means ``means`` ``(G, K, F)``."""
        return float((((self.target - means) / self.scale) ** 2)[bins].sum())

    def spectra(self) -> dict[str, Any]:
        """What effects' ``starts_from_spectra`` read: group means of y_mes - μ_B and of the base model."""
        return {"freqs": self.grid.freqs, "channels": self.grid.channels, "measured": self.target,
                "model": self.base_means}


class EffectFitter:
    """Fits effects' parameters to the measurements at fixed suspension parameters ``w`` (frequency solver)."""

    def __init__(self, config: Config, problem, w: dict[str, float], discrepancy: Discrepancy,
                 flagged: list[tuple[str, float, float, float]], options: DiagnoseOptions,
                 log: Callable[[str], None] = lambda s: None, blocked: dict[str, set[str]] | None = None) -> None:
        self.config, self.problem, self.w, self.disc, self.flagged, self.opts, self.log = (
            config, problem, dict(w), discrepancy, flagged, options, log)
        self.blocked = {k: set(v) for k, v in (blocked or {}).items()}
        self.sim_cls = type(problem.simulator)
        self.file = str(config.source_file)
        self._sims: dict[str, Any] = {}
        self.evaluations = 0

    def simulator_with(self, spec: dict[str, Any]):
        """The configured simulator with one more effect ``spec`` (validated; cached by spec)."""
        key = json.dumps(canonical(spec), sort_keys=True)
        if key not in self._sims:
            options = dict(self.config.simulator.options)
            options["effects"] = list(options.get("effects") or []) + [spec]
            validated = validate_options(self.sim_cls, options, file=self.file, key="simulator.options")
            self._sims[key] = self.sim_cls(**validated)
        return self._sims[key]

    def simulate(self, sim, w_effect: dict[str, float]) -> np.ndarray | None:
        self.evaluations += 1
        try:
            return simulate_spectra(sim, self.w | w_effect, self.problem.segments, self.config.spectra)[0]
        except SimulatorError:
            return None       # e.g. an unstable vehicle: not a candidate there

    def fit(self, cls) -> Candidate:
        """Fit one effect class at ``w``: every starting point of its ``candidates()``, then refine the best."""
        effect = cls()
        speeds = sorted({float(s.mean_speed) for s in self.problem.segments})
        sigs = {f"{v * 3.6:.1f} km/h": _signature_dict(effect.signature(v)) for v in speeds}
        if not effect.matching_cells(self.flagged):
            return Candidate(cls.name, "excluded by signature (no flagged cell in its channels and band)",
                             signature=sigs)
        starts = effect.candidates(speeds, self.flagged, self.problem.channels)
        from_data = getattr(effect, "starts_from_spectra", None)        # optional capability of an effect
        evidence: dict[str, Any] = {}
        if callable(from_data):
            extra = from_data(speeds, self.flagged, self.problem.channels, self.disc.spectra())
            for start in extra:
                for key in [k for k in start if k not in cls.Options.model_fields]:
                    evidence.setdefault(key, []).append({"start": {k: v for k, v in start.items()
                                                                   if k in cls.Options.model_fields},
                                                         key: start.pop(key)})
            starts = list(extra) + list(starts)
        blocked = self.blocked.get(cls.name, set())
        if blocked:        # the effect is already applied on these channels: never a second time there
            starts = [s for s in starts if not set(s.get("channels") or ()) & blocked]
        if not starts:
            return Candidate(cls.name, "no starting point in the flagged cells"
                             + (f" outside {', '.join(sorted(blocked))}" if blocked else ""), signature=sigs)
        defaults = cls.defaults()
        fitted = list(cls.fitted)
        structural = sorted({k for s in starts for k in s if k not in fitted})
        n_params = len(fitted) + len(structural)
        transforms = [_Transform(cls, p) for p in fitted]
        n0 = self.evaluations
        # 1. every starting point
        evaluated = []
        for start in starts:
            spec = {"name": cls.name, **defaults, **{k: start[k] for k in structural if k in start}}
            try:
                sim = self.simulator_with(spec)
            except ConfigError:
                continue
            x = np.array([start.get(p, defaults[p]) for p in fitted], dtype=float)
            y = self.simulate(sim, self._w_effect(cls.name, fitted, x))
            if y is not None:
                evaluated.append((self.disc(y)[0], spec, x, y))
        if not evaluated:
            return Candidate(cls.name, "failed: no starting point could be simulated", n_params, signature=sigs,
                             evaluations=self.evaluations - n0)
        evaluated.sort(key=lambda e: e[0])
        # 2. refine the best starts on the continuous parameters
        best = evaluated[0]
        for D0, spec, x0, y0 in evaluated[: self.opts.n_starts]:
            if not fitted:
                continue
            result = self._refine(cls.name, fitted, transforms, spec, x0, D0, y0)
            if result[0] < best[0]:
                best = result
        D, spec, x, y = best
        params = dict(spec)
        params.pop("name")
        params.update({p: float(v) for p, v in zip(fitted, x)})
        D_all, D_f = self.disc(y)
        return Candidate(cls.name, "fitted", n_params, params, D_all, evaluations=self.evaluations - n0,
                         signature=sigs, y_sim=y, delta_D_flagged=self.disc.D0_flagged - D_f, evidence=evidence)

    @staticmethod
    def _w_effect(name: str, fitted: list[str], x: np.ndarray) -> dict[str, float]:
        return {f"{name}/{p}": float(v) for p, v in zip(fitted, x)}

    def _refine(self, name, fitted, transforms, spec, x0, D0, y0):
        sim = self.simulator_with(spec)
        u0 = np.array([t.to_unit(v) for t, v in zip(transforms, x0)])
        cache: dict[tuple, tuple[float, np.ndarray | None]] = {}

        def objective(u):
            u = np.clip(u, 0.0, 1.0)
            key = tuple(np.round(u, 10))
            if key not in cache:
                x = np.array([t.from_unit(ui) for t, ui in zip(transforms, u)])
                y = self.simulate(sim, self._w_effect(name, fitted, x))
                cache[key] = (math.inf if y is None else self.disc(y)[0], y)
            return cache[key][0]

        cache[tuple(np.round(np.clip(u0, 0, 1), 10))] = (D0, y0)
        simplex = [u0] + [np.clip(u0 + 0.04 * e * (1 if u0[i] < 0.5 else -1), 0, 1)
                          for i, e in enumerate(np.eye(len(u0)))]
        res = minimize(objective, u0, method="Nelder-Mead",
                       options={"initial_simplex": np.array(simplex), "maxfev": self.opts.max_evaluations,
                                "xatol": 2e-3, "fatol": 1e-3 * max(D0, 1.0)})
        u = np.clip(res.x, 0.0, 1.0)
        D, y = cache.get(tuple(np.round(u, 10)), (math.inf, None))
        if y is None or D > D0:
            return D0, spec, x0, y0
        return D, spec, np.array([t.from_unit(ui) for t, ui in zip(transforms, u)]), y


class _Transform:
    """A fitted parameter <-> [0, 1] (linear or log between its bounds)."""

    def __init__(self, cls, parameter: str) -> None:
        self.lo, self.hi = cls.bounds(parameter)
        self.log = cls.log_scale(parameter) and self.lo > 0
        if not (math.isfinite(self.lo) and math.isfinite(self.hi)):
            raise ConfigError(f"effect {cls.name}: fitted parameter '{parameter}' needs finite bounds (ge/le)")

    def to_unit(self, v: float) -> float:
        v = min(max(float(v), self.lo), self.hi)
        if self.log:
            return math.log(v / self.lo) / math.log(self.hi / self.lo)
        return (v - self.lo) / (self.hi - self.lo)

    def from_unit(self, u: float) -> float:
        u = min(max(float(u), 0.0), 1.0)
        if self.log:
            return self.lo * (self.hi / self.lo) ** u
        return self.lo + u * (self.hi - self.lo)


def _signature_dict(sig) -> dict[str, Any]:
    lo, hi = sig.band_hz
    return {"bodies": list(sig.bodies), "directions": list(sig.directions),
            "band_hz": [round(float(lo), 3), None if not math.isfinite(hi) else round(float(hi), 3)],
            "speed_dependence": sig.speed_dependence}


def fit_bump(disc: Discrepancy, dmap: DiscrepancyMap, n_parameters: int) -> Candidate:
    """The generic bump with ``n_parameters`` parameters, fitted with the same D as the effects.

    bump(k, f) = a_g(k) exp(-½ (log2(f / f_c) / w)²) dB on the flagged channels; amplitudes by weighted least
    squares, f_c and w on grids.
    """
    grid = disc.grid
    G, K = len(grid.speeds), len(grid.channels)
    flagged_c = np.nonzero(dmap.flagged)[0]
    if flagged_c.size == 0:
        return Candidate("generic-bump", "nothing flagged", n_parameters)
    per_channel: dict[int, float] = {}
    for c in flagged_c:
        k = grid.index(int(c))[1]
        per_channel[k] = per_channel.get(k, 0.0) + float(dmap.evidence[c])
    order = sorted(per_channel, key=lambda k: -per_channel[k])
    n_amp = max(1, n_parameters - 2)
    groups = [[k] for k in order[: n_amp - 1]] + [order[n_amp - 1:]] if len(order) >= n_amp else [[k] for k in order]
    top = flagged_c[np.argmax(dmap.evidence[flagged_c])]
    f_top = float(np.sqrt(np.prod(grid.band_edges[grid.index(int(top))[2]])))
    f_lo = float(min(grid.band_edges[grid.index(int(c))[2], 0] for c in flagged_c))
    f_hi = float(max(grid.band_edges[grid.index(int(c))[2], 1] for c in flagged_c))
    centres = [f_top] if n_parameters < 2 else list(np.geomspace(max(f_lo, grid.freqs[0]), f_hi, 48))
    widths = [1 / 6] if n_parameters < 3 else [1 / 12, 1 / 6, 1 / 3, 2 / 3, 1.0, 2.0]
    m0 = (disc.target - disc.base_means).ravel()
    weight = 1.0 / disc.scale.ravel() ** 2
    best = (math.inf, None, None)
    F = grid.freqs.size
    for fc in centres:
        for w in widths:
            shape = np.exp(-0.5 * (np.log2(np.maximum(grid.freqs, 1e-9) / fc) / w) ** 2)      # (F,)
            columns = []
            for members in groups:
                col = np.zeros((G, K, F))
                col[:, members, :] = shape
                columns.append(col.ravel())
            X = np.array(columns).T                                  # (n_bins, n_amp)
            Xw = X * weight[:, None]
            a = np.linalg.solve(X.T @ Xw + 1e-12 * np.eye(X.shape[1]), Xw.T @ m0)
            D, D_f = disc.of_means((m0 - X @ a).reshape(G, K, F))
            if D < best[0]:
                best = (D, {"centre_hz": round(fc, 4), "width_octaves": w,
                            "amplitudes_db": {",".join(grid.channels[k] for k in g): round(float(ai), 4)
                                              for g, ai in zip(groups, a)}}, D_f)
    D, params, D_f = best
    return Candidate("generic-bump", "fitted", n_parameters, params, D, delta_D_flagged=disc.D0_flagged - D_f)


LOCAL_WIDTHS = (1 / 12, 1 / 6, 1 / 3, 2 / 3, 1.0, 2.0, math.inf)
"""Widths (octaves, the Gaussian's sd in log2 f) of the local discrepancy bumps; inf: a flat offset (a gain)."""


@dataclass
class LocalFit:
    """The local discrepancy model fitted on top of a model: one free bump per (speed group, channel).

    :ivar D: the criterion D after the bumps; :ivar n_parameters: 3 per bump (amplitude, centre, width),
        1 per flat offset; :ivar bumps: ``{(group, channel): (amplitude_db, centre_hz, width_octaves, ΔD)}``.
    """

    D: float
    n_parameters: int
    bumps: dict[tuple[int, int], tuple[float, float, float, float]]

    def score(self, D0: float, penalty: float, extra_parameters: int = 0) -> float:
        """ΔD from ``D0`` minus ``penalty`` per parameter (the bumps' and ``extra_parameters``)."""
        return (D0 - self.D) - penalty * (self.n_parameters + extra_parameters)

    def as_dict(self, grid: CellGrid) -> dict[str, Any]:
        return {"D": round(self.D, 4), "n_parameters": self.n_parameters,
                "bumps": [{"speed_kmh": round(float(grid.speeds[g] * 3.6), 3), "channel": grid.channels[k],
                           "amplitude_db": round(a, 4), "centre_hz": round(fc, 4),
                           "width_octaves": None if not math.isfinite(w) else w, "delta_D": round(dd, 3)}
                          for (g, k), (a, fc, w, dd) in sorted(self.bumps.items())]}


def fit_local(disc: Discrepancy, flagged: np.ndarray, means: np.ndarray, penalty: float) -> LocalFit:
    """A local discrepancy model (in the spirit of Kennedy and O'Hagan 2001) on top of model group means
    ``means`` ``(G, K, F)``: for each (speed group, channel) holding a flagged cell, the free bump
    a exp(-½ (log2(f / f_c) / w)²) dB (or a flat offset a) that lowers D most, kept when its ΔD beats
    ``penalty`` per parameter. Amplitude by weighted least squares; f_c on 64 log-spaced points over the
    channel's band; w in :data:`LOCAL_WIDTHS`.

    :param flagged: ``(n_cells,)`` bool, the cells whose (group, channel) get a bump.
    """
    grid = disc.grid
    r = disc.target - means                                               # (G, K, F)
    wgt = 1.0 / disc.scale ** 2
    D = float((r ** 2 * wgt).sum())
    lf = np.log2(np.maximum(grid.freqs, 1e-9))
    centres = np.geomspace(max(grid.freqs[0], 1e-3), grid.freqs[-1], 64)
    shapes = [(fc, w, np.exp(-0.5 * ((lf - math.log2(fc)) / w) ** 2)) for fc in centres for w in LOCAL_WIDTHS
              if math.isfinite(w)]
    shapes.append((float(np.sqrt(grid.freqs[0] * grid.freqs[-1])), math.inf, np.ones_like(lf)))
    S = np.array([s for _, _, s in shapes])                                # (n_shapes, F)
    pairs = sorted({grid.index(int(c))[:2] for c in np.nonzero(flagged)[0]})
    bumps, n_par = {}, 0
    for g, k in pairs:
        rk, wk = r[g, k], wgt[g, k]
        num = S @ (wk * rk)
        den = (S ** 2) @ wk
        gain = num ** 2 / np.maximum(den, 1e-300)                          # ΔD of each shape at its best amplitude
        p = np.array([1 if not math.isfinite(w) else 3 for _, w, _ in shapes])
        net = gain - penalty * p
        i = int(np.argmax(net))
        if net[i] > 0:
            fc, w, _ = shapes[i]
            bumps[(g, k)] = (float(num[i] / den[i]), float(fc), float(w), float(gain[i]))
            D -= float(gain[i])
            n_par += int(p[i])
    return LocalFit(D, n_par, bumps)
