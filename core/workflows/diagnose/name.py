"""Naming: rank every candidate effect against the generic alternatives and decide which, if any, is named.

Overview: ``docs/diagnose.md``, "How it works", step 3.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np

from suspid import registry
from suspid.config import Config
from suspid.errors import ConfigError, UnknownPluginError
from suspid.sections import DiagnoseOptions
from suspid.workflows.evaluation import j_of_spectra

from .fit import Candidate, Discrepancy, EffectFitter, LocalFit, fit_bump, fit_local
from .locate import DiscrepancyMap, locate
from .null import NullCalibration
from .coupling import twin


@dataclass
class Ranking:
    """The outcome of one naming step.

    :ivar candidates: every candidate effect, best score first; :ivar bumps: the fixed generic bump by size;
    :ivar local: the local discrepancy model on the base model; :ivar named: the named effect or None;
    :ivar reason: why; :ivar unexplained: the flagged regions no catalogue effect explains.
    """

    candidates: list[Candidate]
    bumps: dict[int, Candidate]
    local: LocalFit | None
    named: str | None
    reason: str
    unexplained: list[dict[str, Any]] = field(default_factory=list)


def rank_effects(config: Config, problem, w: dict[str, float], y_sim: np.ndarray, dmap: DiscrepancyMap,
                 null: NullCalibration, options: DiagnoseOptions, log: Callable[[str], None] = lambda s: None,
                 exclude: Sequence[str] = (), blocked: dict[str, set[str]] | None = None) -> Ranking:
    """Fit every candidate effect (but ``exclude``), the generic bumps and the local discrepancy model; gather
    the evidence of each fit (its after-map, the gap in its own cells) and decide which effect, if any, is named.

    :param blocked: per effect, channels its starting points may not name (an effect already applied there,
        e.g. a tilt corrected in the records).
    """
    disc = Discrepancy(dmap.grid, null, problem.y_mes, problem.noise_model, dmap.flagged, y_sim)
    D0, D0_f = disc.D0, disc.D0_flagged
    flagged = dmap.flagged_cells()
    penalty = math.log(disc.n_terms)
    names = options.effects if options.effects is not None else registry.names("effect")
    supported = _supported_effects(problem.simulator)
    J0 = j_of_spectra(problem, y_sim)[0]
    local = fit_local(disc, dmap.flagged, disc.base_means, penalty) if flagged else None
    ranking: list[Candidate] = []
    fitter = EffectFitter(config, problem, w, disc, flagged, options, log, blocked=blocked)
    for name in names:
        if name in exclude:
            continue
        try:
            cls = registry.get("effect", name)
        except UnknownPluginError as exc:
            raise ConfigError(str(exc), file=str(config.source_file), key="diagnose.effects") from None
        if supported is not None and name not in supported:
            ranking.append(Candidate(name, f"not supported by simulator {config.simulator.plugin}"))
            continue
        if not flagged:
            ranking.append(Candidate(name, "not fitted: no flagged cell"))
            continue
        t0 = time.perf_counter()
        cand = fitter.fit(cls)
        if cand.status == "fitted":
            cand.delta_D = D0 - cand.D
            cand.explained = cand.delta_D_flagged / D0_f if D0_f > 0 else 0.0
            cand.score = cand.delta_D - penalty * cand.n_parameters
            cand.delta_J = j_of_spectra(problem, cand.y_sim)[0] - J0
            evidence, cand.own = effect_evidence(cls, cand, disc, dmap, null, problem, options, local, penalty)
            cand.evidence.update(evidence)
        log(f"  {name}: {cand.status}, score {cand.score:.1f} ({cand.evaluations} simulations, "
            f"{time.perf_counter() - t0:.1f} s)")
        ranking.append(cand)
    ranking.sort(key=lambda c: -c.score)
    bumps: dict[int, Candidate] = {}
    for p in sorted({c.n_parameters for c in ranking if c.status == "fitted"}):
        b = fit_bump(disc, dmap, p)
        if b.status == "fitted":
            b.delta_D = D0 - b.D
            b.explained = b.delta_D_flagged / D0_f if D0_f > 0 else 0.0
            b.score = b.delta_D - penalty * p
        bumps[p] = b
    named, reason = decide(ranking, bumps, dmap, options)
    unexplained = unexplained_regions(dmap, ranking, named, exclude) if dmap.flagged.any() else []
    return Ranking(ranking, bumps, local, named, reason, unexplained)


def effect_evidence(cls, cand: Candidate, disc: Discrepancy, dmap: DiscrepancyMap, null: NullCalibration,
                    problem, options: DiagnoseOptions, local: LocalFit | None, penalty: float
                    ) -> tuple[dict[str, Any], np.ndarray]:
    """What the naming rule reads about one fitted effect.

    - its cells S: the flagged cells its signature covers, plus every cell whose band mean it changes by more
      than half the cell's null sd;
    - the share of D in the bins of S it explains (``explained_own``);
    - the after-map (the same tests with the effect added): flagged cells in S before and after, and the new
      flagged cells (flagged after, not before) anywhere;
    - the local discrepancy model with and without the effect: ``score_vs_local`` = score(effect + local) -
      score(local alone), both penalised per parameter.
    """
    grid = dmap.grid
    effect = cls(**{k: v for k, v in cand.parameters.items() if k in cls.Options.model_fields})
    cells = dmap.flagged_cells()
    idx = np.nonzero(dmap.flagged)[0]
    covered = set(effect.matching_cells(cells))
    in_sig = np.zeros(grid.n_cells, bool)
    for c, cell in zip(idx, cells):
        in_sig[c] = cell in covered
    y_cand = problem.noise_model.effective(cand.y_sim)       # through the sensor-noise floor, if any
    change = np.abs(grid.cell_means(y_cand) - (disc.base_means @ grid.average).ravel())
    changed = change > 0.5 * null.scale
    own = in_sig | changed
    own_bins = grid.cell_to_bins(own.astype(float)) > 0
    cand_means = grid.group_means(y_cand)
    D_own0, D_own1 = disc.within(own_bins, disc.base_means), disc.within(own_bins, cand_means)
    after = locate(grid, null, problem.y_mes, y_cand, null.noise_mean, options.alpha, options.min_db)
    new = after.flagged & ~dmap.flagged
    # per channel: the channels the effect changes (a cell's band mean by more than half its null sd) and the
    # change of D over each channel's bins (positive: the effect brings the model closer to the data there)
    G, K, B = len(grid.speeds), len(grid.channels), grid.band_edges.shape[0]
    changed_channels = changed.reshape(G, K, B).any(axis=(0, 2))
    z0 = ((disc.target - disc.base_means) / disc.scale) ** 2
    z1 = ((disc.target - cand_means) / disc.scale) ** 2
    delta_channel = (z0 - z1).sum(axis=(0, 2))
    null_sd = channel_null_sd(problem.noise_model, G)
    out = {"own_cells": int(own.sum()), "explained_own": (1.0 - D_own1 / D_own0) if D_own0 > 0 else 0.0,
           "channels_changed": [c for c, k in zip(grid.channels, changed_channels) if k],
           "delta_D_by_channel": {c: round(float(d), 3) for c, d, k in zip(grid.channels, delta_channel,
                                                                        changed_channels) if k},
           "null_sd_D_by_channel": {c: round(float(sd), 3) for c, sd, k in zip(grid.channels, null_sd,
                                                                            changed_channels) if k},
           "flagged_own_before": int((dmap.flagged & own).sum()), "flagged_own_after": int((after.flagged & own).sum()),
           "flagged_after": int(after.flagged.sum()), "new_flagged": int(new.sum()),
           "new_flagged_cells": [r for r, n in zip(after.rows(), new) if n][:20]}
    out["new_flagged_cells"] = [{k: r[k] for k in ("channel", "f_low_hz", "f_high_hz", "speed_kmh", "magnitude_db")}
                                for r in out["new_flagged_cells"]]
    if local is not None:
        with_effect = fit_local(disc, dmap.flagged | after.flagged, cand_means, penalty)
        out["score_local_alone"] = local.score(disc.D0, penalty)
        out["score_effect_plus_local"] = with_effect.score(disc.D0, penalty, cand.n_parameters)
        out["score_vs_local"] = out["score_effect_plus_local"] - out["score_local_alone"]
    return out, own


def decide(ranking: list[Candidate], bumps: dict[int, Candidate], dmap: DiscrepancyMap,
           options: DiagnoseOptions) -> tuple[str | None, str]:
    """The naming rule: ``(name or None, reason)``; sets each rejected candidate's ``reason``.

    Only the best-scoring effect may be named (a weaker one waits for the next step, once the best is added or
    reported as unexplained); every candidate gets its ``reason`` for the report. Checks, on the evidence of
    :func:`effect_evidence` when it is there: it beats the runner-up and the fixed bump of its size by
    ``margin``; an effect that changes several channels does not, outside the channel it improves most, take
    the model further from the data (D up by more than ``margin`` over the others), since a discrepancy that
    one channel supports and the others contradict is what a fault of that sensor (a bracket resonance, a
    calibration) gives as well; it explains at least ``min_explained`` of D in
    its own cells (the counts of flagged cells, in
    its cells and new ones, are checked after the joint fit, :func:`check_after_joint_fit`: at biased base
    parameters, which absorbed part of the effect, they can grow while D shrinks); with
    it, the local discrepancy model does better by at least ``margin`` than the local model alone.
    """
    if not dmap.flagged.any():
        return None, "no cell is flagged: no discrepancy beyond the noise model"
    fitted = [c for c in ranking if c.status == "fitted"]
    if not fitted:
        return None, "unexplained discrepancy: no effect's signature covers the flagged cells"
    n_before = int(dmap.flagged.sum())
    for i, c in enumerate(fitted):
        c.reason = _rejection(c, fitted[i + 1] if i + 1 < len(fitted) else None, bumps.get(c.n_parameters),
                              n_before, options)
    best = fitted[0]
    if best.reason is not None:
        return None, (f"unexplained discrepancy: no catalogue effect fits (best: {best.effect}, rejected because "
                      f"{best.reason})")
    runner = fitted[1] if len(fitted) > 1 else None
    ev = best.evidence
    bump = bumps.get(best.n_parameters)
    extra = (f"; it explains {100 * ev['explained_own']:.0f} % of D in its {ev['own_cells']} cells, flagged cells "
             f"there {ev['flagged_own_before']} → {ev['flagged_own_after']}, {ev['new_flagged']} new elsewhere"
             if "explained_own" in ev else f"; it explains {100 * best.explained:.0f} % of the flagged discrepancy")
    vs_local = (f"; with it a local discrepancy model does better by {ev['score_vs_local']:.1f}"
                if "score_vs_local" in ev else "")
    return best.effect, (f"{best.effect} scores {best.score:.1f}, against "
                         f"{f'{runner.effect} ({runner.score:.1f})' if runner else 'no other candidate'} and "
                         f"a generic bump of {best.n_parameters} parameters "
                         f"({bump.score if bump is not None else float('nan'):.1f}){extra}{vs_local}")


def check_after_joint_fit(before: DiscrepancyMap, after: DiscrepancyMap, own: np.ndarray | None,
                          options: DiagnoseOptions) -> str | None:
    """The after-map check of a named effect at the jointly fitted model: the flagged cells in its own cells
    shrink, at most ``max_new_flagged`` (share of the flagged cells before; one at least: a cell at the edge of
    the test) new ones appear in the cells it changes, and the flagged cells in all grow by no more than that
    allowance (elsewhere, a cell or two come and go with the refitted suspension: 2 → 3 is no evidence against
    an effect that cleared its own cells).

    :returns: why the effect is rejected, or None.
    """
    n0, n1 = int(before.flagged.sum()), int(after.flagged.sum())
    # new flags in the cells the effect changes: elsewhere, new flags come from the re-identified suspension
    # (the model-form background the first identification had hidden), not from the effect
    new = int((after.flagged & ~before.flagged & (own if own is not None else True)).sum())
    allowance = max(1.0, options.max_new_flagged * n0)
    if n1 > n0 + allowance or (n1 >= n0 and own is None):
        return f"after the joint fit the flagged cells do not shrink ({n0} → {n1})"
    if own is not None and own.any() and int((after.flagged & own).sum()) >= max(1, int((before.flagged & own).sum())):
        return (f"after the joint fit the flagged cells in its own cells do not shrink "
                f"({int((before.flagged & own).sum())} → {int((after.flagged & own).sum())})")
    if new > allowance:
        return f"after the joint fit it flags {new} new cells among those it changes"
    return None


def _rejection(best: Candidate, runner: Candidate | None, bump: Candidate | None, n_before: int,
               options: DiagnoseOptions) -> str | None:
    """Why ``best`` may not be named (every failed check, joined), or None."""
    why = []
    if runner is not None and best.score - runner.score < options.margin:
        why.append(f"it does not beat {runner.effect} clearly (scores {best.score:.1f} and {runner.score:.1f}, "
                   f"margin {options.margin:g})")
    if bump is not None and bump.status == "fitted" and best.score - bump.score < options.margin:
        why.append(f"it does not beat a generic bump of {best.n_parameters} parameters clearly "
                   f"(scores {best.score:.1f} and {bump.score:.1f})")
    ev = best.evidence
    explained = ev.get("explained_own", best.explained)
    if explained < options.min_explained:
        where = "in its own cells" if "explained_own" in ev else "of the flagged discrepancy"
        why.append(f"it explains only {100 * explained:.0f} % of D {where} (needs {100 * options.min_explained:.0f} %)")
    if len(ev.get("channels_changed", ())) >= 2:
        by_channel = ev["delta_D_by_channel"]
        best_channel = max(by_channel, key=by_channel.get)
        elsewhere = sum(d for c, d in by_channel.items() if c != best_channel)
        # in the units of those channels' D under the null: a side effect within its fluctuation is no evidence
        sd = ev.get("null_sd_D_by_channel") or {}
        sd_else = math.sqrt(sum(v ** 2 for c, v in sd.items() if c != best_channel)) if sd else 0.0
        if elsewhere < -(options.margin + VETO_SIGMAS * sd_else):
            why.append(f"outside {best_channel}, the {len(by_channel) - 1} other channels it changes move away from "
                       f"the data (D up by {-elsewhere:.1f}, beyond {VETO_SIGMAS:g} null sd of their D, "
                       f"{sd_else:.1f}): the data there contradict it, and a fault of that sensor explains the "
                       f"discrepancy as well")
    if "score_vs_local" in ev and ev["score_vs_local"] < options.margin:
        why.append(f"a local discrepancy model (a free bump per flagged channel) explains the data as well without "
                   f"it (score with the effect {ev['score_effect_plus_local']:.1f}, without "
                   f"{ev['score_local_alone']:.1f})")
    return "; ".join(why) or None


VETO_SIGMAS = 2.0
"""How many null standard deviations of the other channels' D their worsening must exceed to veto an effect."""


