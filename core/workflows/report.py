"""Figures and the markdown report of an identification run (paper Figures 1-2).

The figure functions take plain arrays so that a report can be rebuilt from
the files of a run directory; :func:`write_report` assembles ``report.md``.
Figures are PNG files written atomically with matplotlib's Agg backend.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from suspid.config import figure_channel
from suspid.infra.files import pyplot, save_figure, write_text
from suspid.infra.seeds import rng as named_rng
from suspid.interfaces import Executor
from suspid.method.noise import modelled_spectra
from suspid.optimize.loop import LoopOutcome
from suspid.workflows.trust import check_labels, trust_word  # trust_word: importers take it from here too
from suspid.workflows.problem import Problem
from suspid.workflows.linearised import calibration_markdown
from suspid.workflows.no_change import reports_reference
from suspid.workflows.tasks import SpectraTask, run_one
from suspid.workflows.verdict import VerdictRow, format_value, rows_of, verdict_markdown


Y_LABEL = "Y (dB re 1 m s⁻¹·⁵)"
"""Y is 10 log10 of the amplitude |Â| of an acceleration in m/s² (paper eq. 1, :mod:`suspid.method.spectra`):
its reference quantity is 1 m s⁻¹·⁵."""

HZ_TICKS = (0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0)
"""Frequency ticks of the spectra figures, Hz (those inside the grid are shown)."""


def hz_axis(ax: Any, freqs: np.ndarray) -> None:
    """A frequency axis in Hz: logarithmic with plain ticks 0.5-1-2-5-10-20 where the grid spans over a
    decade, linear otherwise."""
    f0, f1 = float(freqs[0]), float(freqs[-1])
    if f1 / max(f0, 1e-9) > 5:
        ax.set_xscale("log")
        ticks = [t for t in HZ_TICKS if f0 * 0.999 <= t <= f1 * 1.001]
        ax.set_xticks(ticks, [f"{t:g}" for t in ticks])
        ax.tick_params(axis="x", which="minor", labelbottom=False)
    ax.set_xlim(f0, f1)


def figure_spectra(path: Path, freqs: np.ndarray, y_mes: np.ndarray, y_model: np.ndarray, channels: Sequence[str],
                   *, title: str, measured: str = "measured", model: str = "model at w_opt with B",
                   quantiles: tuple[float, float] = (0.05, 0.95), first: int = 0) -> Path:
    """Figure 1: every channel in small multiples, the measured spectra against the modelled ones.

    Each panel draws the mean over segments and the ``quantiles`` band of the measured spectra and of the
    modelled spectra Y_mod = Y_sim(w) + B (eq. 4; B's band is the model's expected spread): where the measured
    mean leaves the model's band, the model at w does not reproduce the measurements.

    :param freqs: ``(n_freqs,)`` Hz.
    :param y_mes: ``(n_samples, n_channels, n_freqs)`` dB; :param y_model: ``(n_paths, n_channels, n_freqs)`` dB.
    :param channels: ``(n_channels,)`` names; :param first: the channel drawn first (``output.figure_channel``).
    """
    plt = pyplot()
    n = len(channels)
    order = [first] + [c for c in range(n) if c != first]
    ncols = 1 if n == 1 else 2 if n <= 6 else 3
    nrows = -(-n // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.4 * ncols, 2.5 * nrows + 0.7), sharex=True, squeeze=False)
    band = f"{int(quantiles[0] * 100)}-{int(quantiles[1] * 100)} %"
    for ax, c in zip(axes.flat, order):
        lo, hi = np.quantile(y_model[:, c], quantiles, axis=0)
        ax.fill_between(freqs, lo, hi, color="tab:blue", alpha=0.25, lw=0, label=f"{model}, {band} band")
        ax.plot(freqs, y_model[:, c].mean(axis=0), color="tab:blue", lw=1.3, label=f"{model}, mean")
        lo, hi = np.quantile(y_mes[:, c], quantiles, axis=0)
        ax.plot(freqs, lo, color="black", lw=0.7, ls="--", label=f"{measured}, {band} band")
        ax.plot(freqs, hi, color="black", lw=0.7, ls="--")
        ax.plot(freqs, y_mes[:, c].mean(axis=0), color="black", lw=1.3, label=f"{measured}, mean")
        ax.set_title(channels[c], fontsize=9)
        ax.grid(alpha=0.3)
        hz_axis(ax, freqs)
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    for ax in axes[:, 0]:
        ax.set_ylabel(Y_LABEL, fontsize=8)
    for ax in axes.flat[:n]:   # every panel keeps its Hz ticks (a hidden panel leaves the one above it last)
        ax.xaxis.set_tick_params(labelbottom=True)
    for ax in axes.flat[max(n - ncols, 0):n]:
        ax.set_xlabel("frequency (Hz)")
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="upper center", ncol=4, fontsize=8, frameon=False, bbox_to_anchor=(0.5, 1.0))
    fig.suptitle(title, fontsize=10, y=1.0 - 0.3 / fig.get_figheight())
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.55 / fig.get_figheight()))
    return save_figure(fig, path)


VERDICT_COLOURS = {"ok": "tab:green", "warning": "tab:orange", "alarm": "tab:red", "not assessable": "0.45"}


def _style(row: VerdictRow) -> tuple[str, dict[str, Any], str]:
    """The marker, its keywords and the bar's line style of a verdict row: trusted (filled), trust not assessed
    (hollow), not trustworthy (a grey cross), not identifiable (a light grey hollow square, dotted bar)."""
    colour = VERDICT_COLOURS[row.verdict]
    if not row.identifiable:
        return "s", {"facecolors": "none", "edgecolors": "0.6"}, ":"
    if row.trust == "no":
        return "X", {"color": "0.45"}, ":"
    if row.trust == "not assessed":
        return "o", {"facecolors": "white", "edgecolors": colour, "linewidths": 1.6}, "-"
    return "o", {"color": colour}, "-"


STYLE_LABELS = {"trusted": "trustworthy (filled)", "not assessed": "trust not assessed (hollow)",
                "untrustworthy": "not trustworthy (grey cross)", "not identifiable": "not identifiable (grey square)"}


def figure_verdict(path: Path, rows: Sequence[VerdictRow]) -> Path:
    """Figure 2: each identified parameter (and localised group) as its change in % of its nominal value.

    The interval as a bar, the identified value as a marker coloured by the verdict, the nominal value as the
    zero line, the warning and alarm levels of ``limits:`` as short lines at each parameter; the marker says the
    trust (filled: trustworthy, hollow: not assessed, grey cross: not trustworthy, grey square: not
    identifiable); the known w_ref of a numerical experiment as a black diamond.

    :param rows: the verdict rows; those without a nominal value are left out.
    """
    plt = pyplot()
    rows = [r for r in rows if r.change_percent is not None]
    q = max(len(rows), 1)
    fig, ax = plt.subplots(figsize=(max(6.5, 1.25 * q + 4.0), 4.6))
    seen: dict[str, Any] = {}
    ax.axhline(0.0, color="black", lw=1.0)
    seen["nominal"] = plt.Line2D([], [], color="black", lw=1.0, label="nominal value (0 %)")
    for i, r in enumerate(rows):
        for state, levels, ls in (("warning", r.warning, "--"), ("alarm", r.alarm, "-")):
            for level in levels or ():
                if level is not None:
                    ax.hlines(level, i - 0.38, i + 0.38, colors=VERDICT_COLOURS[state], linestyles=ls, lw=1.6)
                    seen[f"{state} level"] = plt.Line2D([], [], color=VERDICT_COLOURS[state], ls=ls, lw=1.6,
                                                        label=f"{state} level")
        marker, kw, bar = _style(r)
        colour = "0.6" if not r.identifiable or r.trust == "no" else VERDICT_COLOURS[r.verdict]
        lo, hi = r.interval_percent
        ax.vlines(i, lo, hi, colors=colour, lw=6, alpha=0.45, linestyles=bar)
        ax.hlines([lo, hi], i - 0.12, i + 0.12, colors=colour, lw=1.4)
        ax.scatter([i], [r.change_percent], marker=marker, s=70, zorder=4, **kw)
        key = ("not identifiable" if not r.identifiable else "untrustworthy" if r.trust == "no"
               else "not assessed" if r.trust == "not assessed" else "trusted")
        seen[key] = plt.Line2D([], [], ls="", marker=marker, ms=8, color="0.3",
                               markerfacecolor="white" if key in ("not assessed", "not identifiable") else "0.3",
                               label=STYLE_LABELS[key])
        seen[f"verdict {r.verdict}"] = plt.Line2D([], [], color=VERDICT_COLOURS[r.verdict], lw=6, alpha=0.6,
                                                  label=f"interval, verdict {r.verdict}")
        if r.w_ref is not None and r.nominal:
            ax.scatter([i + 0.2], [100 * (r.w_ref / r.nominal - 1)], marker="D", s=28, color="black", zorder=5)
            seen["w_ref"] = plt.Line2D([], [], ls="", marker="D", ms=5, color="black",
                                       label="w_ref (the experiment's truth)")
        ax.text(i, 1.01, r.verdict + ("\n(borderline)" if r.borderline else ""), transform=ax.get_xaxis_transform(),
                ha="center", va="bottom", fontsize=8,
                color=VERDICT_COLOURS[r.verdict], fontweight="bold")
    ax.set_xticks(range(len(rows)), [f"{r.name}\n{format_value(r.nominal, r.unit)}" for r in rows], fontsize=8)
    ax.set_xlim(-0.6, len(rows) - 0.4)
    ax.set_ylabel("change from nominal (% of nominal)")
    title = "Identified parameters against their nominal values and limits (nominal value under each name)"
    if q <= 3:   # a narrow axes (one to three parameters): two lines, so that the title is not clipped
        title = "Identified parameters against their nominal values and limits\n(nominal value under each name)"
    ax.set_title(title, fontsize=9, pad=28 if any(r.borderline for r in rows) else 18)
    ax.grid(alpha=0.3, axis="y")
    order = ["nominal", "warning level", "alarm level", *(f"verdict {v}" for v in VERDICT_COLOURS), *STYLE_LABELS,
             "w_ref"]
    ax.legend(handles=[seen[k] for k in order if k in seen], fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    return save_figure(fig, path)


def figure_parameters(path: Path, names: Sequence[str], variants: Mapping[str, np.ndarray],
                      w_ref: np.ndarray | None = None,
                      intervals: Mapping[str, np.ndarray] | None = None) -> Path:
    """Figure 2 analogue: w_ref and each variant's w_opt on the normalised scale [0, 1].

    :param variants: label -> ``(q,)`` normalised w_opt.
    :param w_ref: ``(q,)`` normalised reference, when known.
    :param intervals: label -> ``(q, 2)`` normalised intervals, drawn as bars.
    """
    plt = pyplot()
    q = len(names)
    fig, ax = plt.subplots(figsize=(max(6, 1.1 * q + 2), 4))
    x = np.arange(q)
    markers = ["^", "o", "s", "D", "v", "P", "X", "*"]
    offsets = np.linspace(-0.2, 0.2, max(len(variants), 1))
    if w_ref is not None:
        ax.scatter(x, w_ref, marker="s", s=70, color="black", label="w_ref", zorder=3)
    for (label, w), off, mk in zip(variants.items(), offsets, markers * 4):
        ax.scatter(x + off, w, marker=mk, s=40, label=f"w_opt ({label})", zorder=4)
        if intervals and label in intervals:
            iv = np.asarray(intervals[label])
            ax.vlines(x + off, iv[:, 0], iv[:, 1], alpha=0.5)
    ax.set_xticks(x, names, rotation=30, ha="right")
    ax.set_ylim(-0.05, 1.05)
    ax.set_ylabel("normalised value")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    return save_figure(fig, path)


def figure_convergence(path: Path, J: np.ndarray, n_initial: int, ei: Sequence[float], n_refine: int = 0) -> Path:
    """Convergence: J of every evaluation, running J_max, and max EI per EGO iteration (log scale).

    :param J: ``(n,)`` J of every evaluation in order; :param ei: EI per iteration, the
        last ``n_refine`` of them at the points of the local refinement (``ego.refine``).
    """
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    n = np.arange(1, len(J) + 1)
    axes[0].plot(n, J, ".", color="0.6", label="J of each evaluation")
    axes[0].plot(n, np.maximum.accumulate(J), color="tab:blue", label="J_max")
    axes[0].axvline(n_initial + 0.5, color="k", ls=":", lw=1, label="end of initial design")
    if n_refine:
        axes[0].axvline(len(J) - n_refine + 0.5, color="tab:orange", ls="--", lw=1,
                        label="paper's stop, refinement after")
    axes[0].set_xlabel("evaluation")
    axes[0].set_ylabel("J")
    axes[0].legend(fontsize=8)
    ei = np.asarray(ei, dtype=float)
    n_loop = ei.size - n_refine
    it = np.arange(1, ei.size + 1)
    if n_loop > 0:
        axes[1].semilogy(it[:n_loop], np.maximum(ei[:n_loop], 1e-300), "o-", ms=3, label="max EI, paper's loop")
    if n_refine:
        axes[1].semilogy(it[n_loop:], np.maximum(ei[n_loop:], 1e-300), "s-", ms=3, color="tab:orange",
                         label="EI at the refinement points")
        axes[1].legend(fontsize=8)
    axes[1].set_xlabel("iteration")
    axes[1].set_ylabel("EI")
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.tight_layout()
    return save_figure(fig, path)


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """A GitHub-flavoured markdown table."""
    def fmt(v: Any) -> str:
        if isinstance(v, float):
            return f"{v:.4g}"
        return str(v)

    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(fmt(v) for v in row) + " |" for row in rows]
    return "\n".join(lines)


def trust_cell(result: dict[str, Any], name: str) -> str:
    """The report's "trustworthy under model error" cell: yes, **no** with the reasons, or not assessed."""
    word = trust_word(result.get("trustworthy", {}).get(name))
    if word == "no":
        return "**no**: " + "; ".join(result.get("untrustworthy_reasons", {}).get(name, []))
    return "*not assessed*" if word == "not assessed" else word


