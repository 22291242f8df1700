"""Small interfaces for the plugin kinds, with their shapes and units.

Conventions (those of scikit-learn's estimators): constructors store their options and
do no work; methods work; fitted state ends in ``_``. A plugin class may
declare ``Options``, a pydantic model of its ``options:`` section, which the
config layer validates with key paths (``simulator.options.fs``) before the
class is built as ``cls(**options)``.

Shapes and units used throughout suspid:

- parameter vectors ``w``: a mapping name -> value in SI units, or arrays
  ``(n_points, q)`` in SI units; normalised designs live in ``[0, 1]^q``;
- accelerations ``(n_channels, n_t)`` in m/s^2 at sampling rate ``fs`` (Hz);
- spectra ``(n_samples, n_channels, n_freqs)`` in dB (paper eq. 1), with
  ``freqs`` ``(n_freqs,)`` in Hz;
- track irregularities ``(4, n_x)`` in m, see :data:`IRREGULARITY_CHANNELS`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
import math
from typing import Any, Callable, ClassVar, Iterator, Mapping, Sequence

import numpy as np

from suspid.optimize.trials import Trial, TrialBook, TrialLoop

IRREGULARITY_CHANNELS = ("vertical", "lateral", "cross_level", "gauge")
"""Rows of :attr:`TrackSegment.irregularities`, all in metres (EN 13848 quantities).

- ``vertical``: longitudinal level, mean vertical position of the two rails, up positive;
- ``lateral``: alignment, mean lateral position of the two rails, left positive;
- ``cross_level``: height of the left rail minus the right rail;
- ``gauge``: gauge deviation from nominal, positive when wider.

