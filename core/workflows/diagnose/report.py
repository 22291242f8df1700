"""``diagnosis.md`` and its figures: the maps before and after, the spectra of the most discrepant channel."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from suspid import registry
from suspid.infra.files import pyplot, save_figure, write_text
from suspid.workflows.report import markdown_table
from suspid.workflows.trust import trust_word
from suspid.workflows.verdict import format_value, short_description

from .fit import Candidate
from .locate import DiscrepancyMap
from .reidentify import Stage


def figure_map(path: Path, dmap: DiscrepancyMap, title: str, limit_db: float | None = None) -> Path:
    """Heat map of the cell magnitudes (dB, + measured above the model) per speed group; flagged cells framed."""
    plt = pyplot()
    grid = dmap.grid
    G, K, B = len(grid.speeds), len(grid.channels), grid.band_edges.shape[0]
    m = dmap.magnitude_db.reshape(G, K, B)
    fl = dmap.flagged.reshape(G, K, B)
    lim = limit_db or max(1.0, float(np.max(np.abs(m))))
    fig, axes = plt.subplots(G, 1, figsize=(max(7, 0.42 * B + 3), 0.38 * K * G + 1.6), squeeze=False)
    centres = np.sqrt(grid.band_edges[:, 0] * np.maximum(grid.band_edges[:, 1], 1e-9))
    for g, ax in enumerate(axes[:, 0]):
        im = ax.imshow(m[g], cmap="RdBu_r", vmin=-lim, vmax=lim, aspect="auto")
        for k, b in zip(*np.nonzero(fl[g])):
            ax.add_patch(plt.Rectangle((b - 0.5, k - 0.5), 1, 1, fill=False, lw=1.6, ec="black"))
        ax.set_yticks(range(K), grid.channels, fontsize=7)
        ax.set_xticks(range(B), [f"{c:.3g}" for c in centres], rotation=90, fontsize=7)
        ax.set_title(f"{title}: {grid.speeds[g] * 3.6:.0f} km/h" if G > 1 else title, fontsize=9)
        fig.colorbar(im, ax=ax, label="y_mes - y_sim - μ_B (dB): band mean or peak bin", fraction=0.04)
    axes[-1, 0].set_xlabel("band centre (Hz); framed: flagged (BY)")
    fig.tight_layout()
    return save_figure(fig, path)


def figure_spectra_gap(path: Path, stage_before: Stage, stage_after: Stage | None, channel: int,
                       dmap: DiscrepancyMap) -> Path:
    """Mean measured spectrum against the modelled mean y_sim + μ_B before and after, one channel."""
    plt = pyplot()
    p = stage_before.problem
    f = p.freqs
    mu = p.noise_model.mean_[channel]
    fig, ax = plt.subplots(figsize=(8, 4))
    ax.plot(f, p.y_mes[:, channel].mean(axis=0), color="black", lw=1.5, label="Y_mes (mean)")
    ax.plot(f, p.noise_model.effective(stage_before.y_sim)[:, channel].mean(axis=0) + mu, color="tab:red", lw=1.2,
            label="Y_sim + μ_B, base model")
    if stage_after is not None:
        noise = stage_after.problem.noise_model
        ax.plot(f, noise.effective(stage_after.y_sim)[:, channel].mean(axis=0) + noise.mean_[channel],
                color="tab:blue", lw=1.2, ls="--", label="Y_sim + μ_B, augmented model")
    grid = dmap.grid
    for c in np.nonzero(dmap.flagged)[0]:
        g, k, b = grid.index(int(c))
        if k == channel:
            ax.axvspan(*grid.band_edges[b], color="orange", alpha=0.2, lw=0)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("Y (dB)")
    ax.set_title(f"channel {p.channels[channel]} (shaded: flagged bands before)")
    if f[-1] / max(f[0], 1e-9) > 20:
        ax.set_xscale("log")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return save_figure(fig, path)


def _fmt_params(params: dict[str, Any]) -> str:
    """``damping=0.0198, frequency_hz=9.496``: an effect's parameters (those left at their default, None, omitted)."""
    out = []
    for k, v in params.items():
        if v is None:
            continue
        if isinstance(v, float):
            out.append(f"{k}={v:.4g}")
        elif isinstance(v, dict):
            out.append(f"{k}={{{', '.join(f'{a}: {b:.3g}' if isinstance(b, float) else f'{a}: {b}' for a, b in v.items())}}}")
        else:
            out.append(f"{k}={v}")
    return ", ".join(out)