def _estimates_from_w0(result: dict[str, Any]) -> str:
    """``k_sec_z -4.1 %, c_yaw +0.0 %``: how far the estimates lie from w0 where no change was shown."""
    nc = result["model_error"]["no_change"]
    return ", ".join(f"{n} {d:+.1f} %" for n, d in zip(result["parameters"], nc.get("estimate_minus_w0_percent", [])))


def no_change_line(result: dict[str, Any]) -> str | None:
    """One line where the no-change test kept w0 and the values reported are the reference date's (None
    otherwise): the test's z and how far the estimates lie from w0 (% of the admissible interval)."""
    if not reports_reference(result):
        return None
    nc = result["model_error"]["no_change"]
    return (f"No change shown since the reference date: the no-change test keeps w0 (z = {nc['z']:.1f}, within "
            f"{nc['n_sigmas']:g}), so the values reported are the reference date's; the estimates lie "
            f"{_estimates_from_w0(result)} of the admissible interval from them, inside the intervals.")


def _reason(status: str) -> str:
    """A check's status without its leading ``not run``: the reason, with what to do where it says so."""
    if status.startswith("not run: "):
        return status[len("not run: "):]
    if status.startswith("not run (") and status.endswith(")"):
        return status[len("not run ("):-1]
    return status


def checks_line(result: dict[str, Any]) -> str | None:
    """One line for the terminal on the model-error checks that did not run: which, why and what to do (their
    statuses, grouped when they share one), and whether trust is therefore not assessed; None when all ran.
    report.md keeps the list (:func:`checks_lines`)."""
    checks = (result.get("model_error") or {}).get("checks")
    if not checks:
        return None
    labels = check_labels((result.get("model_error") or {}).get("method"))
    missed = {c: v for c, v in checks.items() if not v["ran"]}
    if not missed:
        return None
    by_reason: dict[str, list[str]] = {}
    for c, v in missed.items():
        by_reason.setdefault(_reason(v["status"]), []).append(labels.get(c, c))
    if len(missed) == len(checks) and len(by_reason) == 1:
        what = f"Model-error checks not run ({next(iter(by_reason))})"
    else:
        what = (f"Model-error checks: {len(checks) - len(missed)} of {len(checks)} ran; not run: "
                + "; ".join(f"{', '.join(names)} ({reason})" for reason, names in by_reason.items()))
    required = any(v["required"] for v in missed.values())
    return what + (": trust is not assessed (report.md lists the checks)" if required else "")