Per rail: z_left = vertical + cross_level/2, z_right = vertical - cross_level/2,
y_left = lateral + gauge/2, y_right = lateral - gauge/2.
"""


@dataclass(frozen=True)
class Parameter:
    """A model parameter that can be identified.

    ``nominal`` is w0's value; ``lower`` and ``upper`` bound the admissible
    interval C_w (paper §3). All values in SI units named by ``unit``.

    ``nominal`` is also what the maintenance verdict measures the change from
    (:mod:`suspid.workflows.verdict`): a simulator provides its nominal values
    here (a preset's table, the user's ``vehicle:`` overrides, a template's
    declared values); an element group named ``kind[group]`` that the
    simulator does not declare takes its kind's, and a config's
    ``limits.<name>.nominal`` replaces it for the verdict. The head of
    ``description`` (up to its first ``;`` or ``(``) names the element in the
    verdict's plain-language line.
    """

    name: str
    unit: str
    nominal: float
    lower: float
    upper: float
    description: str = ""
    domain: tuple[float, float] = (-math.inf, math.inf)
    """Where the parameter is physical, an open interval (SI): identification bounds must lie inside it
    (``(0, inf)`` for a stiffness or a damping rate: zero and negative values are refused)."""


@dataclass
class TrackSegment:
    """One stretch of track with its measured (or synthetic) geometry.

    :ivar name: identifier, unique within a data set.
    :ivar distance: ``(n_x,)`` m, increasing and uniformly spaced.
    :ivar irregularities: ``(4, n_x)`` m, rows as :data:`IRREGULARITY_CHANNELS`.
    :ivar speed: train speed in m/s, a constant or a ``(n_x,)`` record at each
        distance sample (variable speed).
    :ivar curvature: ``(n_x,)`` 1/m, the track's design curvature (1 / radius),
        positive for a curve to the left in the direction of travel; ``None``
        for straight track.
    :ivar cant: ``(n_x,)`` m, the design cant: height of the right rail above
        the left one in the direction of travel (positive in a canted
        left-hand curve, whose outer rail is the right one); ``None`` for no
        cant.
    """

    name: str
    distance: np.ndarray
    irregularities: np.ndarray
    speed: float | np.ndarray
    meta: dict[str, Any] = field(default_factory=dict)
    curvature: np.ndarray | None = None
    cant: np.ndarray | None = None

    @property
    def dx(self) -> float:
        """Distance step in m."""
        return float(self.distance[1] - self.distance[0])

    @property
    def length(self) -> float:
        """Segment length in m."""
        return float(self.distance[-1] - self.distance[0])

    @property
    def mean_speed(self) -> float:
        """Mean speed over the segment in m/s."""
        return float(np.mean(self.speed))

    def duration(self) -> float:
        """Time in s the train takes to run the segment."""
        if np.ndim(self.speed) == 0:
            return self.length / float(self.speed)
        v = np.asarray(self.speed, dtype=float)
        return float(np.trapezoid(1.0 / v, self.distance))


@dataclass
class Response:
    """Accelerations computed (or measured) on one segment.

    :ivar channels: channel names, ``(n_channels,)``.
    :ivar fs: sampling rate in Hz; sample j is at time j / fs.
    :ivar accelerations: ``(n_channels, n_t)`` in m/s^2.
    """

    channels: tuple[str, ...]
    fs: float
    accelerations: np.ndarray
    segment: str = ""

    @property
    def duration(self) -> float:
        """Record length T in s (n_t / fs)."""
        return self.accelerations.shape[1] / self.fs


class Simulator(ABC):
    """A train model: parameter vector + track segments -> accelerations.

    Subclasses set the class attribute ``name`` and may set ``Options``.
    """

    name: ClassVar[str]
    Options: ClassVar[type | None] = None

    def __init__(self, **options: Any) -> None:
        self.options = options

    @abstractmethod
    def parameters(self) -> list[Parameter]:
        """Every parameter that may be identified, with nominal value and bounds."""

    def default_parameters(self) -> list[str]:
        """Names identified when the config's ``parameters:`` section is empty."""
        return [p.name for p in self.parameters()]

    def calibratable(self) -> list[str]:
        """Model parameters, among :meth:`parameters`, that are uncertain but not meant to be identified
        (a damper mount's series stiffness, a creep-coefficient scale, the equivalent conicity): the
        reference date, where w = w0 is known, estimates them (:mod:`suspid.method.calibration`) over their
        declared bounds. Default: none.
        """
        return []

    @abstractmethod
    def channels(self) -> list[str]:
        """Names of the output channels, in the order of ``Response.accelerations``."""

    @abstractmethod
    def simulate(self, w: Mapping[str, float], segments: Sequence[TrackSegment]) -> list[Response]:
        """Run the model with parameters ``w`` over each segment.

        :param w: parameter name -> SI value; parameters not named keep their
            nominal value.
        :param segments: the track segments to run over.
        :returns: one :class:`Response` per segment, in order.
        :raises suspid.errors.SimulatorError: when a run fails.
        """

    def sampling_rate_hz(self) -> float | None:
        """The sampling rate of the accelerations :meth:`simulate` returns, Hz, when known in advance.

        Lets a dry run check the frequency grid against the Nyquist frequency and
        the records' length before anything is simulated; ``None`` (the default)
        skips those checks until the first simulation.
        """
        return None

    def identity(self) -> dict[str, Any]:
        """What determines this simulator's output besides ``w`` and the track.

        Used to key cached evaluations in the run ledger; the default is the
        plugin name and its options.
        """
        return {"plugin": self.name, "options": self.options}


class DifferentiableSimulator(ABC):
    """Optional capability of a :class:`Simulator`: the derivatives of its accelerations.

    Kept apart from :class:`Simulator` as emukit keeps ``IDifferentiable`` apart
    from ``IModel``: a simulator class that can differentiate subclasses both
    (``class MySim(Simulator, DifferentiableSimulator)``); the core tests
    ``isinstance(sim, DifferentiableSimulator)`` and falls back to finite
    differences through the run's executor otherwise, and for every name that
    :meth:`differentiable` leaves out (:func:`suspid.workflows.jacobian.spectra_jacobian`).
    Parameters are any the simulator declares in :meth:`Simulator.parameters`:
    the identified ones and model parameters that are only calibrated (a damper
    mount's stiffness, a creep scale, the conicity).
    :func:`suspid.testing.check_differentiable` checks the derivatives against
    central finite differences.
    """

    @abstractmethod
    def differentiable(self, names: Sequence[str]) -> list[str]:
        """The names among ``names`` that :meth:`simulate_jacobian` differentiates itself, in that order.

        The rest is differentiated by the caller with finite differences of
        :meth:`Simulator.simulate` (a parameter the simulator cannot
        differentiate, e.g. one of a nonlinear element, or one that changes the
        model's structure).
        """

    @abstractmethod
    def simulate_jacobian(self, w: Mapping[str, float], segments: Sequence[TrackSegment],
                          names: Sequence[str]) -> list[tuple[Response, np.ndarray]]:
        """:meth:`Simulator.simulate` at ``w`` and the derivatives of each record.

        :param w: parameter name -> SI value, as for ``simulate``.
        :param names: ``(n_p,)`` parameters to differentiate, all among :meth:`differentiable`.
        :returns: per segment ``(response, dA)``, ``response`` what ``simulate`` returns and
            ``dA`` ``(n_p, n_channels, n_t)`` in (m/s^2) per SI unit of each parameter:
            dA[p] = ∂ accelerations / ∂ w[names[p]].
        :raises suspid.errors.SimulatorError: when a run fails.
        """


@dataclass(frozen=True)
class Element:
    """One physical suspension element of a simulator (a yaw damper, an air spring, an axlebox's primary
    spring): its ``kind``, the parameter that sets every element of that kind (``c_yaw``), and its ``tags``,
    where it sits (``("bogie1", "left")``); the tags also name it in a group (``c_yaw[bogie1,left]``)."""

    kind: str
    tags: tuple[str, ...]


class ElementSimulator(ABC):
    """Optional capability of a :class:`Simulator`: it models suspension elements one by one.

    A simulator class that has it subclasses both (``class MySim(Simulator, ElementSimulator)``). The core
    derives from :meth:`elements` the *groups* a config may name (:mod:`suspid.elements`: ``kind[tag,...]``
    is every element of ``kind`` carrying those tags) and accepts them wherever it accepts a parameter name;
    the simulator must then take such names in ``w`` (:meth:`Simulator.simulate`, and
    :meth:`DifferentiableSimulator.simulate_jacobian` when it has that capability too): a group's value
    is the SI value of every element in it, elements no group in ``w`` covers keep the kind's value, and
    ``w`` without any group gives exactly the kind-level results. Simulators without the capability are
    unchanged. :func:`suspid.testing.check_elements` checks a simulator's declaration and that a group
    moves the output.
    """

    @abstractmethod
    def elements(self) -> list[Element]:
        """Every element, each kind among :meth:`Simulator.parameters`' names, tags unique within a kind."""

    def candidate_channels(self) -> list[str]:
        """Channels the simulator could output besides :meth:`Simulator.channels` (an accelerometer elsewhere):
        what a sensor-placement advice chooses from (:func:`suspid.workflows.elements.observability`).
        Default: none."""
        return []

    def with_channels(self, channels: Sequence[str]) -> "Simulator":
        """A simulator like this one whose outputs are its channels followed by ``channels`` (names from
        :meth:`candidate_channels`).

        :raises NotImplementedError: the simulator offers no extra channel (the default).
        """
        raise NotImplementedError(f"{type(self).__name__} offers no extra channel")


class Objective(ABC):
    """Ψ_k: a per-channel comparison of measured and modelled spectra (eq. 5-8).

    Higher is better: J = Σ_k α_k Ψ_k is maximised.
    """

    name: ClassVar[str]
    Options: ClassVar[type | None] = None
    #: Optional capability: when True, :class:`~suspid.method.objective.ObjectiveFunction`
    #: also passes ``noise_variance`` ``(n_channels, n_freqs)`` dB², the variance of the
    #: run's noise paths b_i, as a keyword argument of :meth:`psi`.
    uses_noise_variance: ClassVar[bool] = False

    def __init__(self, **options: Any) -> None:
        self.options = options

    @abstractmethod
    def psi(self, y_mes: np.ndarray, y_mod: np.ndarray, freqs: np.ndarray) -> np.ndarray:
        """Ψ_k for every channel.

        :param y_mes: ``(n_mes, n_channels, n_freqs)`` measured spectra in dB.
        :param y_mod: ``(n_mod, n_channels, n_freqs)`` modelled spectra in dB
            (Y_sim(w) + noise paths b_i).
        :param freqs: ``(n_freqs,)`` in Hz.
        :returns: ``(n_channels,)``.
        """


class Surrogate(ABC):
    """A metamodel of a scalar function, used by EGO (paper §3.2).

    Inputs ``X`` are ``(n_points, q)`` points of the unit cube ``[0, 1]^q``; a caller with SI points
    uses it behind its input transform (:class:`suspid.optimize.normalize.Normalized`). Outputs
    ``y`` are ``(n_points,)``.
    """

    name: ClassVar[str]
    Options: ClassVar[type | None] = None

    #: Optional capability, set by :meth:`fit`: the fitted hyperparameters as a
    #: JSON-able dict, recorded in the run ledger with every EGO iteration.
    hyperparameters_: dict[str, Any] | None = None
    #: Optional capability, set by :meth:`fit`: ``(q,)`` length-scales in the
    #: units of ``X``, shown beside the Sobol indices in the report.
    lengthscales_: np.ndarray | None = None

    def __init__(self, **options: Any) -> None:
        self.options = options

    @abstractmethod
    def fit(self, X: np.ndarray, y: np.ndarray) -> "Surrogate":
        """Fit to data ``X (n_points, q)``, ``y (n_points,)``; returns ``self``."""

    @abstractmethod
    def predict(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Noise-free predictive mean and variance, each ``(n_points,)``."""

    def predict_gradients(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Gradients of mean and variance w.r.t. ``X``, each ``(n_points, q)``.

        Optional capability; surrogates without it raise NotImplementedError
        and EGO falls back to derivative-free search.
        """
        raise NotImplementedError


class Executor(ABC):
    """Where independent tasks (simulator calls) run: in process, a process pool, a cluster.

    Used as a context manager: resources (pools, cluster clients) are made in
    ``__enter__`` and released in ``__exit__``, never in the constructor.
    """

    name: ClassVar[str]
    Options: ClassVar[type | None] = None

    def __init__(self, **options: Any) -> None:
        self.options = options

    def __enter__(self) -> "Executor":
        return self

    def __exit__(self, *exc: Any) -> None:
        return None

    @property
    def n_workers(self) -> int:
        """How many tasks run at once (EGO batches use it)."""
        return 1

    def describe(self) -> str:
        """One line for the run's log: where the tasks run (a cluster adds its addresses and dashboard)."""
        return f"executor {self.name}, {self.n_workers} task(s) at once"

    def validate(self) -> None:
        """Check, as ``suspid validate`` does, that tasks could run (e.g. reach a cluster and check its workers).

        Called outside a ``with`` block; it must let go of whatever it opened.
        Default: nothing to check.

        :raises suspid.errors.SuspidError: one line saying what is wrong.
        """

    @abstractmethod
    def map_unordered(self, fn: Callable[[Any], Any], items: Sequence[Any]) -> Iterator[tuple[int, Any]]:
        """Apply ``fn`` to every item; yield ``(index, result)`` as each task finishes.

        A task that raises yields ``(index, exception)`` instead of a result,
        so the caller can record the failure and go on with the others. A
        worker that dies loses only its task in flight, which is retried.
        ``fn`` and the items must be picklable for out-of-process executors.
        A failure of the executor itself (a lost cluster) is raised, not
        yielded: :class:`suspid.errors.ClusterError`.
        """

    # -- asynchronous drivers: one task at a time --------------------------------------------------
    def submit(self, fn: Callable[[Any], Any], item: Any) -> "TaskHandle":
        """Start ``fn(item)`` and return its handle at once, for :meth:`wait_first`.

        For a driver that keeps every worker busy (an asynchronous EGO
        proposes a new point as soon as one finishes). The default runs the
        task here, now, and returns it finished (what ``serial`` does);
        parallel executors override it. Inside the ``with`` block only.
        """
        try:
            outcome = fn(item)
        except Exception as exc:  # yielded by wait_first, like map_unordered's
            outcome = exc
        return TaskHandle(fn, item, done=True, outcome=outcome)

    def wait_first(self, handles: Sequence["TaskHandle"], timeout: float | None = None
                   ) -> list[tuple["TaskHandle", Any]]:
        """Wait until at least one of ``handles`` has finished; return every finished one.

        :param handles: handles from :meth:`submit` whose outcome was not returned yet.
        :param timeout: seconds to wait at most (``None``: no limit of the caller's; an executor
            may still give up on a cluster where nothing finishes for its own limit, with a
            :class:`~suspid.errors.ClusterError`).
        :returns: ``[(handle, result or exception), ...]`` in the order of ``handles``,
            empty when none finished within ``timeout``. A task's exception is
            returned, not raised, as in :meth:`map_unordered`.
        :raises suspid.errors.ClusterError: the executor lost its workers or cluster.
        """
        return [(h, h.outcome) for h in handles if h.done]


class TaskHandle:
    """A task started by :meth:`Executor.submit`: ``fn``, ``item`` and, once known, its outcome.

    Executors keep their own state (a future) in ``future``; callers only
    pass handles back to :meth:`Executor.wait_first`.
    """

    def __init__(self, fn: Callable[[Any], Any], item: Any, *, done: bool = False, outcome: Any = None,
                 future: Any = None) -> None:
        self.fn, self.item, self.done, self.outcome, self.future = fn, item, done, outcome, future
        self.lost = 0  # times its worker died under it (executors that retry)


# ---------------------------------------------------------------------------------------------------
# Optimisers: who chooses the parameter vectors w at which J is evaluated
# ---------------------------------------------------------------------------------------------------
@dataclass
class OptimizerResult:
    """What an :class:`Optimizer` found.

    :ivar x_opt: ``(q,)`` the best evaluated point, SI units.
    :ivar y_opt: J there.
    :ivar X: ``(n_evaluations, q)`` every point told, in evaluation order, SI units.
    :ivar y: ``(n_evaluations,)`` J at those points, NaN where the evaluation failed.
    :ivar stop_reason: why it stopped (``"budget"``, or the optimiser's own rule, e.g. ``"ei_below_tol"``).
    :ivar n_initial: points of an initial design among the first of ``X`` (0 without one).
    :ivar details: the optimiser's own result object, when it has one (the ``ego`` plugin:
        its :class:`suspid.optimize.ego.EGOResult`, with the fitted surrogate and the iteration records,
        which is also its :meth:`Optimizer.loop_state`).
    """

    x_opt: np.ndarray
    y_opt: float
    X: np.ndarray
    y: np.ndarray
    stop_reason: str
    n_initial: int = 0
    details: Any = None

    @property
    def n_evaluations(self) -> int:
        """Evaluations of J told (simulator calls), failed ones included."""
        return int(self.y.shape[0])


class SpectraModel(ABC):
    """What a gradient-based :class:`Optimizer` may ask of the run besides J: the spectra, their
    Jacobian and J of given spectra (the driver's :class:`suspid.workflows.gradient.ProblemSpectraModel`)."""

    @abstractmethod
    def jacobian(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """y_sim ``(v, n_channels, n_freqs)`` dB at ``x (q,)`` SI and ∂y_sim/∂x ``(v, n_channels, n_freqs, q)``
        dB per SI unit (analytic where the simulator offers it, finite differences otherwise)."""

    @abstractmethod
    def objective(self, y_sim: np.ndarray) -> float:
        """J (eq. 5) of spectra ``(v, n_channels, n_freqs)`` dB with the run's data: no simulation."""


class Optimizer(TrialLoop, ABC):
    """A maximiser of J over the parameter box, driven by **ask/tell** on trials (the model is
    :class:`suspid.optimize.ego.EGO`)::

        opt = cls(bounds, budget=300, seed=7, **options)
        while not opt.done:
            trials = opt.ask_trials(n=n_workers)               # Trial objects: id, u, x (SI), phase, details
            opt.tell_trials([t.id for t in trials], values)    # J by trial id; None or NaN where it failed
        res = opt.result()                                     # an OptimizerResult

    The one loop (:func:`suspid.optimize.driver.run_trials`) speaks only the trial interface. A plugin
    may implement just the array interface (``ask(n) -> X (k, q)``, ``tell(X, values)``): the base
    class hands its points out as trials and tells it, once every trial of an ask has a value, the
    points in the order it asked them. The built-in optimisers implement the trials natively.

    Contract: every point :meth:`ask` returns lies in the box; the points of one
    :meth:`ask` are told together, in that order, before the next :meth:`ask`
    (an optimiser may accept more, as ``ego`` takes them one by one in any order;
    asking again before telling returns the same points); no more than ``budget``
    points are asked in all (initial ones included); the same seed and the same
    values give the same points. ``ask(n)`` is a hint: an optimiser may return
    fewer (one at a time) or more (a whole design) points than ``n``. A failed
    point counts against the budget; model-based optimisers give it the worst J
    told so far. Subclasses set ``name`` and may set ``Options`` (a pydantic model
    of ``optimizer.options``). :func:`suspid.testing.check_optimizer` checks the contract.

    :param bounds: ``(q, 2)`` lower and upper bounds, SI units.
    :param budget: the largest number of evaluations of J (simulator calls), initial design included.
    :param seed: seeds every random draw (the config's ``optimizer`` stream, :func:`suspid.infra.seeds.seed_for`).
    :param design: the config's ``design:`` section (:class:`suspid.optimize.design.DesignOptions`),
        for optimisers that start from a space-filling design; None: its defaults.
    :param surrogate: the config's surrogate instance, for model-based optimisers (may be ignored).
    :param options: the validated ``optimizer.options``.
    """

    name: ClassVar[str]
    Options: ClassVar[type | None] = None
    #: A top-level config section holding this optimiser's options when ``optimizer.options`` is
    #: empty (the ``ego`` plugin: the ``ego:`` section, which configs had before optimisers were plugins).
    options_section: ClassVar[str | None] = None
    #: Optional capability: an optimiser that sets it True is given :attr:`spectra_model` (a
    #: :class:`SpectraModel` of the run) by the driver before its first :meth:`ask`, to linearise
    #: the model (a gradient-based search). Its Jacobians are not told evaluations: the driver counts
    #: and reports them apart from the budget of simulator calls.
    uses_jacobian: ClassVar[bool] = False
    spectra_model: "SpectraModel | None" = None

    def __init__(self, bounds: Any, *, budget: int, seed: int = 0, design: Any = None, surrogate: Any = None,
                 **options: Any) -> None:
        self.bounds = bounds
        self.budget = budget
        self.seed = seed
        self.design = design
        self.surrogate = surrogate
        self.options = options

    @abstractmethod
    def ask(self, n: int = 1) -> np.ndarray:
        """The next points to evaluate, ``(k, q)`` SI units, k >= 1 (``n``: how many workers wait)."""

    @abstractmethod
    def tell(self, X: np.ndarray, values: Sequence[float | None]) -> None:
        """J at points :meth:`ask` returned: ``X (k, q)`` SI, ``values (k,)``, None or NaN where it failed."""

    @property
    @abstractmethod
    def done(self) -> bool:
        """True when the optimiser asks nothing more (budget spent or its own stopping rule)."""

    def asynchronous(self, n_workers: int) -> bool:
        """Whether the driver should keep ``n_workers`` trials in flight, one :meth:`ask_trials` at a time.

        An optimiser that answers True takes ``ask_trials(1, beside=True)``: one more trial beside
        the trials being evaluated, or none when it has none to add before one of them is told; and
        it takes trials told one at a time, oldest first (:func:`suspid.optimize.driver.run_trials`).
        Default False: ask, evaluate together, tell.
        """
        return False

    # -- the trial loop's hooks over the array interface (suspid.optimize.trials.TrialLoop) --------
    # An optimiser that speaks only ask/tell of arrays runs on the loop through these defaults:
    # its points are handed out as trials and told back, in the order asked, once they have values.
    def _loop_start(self) -> None:
        if "book_" not in self.__dict__:
            from suspid.optimize.design import check_bounds
            self.book_ = TrialBook(check_bounds(self.bounds))

    def _finished(self) -> bool:
        return bool(self.__dict__.get("_asked_nothing")) or self.done

    def _propose_trials(self, n: int) -> None:
        self._new_trials(np.atleast_2d(self.ask(n=n)))

    def _beside(self) -> list["Trial"]:
        pending = np.array([t.x for t in self.book_.waiting])
        return self._new_trials(np.atleast_2d(self.ask(1, pending=pending)), beside=True)  # type: ignore[call-arg]

    def _new_trials(self, X: np.ndarray, beside: bool = False) -> list["Trial"]:
        from suspid.optimize.design import to_unit
        if X.size == 0:
            if not beside:   # the optimiser has nothing to ask: the loop stops
                self.__dict__["_asked_nothing"] = True
            return []
        return [self.book_.new(u, self.name, x=x.copy()) for u, x in zip(to_unit(X, self.book_.bounds), X)]

    def _commit_trials(self, trials: list["Trial"]) -> None:
        self.tell(np.array([t.x for t in trials]), [t.J for t in trials])

    @abstractmethod
    def result(self) -> OptimizerResult:
        """The :class:`OptimizerResult` (after at least one value was told)."""

    def loop_state(self) -> Any:
        """The loop's state at its end, a :class:`suspid.optimize.loop.LoopOutcome` (which imports this
        module): what the analysis reads, with the surrogate fitted on its points. By default every point
        told (:meth:`result`) and the trials; an optimiser with a model of its own (``ego``) gives its own,
        with that model."""
        from suspid.optimize.design import check_bounds
        from suspid.optimize.loop import LoopOutcome
        res = self.result()
        book = self.__dict__.get("book_")
        return LoopOutcome.of_points(res.x_opt, res.y_opt, res.X, res.y, res.n_initial, res.stop_reason,
                                     check_bounds(self.bounds), book.trials if book is not None else [])


# ---------------------------------------------------------------------------------------------------
# Effects: named model extensions for the discrepancy workflow (``suspid diagnose``)
# ---------------------------------------------------------------------------------------------------
SPEED_DEPENDENCES = ("none", "proportional", "kinematic")
"""How the band of an effect moves with the speed v.

- ``none``: a structural or sensor resonance, fixed in Hz;
- ``proportional``: a wavelength fixed on the wheel or the track, f = v / wavelength
  (wheel polygon of order k: wavelength πD/k; sleeper passing: the sleeper spacing);
- ``kinematic``: the hunting family, f = v/(2π) sqrt(λ/(r0 l0)) (∝ v, and moving with the conicity λ).
"""

CHANNEL_BODIES = ("carbody", "bogie", "axlebox", "wheelset")
"""Body words an effect signature uses; a channel belongs to a body when its name contains the word."""

CHANNEL_DIRECTIONS = ("vertical", "lateral", "longitudinal")
"""Direction words an effect signature uses, matched in channel names like :data:`CHANNEL_BODIES`."""


@dataclass(frozen=True)
class EffectSignature:
    """Where an effect shows in the spectra Y (paper eq. 1) at one speed.

    :ivar bodies: bodies whose channels show it, words of :data:`CHANNEL_BODIES`.
    :ivar directions: directions of those channels, words of :data:`CHANNEL_DIRECTIONS`.
    :ivar band_hz: ``(low, high)`` in Hz, the band where it can show at this
        speed over the admissible range of its parameters (``high`` may be ``inf``).
    :ivar speed_dependence: how the band moves with speed, one of :data:`SPEED_DEPENDENCES`.
    """

    bodies: tuple[str, ...]
    directions: tuple[str, ...]
    band_hz: tuple[float, float]
    speed_dependence: str = "none"

    def matches_channel(self, channel: str) -> bool:
        """True when the channel name shows one of the bodies and one of the directions.

        A name with no body word (or no direction word) at all is not excluded
        on that count: the signature cannot tell, so it does not rule it out.
        """
        name = channel.lower()
        bodies = [b for b in CHANNEL_BODIES if b in name]
        directions = [d for d in CHANNEL_DIRECTIONS if d in name]
        body_ok = not bodies or any(b in self.bodies for b in bodies)
        direction_ok = not directions or any(d in self.directions for d in directions)
        return body_ok and direction_ok

    def overlaps(self, f_low: float, f_high: float) -> bool:
        """True when the band ``[f_low, f_high]`` (Hz) meets :attr:`band_hz`."""
        return f_high >= self.band_hz[0] and f_low <= self.band_hz[1]


class Effect(ABC):
    """A named model extension missing from rigid-body models (the discrepancy catalogue).

    An effect is physics with a few parameters, e.g. the first vertical bending
    mode of the carbody (frequency, damping). It is *declared* here,
    independently of any simulator: its parameters (``Options``, a pydantic
    model whose fields carry units and bounds ``ge``/``le``), its signature
    (which channels, which band, how the band moves with speed) and which
    parameters the diagnosis fits. A simulator *implements* the effects it
    supports, looked up by ``name``; configs enable them as::

        simulator: {plugin: exudyn-train, options: {effects: [{name: carbody-bending, frequency_hz: 9.5}]}}

    Contract for simulators that support effects: ``options["effects"]`` is a
    list of ``{name: <effect>, <parameter>: value, ...}`` validated against the
    effect's ``Options``; an effect the simulator does not implement is an
    error naming it; the parameters of :attr:`fitted` of every enabled effect
    are exposed as simulator parameters named ``<effect>/<parameter>`` (nominal:
    the configured value; bounds: the ``Options`` bounds), so that the
    diagnosis, or an identification, can vary them without rebuilding; a
    method ``supported_effects() -> list[str]`` names the effects it implements.

    Class attributes:

    - ``name``: registered name (``carbody-bending``);
    - ``Options``: pydantic model of the parameters (without ``name``);
    - ``main_parameter``: the parameter a diagnosis reports and is judged on
      (frequency for modes, order for a polygon, angle for a tilt);
    - ``fitted``: continuous parameters fitted by the diagnosis; a field with
      ``json_schema_extra={"scale": "log"}`` is searched on a log scale;
    - ``description``: one line for reports.

    Constructors store the options (``Effect(**options)``); methods work.
    """

    name: ClassVar[str]
    Options: ClassVar[type]
    main_parameter: ClassVar[str]
    fitted: ClassVar[tuple[str, ...]] = ()
    description: ClassVar[str] = ""

    def __init__(self, **options: Any) -> None:
        self.options = options

    @abstractmethod
    def signature(self, speed_mps: float) -> EffectSignature:
        """Where the effect can show at speed ``speed_mps`` (m/s), over its admissible parameters."""

    def candidates(self, speeds_mps: Sequence[float], flagged: Sequence[tuple[str, float, float, float]],
                   channels: Sequence[str]) -> list[dict[str, Any]]:
        """Starting points of the fit: parameter dicts (partial: other parameters keep their defaults).

        :param speeds_mps: the speeds of the data, m/s.
        :param flagged: ``(channel, f_low_hz, f_high_hz, speed_mps)`` of the cells
            where model and measurements disagree.
        :param channels: every channel name.
        :returns: by default five values of :attr:`main_parameter` spread over its bounds.
        """
        lo, hi = self.bounds(self.main_parameter)
        return [{self.main_parameter: float(v)} for v in np.linspace(lo, hi, 7)[1:-1]]

    def matching_cells(self, flagged: Sequence[tuple[str, float, float, float]]
                       ) -> list[tuple[str, float, float, float]]:
        """The cells of ``flagged`` that the signature covers: the cell's channel, and its band at the cell's speed.

        :param flagged: ``(channel, f_low_hz, f_high_hz, speed_mps)`` of cells, as :meth:`candidates` receives them.
        :returns: the covered cells, in the same order. A diagnosis does not fit an effect that covers none.
        """
        out = []
        for channel, lo, hi, v in flagged:
            sig = self.signature(v)
            if sig.matches_channel(channel) and sig.overlaps(lo, hi):
                out.append((channel, lo, hi, v))
        return out

    @classmethod
    def bounds(cls, parameter: str) -> tuple[float, float]:
        """``(lower, upper)`` of a parameter, from the ``ge``/``gt``/``le``/``lt`` of its field."""
        field_info = cls.Options.model_fields[parameter]
        lo, hi = -np.inf, np.inf
        for meta in field_info.metadata:
            for attr in ("ge", "gt"):
                if getattr(meta, attr, None) is not None:
                    lo = float(getattr(meta, attr))
            for attr in ("le", "lt"):
                if getattr(meta, attr, None) is not None:
                    hi = float(getattr(meta, attr))
        return lo, hi

    @classmethod
    def log_scale(cls, parameter: str) -> bool:
        """True when the parameter is searched on a log scale (``json_schema_extra={"scale": "log"}``)."""
        extra = cls.Options.model_fields[parameter].json_schema_extra
        return isinstance(extra, dict) and extra.get("scale") == "log"

    @classmethod
    def defaults(cls) -> dict[str, Any]:
        """Every parameter at its default value."""
        return cls.Options().model_dump()


# ---------------------------------------------------------------------------------------------- readers
@dataclass
class Signal:
    """One channel of a recording, as a :class:`Reader` returns it.

    :ivar name: the channel's name in the file.
    :ivar values: ``(n,)`` float64 samples, in the unit the file stores them in
        (suspid converts them by the unit the config declares).
    :ivar unit: the unit the file gives for the channel (``""`` when it has none); informative only.
    :ivar index: ``(n,)`` abscissa of each sample (time in s for a recording,
        distance in m for a track record), or ``None`` for a uniform record.
    :ivar step: sampling step of a uniform record (s or m), ``None`` when ``index`` is given.
    :ivar start: abscissa of the first sample of a uniform record.
    """

    name: str
    values: np.ndarray
    unit: str = ""
    index: np.ndarray | None = None
    step: float | None = None
    start: float = 0.0


class Reader(ABC):
    """A file format of a data-acquisition system: lists channels and reads them one at a time.

    Subclasses set ``name`` and ``extensions`` (lower case, with the dot, e.g.
    ``(".mf4",)``) and may set ``Options``. The constructor stores the path and
    options and opens nothing; :meth:`channels` and :meth:`read` do the work.
    A reader must not hold the whole file in memory: :meth:`read` returns one
    channel (formats stored row by row read the columns :meth:`select` named in
    one pass, in chunks). Use it as a context manager, so that :meth:`close`
    releases the file. Errors a user can cause (missing file, unknown channel,
    malformed content) raise :class:`suspid.errors.DataError` naming the file.
    """

    name: ClassVar[str]
    extensions: ClassVar[tuple[str, ...]] = ()
    Options: ClassVar[type | None] = None

    def __init__(self, path: Any, **options: Any) -> None:
        self.path = path
        self.options = options

    @abstractmethod
    def channels(self) -> list[str]:
        """Names of the channels in the file (as :meth:`read` accepts them)."""

    @abstractmethod
    def read(self, channel: str) -> Signal:
        """One channel: its samples, the file's unit, and its abscissa (``index`` or ``step``/``start``).

        :raises suspid.errors.DataError: the channel is not in the file (listing those that are).
        """

    def select(self, channels: Sequence[str]) -> None:
        """Announce the channels that will be read, so that row-oriented formats parse the file once.

        Default: nothing to do (column-oriented formats read each channel on its own).
        """

    def close(self) -> None:
        """Release the file; default: nothing to release."""

    def __enter__(self) -> "Reader":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
