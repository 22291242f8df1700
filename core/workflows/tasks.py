"""Simulations as executor tasks: what a worker runs, and how the driver hands tasks to an executor.

Every simulation of a run (the reference and measurement dates, the design,
EGO, the interval points, the checks and the report's figures) is a
:class:`SpectraTask` called with a parameter vector w, run by the run's
executor, so that with a cluster the driver process simulates nothing. The
task holds the simulator class and options, the track segments and the
spectra options; executors send it once per worker (``docs/dask.md``), and
each task carries only w.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

from suspid import registry
from suspid.errors import PluginBugError, SimulatorError, SuspidError
from suspid.infra.ledger import stable_hash
from suspid.interfaces import Executor, Response, Simulator, TrackSegment
from suspid.method.spectra import SpectraOptions, compute_spectra


def simulate_spectra(simulator: Simulator, w: dict[str, float], segments: Sequence[TrackSegment],
                     spectra_options: SpectraOptions | dict[str, Any] | None,
                     transform: Callable[[list[Response]], list[Response]] | None = None
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Spectra ``(y (v, n_channels, n_freqs) dB, freqs (n_freqs,) Hz)`` of ``simulator`` at ``w`` on ``segments``.

    :param transform: applied to the responses before the spectra (e.g. a measurement process).
    """
    try:
        responses = simulator.simulate(w, segments)
    except SuspidError:
        raise
    except Exception as exc:  # noqa: BLE001 - not one of suspid's errors: a bug of the plugin
        raise PluginBugError(f"{registry.describe('simulator', simulator.name)} failed at w = {dict(w)}: "
                             f"{type(exc).__name__}: {exc}") from exc
    expected = list(simulator.channels())
    if len(responses) != len(segments) or any(list(r.channels) != expected
                                              or np.shape(r.accelerations)[:1] != (len(expected),) for r in responses):
        bad = next((r for r in responses if list(r.channels) != expected
                    or np.shape(r.accelerations)[:1] != (len(expected),)), None)
        what = (f"{len(responses)} records for {len(segments)} segments" if bad is None else
                f"{len(bad.channels)} channels ({', '.join(bad.channels)}) with accelerations of shape "
                f"{np.shape(bad.accelerations)} for segment '{bad.segment}'")
        raise PluginBugError(f"{registry.describe('simulator', simulator.name)} returned {what}; its channels() "
                             f"lists {len(expected)}: {', '.join(expected)} (a bug in the plugin)")
    for r in responses:
        if not np.all(np.isfinite(np.asarray(r.accelerations, dtype=float))):
            raise SimulatorError(f"simulator '{simulator.name}' returned non-finite accelerations (NaN or inf) "
                                 f"for segment '{r.segment}' at w = {dict(w)}; the model may be unstable there")
    if transform is not None:
        responses = transform(responses)
    return compute_spectra(responses, spectra_options)


@dataclass(frozen=True)
class SpectraTask:
    """Worker side of simulations on fixed segments: ``task(w) -> y_sim (v, n_channels, n_freqs) dB``.

    Everything but w is in the task (the simulator class, pickled by
    reference, its resolved options, the track segments, the spectra options,
    an optional transform of the responses), so that executors send it once
    per worker and each task carries only w (``docs/dask.md``). The simulator
    is built once per process.

    :ivar with_freqs: return ``(y_sim, freqs (n_freqs,) Hz)`` instead of ``y_sim``.
    """

    simulator_cls: type
    options: dict
    segments: list
    spectra: Any
    transform: Callable[[list], list] | None = None
    with_freqs: bool = False

    @classmethod
    def of(cls, simulator: Simulator, segments: Sequence, spectra: Any, **kwargs: Any) -> "SpectraTask":
        """The task that simulates ``simulator`` (an instance built from its options) on ``segments``."""
        return cls(type(simulator), dict(simulator.options), list(segments), spectra, **kwargs)

    def __call__(self, w: dict[str, float]) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        simulator = simulator_instance(self.simulator_cls, self.options)
        y, freqs = simulate_spectra(simulator, w, self.segments, self.spectra, self.transform)
        return (y, freqs) if self.with_freqs else y


_SIMULATORS: dict[str, Simulator] = {}


def simulator_instance(cls: type, options: dict) -> Simulator:
    """The simulator ``cls(**options)``, built once per process (models keep caches per instance)."""
    key = stable_hash(f"{cls.__module__}.{cls.__qualname__}", options)
    if key not in _SIMULATORS:
        if len(_SIMULATORS) >= 4:
            _SIMULATORS.pop(next(iter(_SIMULATORS)))
        _SIMULATORS[key] = cls(**options)
    return _SIMULATORS[key]


def in_process() -> Executor:
    """The serial executor: tasks run in this process (what callers get without an executor)."""
    return registry.get("executor", "serial")()


def run_tasks(executor: Executor | None, jobs: Sequence[tuple[Callable[[Any], Any], Any]]) -> list[Any]:
    """``fn(item)`` for every ``(fn, item)`` job, run together by ``executor`` (``submit``/``wait_first``).

    :returns: each job's result or exception, in the order of ``jobs``.
    :raises ClusterError: the executor lost its cluster.
    """
    executor = executor or in_process()
    handles = [executor.submit(fn, item) for fn, item in jobs]
    index = {id(h): i for i, h in enumerate(handles)}
    out: list[Any] = [None] * len(jobs)
    while handles:
        for h, outcome in executor.wait_first(handles):
            handles.remove(h)
            out[index[id(h)]] = outcome
    return out


def run_one(executor: Executor | None, fn: Callable[[Any], Any], item: Any) -> Any:
    """``fn(item)`` run by ``executor`` (in this process without one); a task's exception is raised."""
    outcome = run_tasks(executor, [(fn, item)])[0]
    if isinstance(outcome, BaseException):
        raise outcome
    return outcome