def checks_lines(result: dict[str, Any]) -> list[str]:
    """Which model-error checks ran and which did not, and why (from ``result["model_error"]["checks"]``)."""
    checks = (result.get("model_error") or {}).get("checks")
    if not checks:
        return ["Model-error checks: not recorded in this result."]
    labels = check_labels((result.get("model_error") or {}).get("method"))
    ran = [labels.get(c, c) for c, v in checks.items() if v["ran"]]
    out = [f"Model-error checks that ran: {', '.join(ran) if ran else 'none'}."]
    out += [f"- {labels.get(c, c)}{' (needed for a yes)' if v['required'] else ''}: {v['status']}"
            for c, v in checks.items() if not v["ran"]]
    missing = [labels.get(c, c) for c, v in checks.items() if v["required"] and not v["ran"]]
    if missing:
        out.append(f"\nSo no component is called trustworthy: without the {', '.join(missing)}, a component that "
                   f"no check flags is not assessed.")
    return out


def model_error_section(result: dict[str, Any]) -> str:
    """The report's "Model error" section: which checks ran, then the self-check, adequacy test, data groups
    and nuisance sweep that did."""
    me = result.get("model_error")
    if not me:
        return ""
    names = result["parameters"]
    out = ["", "## Model error", "", *checks_lines(result), ""]
    if "self_check" not in me and "adequacy" not in me:
        return "\n".join(out) + "\n"
    sc = me.get("self_check", {})
    if sc.get("status") == "done":
        out.append(f"Reference-date self-check ({sc['n_splits']} random halves: B fitted on {sc['segments_fit']} "
                   f"segments, w identified on the other {sc['segments_identify']} by a local search from w0"
                   f"{' on the spectra linearised at w0' if sc.get('linearised') else ''}, "
                   f"where the truth is w0). A component whose mean shift lies beyond 2 standard errors of the splits' "
                   f"mean (a bias) and exceeds {me['max_bias_percent']:.0f} % of its interval is not trustworthy.\n")
        out.append(markdown_table(["parameter", "bias (% of interval)", "standard error (%)",
                                   "scatter over splits (%)"],
                                  [[n, f"{sc['bias_percent'][n]:+.2f}", f"{sc['standard_error_percent'][n]:.2f}",
                                    f"{sc['scatter_percent'][n]:.2f}"] for n in names]))
    elif "checks" not in me:   # a result written before the checks' summary
        out.append(f"Reference-date self-check: {sc.get('status', 'not run')}.")
    ad = me.get("adequacy", {})
    out.append("")
    if ad.get("status") == "done":
        out.append(f"Adequacy at w_opt: {ad['n_inadequate']} of {ad['n_bands']} channel bands (1/"
                   f"{ad['bands_per_octave']:g} octave) where the mean residual y_mes − y_sim(w_opt) − μ_B exceeds "
                   f"{ad['z_threshold']:g} standard errors and {ad['min_db']:g} dB. A parameter with more than "
                   f"{100 * ad['max_share']:.0f} % of its information there is not trustworthy.\n")
        out.append(markdown_table(["parameter", "share of information in inadequate bands"],
                                  [[n, f"{100 * ad['inadequate_share'][n]:.0f} %"] for n in names]))
        if ad["inadequate_bands"]:
            out += ["", markdown_table(["channel", "band", "residual (dB)", "z"],
                                       [[b["channel"], b["band"], f"{b['residual_db']:+.2f}", f"{b['z']:+.1f}"]
                                        for b in ad["inadequate_bands"]])]
        groups = ad.get("groups")
        if groups:
            gnames = list(groups["estimates_percent"])
            out += ["", f"Re-identification on data groups, from w_opt (a parameter is free where the group holds "
                        f"≥ {100 * groups['min_group_share']:.0f} % of its information; values in % of the "
                        f"interval). A spread above {groups['max_spread_percent']:.0f} % means the parts of the data "
                        f"disagree.", "",
                    markdown_table(["parameter"] + gnames + ["spread (%)"],
                                   [[n] + ["-" if groups["estimates_percent"][g][n] is None
                                           else f"{groups['estimates_percent'][g][n]:.1f}" for g in gnames]
                                    + [f"{groups['spread_percent'][n]:.1f}"] for n in names])]
    elif "checks" not in me:
        out.append(f"Adequacy at w_opt: {ad.get('status', 'not run')}.")
    nu = me.get("nuisance")
    if nu and nu.get("status") == "done":
        how = "linearised" if nu.get("linearised") else "re-identified from w_opt"
        out += ["", f"Model parameters: w_opt's shift ({how}) with each model parameter at an end of its range (its "
                    f"calibrated interval where the reference date pins it down, its assumed range otherwise; B "
                    f"fitted again at the reference date), against the nominal model, in % of the interval. "
                    f"Uncorrected, a component moved by more than {nu['max_shift_percent']:.0f} % rests on the "
                    f"assumption, not on the data.", "",
                markdown_table(["nuisance parameter", "value"] + names,
                               [[row["parameter"], f"{row['value']:g}"] + [f"{row[n]:+.1f}" for n in names]
                                for row in nu["shifts_percent"]])]
    elif nu and "checks" not in me:
        out += ["", f"Nuisance parameters: {nu['status']}."]
    nc = me.get("no_change")
    if nc and nc.get("status") == "done":
        null = "w0 − the correction, where w_opt lies when nothing changed" if nc.get("null") else "w0"
        out += ["", f"No-change test: J(w_opt) − J({null}) = {nc['delta_J']:.4g} on the measurement date, "
                    f"{nc['z']:.1f} times its bootstrap standard deviation ({nc['sd_delta_J']:.3g}, "
                    f"{nc['n_redraws']} replicates): " +
                    (f"w0 is rejected (beyond {nc['n_sigmas']:g})." if nc["rejected"] else
                     f"the data do not reject w0 (within {nc['n_sigmas']:g}), so every interval is widened to hold "
                     f"w0's value; a component w0 lies further from than ± {me.get('max_half_width_percent', 8):.0f} "
                     f"% is not reported as a finding.")]
        if reports_reference(result):
            out += ["", "**No change shown: the values reported are the reference date's** (the column "
                        "\"reported\" of the table; `identifiability.model_error.no_change_report: estimate` "
                        "reports the estimate instead). The estimate lies " + _estimates_from_w0(result)
                    + " of the admissible interval from w0, inside the intervals."]
    bound = me.get("bias_bound_percent")
    corr = me.get("correction")
    if bound and corr:
        sources = me.get("bias_sources_percent") or {}
        transfer = {n: (sources.get(n) or {}).get("model_parameters_transfer") for n in names}
        has_transfer = all(v is not None for v in transfer.values())   # (results written before it: absent)
        rho = me.get("transfer_error")
        out += ["", f"Bias correction: {corr['method']}; the equivalent bound on the remaining bias (the "
                    f"self-check's bias and half the groups' spread"
                    + (f", and the calibrated shift's own error away from the reference date ("
                       f"{rho if rho is not None else '?'} × its size: where nothing changed the shift "
                       f"vanishes up to sampling; at w_opt it is extrapolated)" if has_transfer else "")
                    + " in quadrature, with the model parameters' posterior spread as one) and the interval's "
                    f"half-width, in % of the interval. A component wider than ± {me['max_half_width_percent']:.0f} % "
                    f"is not trustworthy.", "",
                markdown_table(["parameter", "correction (%)", "bias-corrected"]
                               + (["its transfer error (%)"] if has_transfer else [])
                               + ["bound on the bias (%)", "half-width (%)"],
                               [[n, f"{corr['correction_percent'][n]:+.1f}", f"{corr['w_corrected'][n]:.4g}"]
                                + ([f"{transfer[n]:.1f}"] if has_transfer else [])
                                + [f"{bound[n]:.1f}", f"{me['half_width_percent'][n]:.1f}"] for n in names])]
    elif bound:
        out += ["", f"Bound on the bias of w_opt (the self-check's |bias| + half the groups' spread + the model "
                    f"parameters' |shift| at their calibrated values, their signs unknown, with the model parameters' "
                    f"remaining spread added to the sampling one) and the bias-aware interval's half-width, "
                    f"in % of the interval. A component wider than ± {me['max_half_width_percent']:.0f} % is not "
                    f"trustworthy.", "",
                markdown_table(["parameter", "bound on the bias (%)", "half-width (%)"],
                               [[n, f"{bound[n]:.1f}", f"{me['half_width_percent'][n]:.1f}"] for n in names])]
    return "\n".join(out) + "\n"


