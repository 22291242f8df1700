"""Which element groups the sensors separate (``suspid observability``) and which one changed (localisation).

Both work on a run's problem (:func:`suspid.workflows.problem.build_problem`:
the measurement date's spectra and the reference date's, where w = w0) and on
the Jacobian of the model's spectra with respect to every element of the
analysed kinds (:func:`suspid.workflows.jacobian.spectra_jacobian`, analytic where
the simulator differentiates), at w0 on the first ``localisation.n_segments``
segments of the measurement date. The statistics are those of
:mod:`suspid.method.localisation`.

- :func:`observability`: Fisher information over the elements, its rank and
  conditioning, the clusters of elements the sensors cannot tell apart (only
  their sum is seen), which clusters a change of ``localisation.change`` would
  show at all, and a sensor-placement advice: for each channel the simulator
  could add (:meth:`suspid.interfaces.ElementSimulator.candidate_channels`),
  which clusters it would split. Writes ``observability.json``.
- :func:`localise_problem`: the hypotheses "cluster c deviates", fitted on the
  linearised model, the best ones refined by Gauss-Newton on simulations,
  ranked by evidence; the rows of the result's ``localisation`` entry.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from suspid.config import Config
from suspid.elements import declared_groups, finest_groups, kind_of, split_name
from suspid.errors import ConfigError
from suspid.infra.files import write_json
from suspid.infra.lock import open_run_dir
from suspid.method.floor import estimate_floor
from suspid.interfaces import IRREGULARITY_CHANNELS, ElementSimulator, TrackSegment
from suspid.method.calibration import octave_clusters
from suspid.method.localisation import (Hypothesis, HypothesisFit, LocalisationOptions, change_statistics, clusters,
                                        cluster_sd, consistent_channels,
                                        evidence, fisher_information_unbiased, fit_column, fit_hypotheses,
                                        sandwich_sd, separability, smooth_gain_basis, without_channel_gains,
                                        without_smooth_gains)
from suspid.workflows.jacobian import spectra_jacobian
from suspid.workflows.linearised import calibrate, date_jacobian, model_parameters
from suspid.workflows.problem import Problem, _task, build_problem

__all__ = ["ObservabilityResult", "ElementAnalysis", "observability", "element_analysis", "localise_problem",
           "localisation_wanted", "moved_kinds", "with_nuisance", "localisation_markdown", "format_observability"]

Log = Callable[[str], None]


@dataclass
class ElementAnalysis:
    """The element-level linearisation of a problem.

    :ivar groups: ``(n_g,)`` finest group names (one element each); :ivar kinds: their kinds.
    :ivar nominal: ``(n_g,)`` SI values at w0.
    :ivar J: ``(n_channels, n_freqs, n_g)`` dB per unit of ln(value), mean over the Jacobian's segments.
    :ivar delta, var: observed change of the mean residual between the dates and its variance
        ``(n_channels, n_freqs)`` dB, dB².
    :ivar F: ``(n_g, n_g)`` Fisher information.
    :ivar S: separability χ² (:func:`~suspid.method.localisation.separability`).
    :ivar hypotheses: one per cluster of not separable elements.
    """

    groups: list[str]
    kinds: list[str]
    nominal: np.ndarray
    J: np.ndarray
    delta: np.ndarray
    var: np.ndarray
    F: np.ndarray
    S: np.ndarray
    hypotheses: list[Hypothesis]
    options: LocalisationOptions
    segments: list = field(default_factory=list)
    y0: np.ndarray | None = None
    """``(v, n_channels, n_freqs)`` dB: the model at w0 on every measurement segment."""
    residuals: list = field(default_factory=list)
    """Per date ``(v, n_channels, n_freqs)`` dB: measured less model at w0 (channel gains removed when fitted)."""
    n_clusters: int = 0
    """The first ``n_clusters`` hypotheses are the clusters; the others coarser groups made of whole clusters."""
    nuisance: np.ndarray | None = None
    """``(n_channels, n_freqs, k)`` columns fitted with every hypothesis (kind-level changes of other kinds that
    moved), already removed from ``delta``, ``J`` and ``residuals`` (:func:`with_nuisance`)."""
    w0: dict[str, float] = field(default_factory=dict)
    """SI values the model is linearised at: the identified kinds' nominal values and, when
    ``localisation.calibrate`` is on, the model parameters calibrated on the reference date."""
    calibration: dict[str, Any] = field(default_factory=dict)
    """``{"status": ..., "parameters": {name: {"nominal", "estimate", "sd"}}, "sensor_floor": ...}``: the
    linearisation point's model parameters (:func:`calibrated_point`) and the sensor floor's source."""
    floor: Callable[[np.ndarray], np.ndarray] | None = None
    """y_sim -> the spectra the sensors would give (:func:`_floor`); None: the identity."""

    def project(self, x: np.ndarray) -> np.ndarray:
        """``x (n_channels, n_freqs)`` less its weighted least-squares fit by the nuisance columns."""
        if self.nuisance is None:
            return x
        N = self.nuisance.reshape(-1, self.nuisance.shape[-1]) / np.sqrt(self.var.reshape(-1))[:, None]
        y = x.reshape(-1) / np.sqrt(self.var.reshape(-1))
        coef, *_ = np.linalg.lstsq(N, y, rcond=None)
        return x - (self.nuisance.reshape(-1, N.shape[1]) @ coef).reshape(x.shape)


def with_nuisance(analysis: ElementAnalysis, kinds: Sequence[str]) -> ElementAnalysis:
    """The analysis with a kind-level change of each of ``kinds`` fitted along with every hypothesis: those
    kinds' columns (the sum of their elements') removed from the observed change, the Jacobian and the
    residuals by weighted least squares."""
    if not kinds:
        return analysis
    cols = np.stack([analysis.J[..., [i for i, k in enumerate(analysis.kinds) if k == kind]].sum(axis=-1)
                     for kind in kinds], axis=-1)
    out = replace(analysis, nuisance=cols)
    J = np.stack([out.project(analysis.J[..., i]) for i in range(analysis.J.shape[-1])], axis=-1)
    residuals = [np.stack([out.project(r) for r in rs]) for rs in analysis.residuals]
    return replace(out, delta=out.project(analysis.delta), J=J, residuals=residuals)


def mirror(segment: TrackSegment) -> TrackSegment:
    """The segment's mirror image about the track's centre line: alignment and cross-level change sign
    (longitudinal level and gauge do not), curvature and cant too; named ``<name>~mirror``."""
    irr = np.array(segment.irregularities, dtype=float, copy=True)
    irr[IRREGULARITY_CHANNELS.index("lateral")] *= -1.0
    irr[IRREGULARITY_CHANNELS.index("cross_level")] *= -1.0
    return replace(segment, name=f"{segment.name}~mirror", irregularities=irr,
                   curvature=None if segment.curvature is None else -np.asarray(segment.curvature),
                   cant=None if segment.cant is None else -np.asarray(segment.cant))


def mirrored_pairs(segments: Sequence[TrackSegment]) -> list[TrackSegment]:
    """Each segment followed by its :func:`mirror`.

    A track's statistics are the same seen in a mirror, so a left element and its right twin of a
    mirror-symmetric vehicle change the *expected* spectra of its centreline sensors alike; over one
    realisation they do not. Averaging each segment's Jacobian with its mirror's removes that realisation's
    part exactly for centreline sensors (the left twin on a track acts as the right twin on its mirror), and
    keeps what off-centre sensors really see.
    """
    return [s for seg in segments for s in (seg, mirror(seg))]


def _pair_means(a: np.ndarray) -> np.ndarray:
    """``(2 v, ...)`` of :func:`mirrored_pairs` -> ``(v, ...)``: each segment averaged with its mirror."""
    return 0.5 * (a[0::2] + a[1::2])


def _floor(problem: Problem, y_sim0: np.ndarray | None = None, estimate: bool = False
           ) -> tuple[Callable[[np.ndarray], np.ndarray], str]:
    """y_sim -> the spectra the sensors would give, and where the floor comes from.

    The noise model's sensor floor (:meth:`suspid.method.floor.NoiseFloor.effective`) when it has one; else,
    with ``estimate``, one estimated on the reference date against ``y_sim0`` ``(v0, n_channels, n_freqs)`` dB
    as ``noise.floor: auto`` does (:func:`suspid.method.floor.estimate_floor`); else the identity. Where sensor
    noise masks the vehicle's response the measured spectra do not follow an element's change, and the model's
    sensitivity there must not say they do."""
    f = getattr(problem.noise_model, "floor_", None)
    if f is not None:
        return f.effective, "the noise model's (noise.floor)"
    if estimate and y_sim0 is not None and problem.reference["y_mes0"].shape[0] >= 3:
        octaves = problem.config.noise.floor_octaves
        return (estimate_floor(problem.reference["y_mes0"], y_sim0, problem.freqs, octaves).effective,
                "estimated on the reference date (localisation.sensor_floor)")
    return (lambda y: y), "none"


def _floor_gain(floor: Callable[[np.ndarray], np.ndarray], y: np.ndarray, h: float = 1e-3) -> np.ndarray:
    """d floor(y) / dy (1 without a floor, less where the sensor floor masks the model), same shape as ``y``."""
    return (floor(y + h) - floor(y - h)) / (2 * h)


def _kinds(config: Config, simulator, problem: Problem | None, options: LocalisationOptions) -> list[str]:
    if not isinstance(simulator, ElementSimulator):
        raise ConfigError(f"simulator '{simulator.name}' declares no elements: observability and localisation "
                          f"need element-level parameters", key="localisation")
    have = list(dict.fromkeys(e.kind for e in simulator.elements()))
    if options.kinds is not None:
        bad = [k for k in options.kinds if k not in have]
        if bad:
            raise config.error(f"kind(s) {', '.join(bad)} have no declared elements (kinds with elements: "
                               f"{', '.join(have)})", "localisation.kinds")
        return list(options.kinds)
    names = problem.names if problem is not None else list(config.parameters) or simulator.default_parameters()
    out = list(dict.fromkeys(kind_of(n) for n in names if kind_of(n) in have))
    if not out:
        raise config.error(f"no identified parameter has declared elements; name the kinds (kinds with elements: "
                           f"{', '.join(have)})", "localisation.kinds")
    return out


def _cluster_name(simulator, members: list[str]) -> str:
    """The declared group whose elements are exactly those of ``members``, else their names joined by ' + '."""
    groups = declared_groups(simulator.elements())
    tags = {groups[m].members[0] for m in members}
    kind = kind_of(members[0])
    for g in groups.values():
        if g.kind == kind and set(g.members) == tags:
            return g.name
    parts, left = [], set(tags)      # else the fewest declared groups that make it up, largest first
    for g in sorted(groups.values(), key=lambda g: -len(g.members)):
        if g.kind == kind and set(g.members) <= left:
            parts.append(g.name)
            left -= set(g.members)
    return " + ".join(parts)


def _note(names: list[str]) -> str:
    if len(names) == 1:
        return ""
    return f"{len(names)} elements not separable with these sensors ({', '.join(names)}): only their sum is seen"


class _NoCache:
    """A ledger stand-in that stores nothing (:func:`calibrated_point` called without a run's ledger)."""

    def get_array(self, key: str) -> None:
        return None

    def put_array(self, key: str, array: np.ndarray) -> None:
        pass


def calibrated_point(problem: Problem, w0: dict[str, float], *, gain_octaves: float | None = None, ledger=None,
                     executor=None, log: Log = lambda s: None) -> tuple[dict[str, float], dict[str, Any]]:
    """``w0`` with the model parameters estimated on the reference date, and what was done.

    A change of an element is read through the model's sensitivity to it: where the model's resonances sit
    at other frequencies or with other damping than the vehicle's, the sensitivity has the wrong shape, the
    least-squares change (a projection on it) comes out smaller than the true one, and another element whose
    sensitivity happens to overlap the change better may fit better. On the reference date the elements are at
    their nominal values, so the model parameters that are assumptions (the simulator's
    :meth:`~suspid.interfaces.Simulator.calibratable` ones, or ``identifiability.model_error.calibration
    .parameters``, over their assumed ranges) can be estimated there, as the model-error checks do
    (:func:`suspid.workflows.linearised.calibrate`: Gauss-Newton with a gain per channel profiled out).
    The linearisation point is its point estimate, pinned down or not: the model nearest the reference date.
    A smooth gain the same on both dates (sensor transfer functions, unmodelled flexibility) cancels in the
    observed change but would be taken for a creep or conicity change here: with ``gain_octaves`` a smooth
    gain per channel (:func:`~suspid.method.localisation.smooth_gain_basis`, knots that many octaves apart) is
    estimated jointly with the model parameters; None: a flat gain only. ``ledger`` caches the Jacobians
    (none: nothing is cached).
    """
    theta = model_parameters(problem, problem.config.identifiability.model_error)
    if not theta.names:
        return w0, {"status": "not calibrated: the simulator declares no calibratable model parameter"}
    ledger = ledger if ledger is not None else _NoCache()
    log(f"localisation: model parameters {', '.join(theta.names)} calibrated on the reference date")
    jac0 = date_jacobian(problem, ledger, problem.reference_segments, {**dict(problem.w0), **w0}, [], theta,
                         executor)
    strip = None
    if gain_octaves is not None:
        basis = smooth_gain_basis(problem.freqs, gain_octaves)
        strip = lambda x, weights: without_smooth_gains(x, weights, basis)  # noqa: E731
    cal = calibrate(problem, ledger, theta, jac0, [], problem.config.identifiability.model_error, executor, strip)
    estimate = theta.w(np.array(cal["t_hat"]))
    return {**w0, **estimate}, {"status": "calibrated on the reference date",
                                "parameters": {n: {"nominal": float(v), "estimate": estimate[n],
                                                   "sd": float(cal["parameters"][n]["standard_deviation"])}
                                               for n, v in zip(theta.names, theta.nominal)}}


def element_analysis(problem: Problem, options: LocalisationOptions, *, ledger=None, executor=None,
                     log: Log = lambda s: None) -> ElementAnalysis:
    """Jacobian over the finest groups, observed change and its variance, Fisher information, clusters.

    The model is linearised at the identified kinds' nominal values, with the model parameters calibrated on
    the reference date when ``options.calibrate`` (:func:`calibrated_point`; ``ledger`` caches its
    Jacobians)."""
    config, simulator = problem.config, problem.simulator
    kinds = _kinds(config, simulator, problem, options)
    finest = finest_groups(simulator.elements(), kinds)
    names = [g.name for g in finest]
    gkinds = [g.kind for g in finest]
    if not problem.reference:
        raise config.error("observability and localisation compare the measurement date with the reference date: "
                           "give noise.reference (measured data) or let the experiment simulate it", "noise")
    segments = mirrored_pairs(problem.segments[:max(1, options.n_segments // 2)])
    nominal_all = {p.name: p.nominal for p in simulator.parameters()}
    w0 = {n: float(v) for n, v in problem.w0.items() if "[" not in n} if problem.w0 else {}
    nominal = np.array([w0.get(k, nominal_all[k]) for k in gkinds])
    calibration: dict[str, Any] = {"status": "off (localisation.calibrate: false)"}
    y_sim0 = problem.reference["y_sim0"]
    if options.calibrate:
        w0, calibration = calibrated_point(problem, w0, gain_octaves=options.calibration_gain_octaves,
                                           ledger=ledger, executor=executor, log=log)
        if "parameters" in calibration:
            log("model at the calibrated point on the reference date's segments")
            y_sim0, _ = _task(simulator, problem.reference_segments, problem.config.spectra)(w0)
    floor, floor_source = _floor(problem, y_sim0, options.sensor_floor)
    calibration = {**calibration, "sensor_floor": floor_source}
    log(f"element Jacobian: {len(names)} elements of {', '.join(kinds)} on {len(segments)} segment(s)")
    jac = spectra_jacobian(simulator, w0, names, segments, problem.config.spectra, executor=executor)
    log("model at w0 on the measurement date's segments")
    y0, _ = _task(simulator, problem.segments, problem.config.spectra)(w0)
    r_mes = problem.y_mes - floor(y0)
    r_ref = problem.reference["y_mes0"] - floor(y_sim0)
    delta, var = change_statistics(r_mes, r_ref, options.floor_db)
    dy = _pair_means(jac.jacobian * _floor_gain(floor, jac.y)[..., None]) * nominal   # dB per unit ln(value)
    if options.channel_gains:
        delta = without_channel_gains(delta, var)
        r_mes = np.stack([without_channel_gains(r, var) for r in r_mes])
        r_ref = np.stack([without_channel_gains(r, var) for r in r_ref])
        dy = np.stack([without_channel_gains(d, var) for d in dy])
    F, J = fisher_information_unbiased(dy, var)
    S = separability(F, options.change)
    hyps = []
    found = clusters(S, gkinds, options.separation_chi2)   # the first len(found) hypotheses are the clusters
    for c in found:
        members = [names[i] for i in c]
        hyps.append(Hypothesis(_cluster_name(simulator, members), gkinds[c[0]], c, float(nominal[c[0]]),
                               _note(members)))
    # coarser declared groups made of whole clusters (a bogie's elements, a side's, the whole kind): a change of
    # several clusters together is one hypothesis too
    index = {(g.kind, g.members[0]): i for i, g in enumerate(finest)}
    seen = {frozenset(c) for c in found}
    for g in declared_groups(simulator.elements()).values():
        if g.kind not in kinds:
            continue
        idx = frozenset(index[(g.kind, m)] for m in g.members)
        if idx in seen or not all(set(c) <= idx or not set(c) & idx for c in found):
            continue
        seen.add(idx)
        parts = [h.name for h in hyps[:len(found)] if set(h.members) <= idx]
        hyps.append(Hypothesis(g.name, g.kind, sorted(idx), float(nominal[min(idx)]),
                               f"together: {', '.join(parts)}" if len(parts) > 1 else ""))
    return ElementAnalysis(names, gkinds, nominal, J, delta, var, F, S, hyps, options, segments, y0,
                           [r_mes, r_ref], len(found), w0=w0, calibration=calibration, floor=floor)


# -------------------------------------------------------------------------------------------- observability
@dataclass
class ObservabilityResult:
    """What :func:`observability` found (``observability.json``); ``path`` is that file.

    :ivar groups: finest groups (one element each), in the order of ``fisher``.
    :ivar fisher: ``(n_g, n_g)`` Fisher information of ln(values); :ivar eigenvalues: ascending.
    :ivar rank: eigenvalues above ``separation_chi2 / θ²`` (θ = ln(1 - change)): directions a change of that size
        shows; :ivar condition: largest / smallest eigenvalue (inf when singular).
    :ivar clusters: rows ``{name, kind, members, separable, detectable, sd_percent, note}``, one per hypothesis.
    :ivar advice: rows ``{channel, splits: [cluster name], separates: [[a, b]]}``, best first.
    """

    groups: list[str]
    fisher: np.ndarray
    eigenvalues: np.ndarray
    rank: int
    condition: float
    clusters: list[dict[str, Any]]
    advice: list[dict[str, Any]]
    options: dict[str, Any]
    path: Path | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"groups": self.groups, "fisher": self.fisher.tolist(), "eigenvalues": self.eigenvalues.tolist(),
                "rank": self.rank, "condition": None if not math.isfinite(self.condition) else self.condition,
                "clusters": self.clusters, "advice": self.advice, "options": self.options}

    def table(self) -> str:
        """The readable table ``suspid observability`` prints."""
        return format_observability(self)


def _pairs_separated(S: np.ndarray, kinds: Sequence[str], threshold: float) -> set[tuple[int, int]]:
    return {(i, j) for i in range(len(kinds)) for j in range(i + 1, len(kinds))
            if kinds[i] == kinds[j] and min(S[i, j], S[j, i]) >= threshold}


def observability_of(analysis: ElementAnalysis, simulator, problem: Problem, *, executor=None,
                     log: Log = lambda s: None) -> ObservabilityResult:
    """:class:`ObservabilityResult` of an :class:`ElementAnalysis`, with the sensor-placement advice."""
    o = analysis.options
    theta2 = math.log(1.0 - o.change) ** 2
    F = analysis.F
    ev = np.linalg.eigvalsh(F)
    rank = int(np.sum(ev * theta2 >= o.separation_chi2))
    condition = float(ev[-1] / ev[0]) if ev[0] > 0 else math.inf
    rows = []
    cluster_hyps = analysis.hypotheses[:analysis.n_clusters]
    for h in cluster_hyps:
        u = np.zeros(len(analysis.groups))
        u[h.members] = 1.0
        info = float(u @ F @ u)
        rows.append({"name": h.name, "kind": h.kind, "members": [analysis.groups[i] for i in h.members],
                     "separable": len(h.members) == 1, "detectable": bool(info * theta2 >= o.separation_chi2),
                     "sd_percent": 100.0 / math.sqrt(info) if info > 0 else None, "note": h.note})
    advice: list[dict[str, Any]] = []
    candidates = simulator.candidate_channels() if isinstance(simulator, ElementSimulator) else []
    inseparable = [h for h in cluster_hyps if len(h.members) > 1]
    if candidates and inseparable:
        log(f"sensor advice: Jacobian of {len(candidates)} candidate channel(s)")
        extended = simulator.with_channels(candidates)
        jac = spectra_jacobian(extended, analysis.w0, analysis.groups, analysis.segments, problem.config.spectra,
                               executor=executor)
        n_own = analysis.J.shape[0]
        Jc = _pair_means(jac.jacobian)[:, n_own:] * analysis.nominal     # (v/2, n_candidates, n_freqs, n_g)
        var_c = np.median(analysis.var, axis=0)            # per frequency: the own channels' median variance
        base = _pairs_separated(analysis.S, analysis.kinds, o.separation_chi2)
        for k, channel in enumerate(candidates):
            Fc = F + fisher_information_unbiased(Jc[:, k:k + 1], var_c[None, :])[0]
            new = _pairs_separated(separability(Fc, o.change), analysis.kinds, o.separation_chi2) - base
            if not new:
                continue
            splits = [h.name for h in inseparable if any(i in h.members and j in h.members for i, j in new)]
            advice.append({"channel": channel, "splits": splits,
                           "separates": [[analysis.groups[i], analysis.groups[j]] for i, j in sorted(new)]})
        advice.sort(key=lambda a: (-len(a["splits"]), -len(a["separates"]), a["channel"]))
    return ObservabilityResult(analysis.groups, F, ev, rank, condition, rows, advice, o.model_dump())


def format_observability(result: ObservabilityResult) -> str:
    """A readable table of the clusters and the advice."""
    lines = [f"{len(result.groups)} elements; Fisher information rank {result.rank} (changes of "
             f"{100 * result.options['change']:.0f} % detectable), condition number "
             f"{'inf' if not math.isfinite(result.condition) else f'{result.condition:.3g}'}", "",
             f"{'group':<28} {'elements':>8} {'separable':>9} {'detectable':>10} {'sd %':>7}  note"]
    for r in result.clusters:
        sd = "-" if r["sd_percent"] is None else f"{r['sd_percent']:.2g}"
        lines.append(f"{r['name']:<28} {len(r['members']):>8} {('yes' if r['separable'] else 'no'):>9} "
                     f"{('yes' if r['detectable'] else 'no'):>10} {sd:>7}  {r['note']}")
    lines.append("")
    if result.advice:
        lines.append("sensor-placement advice (one extra channel each):")
        for a in result.advice[:10]:
            lines.append(f"  {a['channel']}: splits {', '.join(a['splits'])}")
    elif any(not r["separable"] for r in result.clusters):
        lines.append("sensor-placement advice: no single extra channel the simulator offers separates these clusters")
    return "\n".join(lines)


def observability(config: Config, *, log: Log = lambda s: None, executor=None) -> ObservabilityResult:
    """``suspid observability``: the element groups the configured sensors separate, and where to add one.

    Builds the run's problem (both dates; cached in the run directory's ledger), then
    :func:`element_analysis` and :func:`observability_of`; writes ``observability.json`` in the run directory.
    """
    run_dir = config.run_dir()
    with open_run_dir(run_dir, config_name=config.name, config_file=config.source_file, log=log) as ledger:
        problem = build_problem(config, ledger, log, executor)
        analysis = element_analysis(problem, config.localisation, ledger=ledger, executor=executor, log=log)
        result = observability_of(analysis, problem.simulator, problem, executor=executor, log=log)
        result.path = write_json(run_dir / "observability.json", result.to_dict())
    return result


# -------------------------------------------------------------------------------------------- localisation
def moved_kinds(result: dict[str, Any], simulator) -> list[str]:
    """The identified kinds with declared elements whose interval in ``result`` excludes the nominal value."""
    if not isinstance(simulator, ElementSimulator):
        return []
    have = {e.kind for e in simulator.elements()}
    nominal = {p.name: p.nominal for p in simulator.parameters()}
    out = []
    for n in result.get("parameters", []):
        lo, hi = result.get("interval", {}).get(n, (None, None))
        if n in have and lo is not None and not lo <= nominal[n] <= hi:
            out.append(n)
    return out


def localisation_wanted(config: Config, result: dict[str, Any], simulator) -> bool:
    """``localisation.enabled``; for 'auto': an identified kind with declared elements whose interval excludes
    its nominal value (:func:`moved_kinds`)."""
    enabled = config.localisation.enabled
    if enabled is True or enabled is False:
        return enabled
    return bool(moved_kinds(result, simulator))


def _refine(fit: HypothesisFit, analysis: ElementAnalysis, problem: Problem, *, executor=None,
            keep: np.ndarray | None = None) -> HypothesisFit:
    """Gauss-Newton on simulations: the model's change of the mean spectra over the Jacobian's segments with the
    hypothesis' elements at nominal × e^θ, against the observed change. Its sd is the larger of the segments'
    one and, with ``model_form_octaves``, the cluster-robust one of the misfit the fit leaves
    (:func:`~suspid.method.localisation.cluster_sd`: the channels' disagreement where the model responds to the
    element otherwise than the vehicle); ``details["sd_statistical"]`` keeps the segments' one, and
    ``details["channels"]`` each channel's own estimate ``(θ_k, sd_k)`` at the last step. ``keep``
    ``(n_channels,)`` bool: fit on those channels only."""
    h = fit.hypothesis
    var = analysis.var if keep is None else np.where(keep[:, None], analysis.var, np.inf)
    members = [analysis.groups[i] for i in h.members]
    w0 = analysis.w0
    floor = analysis.floor or (lambda y: y)
    base = floor(analysis.y0).mean(axis=0)
    simulate = _task(problem.simulator, problem.segments, problem.config.spectra)
    theta = fit.theta
    chi2_null = float(np.sum(analysis.delta ** 2 / analysis.var))
    chi2 = fit.chi2
    sd = fit.sd
    sw = 0.0
    for _ in range(analysis.options.gauss_newton_steps):
        w = {**w0, **{m: h.nominal * math.exp(theta) for m in members}}
        jac = spectra_jacobian(problem.simulator, w, members, analysis.segments, problem.config.spectra,
                               executor=executor)
        # the model's change over every measurement segment (those of the observed change); its slope from the
        # Jacobian's segments
        model = floor(simulate(w)[0]).mean(axis=0) - base                 # (n_channels, n_freqs) dB
        dy = jac.jacobian * _floor_gain(floor, jac.y)[..., None]
        column = (dy.mean(axis=0) * h.nominal * math.exp(theta)).sum(axis=-1)
        if analysis.options.channel_gains:
            model = without_channel_gains(model, analysis.var)
            column = without_channel_gains(column, analysis.var)
        model, column = analysis.project(model), analysis.project(column)
        step, sd_step, _ = fit_column(column, analysis.delta - model, var)
        step = float(np.clip(step, -0.5, 0.5))
        own = [fit_column(column[k], analysis.delta[k] - model[k], analysis.var[k]) for k in range(len(column))]
        channels = [(theta + t_k, s_k * math.sqrt(max(1.0, c_k / max(1, column.shape[1] - 1))))
                    for t_k, s_k, c_k in own]
        theta += step
        misfit = analysis.delta - model - column * step
        chi2 = float(np.sum(misfit ** 2 / var))
        sd = sd_step
        sw = sandwich_sd(column, var, analysis.residuals)
        if abs(step) < 1e-3:
            break
    n_cells = int(np.isfinite(var).sum())                  # the cells of the channels fitted
    ev, s2 = evidence(chi2_null, chi2, n_cells, (sw / sd) ** 2 if sd > 0 else 1.0)
    details = {"chi2_null": chi2_null, "s2": s2, "method": "gauss-newton", "sd_statistical": sd * math.sqrt(s2)}
    if analysis.options.gauss_newton_steps > 0:
        details["channels"] = channels
    octaves = analysis.options.model_form_octaves
    sd_out = sd * math.sqrt(s2)
    if octaves is not None and analysis.options.gauss_newton_steps > 0:
        # the structured misfit the refined fit leaves (model-form error) widens the interval, not the evidence
        details["sd_model_form"] = cluster_sd(column, var, misfit,
                                              octave_clusters(problem.freqs, misfit.shape[0], octaves))
        sd_out = max(sd_out, details["sd_model_form"])
    return HypothesisFit(h, theta, sd_out, chi2, ev, details)


def localise_problem(problem: Problem, options: LocalisationOptions, *, analysis: ElementAnalysis | None = None,
                     moved: Sequence[str] | None = None, ledger=None, executor=None,
                     log: Log = lambda s: None) -> dict[str, Any]:
    """The localisation entry of a result: ``{"named": bool, "rows": [...], "hypotheses": [...]}``.

    ``rows``: the named group (none when the best evidence is below ``min_evidence``) as
    ``{group, kind, value, nominal, interval, interval_statistical, evidence, alternatives, members, separable,
    note}``: ``value`` and ``interval`` in SI units (2 sd, the model-form misfit included:
    :func:`_refine`), ``interval_statistical`` the segments' spread alone, ``alternatives`` the hypotheses within
    ``near`` of its evidence (``{group, value, evidence}``). ``hypotheses``: every hypothesis, best first.
    """
    analysis = analysis or element_analysis(problem, options, ledger=ledger, executor=executor, log=log)
    moved = [k for k in (moved or []) if k in analysis.kinds]
    rows: list[dict[str, Any]] = []
    every: list[HypothesisFit] = []
    for focus in (moved or [None]):
        # after an identification in which several kinds moved: one kind at a time, the others' kind-level
        # changes fitted along (nuisance); on request: every hypothesis of every kind against every other
        part = with_nuisance(analysis, [k for k in moved if k != focus]) if focus else analysis
        hyps = [h for h in part.hypotheses if focus is None or h.kind == focus]
        found = _localise_one(problem, options, part, hyps, executor, log)
        rows += found[0]
        every += found[1]
    every.sort(key=lambda f: -f.evidence)
    return {"named": bool(rows), "rows": rows, "hypotheses": [_row(f, analysis) for f in every],
            "moved": moved, "options": options.model_dump(), "linearised_at": analysis.calibration}


def _row(f: HypothesisFit, analysis: ElementAnalysis) -> dict[str, Any]:
    members = [analysis.groups[i] for i in f.hypothesis.members]
    return {"group": f.hypothesis.name, "kind": f.hypothesis.kind, "value": f.value,
            "nominal": f.hypothesis.nominal, "interval": list(f.interval()), "evidence": f.evidence,
            "interval_statistical": list(f.interval(sd=f.details.get("sd_statistical", f.sd))),
            "members": members, "separable": len(members) == 1, "note": f.hypothesis.note,
            "not_separated": not_separated(members) if "not separable" in f.hypothesis.note else "",
            "method": f.details.get("method")}


def not_separated(members: Sequence[str]) -> str:
    """``"left/right not separable with these sensors"``: the tags in which the members of a cluster differ."""
    tags = [split_name(m)[1] for m in members]
    varying = ["/".join(dict.fromkeys(t[i] for t in tags)) for i in range(min(map(len, tags)))
               if len({t[i] for t in tags}) > 1]
    return f"{', '.join(varying)} not separable with these sensors" if varying else ""


def _localise_one(problem: Problem, options: LocalisationOptions, analysis: ElementAnalysis, hypotheses,
                  executor, log) -> tuple[list[dict[str, Any]], list[HypothesisFit]]:
    """The named row (or none) among ``hypotheses`` and every fit, best first."""
    fits = fit_hypotheses(hypotheses, analysis.J, analysis.delta, analysis.var, analysis.residuals)
    log(f"localisation: {len(fits)} hypotheses, refining the best {min(options.refine_top, len(fits))}")
    refined = [_refine(f, analysis, problem, executor=executor) for f in fits[:options.refine_top]]
    fits = sorted(refined, key=lambda f: -f.evidence) + fits[options.refine_top:]
    if options.direction == "decrease":   # a loss only: a fitted rise is listed, never named
        fits = [f for f in fits if f.theta < 0] + [f for f in fits if f.theta >= 0]
    if not fits:
        return [], []
    best = fits[0]

    named = best.evidence >= options.min_evidence and (options.direction == "any" or best.theta < 0)
    if not named:
        return [], fits
    if options.consistent_channels and "channels" in best.details:
        theta_k, sd_k = np.array(best.details["channels"]).T
        keep = consistent_channels(theta_k, sd_k)
        if not keep.all():
            dropped = [problem.channels[k] for k in np.flatnonzero(~keep)]
            log(f"localisation: {best.hypothesis.name} from the channels that agree (without {', '.join(dropped)})")
            again = _refine(best, analysis, problem, executor=executor, keep=keep)
            best = replace(again, evidence=best.evidence,
                           details={**again.details, "dropped_channels": dropped, "evidence_all": best.evidence,
                                    "value_all_channels": best.value})
    r = _row(best, analysis)
    if "dropped_channels" in best.details:
        r["dropped_channels"] = best.details["dropped_channels"]
    r["alternatives"] = [{"group": f.hypothesis.name, "value": f.value, "evidence": f.evidence}
                         for f in fits[1:] if f.evidence >= best.evidence - options.near]
    return [r], fits


def localisation_markdown(entry: dict[str, Any], units: dict[str, str] | None = None) -> str:
    """The short report.md section of a localisation entry."""
    units = units or {}
    lines = ["## Localisation: which element group changed", ""]
    if entry.get("not_assessed"):
        return "\n".join(lines + [f"Not assessed: {entry['not_assessed']}"]) + "\n"
    if not entry["rows"]:
        best = entry["hypotheses"][0] if entry["hypotheses"] else None
        lines.append("No element group is named: no hypothesis reaches the evidence "
                     f"{entry['options']['min_evidence']:g}"
                     + (f" (best: {best['group']}, evidence {best['evidence']:.1f})." if best else "."))
        return "\n".join(lines) + "\n"
    for r in entry["rows"]:
        u = units.get(r["kind"], "")
        change = 100.0 * (r["value"] / r["nominal"] - 1.0)
        lo, hi = r["interval"]
        lines.append(f"- **{r['group']}**: {r['value']:.4g} {u} ({change:+.0f} % of nominal {r['nominal']:.4g}; "
                     f"interval {lo:.4g} to {hi:.4g}), evidence {r['evidence']:.1f}"
                     + (f". {r['note']}." if r["note"] else "."))
        if r["alternatives"]:
            lines.append("  Fit nearly as well: " + ", ".join(
                f"{a['group']} ({a['value']:.4g} {u}, evidence {a['evidence']:.1f})" for a in r["alternatives"]))
    cal = entry.get("linearised_at") or {}
    if cal.get("parameters"):
        lines += ["", "Model linearised at its model parameters calibrated on the reference date: " + ", ".join(
            f"{n} {p['estimate']:.4g} (nominal {p['nominal']:.4g})" for n, p in cal["parameters"].items()) + "."]
    lines += ["", "Intervals: 2 standard deviations, the larger of the segments' spread and the misfit the fit "
              "leaves (model-form error: channels whose model responds to the element otherwise than the vehicle "
              "disagree). On independent train models they did not always hold the truth: read the value as about, "
              "the group as the finding (docs/elements.md)."]
    return "\n".join(lines) + "\n"
