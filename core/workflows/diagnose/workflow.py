"""``run_diagnose``: the whole workflow, from a config file to ``diagnosis.json`` and ``diagnosis.md``.

Method: ``docs/diagnose.md`` (steps 3-6).
"""

from __future__ import annotations

import dataclasses
import json
import math
import shutil
import time
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from suspid import registry
from suspid.config import Config
from suspid.data.corrections import untilt
from suspid.errors import SimulatorError
from suspid.infra.files import canonical, write_json
from suspid.infra.ledger import stable_hash
from suspid.infra.seeds import rng as named_rng
from suspid.infra.threads import single_blas_thread
from suspid.workflows.evaluation import j_of_spectra
from suspid.method.spectra import compute_spectra
from suspid.workflows.problem import read_measurements
from suspid.workflows.tasks import simulate_spectra
from suspid.workflows.trust import checks_report, trust_states

from .cells import CellGrid, make_cells
from .coupling import coupling_test, pooled_tilt
from .fit import Discrepancy
from .joint import check_groups, fit_jointly
from .locate import locate
from .name import (Ranking, _supported_effects, channel_gains, check_after_joint_fit, rank_effects,
                   unexplained_regions)
from .null import NullCalibration, calibrate_null
from .reidentify import Stage, augmented_config, make_stage, write_augmented
from .report import write_diagnosis_report
from .result import DiagnosisResult, DiagnosisStatistics, NamedEffect, SequenceRow, joint_fit_text


