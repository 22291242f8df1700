"""The ``ego:`` config section (options of the EGO loop and of its local refinement) and the surrogate.

Public API: :class:`EGOOptions`, :class:`RefineOptions`, :func:`make_surrogate`.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationInfo, field_validator

from suspid import registry
from suspid.interfaces import Surrogate
from suspid.options import parse_options

__all__ = ["EGOOptions", "RefineOptions", "make_surrogate"]


class RefineOptions(BaseModel):
    """The ``ego.refine:`` section: a local refinement after the paper's loop (beyond the paper).

    Why. The paper's loop fits one Kriging model on every point. After a
    large space-filling design (m0 = 500) that global model cannot resolve J
    near its maximum to the tolerance: its EI falls below eps while w_opt is
    still a few % of the admissible interval from the maximiser of J (measured
    on the Table 1 analogue: ``benchmarks/RESULTS.md``, "Table 1 analogue").

    What. A model-based trust-region search (Conn, Scheinberg and Vicente,
    *Introduction to Derivative-Free Optimization*, 2009, ch. 10) whose model
    is a local Kriging fit, as in local approximate GPs (Gramacy and Apley,
    2015). Each step fits a local surrogate (a new instance of the run's
    surrogate class, same options) on the ``n_points`` evaluated points
    nearest to the current best w_opt (Euclidean distance in [0, 1]^q),
    evaluates J at the maximiser of its mean over the box w_opt ± ``radius``
    (clipped to [0, 1]^q), and moves the box to the new point when J improved
    by more than the paper's eps = tol * (max J - min J). When the mean peaks
    at a point already evaluated, the step takes the EI maximiser in the box
    instead; if that too is a known point, the step counts as a failure
    without a simulation. After ``patience`` failures in a row the radius is
    halved (it never grows). The refinement stops when the radius falls below
    ``min_radius`` (``"radius_below_min"``: w_opt is then located to about
    that fraction of each admissible interval) or after ``max_iter`` points
    (``"max_iter"``). The run's global surrogate is not touched by the local
    fits; with ``refit_final`` it is refitted on every point at the end.
    The refinement evaluates one point per step, also with ``ego.batch`` > 1.

    The step maximises the mean, not EI: inside a small box EI prefers the
    corners where the local model is least sure, and on the Table 1 analogue
    EI steps failed four times in a row while mean steps climbed to the
    maximiser found by a Nelder-Mead search on J itself.

    :ivar enabled: run the refinement after the paper's loop stops (on EI < eps or m1).
    :ivar max_iter: largest number of refinement points.
    :ivar n_points: size of the local data set (default 10 q).
    :ivar radius: initial half-width of the trust region in [0, 1] units.
    :ivar min_radius: the refinement stops below this half-width.
    :ivar patience: steps without improvement before the radius is halved.
    """

    model_config = ConfigDict(extra="forbid")

    enabled: bool = False
    max_iter: int = Field(default=30, ge=0)
    n_points: int | None = Field(default=None, ge=3)
    radius: float = Field(default=0.1, gt=0, le=0.5)
    min_radius: float = Field(default=0.01, gt=0)
    patience: int = Field(default=2, ge=1)


class EGOOptions(BaseModel):
    """The ``ego:`` config section.

    :ivar max_iter: m1, the largest number of EGO points after the initial design.
    :ivar tol: the EI stop: eps = tol * (max J - min J) over the current data;
        with tol = 0 (or all J equal) the loop runs to ``max_iter``.
    :ivar seed: seeds the EI candidate sets (one stream per iteration).
    :ivar n_candidates: size of the space-filling (Sobol') candidate set.
    :ivar n_best: how many of the best evaluated points seed local candidates.
    :ivar n_local: Gaussian perturbations per best point and per scale.
    :ivar n_starts: L-BFGS-B starts, the best candidates by EI.
    :ivar search_maxiter: iterations of each L-BFGS-B run.
    :ivar refit_final: refit the surrogate on every point at the end (for
        the sensitivity report) when the last point was not yet in it.
    :ivar explore_tol: budget mode (tol below it, e.g. tol = 0): when the EI
        maximiser's EI is below ``explore_tol`` * (max J - min J), the step
        explores instead (0: never); EI is maximised on a model of the warped
        J, and every third step maximises the model's mean instead, as does
        the step after one of those that missed the best J by less than
        ``explore_tol`` * (max J - min J)
        (:class:`suspid.optimize.loop.EIProposer`). With the default tol = 1e-4
        the run is not in budget mode: the paper's loop is unchanged.
    :ivar explore_distance: ... or when the EI maximiser lies within this
        distance (each unit coordinate) of an evaluated point (default 0: never).
    :ivar explore: how it explores: ``"set-aside"`` (default) sets the
        incumbent's basin aside and maximises EI over the rest of the box
        against the best J there; ``"random"`` evaluates a uniformly random
        point. See :class:`suspid.optimize.loop.EIProposer`.
    :ivar batch: points per iteration (kriging believer, see :class:`suspid.optimize.loop.EIProposer`).
    :ivar asynchronous: with ``batch = 1``, keep one point in flight per worker of the executor:
        ``"auto"`` (default) when the executor runs more than one task at once, ``true`` likewise
        (an error with ``batch`` > 1), ``false`` never (one simulation at a time, the paper's loop).
        See :mod:`suspid.optimize.driver` for the schedule, which keeps the run
        reproducible.
    :ivar refine: the local refinement after the loop (:class:`RefineOptions`, off by default).
    """

    model_config = ConfigDict(extra="forbid")

    max_iter: int = Field(default=50, ge=0)
    tol: float = Field(default=1e-4, ge=0)
    seed: int = Field(default=0, ge=0, lt=2**63, description="seed of the EI search's random draws")
    n_candidates: int = Field(default=2000, ge=1)
    n_best: int = Field(default=3, ge=0)
    n_local: int = Field(default=30, ge=0)
    n_starts: int = Field(default=8, ge=1)
    search_maxiter: int = Field(default=200, ge=1)
    refit_final: bool = True
    explore_tol: float = Field(default=1e-4, ge=0)
    explore_distance: float = Field(default=0.0, ge=0, le=1)
    explore: Literal["set-aside", "random"] = "set-aside"
    batch: int = Field(default=1, ge=1, description="points per iteration (kriging believer); 1 = the paper's loop")
    asynchronous: Literal["auto", True, False] = "auto"
    refine: RefineOptions = Field(default_factory=RefineOptions)

    @field_validator("asynchronous")
    @classmethod
    def _one_point_at_a_time(cls, value: str | bool, info: ValidationInfo) -> str | bool:
        if value is True and info.data.get("batch", 1) > 1:
            raise ValueError(f"asynchronous EGO proposes one point at a time; with batch = {info.data['batch']} "
                             f"set asynchronous: false (or auto), or batch: 1")
        return value


def make_surrogate(surrogate: str | Surrogate = "gpy-kriging",
                   options: dict[str, Any] | None = None, seed: int | None = None) -> Surrogate:
    """A surrogate instance: ``surrogate`` itself, or the registered class of that name
    built with ``options``. ``seed`` is passed when the class's ``Options`` has a
    ``seed`` field that ``options`` does not set.

    :raises UnknownPluginError: no surrogate of that name (listing the available ones).
    """
    if isinstance(surrogate, Surrogate):
        return surrogate
    cls = registry.get("surrogate", surrogate)
    options = dict(options or {})
    fields = getattr(getattr(cls, "Options", None), "model_fields", {})
    if seed is not None and "seed" in fields and "seed" not in options:
        options["seed"] = seed
    if getattr(cls, "Options", None) is not None:
        parse_options(cls.Options, options, "surrogate.options")
    return cls(**options)
