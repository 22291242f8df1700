"""Naming: rank every candidate effect against the generic bumps and decide which, if any, is named.

Method: ``docs/diagnose.md``, "Name".
"""

from __future__ import annotations

import math
import time
from typing import Callable

import numpy as np

from suspid import registry
from suspid.config import Config
from suspid.errors import ConfigError, UnknownPluginError
from suspid.workflows.evaluation import j_of_spectra

from .fit import Candidate, Discrepancy, EffectFitter, fit_bump
from .locate import DiscrepancyMap
from .null import NullCalibration
from suspid.sections import DiagnoseOptions


def rank_effects(config: Config, problem, w: dict[str, float], y_sim: np.ndarray, dmap: DiscrepancyMap,
                 null: NullCalibration, options: DiagnoseOptions, log: Callable[[str], None] = lambda s: None
                 ) -> tuple[list[Candidate], dict[int, Candidate], str | None, str]:
    """Fit every candidate effect and the bumps, rank them, and decide which (if any) is named.

    :returns: ``(ranking, bumps by size, named or None, reason)``.
    """
    disc = Discrepancy(dmap.grid, null, problem.y_mes, problem.noise_model, dmap.flagged, y_sim)
    D0, D0_f = disc.D0, disc.D0_flagged
    flagged = dmap.flagged_cells()
    penalty = math.log(disc.n_terms)
    names = options.effects if options.effects is not None else registry.names("effect")
    supported = _supported_effects(problem.simulator)
    J0 = j_of_spectra(problem, y_sim)[0]
    ranking: list[Candidate] = []
    fitter = EffectFitter(config, problem, w, disc, flagged, options, log)
    for name in names:
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
    return ranking, bumps, named, reason


def decide(ranking: list[Candidate], bumps: dict[int, Candidate], dmap: DiscrepancyMap,
           options: DiagnoseOptions) -> tuple[str | None, str]:
    """The naming rule: ``(name or None, reason)``."""
    if not dmap.flagged.any():
        return None, "no cell is flagged: no discrepancy beyond the noise model"
    fitted = [c for c in ranking if c.status == "fitted"]
    if not fitted:
        return None, "unexplained discrepancy: no effect's signature covers the flagged cells"
    best = fitted[0]
    if len(fitted) > 1 and best.score - fitted[1].score < options.margin:
        return None, (f"unexplained discrepancy: {best.effect} does not beat {fitted[1].effect} clearly "
                      f"(scores {best.score:.1f} and {fitted[1].score:.1f}, margin {options.margin:g})")
    bump = bumps.get(best.n_parameters)
    if bump is not None and bump.status == "fitted" and best.score - bump.score < options.margin:
        return None, (f"unexplained discrepancy: {best.effect} does not beat a generic bump of "
                      f"{best.n_parameters} parameters clearly (scores {best.score:.1f} and {bump.score:.1f})")
    if best.explained < options.min_explained:
        return None, (f"unexplained discrepancy: {best.effect} explains only {100 * best.explained:.0f} % of the "
                      f"flagged discrepancy (needs {100 * options.min_explained:.0f} %)")
    runner = f"{fitted[1].effect} ({fitted[1].score:.1f})" if len(fitted) > 1 else "no other candidate"
    return best.effect, (f"{best.effect} scores {best.score:.1f}, against {runner} and a generic bump of "
                         f"{best.n_parameters} parameters ({bump.score:.1f}); it explains "
                         f"{100 * best.explained:.0f} % of the flagged discrepancy")


def _supported_effects(simulator) -> set[str] | None:
    """Effects the simulator implements: none without an ``effects`` option, its ``supported_effects()``
    when it has that method, else ``None`` (unknown: every candidate is tried, a refusal ranks it unsupported)."""
    model = getattr(type(simulator), "Options", None)
    if model is None or "effects" not in getattr(model, "model_fields", {}):
        return set()
    supported = getattr(simulator, "supported_effects", None)
    return set(supported()) if callable(supported) else None
