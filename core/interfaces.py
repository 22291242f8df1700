"""Small interfaces for the three plugin kinds, with their shapes and units.

Conventions (``shared/CONVENTIONS.md``): constructors store their options and
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
from typing import Any, Callable, ClassVar, Iterator, Mapping, Sequence

import numpy as np

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
    """

    name: str
    unit: str
    nominal: float
    lower: float
    upper: float
    description: str = ""


@dataclass
class TrackSegment:
    """One stretch of track with its measured (or synthetic) geometry.

    :ivar name: identifier, unique within a data set.
    :ivar distance: ``(n_x,)`` m, increasing and uniformly spaced.
    :ivar irregularities: ``(4, n_x)`` m, rows as :data:`IRREGULARITY_CHANNELS`.
    :ivar speed: train speed in m/s, a constant or a ``(n_x,)`` record at each
        distance sample (variable speed).
    """

    name: str
    distance: np.ndarray
    irregularities: np.ndarray
    speed: float | np.ndarray
    meta: dict[str, Any] = field(default_factory=dict)

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

    def identity(self) -> dict[str, Any]:
        """What determines this simulator's output besides ``w`` and the track.

        Used to key cached evaluations in the run ledger; the default is the
        plugin name and its options.
        """
        return {"plugin": self.name, "options": self.options}


class Objective(ABC):
    """Ψ_k: a per-channel comparison of measured and modelled spectra (eq. 5-8).

    Higher is better: J = Σ_k α_k Ψ_k is maximised.
    """

    name: ClassVar[str]
    Options: ClassVar[type | None] = None

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

    Inputs ``X`` are ``(n_points, q)``; EGO passes points of the unit cube
    ``[0, 1]^q``. Outputs ``y`` are ``(n_points,)``.
    """

    name: ClassVar[str]
    Options: ClassVar[type | None] = None

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

    @abstractmethod
    def map_unordered(self, fn: Callable[[Any], Any], items: Sequence[Any]) -> Iterator[tuple[int, Any]]:
        """Apply ``fn`` to every item; yield ``(index, result)`` as each task finishes.

        A task that raises yields ``(index, exception)`` instead of a result,
        so the caller can record the failure and go on with the others. A
        worker that dies loses only its task in flight, which is retried.
        ``fn`` and the items must be picklable for out-of-process executors.
        """
