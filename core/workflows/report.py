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
from suspid.optimize.ego import EGOResult
from suspid.workflows.trust import CHECK_LABELS
from suspid.workflows.problem import Problem
from suspid.workflows.linearised import calibration_markdown
from suspid.workflows.tasks import SpectraTask, run_one


def figure_spectra(path: Path, freqs: np.ndarray, y_mes: np.ndarray, y_sim: np.ndarray, y_mod: np.ndarray,
                   channel: int, channel_name: str, quantiles: tuple[float, float] = (0.05, 0.95)) -> Path:
    """Figure 1 analogue: mean and quantiles of Y_mes against Y_sim(w0) (top) and Y_mod(w0) (bottom).

    :param freqs: ``(n_freqs,)`` Hz.
    :param y_mes, y_sim, y_mod: ``(n_samples, n_channels, n_freqs)`` dB.
    """
    plt = pyplot()
    fig, axes = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    for ax, other, label, color in ((axes[0], y_sim, "Y_sim(w0)", "tab:red"),
                                    (axes[1], y_mod, "Y_mod(w0)", "tab:blue")):
        for y, lab, col in ((y_mes, "Y_mes", "black"), (other, label, color)):
            q_lo, q_hi = np.quantile(y[:, channel], quantiles, axis=0)
            ax.fill_between(freqs, q_lo, q_hi, color=col, alpha=0.18, lw=0)
            ax.plot(freqs, y[:, channel].mean(axis=0), color=col, lw=1.4,
                    label=f"{lab} mean, {int(quantiles[0] * 100)}-{int(quantiles[1] * 100)} % band")
        ax.set_ylabel("Y (dB)")
        ax.legend(loc="best", fontsize=8)
        ax.grid(alpha=0.3)
    axes[0].set_title(f"Channel {channel_name}: measured against simulated (top) and modelled (bottom)")
    axes[1].set_xlabel("frequency (Hz)")
    if freqs[-1] / max(freqs[0], 1e-9) > 20:
        axes[1].set_xscale("log")
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


def trust_word(trustworthy: bool | None) -> str:
    """A component's trust under model error in words: True "yes", False "no", None (or absent) "not assessed"."""
    return "yes" if trustworthy is True else "no" if trustworthy is False else "not assessed"


def trust_cell(result: dict[str, Any], name: str) -> str:
    """The report's "trustworthy under model error" cell: yes, **no** with the reasons, or not assessed."""
    word = trust_word(result.get("trustworthy", {}).get(name))
    if word == "no":
        return "**no**: " + "; ".join(result.get("untrustworthy_reasons", {}).get(name, []))
    return "*not assessed*" if word == "not assessed" else word


def checks_lines(result: dict[str, Any]) -> list[str]:
    """Which model-error checks ran and which did not, and why (from ``result["model_error"]["checks"]``)."""
    checks = (result.get("model_error") or {}).get("checks")
    if not checks:
        return ["Model-error checks: not recorded in this result."]
    labels = CHECK_LABELS
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
                   f"segments, w identified on the other {sc['segments_identify']} by a local search from w0, "
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
        out += ["", f"Nuisance parameters: w identified again, from w_opt, with each assumed model parameter at an "
                    f"end of its plausible range (B fitted again at the reference date); shift against the nominal "
                    f"model in % of the interval. A component moved by more than {nu['max_shift_percent']:.0f} % "
                    f"rests on the assumption, not on the data.", "",
                markdown_table(["nuisance parameter", "value"] + names,
                               [[row["parameter"], f"{row['value']:g}"] + [f"{row[n]:+.1f}" for n in names]
                                for row in nu["shifts_percent"]])]
    elif nu and "checks" not in me:
        out += ["", f"Nuisance parameters: {nu['status']}."]
    bound = me.get("bias_bound_percent")
    corr = me.get("correction")
    if bound and corr:
        out += ["", f"Bias correction: {corr['method']}; the equivalent bound on the remaining bias (the "
                    f"self-check's bias and half the groups' spread in quadrature, with the model parameters' "
                    f"posterior spread as one) and the interval's half-width, in % of the interval. A component "
                    f"wider than ± {me['max_half_width_percent']:.0f} % is not trustworthy.", "",
                markdown_table(["parameter", "correction (%)", "bias-corrected", "bound on the bias (%)",
                                "half-width (%)"],
                               [[n, f"{corr['correction_percent'][n]:+.1f}", f"{corr['w_corrected'][n]:.4g}",
                                 f"{bound[n]:.1f}", f"{me['half_width_percent'][n]:.1f}"] for n in names])]
    elif bound:
        out += ["", f"Bound on the bias of w_opt (the self-check's |bias| + half the groups' spread + each nuisance "
                    f"parameter's larger |shift|, their signs unknown) and the bias-aware interval's half-width, "
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


def write_report(run_dir: Path, problem: Problem, ego: EGOResult, result: dict[str, Any],
                 ei_history: list[float], executor: Executor | None = None) -> Path:
    """``report.md`` with the parameter table and Figures 1-2 analogues and the convergence plot.

    :param executor: runs Figure 1's simulation at w0 when the run has no reference date
        (entered; in this process without one).
    """
    config = problem.config
    names = problem.names
    k = figure_channel(config, problem.channels)
    if problem.reference:
        y_mes0, y_sim0 = problem.reference["y_mes0"], problem.reference["y_sim0"]
        date = "reference date (where B is identified)"
    else:
        y_mes0 = problem.y_mes
        y_sim0 = run_one(executor, SpectraTask.of(problem.simulator, problem.segments, config.spectra), {})
        date = "measurement date"
    y_mod0 = modelled_spectra(y_sim0, problem.noise_model.sample(y_sim0.shape[0], named_rng(config.seed, "figure-1")),
                              problem.noise_model.floor_)
    figure_spectra(run_dir / "figure1_spectra.png", problem.freqs, y_mes0, y_sim0, y_mod0, k, problem.channels[k])
    w_ref_n = np.array([result["w_ref_normalized"][n] for n in names]) if "w_ref" in result else None
    figure_parameters(run_dir / "figure2_parameters.png", names,
                      {config.objective.plugin: np.array([result["w_opt_normalized"][n] for n in names])},
                      w_ref_n, {config.objective.plugin: np.array([result["interval_normalized"][n] for n in names])})
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
    header = ["parameter", "unit", "w_opt"] + (["bias-corrected"] if "w_corrected" in result else []) \
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
    centre = "the bias-corrected value" if "w_corrected" in result else "w_opt"
    text = f"""# suspid run `{config.name}`

Objective `{config.objective.plugin}`, surrogate `{config.surrogate.plugin}`, simulator `{config.simulator.plugin}`,
seed {config.seed}. {search_line(result)}{refine},
J_max = {result['J_max']:.6g}, wall time {result['wall_time_s']:.1f} s.

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
## Figure 1: measured, simulated and modelled spectra ({date}), channel `{problem.channels[k]}`

![figure 1](figure1_spectra.png)

## Figure 2: identified parameters, normalised

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