def channel_correlation(noise_model, k: int) -> np.ndarray:
    """``(F, F)`` the correlation of channel ``k``'s whitened bins under the noise model (low rank plus diagonal,
    as in :mod:`.joint`)."""
    K, F = noise_model.variance_.shape
    sd = np.sqrt(np.maximum(noise_model.variance_.ravel(), 1e-30))
    sl = slice(k * F, (k + 1) * F)
    phi = noise_model.components_[:, sl] / sd[None, sl]
    lam = (1.0 - noise_model.shrinkage_) * noise_model.eigenvalues_
    dd = noise_model.residual_variance_.ravel()[sl] / sd[sl] ** 2
    return phi.T @ (lam[:, None] * phi) + np.diag(dd)


FLAT_SIGMAS = 2.0
"""A channel-level gain is flat: the rms of its band means about the channel mean within this many band null sd."""


def channel_gains(dmap: DiscrepancyMap, noise_model, alpha: float) -> list[dict[str, Any]]:
    """Channel-level gains: a calibration error g moves a channel's whole spectrum by 10 log10 g dB (Y = 5 log10
    of the power, eq. 2), which can stay below ``min_db`` in every cell and still be certain over the channel.

    Per channel: the mean m̄ of its mean residuals over every bin and speed group, against its null sd
    sqrt(Σ σ_b σ_b' R_bb') / n (σ the bins' null sd, R their correlation under the noise model: a model-form
    error moves whole spectra, so the bins are far from independent); two-sided, Bonferroni over the channels
    at ``alpha``. A gain is flat: the rms of the channel's band means about m̄ must stay within
    :data:`FLAT_SIGMAS` of their null sd (a resonance that lifts the channel's mean is not a gain). A channel
    with a twin (:func:`.coupling.twin`) must also differ from it (m̄ - m̄_twin against the two sd, at the same
    level): a calibration is one sensor's; the same gain on both twins is not found.

    :returns: per channel ``{channel, mean_db, sd_db, z, p, gain, significant, band_spread_db, band_sd_db,
        flat, twin, z_twin}``.
    """
    from scipy.stats import norm

    grid = dmap.grid
    r, sd = dmap.bin_residual, dmap.bin_sd                           # (G, K, F) dB
    G, K, F = r.shape
    out = []
    for k in range(K):
        R = channel_correlation(noise_model, k)
        var = sum(float(sd[g, k] @ R @ sd[g, k]) for g in range(G)) / (G * F) ** 2
        m = float(r[:, k].mean())
        s = math.sqrt(max(var, 1e-30))
        z = m / s
        p = float(2 * norm.sf(abs(z)))
        bands = (r[:, k] @ grid.average).ravel()
        spread = float(np.sqrt(np.mean((bands - m) ** 2)))
        band_sd = float(np.sqrt(np.mean((sd[:, k] @ grid.average) ** 2)))   # bins fully correlated: an upper bound
        flat = spread <= FLAT_SIGMAS * band_sd
        out.append({"channel": grid.channels[k], "mean_db": round(m, 4), "sd_db": round(s, 4), "z": round(z, 3),
                    "p": p, "gain": round(10 ** (m / 10.0), 4), "significant": bool(p < alpha / K and flat),
                    "band_spread_db": round(spread, 4), "band_sd_db": round(band_sd, 4), "flat": bool(flat),
                    "twin": None, "z_twin": None})
    # one sensor's calibration sets it apart from its twin (the same sensor at the other end); a level the model
    # misses at the fitted suspension moves both alike (a bracket the fit compromised with: both bogie verticals
    # -0.2 dB, 0.05 dB apart)
    by_name = {row["channel"]: row for row in out}
    for row in out:
        t = twin(row["channel"], list(by_name))
        if t is None:
            continue
        other = by_name[t]
        d = row["mean_db"] - other["mean_db"]
        z_t = d / math.hypot(row["sd_db"], other["sd_db"])
        row.update(twin=t, z_twin=round(z_t, 3),
                   significant=bool(row["significant"] and 2 * norm.sf(abs(z_t)) < alpha / K))
    return out