def _parameter_words(effect: str, name: str, value: Any) -> str:
    """``natural frequency of the first vertical bending mode 9.496 Hz``: an effect's parameter as its option's
    description words it (its head and unit), else ``name = value``."""
    field = getattr(registry.get("effect", effect), "Options", None)
    field = field.model_fields.get(name) if field is not None else None
    shown = f"{value:.4g}" if isinstance(value, float) else str(value)
    if field is None or not field.description:
        return f"{name} = {shown}"
    head = short_description(field.description)
    what, _, unit = head.rpartition(", ") if ", " in head else (head, "", "")
    return f"{what} {shown}{' ' + unit if unit else ''}"


def _effect_words(effect: str, parameters: dict[str, Any]) -> str:
    """``a carbody first vertical bending mode (`carbody-bending`; natural frequency of the first vertical bending
    mode 9.496 Hz)``: a named effect in plain words with its main parameter (the others in section 2)."""
    cls = registry.get("effect", effect)
    main = getattr(cls, "main_parameter", None)
    value = f"; {_parameter_words(effect, main, parameters[main])}" if parameters.get(main) is not None else ""
    return f"a {short_description(cls.description)} (`{effect}`{value})"


def _changes(before: dict[str, float], after: dict[str, float], units: dict[str, str]) -> str:
    """``c_yaw 213.9 → 298.1 kN s/m (+39 %)``, largest change first; those within 0.5 % summed up."""
    moved, still = [], []
    for n in after:
        if n not in before or not before[n]:
            continue
        change = 100.0 * (after[n] / before[n] - 1.0)
        (moved if abs(change) >= 0.5 else still).append((abs(change), n, change))
    parts = [f"{n} {format_value(before[n], units.get(n, ''))} → {format_value(after[n], units.get(n, ''))} "
             f"({c:+.0f} %)" for _, n, c in sorted(moved, reverse=True)]
    if still:
        parts.append(f"{', '.join(n for _, n, _ in still)} within 0.5 %")
    return "; ".join(parts) if parts else "no parameter moves"


def plain_summary(diagnosis: dict[str, Any], units: dict[str, str]) -> str:
    """The report's first lines, in plain words: what was found, how sure, and what changed in the
    identification; the statistics (tests, scores, q values) stay in the sections below.

    :param units: parameter name -> SI unit (the simulator's), for the suspension's values.
    """
    gb, ga = diagnosis["gap_before"], diagnosis["gap_after"]
    alpha = diagnosis["statistics"]["alpha"]
    named = [(s["named"], s["named_parameters"]) for s in diagnosis.get("steps") or [] if s.get("named")] or (
        [(diagnosis["named"], diagnosis["named_parameters"])] if diagnosis["named"] else [])
    share = f"{100 * gb['share_flagged']:.1f} % of the spectra ({gb['n_flagged']} of {gb['n_cells']} cells)"
    if not gb["n_flagged"]:
        found = (f"nothing: the model reproduces the measurements within the noise model (no part of the spectra "
                 f"disagrees at a false discovery rate of {100 * alpha:g} %).")
        sure = None
    elif named:
        found = ("the measurements show what the model lacks: " + "; then ".join(_effect_words(e, p) for e, p in named)
                 + ".")
        best = next((c for c in diagnosis.get("ranking") or [] if c.get("effect") == named[0][0]), {})
        explained = (best.get("evidence") or {}).get("explained_own", best.get("explained"))
        runner = next((c["effect"] for c in diagnosis.get("ranking") or []
                       if c.get("status") == "fitted" and c.get("effect") != named[0][0]), None)
        sure = ((f"it explains {100 * explained:.0f} % of the disagreement where it acts" if explained is not None
                 else "it explains the disagreement where it acts")
                + (f", clearly ahead of the next explanation (`{runner}`) and of a generic bump" if runner else
                   ", clearly ahead of a generic bump")
                + (f"; with it in the model the part of the spectra that disagrees falls from {share} to "
                   f"{100 * ga['share_flagged']:.1f} %." if ga else "."))
    else:
        top = (diagnosis.get("flagged") or [{}])[0]
        where = (f", most on {top['channel']} at {top['f_low_hz']:.3g}-{top['f_high_hz']:.3g} Hz"
                 if top.get("channel") else "")
        found = (f"the model and the measurements disagree in {share}{where}, and no effect of the catalogue "
                 f"explains it (section 3 lists what is left unexplained).")
        sure = (f"the disagreement lies beyond the noise model at a false discovery rate of {100 * alpha:g} %; its "
                f"cause is not named.")
    reported = diagnosis.get("suspension") or {}
    start = (gb.get("identified") or {}).get("w") or gb.get("w") or {}
    if reported.get("w") and start:
        ident = (f"the suspension reported with the effect{'s' if len(named) > 1 else ''} added "
                 f"(the {reported.get('source', 're-identification')}) against the identification before: "
                 f"{_changes(start, reported['w'], units)}.")
    elif diagnosis.get("base_model") != "identified":
        ident = ("not re-run: the diagnosis compared the model at its nominal suspension (diagnose.at: nominal); "
                 "run it at the identified one (diagnose.at: identified) to see the suspension change.")
    else:
        ident = "unchanged (nothing was added to the model)."
    lines = [f"**Found:** {found}"] + ([f"**How sure:** {sure}"] if sure else []) + [f"**Identification:** {ident}"]
    return "\n\n".join(lines) + "\n\nThe statistics behind each statement are in the sections below."


