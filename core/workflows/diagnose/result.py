"""A finished diagnosis, typed: :class:`DiagnosisResult`, written as ``diagnosis.json`` (its serialisation,
versioned by ``schema_version``) and read back by :meth:`DiagnosisResult.load`.

The maps, rankings and steps keep the layout of the modules that make them (:mod:`.locate`, :mod:`.name`,
:mod:`.fit`): they are lists of plain rows here.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from suspid.infra.files import canonical
from suspid.sections import DiagnoseOptions
from suspid.workflows.records import Record, key

__all__ = ["DiagnosisResult", "DiagnosisStatistics", "NamedEffect", "SequenceRow", "joint_fit_text"]

STATISTIC = ("per cell: band mean of r = y_mes - y_sim - mu_B (mean test), sum of squared standardised bin means "
             "(shape test), largest standardised bin mean (peak test); p = min(1, 3 min(p_mean, p_shape, p_peak))")
"""How a cell of the discrepancy map is tested (:mod:`.locate`)."""

NULL = ("mean: N(0, kappa_c^2 s_c^2), s_c from the noise covariance; shape: a_c chi2(nu_c); peak: Bonferroni over "
        "the band's bins; kappa, a_c, nu_c from a parametric bootstrap; each test against a discrepancy of min_db "
        "(|mean| <= min_db), the shape test on the excesses")
"""The null distributions of the cell tests (:mod:`.null`)."""


def joint_fit_text(opts: DiagnoseOptions) -> str:
    """How the named effects were fitted, in words (``diagnosis.json``'s ``joint_fit``)."""
    if not opts.reidentify:
        return "none: reidentify is false, the effects are fitted at the base parameters"
    return ("together: the suspension and the continuous parameters of every named effect fitted at once by least "
            "squares on D (the whitened mean residuals the map tests), from the "
            + ("fitted identified suspension and the effects' fits at it; then the augmented model identified with "
               "the configured objective (after/)" if opts.at == "identified" else
               "nominal suspension and the effects' fits at it"))


@dataclass(kw_only=True)
class NamedEffect(Record):
    """A named effect and its fitted parameters."""

    name: str
    parameters: dict[str, Any]


@dataclass(kw_only=True)
class SequenceRow(Record):
    """One step of the naming sequence: what it named and the share of flagged cells before and after."""

    step: int
    named: str | None
    share_flagged_before: float | None
    share_flagged_after: float | None
    integrated_db_hz_after: float | None


@dataclass(kw_only=True)
class DiagnosisStatistics(Record):
    """The statistics of the discrepancy map: the cells, their tests and null, the FDR and the naming rule's
    thresholds (the ``diagnose:`` options)."""

    cells: str = "speed group x channel x band"
    n_cells: int
    bands_hz: list[list[float]]
    statistic: str = STATISTIC
    null: str = NULL
    min_db: float
    noise_mean_by_speed: Any
    n_bootstrap: int
    kappa_median: float
    kappa_raw_median: float | None
    bootstrap_null_rate_at_5pct: Any
    fdr: str = "Benjamini-Yekutieli"
    alpha: float
    penalty_per_parameter: float
    margin: float
    min_explained: float
    max_new_flagged: float


@dataclass(kw_only=True)
class DiagnosisResult(Record):
    """A finished diagnosis: its folder (``out_dir``) and what ``diagnosis.json`` holds, typed.

    :ivar flagged: the cells flagged on the base model (channel, band, sign, magnitude, test, z, q, speed).
    :ivar ranking: the catalogue's effects ranked at the first step that ranked them.
    :ivar named: the first named effect, or None; :ivar named_effects: every one, in the order named.
    :ivar effects: the named effects with their fitted parameters.
    :ivar steps: every step's record (ranking, local model, joint fit, gaps).
    :ivar sequence: per step, what it named and the share of flagged cells before and after.
    :ivar suspension: the suspension reported (fitted under D, or re-identified), with its trust.
    :ivar gap_before, gap_after: the discrepancy's measures on the base and the final model (None: nothing named).
    :ivar augmented_config: the augmented model's config file (None: nothing named).
    :ivar map_before, map_after: every cell of the map on the base and the final model.
    """

    SCHEMA_VERSION = 1

    name: str
    config: str
    base_model: str
    flagged: list[dict[str, Any]]
    ranking: list[dict[str, Any]]
    generic_bumps: dict[str, Any]
    local_model: dict[str, Any] | None
    coupling: list[dict[str, Any]] | None
    named: str | None
    named_effects: list[str]
    reason: str
    named_parameters: dict[str, Any] | None
    effects: list[NamedEffect] = key(items=NamedEffect)
    steps: list[dict[str, Any]]
    sequence: list[SequenceRow] = key(items=SequenceRow)
    unexplained: list[dict[str, Any]]
    channel_gains: list[dict[str, Any]]
    suspension: dict[str, Any] | None
    joint_fit: str
    gap_before: dict[str, Any]
    gap_after: dict[str, Any] | None
    augmented_config: str | None
    statistics: DiagnosisStatistics = key(record=DiagnosisStatistics)
    map_before: list[dict[str, Any]]
    map_after: list[dict[str, Any]] | None
    wall_time_s: float | None
    ranking_time_s: float
    out_dir: Path = field(default=Path("."), metadata={"json": False})

    def to_json(self) -> dict[str, Any]:
        """The content of ``diagnosis.json``: canonical (sorted keys, floats to 17 digits; :func:`canonical`)."""
        return canonical(super().to_json())

    @property
    def diagnosis(self) -> dict[str, Any]:
        """The content of ``diagnosis.json`` (:meth:`to_json`)."""
        return self.to_json()

    @classmethod
    def load(cls, out_dir: str | Path) -> "DiagnosisResult":
        """Read the ``diagnosis.json`` of a finished diagnosis."""
        out_dir = Path(out_dir)
        return cls.load_file(out_dir / "diagnosis.json", out_dir=out_dir)
