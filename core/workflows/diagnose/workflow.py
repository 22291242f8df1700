"""``run_diagnose``: the whole workflow, from a config file to ``diagnosis.json`` and ``diagnosis.md``."""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from suspid.config import Config, load_config
from suspid.infra.files import canonical, write_json
from suspid.infra.seeds import rng as named_rng
from suspid.infra.threads import single_blas_thread
from suspid.workflows.evaluation import j_of_spectra

from .cells import make_cells
from .locate import locate
from .name import rank_effects
from .null import calibrate_null
from .reidentify import Stage, make_stage, write_augmented
from .report import write_diagnosis_report


@dataclass
class DiagnosisResult:
    """A finished diagnosis: its folder and the content of ``diagnosis.json``."""

    out_dir: Path
    diagnosis: dict[str, Any]

    @property
    def named(self) -> str | None:
        """The named effect, or None."""
        return self.diagnosis["named"]


def run_diagnose(source: str | Path | Mapping[str, Any], overrides: Sequence[str], config: Config, *,
                 fresh: bool = False, progress: bool = False, log: Callable[[str], None] = lambda s: None
                 ) -> DiagnosisResult:
    """Diagnose ``config``: writes diagnosis.json, diagnosis.md and figures in its run folder.

    :param source: the config file or mapping ``config`` was loaded from (with ``overrides``).
    :param fresh: start the identifications over.
    :param progress: show progress bars.
    :param log: where progress lines go.
    """
    t_start = time.perf_counter()
    opts = config.diagnose
    out_dir = config.run_dir()
    out_dir.mkdir(parents=True, exist_ok=True)
    before = make_stage("before", config, opts.at == "identified", out_dir / "before", fresh=fresh,
                        progress=progress, log=log)
    problem = before.problem
    grid = make_cells(problem.channels, problem.freqs, [s.mean_speed for s in problem.segments],
                      opts.bands_per_octave, opts.min_bins_per_band)
    log(f"locate: {grid.n_cells} cells, null calibrated by {opts.n_bootstrap} bootstrap replicates")
    with single_blas_thread():     # small products: OpenBLAS threads only contend (suspid.infra.threads)
        null = calibrate_null(grid, problem.noise_model, opts.n_bootstrap,
                              named_rng(config.seed, "diagnose-bootstrap"))
        mu = problem.noise_model.mean_
        before.dmap = locate(grid, null, problem.y_mes, before.y_sim, mu, opts.alpha)
        before.dmap.J = j_of_spectra(problem, before.y_sim)[0]
        log(f"located: {int(before.dmap.flagged.sum())} flagged cells; ranking the effects")
        t_rank = time.perf_counter()
        ranking, bumps, named, reason = rank_effects(config, problem, before.w, before.y_sim, before.dmap, null,
                                                     opts, log)
        rank_s = time.perf_counter() - t_rank
    log(f"named: {named or 'nothing'} ({reason})")
    after, aug_path = None, None
    if named is not None:
        cand = next(c for c in ranking if c.effect == named)
        aug_path = write_augmented(config, cand, out_dir, out_dir / "before" / "noise_model.npz")
        aug = load_config(aug_path)
        if opts.reidentify:
            after = make_stage("after", aug, True, out_dir / "after", fresh=fresh, progress=progress, log=log)
        else:
            after = Stage("after", aug, problem, before.w, cand.y_sim, None)
        after.dmap = locate(grid, null, after.problem.y_mes, after.y_sim, after.problem.noise_model.mean_,
                            opts.alpha)
        after.dmap.J = j_of_spectra(after.problem, after.y_sim)[0]
    diagnosis = {
        "name": config.name,
        "config": str(config.source_file),
        "base_model": opts.at,
        "flagged": [{k: r[k] for k in ("channel", "f_low_hz", "f_high_hz", "sign", "magnitude_db", "test", "z", "q",
                                       "speed_kmh")} for r in before.dmap.rows(only_flagged=True)],
        "ranking": [c.as_dict() for c in ranking],
        "generic_bumps": {str(p): b.as_dict() for p, b in bumps.items()},
        "named": named,
        "reason": reason,
        "named_parameters": next((canonical(c.parameters) for c in ranking if c.effect == named), None),
        "gap_before": before.gap(),
        "gap_after": after.gap() if after is not None else None,
        "augmented_config": str(aug_path) if aug_path is not None else None,
        "statistics": {
            "cells": "speed group x channel x band", "n_cells": grid.n_cells,
            "bands_hz": grid.band_edges.round(4).tolist(),
            "statistic": "per cell: band mean of r = y_mes - y_sim - mu_B (mean test), sum of squared "
                         "standardised bin means (shape test), largest standardised bin mean (peak test); "
                         "p = min(1, 3 min(p_mean, p_shape, p_peak))",
            "null": "mean: N(0, kappa_c^2 s_c^2), s_c from the noise covariance; shape: a_c chi2(nu_c); "
                    "peak: Bonferroni over the band's bins; kappa, a_c, nu_c from a parametric bootstrap",
            "n_bootstrap": null.n_bootstrap, "kappa_median": float(np.median(null.kappa)),
            "kappa_raw_median": None if null.kappa_raw is None else float(np.median(null.kappa_raw)),
            "bootstrap_null_rate_at_5pct": null.null_rate, "fdr": "Benjamini-Yekutieli", "alpha": opts.alpha,
            "penalty_per_parameter": math.log(grid.n_cells // grid.band_edges.shape[0] * grid.freqs.size),
            "margin": opts.margin,
            "min_explained": opts.min_explained},
        "map_before": before.dmap.rows(),
        "map_after": after.dmap.rows() if after is not None else None,
        "wall_time_s": None, "ranking_time_s": round(rank_s, 2),
    }
    diagnosis["wall_time_s"] = round(time.perf_counter() - t_start, 2)
    diagnosis = canonical(diagnosis)
    write_json(out_dir / "diagnosis.json", diagnosis)
    write_diagnosis_report(out_dir, diagnosis, before, after, ranking, bumps)
    return DiagnosisResult(out_dir, json.loads(json.dumps(diagnosis)))