def write_diagnosis_report(out_dir: Path, diagnosis: dict[str, Any], before: Stage, after: Stage | None,
                           ranking: list[Candidate], bumps: dict[int, Candidate]) -> Path:
    """``diagnosis.md`` and its figures."""
    dmap = before.dmap
    lim = max(1.0, float(np.max(np.abs(dmap.magnitude_db))))
    figure_map(out_dir / "diagnosis_map_before.png", dmap, "before (base model)", lim)
    if after is not None:
        figure_map(out_dir / "diagnosis_map_after.png", after.dmap, "after (augmented model)", lim)
    per_channel = np.zeros(len(before.problem.channels))
    for c in np.nonzero(dmap.flagged)[0]:
        per_channel[dmap.grid.index(int(c))[1]] += dmap.evidence[c]
    channel = int(np.argmax(per_channel)) if dmap.flagged.any() else dmap.grid.index(int(np.argmax(dmap.evidence)))[1]
    figure_spectra_gap(out_dir / "diagnosis_spectra.png", before, after, channel, dmap)

    flagged = sorted(dmap.rows(only_flagged=True), key=lambda r: r["p"])
    flag_rows = [[r["channel"], f"{r['f_low_hz']:.3g}-{r['f_high_hz']:.3g}", f"{r['speed_kmh']:.0f}", r["sign"],
                  f"{r['magnitude_db']:+.2f}", r["test"], f"{r['q']:.2g}"] for r in flagged[:30]]
    rank_rows = []
    for c in ranking:
        score = f"{c.score:.1f}" if math.isfinite(c.score) else "-"
        main = ""
        if c.status == "fitted":
            cls = registry.get("effect", c.effect)
            main = f"{cls.main_parameter} = {c.parameters.get(cls.main_parameter)}"
            if isinstance(c.parameters.get(cls.main_parameter), float):
                main = f"{cls.main_parameter} = {c.parameters[cls.main_parameter]:.4g}"
        rank_rows.append([f"**{c.effect}**" if c.effect == diagnosis["named"] else c.effect, c.status, score,
                          c.n_parameters or "-", f"{c.delta_D:.1f}" if math.isfinite(c.delta_D) else "-",
                          f"{100 * c.explained:.0f} %" if c.status == "fitted" else "-",
                          f"{c.delta_J:+.4f}" if c.delta_J is not None else "-", main,
                          _fmt_params(c.parameters) if c.status == "fitted" else ""])
    for p, b in sorted(bumps.items()):
        rank_rows.append([f"generic bump ({p} parameters)", b.status, f"{b.score:.1f}" if math.isfinite(b.score)
                          else "-", p, f"{b.delta_D:.1f}" if math.isfinite(b.delta_D) else "-",
                          f"{100 * b.explained:.0f} %" if b.status == "fitted" else "-", "-", "",
                          _fmt_params(b.parameters) if b.status == "fitted" else ""])
    gb, ga = diagnosis["gap_before"], diagnosis["gap_after"]

    def shrink(a, b):
        return f"{100 * (1 - b / a):.0f} %" if a and b is not None and a > 0 else "-"

    gap_rows = [["flagged cells", f"{gb['n_flagged']} of {gb['n_cells']} ({100 * gb['share_flagged']:.1f} %)",
                 f"{ga['n_flagged']} ({100 * ga['share_flagged']:.1f} %)" if ga else "-",
                 shrink(gb["share_flagged"], ga["share_flagged"]) if ga else "-"],
                ["integrated discrepancy (dB·Hz)", f"{gb['integrated_db_hz']:.2f}",
                 f"{ga['integrated_db_hz']:.2f}" if ga else "-",
                 shrink(gb["integrated_db_hz"], ga["integrated_db_hz"]) if ga else "-"],
                ["J (run objective)", f"{gb['J']:.5g}", f"{ga['J']:.5g}" if ga else "-", ""]]
    if "errors_percent" in gb or (ga and "errors_percent" in ga):
        names = list((ga or gb).get("errors_percent", gb.get("errors_percent", {})))
        for n in names:
            eb = gb.get("errors_percent", {}).get(n)
            ea = (ga or {}).get("errors_percent", {}).get(n)
            gap_rows.append([f"error of {n} (% of interval)", f"{eb:.2f}" if eb is not None else "-",
                             f"{ea:.2f}" if ea is not None else "-", ""])
    named = diagnosis["named"]
    verdict = (f"Named: `{named}` with {_fmt_params(diagnosis['named_parameters'])}. {diagnosis['reason']}."
               if named else f"Nothing named. {diagnosis['reason']}.")
    if len(diagnosis.get("named_effects") or []) > 1:
        verdict += " Then: " + "; ".join(f"step {s['step']}: `{s['named']}` ({s['reason']})"
                                         for s in diagnosis["steps"][1:] if s["named"]) + "."
    seq_rows = [[s["step"], s["named"] or "(nothing)",
                 f"{100 * s['gap_before']['share_flagged']:.1f} %",
                 f"{100 * s['gap_after']['share_flagged']:.1f} %" if s.get("gap_after") else "-",
                 f"{s['gap_after']['integrated_db_hz']:.2f}" if s.get("gap_after") else "-",
                 _joint_fit_cell(s.get("joint_fit")),
                 s["reason"]] for s in diagnosis.get("steps", [])]
    unexplained = "\n".join(f"- {u['text']}" for u in diagnosis.get("unexplained") or []) or "(none)"
    st = diagnosis["statistics"]
    units = {p.name: p.unit for p in before.problem.simulator.parameters()}
    text = f"""# Discrepancy diagnosis `{diagnosis['name']}`

{plain_summary(diagnosis, units)}

Base model: the config's model at its {'identified' if diagnosis['base_model'] == 'identified' else 'nominal'}
parameters. Measurements: {before.problem.y_mes.shape[0]} segments, {len(before.problem.channels)} channels,
{before.problem.freqs.size} frequencies. Wall time {diagnosis['wall_time_s']:.0f} s (ranking {diagnosis['ranking_time_s']:.0f} s).

## 1. Where the model and the measurements disagree

{gb['n_flagged']} of {gb['n_cells']} cells (speed group × channel × band) are flagged at a false discovery rate
of {st['alpha']:g} (Benjamini-Yekutieli); integrated discrepancy {gb['integrated_db_hz']:.2f} dB·Hz. Sign +: the
measurements are above the model; magnitude: the band mean (mean test) or the most deviant bin (shape and
peak tests: a moved resonance, a narrow line). Null calibrated by {st['n_bootstrap']} parametric-bootstrap replicates
(median scale κ {st['kappa_median']:.3f}, unfloored {st['kappa_raw_median'] if st['kappa_raw_median'] is None else round(st['kappa_raw_median'], 3)}).
{_speed_note(st.get('noise_mean_by_speed') or [])}

{markdown_table(['channel', 'band (Hz)', 'km/h', 'sign', 'magnitude (dB)', 'test', 'q (BY)'], flag_rows) if flag_rows else '(no flagged cell)'}
{f'(and {len(flagged) - 30} more)' if len(flagged) > 30 else ''}

![map before](diagnosis_map_before.png)

## 2. Which effect is missing

Each candidate's parameters are fitted to minimise D = Σ z² over every channel and frequency (z: the mean
residual over its null standard deviation); score = ΔD - p ln(n) ({st['penalty_per_parameter']:.2f} per
parameter p); a generic bump of the same size is the yardstick. Named
only with a margin of {st['margin']:g} over the runner-up, the bump and a local discrepancy model (a free bump per
flagged channel), explaining at least {100 * st['min_explained']:.0f} % of D in its own cells; after the joint fit
the flagged cells must shrink, with at most {100 * st.get('max_new_flagged', 0):.0f} % new ones (one at least) among
the cells it changes, or it is retracted.

{markdown_table(['candidate', 'status', 'score', 'p', 'ΔD', 'explained', 'ΔJ', 'main parameter', 'parameters'], rank_rows)}

{verdict}

## 3. One effect after the other

Joint fit: {diagnosis.get('joint_fit', '-')}.

{markdown_table(['step', 'named', 'flagged before', 'flagged after', 'integrated dB·Hz after', 'joint fit', 'reason'], seq_rows) if seq_rows else ''}

Unexplained at the end:

{unexplained}

## 4. The gap before and after adding the effects

{f"Augmented config: `{diagnosis['augmented_config']}`" if diagnosis['augmented_config'] else 'No augmented config (nothing named).'}

{markdown_table(['', 'before', 'after', 'shrink'], gap_rows)}

{'![map after](diagnosis_map_after.png)' if after is not None else ''}

![spectra](diagnosis_spectra.png)

## 5. The suspension

{_suspension_text(gb, ga)}

{reported_suspension_text(diagnosis.get("suspension"))}

Method: `docs/diagnose.md`.
"""
    return write_text(out_dir / "diagnosis.md", text)