def channel_null_sd(noise_model, n_groups: int) -> np.ndarray:
    """``(K,)`` the standard deviation of each channel's D (its whitened squared mean residuals, summed over its
    bins and ``n_groups`` speed groups) under the null: D_k = Σ e², e ~ N(0, R_k), Var D_k = 2 tr(R_k²) per group,
    R_k the correlation of the channel's bins under the noise model (low rank plus diagonal, as in
    :mod:`.joint`). Bins taken as independent would give sqrt(2 F): far too small where the model-form error
    moves whole spectra together."""
    K = noise_model.variance_.shape[0]
    return np.array([math.sqrt(2.0 * n_groups * float(np.sum(channel_correlation(noise_model, k) ** 2)))
                     for k in range(K)])


def unexplained_regions(dmap: DiscrepancyMap, ranking: list[Candidate], named: str | None,
                        added: Sequence[str] = ()) -> list[dict[str, Any]]:
    """Flagged cells no named effect covers, merged into contiguous bands per (speed, channel): each with the
    band, its largest magnitude, the best candidate whose signature covers it and why that one was rejected
    (``added``: effects already in the model, named at earlier steps)."""
    grid = dmap.grid
    rows = [r for r in dmap.rows(only_flagged=True)]
    fitted = [c for c in ranking if c.status == "fitted"]
    out: list[dict[str, Any]] = []
    key = lambda r: (r["speed_kmh"], r["channel"])  # noqa: E731
    for (speed, channel), group in _groupby(sorted(rows, key=lambda r: (key(r), r["f_low_hz"])), key):
        runs: list[list[dict]] = []
        for r in group:
            if runs and abs(runs[-1][-1]["f_high_hz"] - r["f_low_hz"]) < 1e-6:
                runs[-1].append(r)
            else:
                runs.append([r])
        for run in runs:
            lo, hi = run[0]["f_low_hz"], run[-1]["f_high_hz"]
            top = max(run, key=lambda r: abs(r["magnitude_db"]))
            covering = [c for c in fitted if _covers(c, channel, lo, hi, speed / 3.6)]
            if named is not None and any(c.effect == named for c in covering):
                continue
            best = covering[0] if covering else None
            why = (f"best: {best.effect}, rejected because {best.reason}" if best is not None and best.reason
                   else f"best: {best.effect}" if best is not None else "no catalogue effect's signature covers it")
            left = [n for n in added if registry.get("effect", n)().matching_cells([(channel, lo, hi, speed / 3.6)])]
            if left:
                why = f"left after {', '.join(left)} was added; {why}"
            out.append({"channel": channel, "speed_kmh": speed, "f_low_hz": lo, "f_high_hz": hi,
                        "magnitude_db": top["magnitude_db"], "n_cells": len(run),
                        "best_effect": best.effect if best is not None else None,
                        "text": (f"unexplained: channel {channel}, band {lo:.3g}-{hi:.3g} Hz"
                                 f"{f' at {speed:.0f} km/h' if len(grid.speeds) > 1 else ''}, "
                                 f"{top['magnitude_db']:+.1f} dB, no catalogue effect fits ({why})")})
    return out


def _covers(cand: Candidate, channel: str, lo: float, hi: float, speed: float) -> bool:
    cls = registry.get("effect", cand.effect)
    effect = cls(**{k: v for k, v in cand.parameters.items() if k in cls.Options.model_fields})
    return bool(effect.matching_cells([(channel, lo, hi, speed)]))


def _groupby(items, key):
    out: dict[Any, list] = {}
    for it in items:
        out.setdefault(key(it), []).append(it)
    return out.items()


def _supported_effects(simulator) -> set[str] | None:
    """Effects the simulator implements: none without an ``effects`` option, its ``supported_effects()``
    when it has that method, else ``None`` (unknown: every candidate is tried, a refusal ranks it unsupported)."""
    model = getattr(type(simulator), "Options", None)
    if model is None or "effects" not in getattr(model, "model_fields", {}):
        return set()
    supported = getattr(simulator, "supported_effects", None)
    return set(supported()) if callable(supported) else None
