"""What an identification found, typed: :class:`Analysis` (what :func:`~suspid.workflows.analysis.analyse`
returns) and :class:`IdentificationResult` (the whole run, written as ``result.json``).

``result.json`` is the serialisation of :class:`IdentificationResult` (:meth:`~suspid.workflows.records.Record.to_json`,
versioned by ``schema_version``); :meth:`IdentificationResult.load` reads it back, files written before
the version existed included. Per-parameter quantities are ``name -> value`` mappings, in the order of
``parameters``, as in the file; :attr:`IdentificationResult.components` gives them per component.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from html import escape
from pathlib import Path
from typing import Any

from suspid.workflows.records import Record, key, pairs
from suspid.workflows.trust import trust_word
from suspid.workflows.verdict import VerdictRow, rows_of, summary_line, table

__all__ = ["Analysis", "Anytime", "ComponentResult", "FailedPoint", "IdentificationResult", "IntervalMethod",
           "PaperLoop", "Sensitivity"]


@dataclass(kw_only=True)
class FailedPoint(Record):
    """A point whose simulation failed: the phase (``design``, the optimiser's name, ``intervals``, ...),
    its w (SI) and the simulator's message."""

    phase: str
    w: dict[str, float]
    error: str


@dataclass(kw_only=True)
class IntervalMethod(Record):
    """How the intervals were computed (:func:`~suspid.workflows.analysis.gradient_noise`).

    :ivar sigma_J: scatter of J(w_opt) over the bootstrap replicates.
    :ivar covariance_normalized: ``(q, q)`` sandwich covariance of w_opt in [0, 1]^q.
    """

    sigma_J: float
    n_redraws: int
    step: float
    bootstrap: str
    bootstrap_reference: bool
    widened_by_model_error: bool
    n_sigmas: float
    covariance_normalized: list[list[float]]


@dataclass(kw_only=True)
class Sensitivity(Record):
    """The metamodel's Sobol indices (total and first order) and its lengthscales (None without them)."""

    total_sobol: dict[str, float]
    first_sobol: dict[str, float]
    lengthscales: dict[str, float] | None


@dataclass(kw_only=True)
class PaperLoop(Record):
    """Where the paper's loop stood when it stopped, before the local refinement (``ego.refine``)."""

    n_iterations: int
    n_simulator_calls: int
    J_max: float
    w_opt: dict[str, float]
    w_opt_normalized: dict[str, float]
    errors_percent: dict[str, float] | None = key(omit_none=True, default=None)


@dataclass(kw_only=True)
class Anytime(Record):
    """J (None for a failed point) and w in [0, 1]^q of every evaluation, in the order the optimiser was told."""

    J: list[float | None]
    w_normalized: list[list[float]]


@dataclass(frozen=True)
class ComponentResult:
    """One identified parameter's findings (a view of an :class:`Analysis`'s per-parameter mappings).

    :ivar value: the reported value, SI: the bias-corrected one where the model-error checks gave it,
        else w_opt (the interval's centre).
    :ivar trustworthy: True, False or None (not assessed).
    :ivar reasons: why it is not identifiable, or not trustworthy, or not assessed (empty otherwise).
    """

    name: str
    unit: str
    bounds: tuple[float, float]
    w_opt: float
    w_opt_normalized: float
    value: float
    interval: tuple[float, float]
    identifiable: bool
    trustworthy: bool | None
    reasons: list[str]
    w_ref: float | None = None
    error_percent: float | None = None


@dataclass(kw_only=True)
class Analysis(Record):
    """w_opt, errors against w_ref, identifiability, intervals, trust and sensitivity of one identification
    (:func:`~suspid.workflows.analysis.analyse`); the first keys of ``result.json``.

    Mappings are keyed by the identified parameter names, in order; SI units unless ``_normalized``
    ([0, 1] of each admissible interval) or ``_percent`` (% of it).

    :ivar interval: ``name -> (lower, upper)`` SI, widened by the model-error bound where it applies;
        ``interval_sampling`` the sandwich's alone.
    :ivar trustworthy: ``name -> True | False | None``: trust under model error, yes, no or not assessed.
    :ivar model_error: the model-error checks' report (its layout is the checks').
    :ivar calibration: the calibrated model parameters (None where the linearised checks did not run).
    :ivar w_ref, w_ref_normalized, errors_percent: the numerical experiment's truth and errors (else None).
    :ivar w_corrected, w_corrected_normalized, errors_percent_corrected: the bias-corrected values (linearised
        checks), else None.
    :ivar identifiability_method: how the verdict was reached when not by the Sobol indices (Fisher), else None.
    """

    name: str
    parameters: list[str]
    units: dict[str, str]
    bounds: dict[str, tuple[float, float]] = key(read=pairs)
    w_opt: dict[str, float]
    w_opt_normalized: dict[str, float]
    identifiable: dict[str, bool]
    non_identifiable_reasons: dict[str, list[str]]
    correlated_with: dict[str, Any]
    interval: dict[str, tuple[float, float]] = key(read=pairs)
    interval_normalized: dict[str, tuple[float, float]] = key(read=pairs)
    interval_sampling: dict[str, tuple[float, float]] = key(read=pairs)
    trustworthy: dict[str, bool | None] | None
    untrustworthy_reasons: dict[str, list[str]] = key(default_factory=dict)
    not_assessed_reasons: dict[str, list[str]] = key(default_factory=dict)
    model_error: dict[str, Any] | None
    calibration: dict[str, Any] | None
    interval_method: IntervalMethod = key(record=IntervalMethod)
    sensitivity: Sensitivity = key(record=Sensitivity)
    J_max: float
    objective: str
    surrogate: str
    simulator: str
    seed: int
    failed_points: list[FailedPoint] = key(items=FailedPoint, default_factory=list)
    w_ref: dict[str, float] | None = key(omit_none=True, default=None)
    w_ref_normalized: dict[str, float] | None = key(omit_none=True, default=None)
    errors_percent: dict[str, float] | None = key(omit_none=True, default=None)
    w_corrected: dict[str, float] | None = key(omit_none=True, default=None)
    w_corrected_normalized: dict[str, float] | None = key(omit_none=True, default=None)
    errors_percent_corrected: dict[str, float] | None = key(omit_none=True, default=None)
    paper_loop: PaperLoop | None = key(omit_none=True, record=PaperLoop, default=None)
    identifiability_method: dict[str, Any] | None = key(omit_none=True, default=None)

    @property
    def components(self) -> list[ComponentResult]:
        """The findings per identified parameter, in order."""
        out = []
        for n in self.parameters:
            trust = (self.trustworthy or {}).get(n)
            reasons = (self.non_identifiable_reasons.get(n, []) if not self.identifiable[n]
                       else self.untrustworthy_reasons.get(n, []) if trust is False
                       else self.not_assessed_reasons.get(n, []) if trust is None else [])
            out.append(ComponentResult(
                name=n, unit=self.units.get(n, ""), bounds=self.bounds[n], w_opt=self.w_opt[n],
                w_opt_normalized=self.w_opt_normalized[n], value=(self.w_corrected or self.w_opt)[n],
                interval=self.interval[n], identifiable=self.identifiable[n], trustworthy=trust,
                reasons=list(reasons), w_ref=(self.w_ref or {}).get(n),
                error_percent=(self.errors_percent or {}).get(n)))
        return out


@dataclass(kw_only=True)
class IdentificationResult(Analysis):
    """What one identification found (``result.json``), typed: the :class:`Analysis`, then how the run went.

    :ivar intervals: (property) ``name -> (lower, upper)`` SI: :attr:`interval`; not a finding where
        ``identifiable`` is False.
    :ivar reasons: (property) why a component is not identifiable: :attr:`non_identifiable_reasons`.
    :ivar n_initial, n_iterations, n_simulator_calls: m0, optimiser iterations, evaluations of J.
    :ivar stop_reason, refine_stop_reason: why the loop (and the refinement) stopped.
    :ivar anytime: J and w of every evaluation in order.
    :ivar jacobian: the Jacobians' count and cost (gradient-based optimisers), else None.
    :ivar noise_floor: the noise model's sensor-noise floor per channel, else None.
    :ivar objective_weights: with ``objective.weights: efficient``, the channel weights α and how the
        reference date gave them (:func:`suspid.workflows.weights.reference_efficient_weights`), else None.
    :ivar localisation: the element groups localised, when the run localised (else None).
    :ivar nominal: ``name -> nominal value`` (SI) the verdict measures the change from.
    :ivar verdict_block: ``result.json``'s ``verdict`` (version, limits, counts, rows); :attr:`verdict` its rows
        as :class:`~suspid.workflows.verdict.VerdictRow` (:meth:`summary`, :meth:`verdict_table`,
        :meth:`to_dataframe`).
    :ivar run_dir: the run directory (``result.json``, ``report.md``, ``ledger.sqlite``, ``noise_model.npz``):
        they are the latest finished run's; this run's own are in ``history/<run_id>/``.
    :ivar problem, ego: a live run's problem and optimiser result (None for a loaded result).
    """

    SCHEMA_VERSION = 1

    run_id: str | None = key(omit_none=True, default=None)
    n_initial: int
    n_iterations: int
    n_simulator_calls: int
    n_simulator_calls_this_session: int | None = key(omit_none=True, default=None)
    stop_reason: str
    n_refine_iterations: int | None = key(omit_none=True, default=None)
    refine_stop_reason: str | None = None
    wall_time_s: float
    design_min_distance: float | None = None
    optimizer: str | None = key(omit_none=True, default=None)
    budget: int | None = key(omit_none=True, default=None)
    anytime: Anytime | None = key(omit_none=True, record=Anytime, default=None)
    jacobian: dict[str, Any] | None = key(omit_none=True, default=None)
    noise_floor: dict[str, Any] | None = key(omit_none=True, default=None)
    objective_weights: dict[str, Any] | None = key(omit_none=True, default=None)
    localisation: dict[str, Any] | None = key(omit_none=True, default=None)
    nominal: dict[str, float | None] = key(default_factory=dict)
    verdict_block: dict[str, Any] | None = key("verdict", omit_none=True, default=None)
    run_dir: Path = field(default=Path("."), metadata={"json": False})
    problem: Any = key(json=False, default=None)
    ego: Any = key(json=False, default=None)

    @classmethod
    def of(cls, analysis: Analysis, **run: Any) -> "IdentificationResult":
        """The result of a run from its analysis and the run's own fields."""
        return cls(**{f.name: getattr(analysis, f.name) for f in fields(Analysis)}, **run)

    @classmethod
    def from_dict(cls, data: dict[str, Any], run_dir: Path, problem: Any = None,
                  ego: Any = None) -> "IdentificationResult":
        """From the content of a ``result.json`` (and, in a live run, the problem and the optimiser's result)."""
        return cls.from_json(data, run_dir=Path(run_dir), problem=problem, ego=ego)

    @classmethod
    def load(cls, run_dir: str | Path) -> "IdentificationResult":
        """Read the ``result.json`` of a finished run."""
        run_dir = Path(run_dir)
        return cls.load_file(run_dir / "result.json", run_dir=run_dir)

    @property
    def intervals(self) -> dict[str, tuple[float, float]]:
        """``name -> (lower, upper)`` SI (:attr:`interval`)."""
        return self.interval

    @property
    def reasons(self) -> dict[str, list[str]]:
        """Why a component is not identifiable (:attr:`non_identifiable_reasons`)."""
        return self.non_identifiable_reasons

    @property
    def verdict(self) -> list[VerdictRow]:
        """The maintenance verdict, one row per identified parameter and per localised element group."""
        return rows_of({"verdict": self.verdict_block})

    @property
    def result(self) -> dict[str, Any]:
        """The whole result as in ``result.json`` (:meth:`to_json`)."""
        return self.to_json()

    def to_dict(self) -> dict[str, Any]:
        """The JSON-able dict written to ``result.json`` (equal to it once read back)."""
        return self.to_json()

    @property
    def trust(self) -> dict[str, str]:
        """``name -> "yes" | "no" | "not assessed"``: :attr:`trustworthy` in words."""
        return {n: trust_word((self.trustworthy or {}).get(n)) for n in self.parameters}

    def verdict_table(self) -> list[dict[str, Any]]:
        """The verdict as plain rows (no pandas needed): one dict per parameter or group, SI values and units,
        change and interval in % of nominal, identifiable, trust, verdict and its rule."""
        return [r.to_dict() for r in self.verdict]

    def to_dataframe(self):
        """The verdict table as a pandas DataFrame, one row per parameter or group (pandas is imported here,
        only when asked for: suspid does not depend on it).

        :raises ImportError: pandas is not installed (``verdict_table()`` gives the same rows without it).
        """
        try:
            import pandas as pd   # optional: only this method needs it
        except ImportError:
            raise ImportError("to_dataframe() needs pandas (pip install pandas); verdict_table() gives the same "
                              "rows as plain dicts") from None
        return pd.DataFrame(self.verdict_table()).set_index("name")

    def _table(self) -> tuple[list[str], list[list[str]]]:
        return table(self.verdict, with_reference=self.w_ref is not None)

    def summary(self) -> str:
        """A plain-text table: per parameter (and localised group) nominal, identified value with units, change
        and interval in % of nominal, identifiable, trust and verdict; then one plain-language line each."""
        header, cells = self._table()
        widths = [max(len(h), *(len(c[i]) for c in cells)) if cells else len(h) for i, h in enumerate(header)]
        line = lambda row: "  ".join(v.ljust(w) for v, w in zip(row, widths)).rstrip()  # noqa: E731
        title = (f"{self.name or 'identification'}: J_max = {self.J_max:.6g}, "
                 f"{self.n_simulator_calls} simulations, {self.wall_time_s:.0f} s")
        out = [title, line(header), line(["-" * w for w in widths]), *map(line, cells), ""]
        out += [summary_line(r, markdown=False) for r in self.verdict]
        return "\n".join(out)

    def _repr_html_(self) -> str:
        """The verdict table in a notebook (HTML), with the plain-language lines below it."""
        header, cells = self._table()
        colour = {"ok": "#1a7f37", "warning": "#b35900", "alarm": "#c62828", "not assessable": "#666"}
        k = header.index("verdict")
        body = "".join("<tr>" + "".join(
            f'<td style="color:{colour.get(c, "inherit")}">{escape(c)}</td>' if i == k else f"<td>{escape(c)}</td>"
            for i, c in enumerate(row)) + "</tr>" for row in cells)
        lines = "".join(f"<li>{escape(summary_line(r, markdown=False))}</li>" for r in self.verdict)
        return (f"<p><b>{escape(str(self.name or 'identification'))}</b>: J_max = {self.J_max:.6g}, "
                f"{self.n_simulator_calls} simulations, run directory <code>{escape(str(self.run_dir))}</code></p>"
                f"<table><thead><tr>{''.join(f'<th>{escape(h)}</th>' for h in header)}</tr></thead>"
                f"<tbody>{body}</tbody></table><ul>{lines}</ul>")

    def __repr__(self) -> str:
        states = ", ".join(f"{r.name} {r.verdict}" for r in self.verdict)
        return (f"IdentificationResult({self.name or '?'!r}, {len(self.parameters)} parameters, "
                f"J_max={self.J_max:.6g}, verdict: {states or 'none'}, run_dir={str(self.run_dir)!r})")

    @property
    def max_error_percent(self) -> float | None:
        """The largest error over the identifiable components (numerical experiment), else None."""
        if self.errors_percent is None:
            return None
        errors = [e for n, e in self.errors_percent.items() if self.identifiable[n]]
        return max(errors) if errors else None