def _speed_note(coverage: list[dict]) -> str:
    """A sentence on the mean of B each speed group takes: a reference-date speed group's, or the pooled one."""
    if len(coverage) < 2 and all(c["covered"] for c in coverage):
        return ""
    parts = [f"{c['speed_kmh']:.0f} km/h: " + (f"the reference date's mean at this speed ({c['reference_segments']} "
                                               f"segments)" if c["mean"] == "speed_group" else
                                               f"the mean over all {c['reference_segments']} reference-date segments"
                                               + ("" if c["covered"] else
                                                  " (**no reference-date data at this speed**: model-form error that "
                                                  "changes with speed shows as discrepancy here)"))
             for c in coverage]
    return "μ_B per speed group: " + "; ".join(parts) + "."


def _joint_fit_cell(fit: dict | None) -> str:
    """One table cell on a step's joint fit: its mode, D before and after, its simulations."""
    if not fit:
        return "-"
    if "D" not in fit:
        return fit["mode"]
    return f"{fit['mode']}: D {fit['D_start']:.0f} → {fit['D']:.0f}, {fit['n_simulations']} simulations"


def _suspension_text(gb: dict, ga: dict | None) -> str:
    """The suspension before and after: fitted under D (± its 2-sd sampling half-width) and the identification's
    own w_opt; errors in % of the interval where w_ref is known."""
    fits = [g.get("suspension_fit") if g else None for g in (gb, ga)]
    if not any(fits):
        return "The base model's suspension is the " + ("nominal one." if not gb.get("w") else "identified one.")

    def cell(g, fit, n):
        if not g or n not in g.get("w", {}):
            return "-"
        hw = (fit or {}).get("half_width_percent", {}).get(n)
        err = g.get("errors_percent", {}).get(n)
        return (f"{g['w'][n]:.5g}" + (f" ± {hw:.1f} %" if hw is not None else "")
                + (f" (error {err:.1f} %)" if err is not None else ""))

    def ident(g, n):
        w = ((g or {}).get("identified") or {}).get("w") or {}
        return f"{w[n]:.5g}" if n in w else "-"

    names = list(dict.fromkeys(list(gb.get("w", {})) + list((ga or {}).get("w", {}))))
    rows = [[n, cell(gb, fits[0], n), ident(gb, n), cell(ga, fits[1], n), ident(ga, n)] for n in names]
    start = ("from the identification's w_opt, which the columns *identified* give (`suspid run` with the "
             "configured objective)" if gb.get("identified") else "from the nominal values (at: nominal)")
    return ("Fitted under D (least squares on the mean residuals, ± two sampling standard deviations in % of the "
            f"admissible interval) {start}; errors in % of the interval where the truth is known.\n\n"
            + markdown_table(["parameter", "before: fitted", "before: identified", "after: fitted",
                              "after: identified"], rows))


def reported_suspension_text(reported: dict | None) -> str:
    """Which suspension the diagnosis reports (the joint fit under D or the re-identification), why, and its
    trust per component (no, or not assessed: never yes without the identification's checks)."""
    if not reported:
        return ""
    trust = reported.get("trustworthy") or {}
    rows = [[n, f"{v:.5g}", trust_word(trust.get(n))] for n, v in (reported.get("w") or {}).items()]
    return (f"Reported suspension: the **{reported['source']}** ({reported['why']}). Trust: not assessed unless a "
            "check that ran flags a component (the reference-date self-check and the adequacy test do not run on "
            "the diagnosis's models).\n\n" + markdown_table(["parameter", "value", "trustworthy"], rows))