def noise_floor_section(floor: dict[str, Any]) -> str:
    """The report's section on the sensor-noise floor of the noise model (``result['noise_floor']``)."""
    rows = [[ch, f"{100 * r['share']:.0f} %", f"{r['median_db']:.1f}" if "median_db" in r else "-",
             "{:.3g}-{:.3g}".format(*r["f_hz"]) if "f_hz" in r else "-"] for ch, r in floor["channels"].items()]
    return ("\n## Sensor-noise floor\n\nThe noise model separates a multiplicative model error (dB) from an "
            "additive floor N in power: y_mod = 5 log10(10^((y_sim + m)/5) + N) + e "
            f"(`noise.floor: {floor['mode']}`). Where N is given, the modelled level does not follow y_sim below "
            "it.\n\n" + markdown_table(["channel", "frequencies with a floor", "median 5 log10 N (dB)",
                                           "range (Hz)"], rows) + "\n")


def search_line(result: dict[str, Any]) -> str:
    """How the optimiser searched: the paper's design and iterations, or another optimiser's evaluations."""
    if result.get("optimizer", "ego") == "ego":
        return (f"{result['n_initial']} initial points (maximin design, minimum distance\n"
                f"{result['design_min_distance']:.3f} in [0, 1]^q), {result['n_iterations']} iterations, "
                f"stop: `{result['stop_reason']}`")
    return (f"Optimizer `{result['optimizer']}`: {result['n_simulator_calls']} evaluations of J with a value "
            f"(budget {result['budget']}, {result['n_initial']} of them a design), stop: `{result['stop_reason']}`")