def run_diagnose(source: str | Path | Mapping[str, Any], overrides: Sequence[str], config: Config, *,
                 fresh: bool = False, progress: bool = False, log: Callable[[str], None] = lambda s: None
                 ) -> DiagnosisResult:
    """Diagnose ``config``: writes diagnosis.json, diagnosis.md and figures in its run folder.

    Steps: identify (or take the nominal model) and fit the suspension under D, locate, name an effect (a
    tilted sensor first, from the coupling of the records, corrected in them); add it, fit it together with the
    suspension, locate again and name the next one, until nothing more is named, nothing is flagged, or
    ``diagnose.max_effects`` effects are named.

    :param source: the config file or mapping ``config`` was loaded from (with ``overrides``).
    :param fresh: start the identifications over.
    :param progress: show progress bars.
    :param log: where progress lines go.
    """
    t_start = time.perf_counter()
    opts = config.diagnose
    out_dir = config.run_dir()
    out_dir.mkdir(parents=True, exist_ok=True)
    noise_path = out_dir / "before" / "noise_model.npz"
    before = make_stage("before", config, opts.at == "identified", out_dir / "before", fresh=fresh,
                        progress=progress, log=log)
    problem = before.problem
    grid = make_cells(problem.channels, problem.freqs, problem.speeds,
                      opts.bands_per_octave, opts.min_bins_per_band)
    log(f"locate: {grid.n_cells} cells, null calibrated by {opts.n_bootstrap} bootstrap replicates")
    named: list[tuple[str, dict[str, Any], int]] = []
    in_data: dict[str, list[dict[str, Any]]] = {}   # effects corrected in the measured records: data.corrections
    steps: list[dict[str, Any]] = []
    coupling, records = _coupling(config, problem, log)
    rankings: list[Ranking] = []
    rank_s = 0.0
    with single_blas_thread():     # small products: OpenBLAS threads only contend (suspid.infra.threads)
        null = calibrate_null(grid, problem.noise_model, opts.n_bootstrap,
                              named_rng(config.seed, "diagnose-bootstrap"))
        if opts.at == "identified" and opts.fit_suspension:
            _fit_suspension(before, config, grid, null, log)
        _locate(before, grid, null, opts.alpha)
        current = before
        coupling_tried = False
        for step in range(1, opts.max_effects + 1):
            tilted = [r for r in (coupling or []) if r["significant"]]
            if tilted and not coupling_tried and _eligible(config, problem, "sensor-tilt"):
                coupling_tried = True
                record, stage = _tilt_from_coupling(config, named, in_data, tilted, coupling, records, current, step,
                                                    grid, null, out_dir, noise_path, fresh, progress, log)
                steps.append(record)
                rankings.append(Ranking([], {}, None, record["named"], record["reason"], []))
                if stage is None:       # retracted: the catalogue is ranked at the next step, on the data as they are
                    continue
                current = stage
                if not current.dmap.flagged.any():
                    break
                continue
            log(f"step {step}: {int(current.dmap.flagged.sum())} flagged cells; ranking the effects")
            t_rank = time.perf_counter()
            cfg_now = _with_effects(config, _model_effects(named, in_data))
            # an effect named on some channels may extend to others (a tilt corrected in the records on some
            # lateral channels, in the model on others), never twice on one channel
            corrected = {c["channel"] for c in _corrections(in_data)}
            rk = rank_effects(cfg_now, current.problem, current.w, current.y_sim, current.dmap, null, opts, log,
                              exclude=[n for n, p, _ in named if p.get("applied") != CORRECTED],
                              blocked={"sensor-tilt": corrected})
            rank_s += time.perf_counter() - t_rank
            rankings.append(rk)
            log(f"step {step}: named {rk.named or 'nothing'} ({rk.reason})")
            record: dict[str, Any] = {"step": step, "named": rk.named, "reason": rk.reason,
                                      "gap_before": current.gap(), "unexplained": rk.unexplained,
                                      "ranking": [c.as_dict() for c in rk.candidates],
                                      "local_model": rk.local.as_dict(grid) if rk.local is not None else None}
            steps.append(record)
            if rk.named is None:
                break
            cand = next(c for c in rk.candidates if c.effect == rk.named)
            saved = list(named)          # the joint fit refits every named effect: restored if this one is retracted
            named.append((cand.effect, dict(cand.parameters), cand.n_parameters))
            stage, record["joint_fit"] = _add_and_fit(config, named, in_data, cand, current, step, grid, null,
                                                      out_dir, noise_path, fresh, progress, log)
            rejected = check_after_joint_fit(current.dmap, stage.dmap, cand.own, opts)
            if rejected is not None:   # the after-map decides: the effect is not named after all
                log(f"step {step}: {cand.effect} retracted: {rejected}")
                cand.reason = rejected
                named[:] = saved
                record.update(named=None, retracted=cand.effect, gap_retracted=stage.gap(),
                              reason=f"unexplained discrepancy: no catalogue effect fits (best: {cand.effect}, "
                                     f"rejected because {rejected})")
                record["unexplained"] = unexplained_regions(current.dmap, rk.candidates, None)
                if step == 1:
                    rk.named, rk.reason = None, record["reason"]
                break
            current = stage
            record["named_parameters"] = canonical(named[-1][1])
            record["effects_after"] = [{"name": n, "parameters": canonical(p)} for n, p, _ in named]
            record["gap_after"] = current.gap()
            if not current.dmap.flagged.any():
                break
    after = current if named else None
    aug_path = None
    if named:
        final_run = Path(current.config.output.dir)
        aug_path = write_augmented(config, _model_effects(named, in_data), out_dir, noise_path,
                                   corrections=_corrections(in_data))
        if final_run.resolve() != (out_dir / "after").resolve() and final_run.exists():
            shutil.copytree(final_run, out_dir / "after", dirs_exist_ok=True)
    first = next((r for r in rankings if r.candidates), rankings[0])
    last = steps[-1]
    unexplained = last["unexplained"] if last["named"] is None else (
        unexplained_regions(current.dmap, [], None) if current.dmap.flagged.any() else [])
    with single_blas_thread():
        gains = _channel_gains(config, current, named, in_data, grid, null, log)
    unexplained = list(unexplained) + [_gain_region(g, grid) for g in gains if g["significant"]]
    reported = _reported_suspension(current, config, grid, null, log)
    out = DiagnosisResult(
        name=config.name,
        config=str(config.source_file),
        base_model=opts.at,
        flagged=[{k: r[k] for k in ("channel", "f_low_hz", "f_high_hz", "sign", "magnitude_db", "test", "z", "q",
                                    "speed_kmh")} for r in before.dmap.rows(only_flagged=True)],
        ranking=next((s["ranking"] for s in steps if s.get("ranking")), []),
        generic_bumps={str(p): b.as_dict() for p, b in first.bumps.items()},
        local_model=next((s["local_model"] for s in steps if s.get("local_model")), None),
        coupling=coupling,
        named=named[0][0] if named else None,
        named_effects=[n for n, _, _ in named],
        reason=steps[0]["reason"],
        named_parameters=canonical(named[0][1]) if named else None,
        effects=[NamedEffect(name=n, parameters=canonical(p)) for n, p, _ in named],
        steps=steps,
        sequence=[SequenceRow(step=s["step"], named=s["named"],
                              share_flagged_before=s["gap_before"]["share_flagged"],
                              share_flagged_after=s.get("gap_after", {}).get("share_flagged"),
                              integrated_db_hz_after=s.get("gap_after", {}).get("integrated_db_hz")) for s in steps],
        unexplained=unexplained,
        channel_gains=gains,
        suspension=reported,
        joint_fit=joint_fit_text(opts),
        gap_before=before.gap(),
        gap_after=after.gap() if after is not None else None,
        augmented_config=str(aug_path) if aug_path is not None else None,
        statistics=DiagnosisStatistics(
            n_cells=grid.n_cells, bands_hz=grid.band_edges.round(4).tolist(), min_db=opts.min_db,
            noise_mean_by_speed=problem.noise_model.speed_coverage(grid.speeds),
            n_bootstrap=null.n_bootstrap, kappa_median=float(np.median(null.kappa)),
            kappa_raw_median=None if null.kappa_raw is None else float(np.median(null.kappa_raw)),
            bootstrap_null_rate_at_5pct=null.null_rate, alpha=opts.alpha,
            penalty_per_parameter=math.log(grid.n_cells // grid.band_edges.shape[0] * grid.freqs.size),
            margin=opts.margin, min_explained=opts.min_explained, max_new_flagged=opts.max_new_flagged),
        map_before=before.dmap.rows(),
        map_after=after.dmap.rows() if after is not None else None,
        wall_time_s=round(time.perf_counter() - t_start, 2), ranking_time_s=round(rank_s, 2),
        out_dir=out_dir)
    diagnosis = out.to_json()
    write_json(out_dir / "diagnosis.json", diagnosis)
    write_diagnosis_report(out_dir, diagnosis, before, after, first.candidates, first.bumps)
    return DiagnosisResult.from_json(json.loads(json.dumps(diagnosis)), out_dir=out_dir)


def _channel_gains(config: Config, stage: Stage, named, in_data, grid: CellGrid, null: NullCalibration,
                   log: Callable[[str], None], max_channels: int = 2) -> list[dict[str, Any]]:
    """Channel-level gains (:func:`.name.channel_gains`), each measured at a suspension fitted under D without
    the bins that would bias it: the flagged cells left unexplained (a bracket resonance the fit compromises
    with moved the bogie verticals by -0.2 dB, z -4 to -5) and, for each significant channel (the
    ``max_channels`` strongest), that channel's own bins (a fit with them absorbs part of the gain: +8 % read as
    +5 %). A gain is reported when it is significant at the final model and stays so at both fits;
    ``gain_at_final_model`` keeps the first reading.
    """
    opts = config.diagnose
    problem = stage.problem
    if stage.fit is None or not opts.reidentify:
        return channel_gains(stage.dmap, problem.noise_model, opts.alpha)
    effects = _model_effects(named, in_data)
    fixed = {n for n, _ in effects}
    sim = getattr(stage.fit, "simulator", None)
    unexplained = grid.cell_to_bins(stage.dmap.flagged.astype(float)) > 0         # (G, K, F)

    def fit_without(mask: np.ndarray):
        disc = Discrepancy(grid, null, problem.y_mes, problem.noise_model, np.zeros(grid.n_cells, bool),
                           stage.y_sim)
        disc.scale = np.where(mask, np.inf, disc.scale)
        fit = fit_jointly(config, problem, disc, stage.w, effects, fixed,
                          max_evaluations=opts.joint_max_evaluations // 2, simulator=sim)
        return fit, locate(grid, null, problem.y_mes, problem.noise_model.effective(fit.y_sim), null.noise_mean,
                           opts.alpha, opts.min_db)

    dmap = stage.dmap
    if unexplained.any():
        _, dmap = fit_without(unexplained)
    first = {g["channel"]: g for g in channel_gains(stage.dmap, problem.noise_model, opts.alpha)}
    gains = channel_gains(dmap, problem.noise_model, opts.alpha)
    # significant at the final model too: a fit that leaves cells out can move a channel it barely constrains
    # (without the unexplained cells of a bending's remainder, the mid-car vertical sat +1.4 dB off, z 3.3,
    # against +1.1 dB, z 2.6, at the final model)
    strong = sorted([g for g in gains if g["significant"] and first[g["channel"]]["significant"]],
                    key=lambda g: -abs(g["z"]))[:max_channels]
    for g in gains:
        g["gain_at_final_model"] = first[g["channel"]]["gain"]
        g["z_at_final_model"] = first[g["channel"]]["z"]
        if g["significant"] and g not in strong:
            g["significant"] = False                                  # not confirmed: not reported
    for g in strong:
        k = grid.channels.index(g["channel"])
        mask = unexplained.copy()
        mask[:, k, :] = True
        fit, dmap_k = fit_without(mask)
        again = channel_gains(dmap_k, problem.noise_model, opts.alpha)[k]
        log(f"channel-level gain on {g['channel']}: {g['gain']:.4f}, {again['gain']:.4f} at the suspension fitted "
            f"without it (z {again['z']:.1f})")
        g.update({k_: again[k_] for k_ in ("gain", "mean_db", "sd_db", "z", "p", "band_spread_db", "band_sd_db",
                                           "flat", "significant")})
        g["refit_without_channel"] = {"w": fit.w, "D": round(fit.D, 3), "status": fit.status}
    return gains


def _gain_region(gain: dict[str, Any], grid: CellGrid) -> dict[str, Any]:
    """A channel-level gain as an unexplained region: the whole channel, every speed."""
    pct = 100.0 * (gain["gain"] - 1.0)
    return {"channel": gain["channel"], "speed_kmh": None, "f_low_hz": round(float(grid.band_edges[0, 0]), 4),
            "f_high_hz": round(float(grid.band_edges[-1, 1]), 4), "magnitude_db": gain["mean_db"],
            "best_effect": None, "kind": "channel-level gain", "gain": gain["gain"],
            "text": f"channel-level gain on {gain['channel']}: {pct:+.1f} % ({gain['mean_db']:+.2f} ± "
                    f"{gain['sd_db']:.2f} dB over the whole channel, z {gain['z']:.1f}, band spread "
                    f"{gain['band_spread_db']:.2f} dB); no catalogue effect fits: a calibration of that sensor"}


def suspension_trust(names: list[str], identifiable: Mapping[str, bool], groups_ran: bool) -> dict[str, Any]:
    """Trust per component of a suspension the diagnosis fitted (:func:`suspid.workflows.trust.trust_states`):
    no where the data-group check flags it; otherwise not assessed, since the reference-date self-check and the
    adequacy test do not run on the diagnosis's models."""
    checks = {"groups": "done" if groups_ran else "not run",
              "self_check": "not run on the diagnosis's models", "adequacy": "not run on the diagnosis's models"}
    flags = [[] if identifiable.get(n, True) else ["data groups: the parts of the data disagree or the bias-aware "
                                                   "half-width exceeds max_half_width"] for n in names]
    return {**trust_states(names, flags, checks), "checks": checks_report(checks)}


def _reported_suspension(stage: Stage, config: Config, grid: CellGrid, null: NullCalibration,
                         log: Callable[[str], None]) -> dict[str, Any] | None:
    """Which suspension the diagnosis reports, and why: the joint fit under D, or the re-identification with the
    configured objective (``stage.result``), whichever has the lower D (the criterion the map and the naming
    test; the identification's objective compares densities and can sit where the mean spectrum is not
    matched), with its trust per component: no when the data-group check flags it, otherwise not assessed
    (the reference-date self-check and the adequacy test do not run on the diagnosis's models).
    """
    fit = stage.fit
    if fit is None:
        return None
    problem = stage.problem
    names = list(problem.names)
    disc = Discrepancy(grid, null, problem.y_mes, problem.noise_model, np.zeros(grid.n_cells, bool), fit.y_sim)
    D_fit = disc.D0
    D_reid, w_reid = None, None
    if stage.result is not None and stage.result.get("w_opt"):
        w_reid = {n: float(stage.result["w_opt"][n]) for n in names if n in stage.result["w_opt"]}
        effects = {f"{n}/{q}": float(p[q]) for n, p in fit.effects for q in registry.get("effect", n).fitted}
        try:
            y = simulate_spectra(fit.simulator, {**fit.w, **w_reid, **effects}, problem.segments, config.spectra)[0]
            D_reid = Discrepancy(grid, null, problem.y_mes, problem.noise_model, np.zeros(grid.n_cells, bool),
                                 y).D0
        except SimulatorError as exc:       # a re-identified vehicle the simulator cannot run: not comparable
            log(f"the re-identified suspension could not be simulated: {exc}")
    use_fit = D_reid is None or D_fit <= D_reid
    trust = suspension_trust(names, fit.identifiable or {}, fit.model_error is not None)
    why = ("the lower D, the criterion the map and the naming rule test: " if D_reid is not None else "") + (
        f"D {D_fit:.1f} at the joint fit" + (f", {D_reid:.1f} at the re-identification" if D_reid is not None else
                                            ", no re-identification to compare"))
    return canonical({"source": "joint fit under D" if use_fit else "re-identification",
                      "why": why, "w": fit.w if use_fit else {**fit.w, **w_reid}, "D_joint_fit": D_fit,
                      "D_reidentified": D_reid, "w_reidentified": w_reid,
                      "trustworthy": trust["trustworthy"], "not_assessed": trust["not_assessed"],
                      "reasons": trust["reasons"], "checks": trust["checks"]})


def _eligible(config: Config, problem, name: str) -> bool:
    names = config.diagnose.effects if config.diagnose.effects is not None else registry.names("effect")
    supported = _supported_effects(problem.simulator)
    return name in names and (supported is None or name in supported)


def _coupling(config: Config, problem, log: Callable[[str], None]) -> tuple[list[dict[str, Any]] | None, list]:
    """The coupling test on the measured records, and the records (with ``data.corrections`` applied); None and
    no records for a numerical experiment: its data are spectra."""
    if config.data.source != "measured" or config.data.measurements is None:
        return None, []
    segments, records = read_measurements(config.data.measurements, config.data.track_file, problem.channels,
                                          accept=config.data.accept, strict=config.data.strict)
    records = untilt(records, config.data.corrections, problem.channels, error=config.error)
    opts = config.diagnose
    reference, ref_groups = None, None
    if opts.coupling_reference is not None:
        ref_segments, reference = read_measurements(opts.coupling_reference, opts.coupling_reference_track,
                                                    problem.channels, accept=config.data.accept,
                                                    strict=config.data.strict)
        ref_groups = _speed_groups(ref_segments)
    # every frequency of the records up to their Nyquist frequency: the coupling is a property of the sensor,
    # and the bins above the spectra band (where the vertical often dominates a bogie's lateral) weigh most.
    # The model's own coupling is 0: the simulators' vertical and lateral motions are uncoupled (symmetric linear
    # vehicles, independent vertical and cross-level track inputs)
    rows = coupling_test(records, problem.channels, (config.spectra.f_min_hz, math.inf), opts.alpha,
                         reference=reference, groups=_speed_groups(segments), reference_groups=ref_groups)
    for r in rows:
        log(f"coupling {r['channel']} <- {r['vertical']}: beta {r['beta']:.4f} ± {r['se']:.4f} "
            f"(t {r['t']:.1f}){' significant' if r['significant'] else ''}")
    return rows, records


def _speed_groups(segments) -> list[float]:
    """The speed group (m/s, rounded as the cells' groups) of each segment."""
    return [round(float(s.mean_speed), 3) for s in segments]


def _tilt_from_coupling(config: Config, named, in_data: dict[str, list[dict[str, Any]]],
                        tilted: list[dict[str, Any]], coupling: list[dict[str, Any]], records: list,
                        current: Stage, step: int,
                        grid: CellGrid, null: NullCalibration, out_dir: Path, noise_path: Path, fresh: bool,
                        progress: bool, log: Callable[[str], None]) -> tuple[dict[str, Any], Stage | None]:
    """Name ``sensor-tilt`` from a significant coupling and correct it in the measured records.

    Each tilted channel is rotated back by its own angle asin β (``data.corrections``); the model is unchanged
    (a tilt mixes two channels whose reference-date model errors differ: :mod:`suspid.data.corrections`). The
    suspension is fitted again on the corrected data. The naming rule of every route applies per tilted
    channel: the correction must shrink the flagged cells of that channel (when it has any) and flag no more
    than ``max_new_flagged`` (one at least) new ones there; a channel that fails is dropped and the others are
    corrected again. The generic alternative (the vehicle's own coupling, a resonance of the sensor) is what the
    coupling test already weighed (against the model's coupling, the twin, constancy over frequency). The main
    parameter is the angle, weighted by 1/se² over the tilted channels.
    """
    opts = config.diagnose
    saved = list(named)
    record: dict[str, Any] = {"step": step, "named": "sensor-tilt", "route": "coupling",
                              "applied": "data.corrections: the tilted channels' records rotated back",
                              "coupling": coupling, "gap_before": current.gap(), "unexplained": [],
                              "ranking": [], "local_model": None}
    dropped: list[str] = []
    while True:
        params = _tilt_parameters(tilted)
        named[:] = saved + [("sensor-tilt", params, 2)]
        in_data["sensor-tilt"] = [{"channel": r["channel"], "tilt_deg": float(r["angle_deg"]),
                                   "vertical": r["vertical"]} for r in tilted]
        log(f"step {step}: sensor-tilt from the coupling on {', '.join(params['channels'])}")
        corrected = Stage(current.label, current.config,
                          _corrected_problem(config, current.problem, records, in_data),
                          current.w, current.y_sim, current.result, fit=current.fit)
        _locate(corrected, grid, null, opts.alpha)
        stage, record["joint_fit"] = _add_and_fit(config, named, in_data, None, corrected, step, grid, null,
                                                  out_dir, noise_path, fresh, progress, log)
        failed = {}
        for r in tilted:
            evidence, why = correction_evidence(grid, r["channel"], current.dmap.flagged, stage.dmap.flagged,
                                                opts.max_new_flagged)
            r.setdefault("evidence", {}).update(evidence)
            if why is not None:
                failed[r["channel"]] = why
        if not failed:
            break
        for c, why in failed.items():
            log(f"step {step}: sensor-tilt on {c} dropped: {why}")
            dropped.append(f"{c}: {why}")
        tilted = [r for r in tilted if r["channel"] not in failed]
        if not tilted:
            named[:] = saved
            in_data.pop("sensor-tilt", None)
            record.update(named=None, retracted="sensor-tilt", gap_retracted=stage.gap(),
                          reason="sensor-tilt from the coupling retracted: " + "; ".join(dropped),
                          unexplained=unexplained_regions(current.dmap, [], None))   # what stays flagged, as it is
            return record, None
    record["reason"] = ("sensor-tilt from the coupling of vertical into lateral at the same point (instrumental "
                        "variables): " + "; ".join(
                            f"{r['channel']}: β = {r['beta']:.4f} ± {r['se']:.4f} {r['estimate']} "
                            f"(t = {r['t']:.1f}, angle {abs(r['angle_deg']):.2f}°, flagged cells there {r['evidence']['flagged_before']} → "
                            f"{r['evidence']['flagged_after']})" for r in tilted)
                        + "; corrected in the measured records (data.corrections)"
                        + (f"; dropped: {'; '.join(dropped)}" if dropped else ""))
    log(f"step {step}: {record['reason']}")
    record["named_parameters"] = canonical(params)
    record["effects_after"] = [{"name": n, "parameters": canonical(p)} for n, p, _ in named]
    record["gap_after"] = stage.gap()
    return record, stage


def _tilt_parameters(tilted: list[dict[str, Any]]) -> dict[str, Any]:
    """The coupling route's sensor-tilt: one angle pooled over the channels (:func:`.coupling.pooled_tilt`), each
    channel's own."""
    pooled = pooled_tilt(tilted)
    return {"angle_deg": pooled["angle_deg"], "angle_se_deg": pooled["se_deg"],
            "channels": [r["channel"] for r in tilted], "angles_deg": {r["channel"]: r["angle_deg"] for r in tilted},
            "weights": pooled["weights"], "applied": CORRECTED}


CORRECTED = "data.corrections"
"""The ``applied`` mark of an effect corrected in the measured records, not added to the model."""


def correction_evidence(grid: CellGrid, channel: str, before: np.ndarray, after: np.ndarray,
                        max_new_flagged: float) -> tuple[dict[str, int], str | None]:
    """The naming rule on one channel corrected in the records: its flagged cells (``before``, ``after``:
    ``(n_cells,)`` bool) shrink when it has any, and at most ``max_new_flagged`` of all the cells flagged before
    (one at least) are new there. Returns the counts and why the channel fails, or None."""
    mine = _channel_cells(grid, channel)
    b0, b1 = int((before & mine).sum()), int((after & mine).sum())
    new = int((after & ~before & mine).sum())
    evidence = {"flagged_before": b0, "flagged_after": b1, "new_flagged": new}
    if new > max(1.0, max_new_flagged * int(before.sum())):
        return evidence, f"its correction flags {new} new cells on {channel}"
    if b0 > 0 and b1 >= b0:
        return evidence, (f"its correction does not shrink the flagged cells of {channel} ({b0} → {b1}): the "
                          f"coupling is not what makes them differ")
    return evidence, None


def _channel_cells(grid: CellGrid, channel: str) -> np.ndarray:
    """``(n_cells,)`` bool: the cells of ``channel``."""
    return np.array([grid.channels[grid.index(c)[1]] == channel for c in range(grid.n_cells)])


def _corrections(in_data: dict[str, list[dict[str, Any]]]) -> list[dict[str, Any]]:
    """The ``data.corrections`` items of the effects corrected in the data."""
    return [c for items in in_data.values() for c in items]


def _model_effects(named, in_data) -> list[tuple[str, dict[str, Any]]]:
    """The named effects that go into the simulator (not those corrected in the data)."""
    return [(n, p) for n, p, _ in named if p.get("applied") != CORRECTED]


def _corrected_problem(config: Config, problem, records: list, in_data: dict[str, list[dict[str, Any]]]):
    """``problem`` with y_mes from ``records`` (the measured records as the run read them, ``data.corrections``
    applied) corrected by the diagnosis's own corrections ``in_data``."""
    from suspid.sections import SensorCorrection

    items = [SensorCorrection(**c) for c in _corrections(in_data)]
    y_mes, freqs = compute_spectra(untilt(records, items, problem.channels, error=config.error), config.spectra)
    if y_mes.shape != problem.y_mes.shape or not np.allclose(freqs, problem.freqs):
        raise RuntimeError("corrected records give other spectra than the run's")   # same files: cannot happen
    tag = json.dumps(canonical(_corrections(in_data)), sort_keys=True)
    return dataclasses.replace(problem, y_mes=y_mes, data_identity=stable_hash(problem.data_identity, "corrections", tag),
                               legacy_identity=stable_hash(problem.legacy_identity, "corrections", tag))


def _locate(stage: Stage, grid: CellGrid, null: NullCalibration, alpha: float) -> None:
    noise = stage.problem.noise_model
    stage.dmap = locate(grid, null, stage.problem.y_mes, noise.effective(stage.y_sim), null.noise_mean, alpha,
                        stage.config.diagnose.min_db)
    stage.dmap.J = j_of_spectra(stage.problem, stage.y_sim)[0]


def _with_effects(config: Config, effects: list[tuple[str, dict[str, Any]]]) -> Config:
    """``config`` with ``effects`` appended to its simulator's effects (for fitting; nothing written)."""
    if not effects:
        return config
    options = dict(config.simulator.options)
    options["effects"] = list(options.get("effects") or []) + [{"name": n, **p} for n, p in effects]
    return config.model_copy(update={"simulator": config.simulator.model_copy(update={"options": options})})


def _fit_suspension(stage: Stage, config: Config, grid: CellGrid, null: NullCalibration,
                    log: Callable[[str], None]) -> None:
    """The base model's suspension fitted by least squares on D from the identification's w_opt (in place)."""
    opts = config.diagnose
    problem = stage.problem
    disc = Discrepancy(grid, null, problem.y_mes, problem.noise_model, np.zeros(grid.n_cells, bool), stage.y_sim)
    fit = fit_jointly(config, problem, disc, stage.w, max_evaluations=opts.joint_max_evaluations, log=log)
    _check_groups(config, problem, disc, fit, log)
    stage.w, stage.y_sim, stage.fit = fit.w, fit.y_sim, fit


def _check_groups(config: Config, problem, disc: Discrepancy, fit, log: Callable[[str], None]) -> None:
    """The data-group check of a least-squares fit (``identifiability.model_error.adequacy.groups``)."""
    if config.identifiability.model_error.adequacy.groups:
        check_groups(config, problem, disc, fit, max_evaluations=config.diagnose.joint_max_evaluations // 2,
                     log=log)


def _add_and_fit(config: Config, named: list[tuple[str, dict[str, Any], int]],
                 in_data: dict[str, list[dict[str, Any]]], cand, current: Stage, step: int, grid: CellGrid,
                 null: NullCalibration, out_dir: Path, noise_path: Path, fresh: bool, progress: bool,
                 log: Callable[[str], None]) -> tuple[Stage, dict[str, Any]]:
    """Add the named effects to the model and fit them together with the suspension.

    With ``reidentify``: the suspension and every named effect's continuous parameters by least squares on D
    from the current suspension and the effects' values (``named`` is updated in place; effects corrected in the
    data, ``in_data``, are not in the model); then, with ``at: identified``, the augmented model identified with
    the configured objective in ``steps/<step>/`` (its ``w_opt`` reported beside the fit, under
    ``identified``). Without: the effect as fitted at the base parameters (``cand``). Returns the stage and the
    joint fit's record.
    """
    opts = config.diagnose
    if not opts.reidentify:
        aug = augmented_config(config, _model_effects(named, in_data), out_dir, noise_path,
                               path=out_dir / "steps" / f"augmented-{step}.yaml", corrections=_corrections(in_data))
        stage = Stage(f"after-{step}", aug, current.problem, current.w,
                      cand.y_sim if cand is not None else current.y_sim, None)
        _locate(stage, grid, null, opts.alpha)
        return stage, {"mode": "none (reidentify: false)"}
    problem = current.problem
    disc = Discrepancy(grid, null, problem.y_mes, problem.noise_model, current.dmap.flagged, current.y_sim)
    fit = fit_jointly(config, problem, disc, current.w, _model_effects(named, in_data),
                      max_evaluations=opts.joint_max_evaluations, log=log)
    _check_groups(config, problem, disc, fit, log)
    refitted = dict(fit.effects)
    named[:] = [(n, p if p.get("applied") == CORRECTED else refitted.get(n, p), k) for n, p, k in named]
    result = None
    aug = augmented_config(config, _model_effects(named, in_data), out_dir, noise_path,
                           path=out_dir / "steps" / f"augmented-{step}.yaml", run_dir=out_dir / "steps" / str(step),
                           corrections=_corrections(in_data))
    if opts.at == "identified":
        result = make_stage(f"identified-{step}", aug, True, out_dir / "steps" / str(step), fresh=fresh,
                            progress=progress, log=log).result
    stage = Stage(f"after-{step}", aug, problem, fit.w, fit.y_sim, result, fit=fit)
    _locate(stage, grid, null, opts.alpha)
    return stage, {"mode": "together (least squares on D)", **fit.as_dict()}