def weights_line(result: dict[str, Any]) -> str:
    """One line on the channel weights α of eq. 5 when the reference date chose them (else empty)."""
    rec = result.get("objective_weights")
    if not rec:
        return ""
    alpha = ", ".join(f"{ch} {a:.3f}" for ch, a in rec["alpha"].items())
    return f"\nChannel weights α ({rec['method']}; {rec['how']}; {rec['n_simulations']} simulations): {alpha}.\n"


def write_report(run_dir: Path, problem: Problem, ego: LoopOutcome, result: dict[str, Any],
                 ei_history: list[float], executor: Executor | None = None, y_opt: np.ndarray | None = None) -> Path:
    """``report.md``: the maintenance verdict first, then the parameter table, the model-error checks,
    Figures 1-2 and the convergence plot.

    :param y_opt: ``(v, n_channels, n_freqs)`` dB, the model's spectra at w_opt on the measurement date's
        segments (Figure 1); simulated on ``executor`` (entered; in this process without one) when not given.
    """
    config = problem.config
    names = problem.names
    k = figure_channel(config, problem.channels)
    if y_opt is None:
        y_opt = run_one(executor, SpectraTask.of(problem.simulator, problem.segments, config.spectra),
                        dict(result["w_opt"]))
    noise, floor = problem.noise_model, problem.noise_model.floor_
    y_mod = modelled_spectra(y_opt, noise.sample(y_opt.shape[0], named_rng(config.seed, "figure-1")), floor)
    figure_spectra(run_dir / "figure1_spectra.png", problem.freqs, problem.y_mes, y_mod, problem.channels,
                   title="Measurement date: measured spectra against the model at w_opt with the noise model B",
                   first=k)
    reference_figure = ""
    if problem.reference:
        y_sim0 = problem.reference["y_sim0"]
        y_mod0 = modelled_spectra(y_sim0, noise.sample(y_sim0.shape[0], named_rng(config.seed, "figure-1-reference")),
                                  floor)
        figure_spectra(run_dir / "figure1_reference.png", problem.freqs, problem.reference["y_mes0"], y_mod0,
                       problem.channels, model="model at w0 with B", first=k,
                       title="Reference date (where B is identified): measured spectra against the model at w0 with B")
        reference_figure = ("\nThe reference date, where B is identified at the nominal parameters w0 (the "
                            "paper's Figure 1):\n\n![figure 1, reference date](figure1_reference.png)\n")
    figure_verdict(run_dir / "figure2_parameters.png", rows_of(result))
    figure_convergence(run_dir / "convergence.png", np.asarray(ego.y), ego.n_initial, ei_history, ego.n_refine)

    rows = []
    for n in names:
        u = result["units"][n]
        row = [n, u, result["w_opt"][n]] + ([result["w_corrected"][n]] if "w_corrected" in result else [])
        if "w_ref" in result:
            row += [result["w_ref"][n], f"{result.get('errors_percent_corrected', result['errors_percent'])[n]:.2f}"]
        lo_i, hi_i = result["interval"][n]
        row += [f"[{lo_i:.4g}, {hi_i:.4g}]", "yes" if result["identifiable"][n] else
                "**no**: " + "; ".join(result["non_identifiable_reasons"].get(n, [])),
                trust_cell(result, n), f"{result['sensitivity']['total_sobol'][n]:.3f}"]
        rows.append(row)
    unchanged = reports_reference(result)
    header = ["parameter", "unit", "w_opt"] + ([("reported (unchanged: w0)" if unchanged else "bias-corrected")]
                                               if "w_corrected" in result else []) \
        + (["w_ref", "error (% of interval)"] if "w_ref" in result else []) \
        + ["interval", "identifiable", "trustworthy under model error", "total Sobol index"]
    refine = ""
    if result.get("refine_stop_reason"):
        refine = (f" (the last {result['n_refine_iterations']} in the local refinement, stop: "
                  f"`{result['refine_stop_reason']}`)")
    widened = (", made bias-aware: widened by the model-error checks' bound on the bias (reference-date "
               "self-check bias + half the spread of the data groups' estimates + the nuisance parameters' shifts; "
               "Armstrong and Kolesár's fixed-length interval, which keeps the level for any bias within the bound)"
               if result.get("interval_method", {}).get("widened_by_model_error") else "")
    reference_date = (", and over the reference date's segments with B fitted again on each resample"
                      if result.get("interval_method", {}).get("bootstrap_reference") else "")
    if "w_corrected" in result:
        widened = (", the bias-corrected value being w_opt + the shift the model parameters calibrated at the "
                   "reference date give (the error column is its error); with their posterior spread added in "
                   "quadrature, and the reference-date self-check's bias and half the data groups' spread, "
                   "combined in quadrature, as a bound on the bias (Armstrong and Kolesár's fixed-length interval)")
    centre = ("w0 (no change shown)" if unchanged else "the bias-corrected value") if "w_corrected" in result \
        else "w_opt"
    text = f"""# suspid run `{config.name}`

{verdict_markdown(rows_of(result), markdown_table, with_reference="w_ref" in result)}
{no_change_line(result) + chr(10) if unchanged else ""}
## Identification

Objective `{config.objective.plugin}`, surrogate `{config.surrogate.plugin}`, simulator `{config.simulator.plugin}`,
seed {config.seed}. {search_line(result)}{refine},
J_max = {result['J_max']:.6g}, wall time {result['wall_time_s']:.1f} s.
{weights_line(result)}{"".join(chr(10) + "Track band: " + n + "." + chr(10) for n in config._notes)}
{markdown_table(header, rows)}

Components marked **no** (not identifiable, or not trustworthy under model error) are not findings:
their value is not to be reported. *not assessed*: no model-error check that ran flags the component, but
the checks that would judge it did not all run (see "Model error"); its interval holds no bias those
checks would have bounded.
Intervals: {centre} ± {result['interval_method']['n_sigmas']:g} standard deviations of the sandwich covariance
H⁻¹ Σ_g H⁻¹ (H the Hessian of J at w_opt: curvatures from simulations, correlations from the metamodel, Σ_g the covariance of the gradient of J at w_opt under a
bootstrap over segments, {result['interval_method']['bootstrap']}, with redrawn noise paths{reference_date}){widened}, clipped to the
admissible box.
{model_error_section(result)}
{calibration_markdown(result)}
## Figure 1: measured spectra against the model at w_opt, every channel

Measurement date: mean and 5-95 % band over the segments of the measured spectra (black) and of the modelled
ones Y_mod = Y_sim(w_opt) + B (blue, B the noise model): a measured mean outside the blue band is a misfit.
Y = 10 log10 |Â| in dB re 1 m s⁻¹·⁵ (paper eq. 1).

![figure 1](figure1_spectra.png)
{reference_figure}
## Figure 2: identified parameters in % of their nominal values, with the limits

Bars: intervals; markers: identified values, coloured by the verdict (filled: trustworthy, hollow: trust not
assessed, grey cross: not trustworthy, grey square: not identifiable); lines: warning (dashed) and alarm (solid)
levels of `limits:`.

![figure 2](figure2_parameters.png)

## Convergence

![convergence](convergence.png)
"""
    if result.get("correlated_with"):
        text += "\n## Correlated components\n\n" + "\n".join(
            f"- `{n}` with {', '.join(c)}" for n, c in result["correlated_with"].items()) + "\n"
    if result.get("noise_floor"):
        text += noise_floor_section(result["noise_floor"])
    if result.get("failed_points"):
        rows = [[p["phase"], ", ".join(f"{k} = {v:.4g}" for k, v in p["w"].items()), p["error"]]
                for p in result["failed_points"]]
        text += (f"\n## Failed simulations\n\n{len(rows)} simulation(s) failed; the run went on without them "
                 f"(in EGO a failed point takes the worst J found so far, so it is never w_opt). A rerun does "
                 f"not simulate them again unless `--retry-failed`.\n\n"
                 + markdown_table(["phase", "w", "error"], rows) + "\n")
    return write_text(run_dir / "report.md", text)
