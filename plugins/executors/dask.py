"""The ``dask`` executor: tasks on a dask.distributed cluster.

Select it with ``executor: {plugin: dask, options: {...}}``. The scheduler is,
in this order: the option ``address``, the environment variable
``SUSPID_DASK_SCHEDULER``, the environment variable ``DASK_SCHEDULER_ADDRESS``;
with none of them a :class:`distributed.LocalCluster` of ``n_workers``
processes is started on this machine for the ``with`` block and closed after
it. A cluster given by address is only connected to, never closed. How to
run on a real cluster: ``docs/dask.md``.

**On entering**, once the workers are there, every worker runs
:func:`~suspid.plugins.executors._common.worker_report` (``client.run``): a
worker that cannot import suspid, or runs another suspid, Python or plugin
version than the driver, stops the run before its first task with a
:class:`~suspid.errors.ClusterError` naming the worker's address.

**The task function is sent once per worker**, not with each task. ``fn`` is
pickled, named by the hash of its pickle, and left with the scheduler
(``client.set_metadata``) the first time this executor meets it; each worker
fetches it there on its first task that needs it and keeps the last few in a
cache keyed by that hash. So a callable holding the track (a simulation task
of :mod:`suspid.workflows.evaluation`) crosses the network once per worker for
the whole run, whatever the number of ``map_unordered`` calls, and the
scheduler holds one copy of it, not one per task; each task carries only its
item (a parameter vector). ``fn`` is deliberately not a dask dependency of the
tasks (scattered or computed): dask places a task on a worker holding its
dependencies, which would pile every task on one worker.

**Faults.** A dead worker: the scheduler reschedules its tasks on other
workers; a task whose workers died more than ``allowed-failures`` times
(dask's ``distributed.scheduler.allowed-failures``, default 3; the option
``allowed_failures`` for a LocalCluster) is given up, and a
:class:`~suspid.plugins.executors._common.WorkerLostError` naming it is
yielded (for the run, a failed simulation). A task's own exception is
yielded too, after ``retries`` more tries. Everything else is the cluster's
failure, not the task's, and raises :class:`~suspid.errors.ClusterError`
(nothing is yielded for the tasks in flight): the connection to the scheduler
lost (the client is no longer ``running``), a task cancelled or lost by the
cluster without a result (a scheduler restarted on the same port forgets
every task), a result that cannot be fetched within ``timeout_s``, and no
task finishing for ``result_timeout_s``. Every wait has a time limit, so the
driver never hangs; Ctrl-C (``KeyboardInterrupt``) goes through unchanged.

``distributed`` is imported only when the executor is entered, so listing
plugins does not pay for importing dask.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import hashlib
import logging
import os
import socket
import struct
import threading
import time
import uuid
from collections import OrderedDict
from typing import Any, Callable, ClassVar, Iterator, Sequence

from pydantic import BaseModel, ConfigDict, Field, PositiveFloat

from suspid import hookimpl
from suspid.errors import ClusterError, ConfigError, PluginError
from suspid.interfaces import Executor, TaskHandle

from ._common import WorkerLostError, executor_options, report_differences, worker_report
from .processes import default_workers

log = logging.getLogger(__name__)

ADDRESS_ENV_VARS = ("SUSPID_DASK_SCHEDULER", "DASK_SCHEDULER_ADDRESS")
"""Environment variables read, in this order, when the option ``address`` is not set."""

INSTALL_HINT = "pip install 'suspid[dask]'"


class DaskOptions(BaseModel):
    """Options of the ``dask`` executor (``executor.options``)."""

    model_config = ConfigDict(extra="forbid")

    address: str | None = Field(
        default=None, min_length=1,
        description="scheduler address (tcp://host:8786); default: $SUSPID_DASK_SCHEDULER, "
                    "$DASK_SCHEDULER_ADDRESS, else a LocalCluster")
    n_workers: int | None = Field(
        default=None, ge=1,
        description="LocalCluster: worker processes (default: CPUs / threads_per_worker); "
                    "with an address: wait until this many workers are connected (default 1)")
    threads_per_worker: int = Field(
        default=1, ge=1, description="LocalCluster only: threads per worker (1: the simulator is CPU-bound)")
    processes: bool = Field(default=True, description="LocalCluster only: workers in processes (false: threads)")
    profile: bool = Field(default=False, description="LocalCluster of processes only: dask's statistical profiler "
                          "in the workers (it samples the running task's stack every 10 ms, which slows CPU-bound "
                          "simulations)")
    retries: int = Field(default=0, ge=0,
                         description="tries more for a task that raises (client.submit retries=); "
                                     "worker deaths are allowed_failures' business")
    allowed_failures: int | None = Field(
        default=None, ge=0,
        description="LocalCluster only: worker deaths a task may suffer before it is given up "
                    "(dask's distributed.scheduler.allowed-failures, default 3); "
                    "an existing scheduler has its own setting")
    resources: dict[str, PositiveFloat] = Field(
        default_factory=dict,
        description="abstract resources each task holds, e.g. {vampire: 1} with workers started "
                    "with --resources vampire=1 (licence seats)")
    timeout_s: PositiveFloat = Field(
        default=60.0, description="wait for the scheduler and the workers, and for one result's transfer, s")
    result_timeout_s: PositiveFloat = Field(
        default=600.0, description="no task finished for this long: the cluster is taken as lost "
                                   "(ClusterError), s; longer than the slowest simulation")


def scheduler_address(options: DaskOptions) -> tuple[str | None, str]:
    """The scheduler to connect to and where that came from.

    :returns: ``(address, source)``: the address, or ``None`` for a new
        LocalCluster, and ``"executor.options.address"``, the environment
        variable's name or ``"LocalCluster"``.
    """
    if options.address:
        return options.address, "executor.options.address"
    for var in ADDRESS_ENV_VARS:
        value = os.environ.get(var, "").strip()
        if value:
            return value, var
    return None, "LocalCluster"


def _import_distributed():
    try:
        import distributed
    except ImportError as exc:
        raise PluginError(f"the dask executor needs dask.distributed, which is not installed "
                          f"({exc}); {INSTALL_HINT}") from None
    return distributed


_FN_CACHE: OrderedDict[str, Callable[[Any], Any]] = OrderedDict()
"""In each worker process: hash of a task function's pickle -> the function, the latest few."""

_FN_CACHE_SIZE = 4
_FN_LOCK = threading.Lock()
_PUBLISHED_MAX = 8
"""Task functions this executor leaves with the scheduler at once (the oldest is taken back)."""


def _fn_metadata_key(session: str, token: str) -> list[str]:
    return ["suspid", "executor-fn", session, token]


def _call(session: str, token: str, item: Any) -> Any:
    """One task on a worker: ``fn(item)``, ``fn`` fetched from the scheduler once per worker (cached by hash).

    :raises ClusterError: this worker cannot import what ``fn`` refers to (a plugin missing here).
    """
    with _FN_LOCK:  # workers with several threads
        fn = _FN_CACHE.get(token)
        if fn is None:
            import cloudpickle  # a dependency of distributed
            from distributed import get_client, get_worker

            payload = get_client().get_metadata(_fn_metadata_key(session, token), None)
            if payload is None:
                raise RuntimeError(f"dask executor: the scheduler no longer holds the task function {token}")
            try:
                fn = cloudpickle.loads(payload)
            except ImportError as exc:
                raise ClusterError(f"dask worker {get_worker().address} cannot import what the task needs "
                                   f"({type(exc).__name__}: {exc}); install the same packages as the driver "
                                   f"on every worker") from None
            _FN_CACHE[token] = fn
            while len(_FN_CACHE) > _FN_CACHE_SIZE:
                _FN_CACHE.popitem(last=False)
    return fn(item)


def _label(fn: Callable[[Any], Any]) -> str:
    """A short name for ``fn`` in task keys (shown on the dashboard)."""
    name = getattr(fn, "__name__", None) or type(fn).__name__
    return "".join(c if c.isalnum() or c in "_-" else "_" for c in name)[:40]


_TRANSFER_ERRORS = (TimeoutError, OSError, asyncio.CancelledError, concurrent.futures.CancelledError)
"""What fetching a result from a failing cluster raises (CommClosedError is an OSError)."""


class DaskExecutor(Executor):
    """Tasks on a dask.distributed cluster (a LocalCluster by default); see the module docstring.

    ``fn``, the items and the results must be picklable (cloudpickle), and
    every worker must be able to import what they refer to: suspid, the
    plugins in use and their dependencies, in the driver's versions.
    """

    name: ClassVar[str] = "dask"
    Options: ClassVar[type] = DaskOptions

    opts_: DaskOptions | None = None
    client_: Any = None
    cluster_: Any = None  # only a LocalCluster we started ourselves; closed in __exit__
    address_: str = ""  # the scheduler, as the user named it (or the LocalCluster's)
    source_: str = ""  # where that address came from
    lost_: bool = False  # a ClusterError was raised: the cluster is gone
    published_: OrderedDict | None = None  # hashes of the task functions left with the scheduler

    def _options(self) -> DaskOptions:
        return self.opts_ if self.opts_ is not None else executor_options(DaskOptions, self.options)

    @property
    def n_workers(self) -> int:
        """Tasks the cluster runs at once: its threads, fewer where ``resources`` are scarcer.

        Inside the ``with`` block this asks the scheduler (workers may come and
        go); outside it, the configured ``n_workers`` (or 1).
        """
        if self.client_ is None:
            return self._options().n_workers or 1
        return max(self._slots(), 1)

    def _workers(self) -> dict[str, Any]:
        """The scheduler's record of its workers.

        :raises ClusterError: the connection is lost (the client's last record of the scheduler is empty then).
        """
        self._check_connection()
        info = self.client_.scheduler_info(n_workers=-1)
        if "workers" not in info:
            self.lost_ = True
            raise ClusterError(f"lost the connection to the dask scheduler at {self.address_} (no record of its "
                               f"workers); the simulations in flight were not recorded: run the same command "
                               f"again to resume once the scheduler and its workers are back")
        return info["workers"]

    def _slots(self) -> int:
        """Σ over the connected workers of min(threads, ⌊resource held / resource needed⌋)."""
        slots = 0
        for worker in self._workers().values():
            n = int(worker.get("nthreads", 1))
            for resource, need in self.opts_.resources.items():
                n = min(n, int(worker.get("resources", {}).get(resource, 0) // need))
            slots += n
        return slots

    @property
    def dashboard_link(self) -> str | None:
        """The dask dashboard's URL inside the ``with`` block (``None`` when not available)."""
        if self.client_ is None:
            return None
        try:
            return self.client_.dashboard_link
        except Exception:  # no dashboard (bokeh missing, or the scheduler has none)
            return None

    def describe(self) -> str:
        """The scheduler, where its address came from, the workers, the task slots and the dashboard."""
        if self.client_ is None:
            address, source = scheduler_address(self._options())
            return f"dask executor: scheduler {address or 'a new LocalCluster'} (from {source}), not connected"
        return (f"dask executor: scheduler {self.address_} ({self.source_}), {len(self._workers())} worker(s), "
                f"{self.n_workers} task slot(s), dashboard {self.dashboard_link or 'not available'}")

    def validate(self) -> None:
        """With a scheduler address: connect, wait for the workers, check them, disconnect (a LocalCluster: nothing).

        :raises ConfigError: the scheduler cannot be reached, or too few workers.
        :raises ClusterError: a worker cannot run suspid's tasks (named by its address).
        """
        opts = self._options()
        _import_distributed()
        if scheduler_address(opts)[0] is not None:
            with self:
                pass

    def __enter__(self) -> "DaskExecutor":
        if self.client_ is not None:
            raise RuntimeError("dask executor: already entered (one `with` block at a time)")
        opts = self.opts_ = self._options()
        distributed = _import_distributed()
        address, self.source_ = scheduler_address(opts)
        self.session_, self.published_, self.tokens_ = uuid.uuid4().hex[:12], OrderedDict(), OrderedDict()
        self.n_submitted_, self.lost_ = 0, False
        try:
            if address is None:
                self._start_local_cluster(distributed, opts)
                self.address_ = self.cluster_.scheduler_address
            else:
                self._connect(distributed, opts, address, self.source_)
                self.address_ = address
            self._check_workers()
        except BaseException:
            self._close()
            raise
        log.info(self.describe())
        return self

    def _start_local_cluster(self, distributed: Any, opts: DaskOptions) -> None:
        n_workers = opts.n_workers or max(1, default_workers() // opts.threads_per_worker)
        scheduler_kwargs = {}
        if opts.allowed_failures is not None:
            scheduler_kwargs["allowed_failures"] = opts.allowed_failures
        worker_resources = {"resources": dict(opts.resources)} if opts.resources else {}
        # the dask config of worker processes (their nannies pass it on); threads share the driver's
        profiler = {"config": {"distributed.worker.profile.enabled": opts.profile}} if opts.processes else {}
        self.cluster_ = distributed.LocalCluster(
            n_workers=n_workers, threads_per_worker=opts.threads_per_worker, processes=opts.processes,
            dashboard_address=":0",  # a free port: never collides with another run's dashboard
            scheduler_kwargs=scheduler_kwargs, **worker_resources, **profiler)
        self.client_ = distributed.Client(self.cluster_, timeout=opts.timeout_s)
        self.client_.wait_for_workers(n_workers, timeout=opts.timeout_s)

    def _connect(self, distributed: Any, opts: DaskOptions, address: str, source: str) -> None:
        key = "executor.options.address" if source == "executor.options.address" else None
        if opts.allowed_failures is not None:
            raise ConfigError("allowed_failures applies to a LocalCluster only; for the scheduler at "
                              f"{address} (from {source}) set distributed.scheduler.allowed-failures "
                              "in that scheduler's dask config", key="executor.options.allowed_failures")
        probe_scheduler(address, source, opts.timeout_s, key)
        try:
            self.client_ = distributed.Client(address, timeout=opts.timeout_s)
        except (OSError, TimeoutError) as exc:
            raise ConfigError(f"cannot connect to the dask scheduler at {address} (from {source}) "
                              f"within timeout_s={opts.timeout_s:g}: {exc}", key=key) from None
        wanted = opts.n_workers or 1
        try:
            self.client_.wait_for_workers(wanted, timeout=opts.timeout_s)
        except (OSError, TimeoutError):
            have = len(self._workers())
            raise ConfigError(f"the dask scheduler at {address} has {have} worker(s) after "
                              f"timeout_s={opts.timeout_s:g}, {wanted} wanted; start workers with "
                              f"`dask worker {address}`", key="executor.options.n_workers") from None
        if opts.resources and self._slots() == 0:  # tasks would wait for ever
            needs = " ".join(f"{r}={v:g}" for r, v in opts.resources.items())
            raise ConfigError(f"no worker of the dask scheduler at {address} holds the resources {needs} "
                              f"a task needs; start workers with `dask worker {address} --resources "
                              f"\"{needs}\"`", key="executor.options.resources")

    def _check_workers(self) -> None:
        """Every connected worker imports suspid and runs the driver's suspid, Python and plugin versions.

        :raises ClusterError: naming each worker that does not, and why.
        """
        mine = worker_report()
        problems = []
        for address, theirs in sorted(self.client_.run(worker_report, on_error="return").items()):
            if isinstance(theirs, BaseException):
                problems.append(f"{address} cannot run suspid ({type(theirs).__name__}: {theirs})")
            elif report_differences(mine, theirs):
                problems.append(f"{address} differs from the driver: {'; '.join(report_differences(mine, theirs))}")
        if problems:
            raise ClusterError(f"dask scheduler at {self.address_}: worker {' | worker '.join(problems)}; every "
                               f"worker needs suspid and the plugins in use, in the driver's versions")

    def __exit__(self, *exc: Any) -> None:
        self._close()

    def _close(self) -> None:
        """Let go of the cluster; never raises, so that the error (or Ctrl-C) that ends the block goes through.

        After a lost cluster the client is closed without a word: dask would
        log the end of its reconnection attempts as errors with tracebacks,
        under the one line of the :class:`~suspid.errors.ClusterError`.
        """
        client, cluster = self.client_, self.cluster_
        self.client_ = self.cluster_ = None
        lost = self.lost_ or (client is not None and client.status != "running")
        with _quiet_dask_logs(lost):
            if client is not None:
                try:
                    if not lost and self.published_:
                        client.set_metadata(["suspid", "executor-fn", self.session_], {})  # the scheduler lets go
                    client.close(timeout=self.opts_.timeout_s if self.opts_ else 10)
                except Exception as exc:  # noqa: BLE001 - a lost cluster: nothing left to close
                    log.debug("dask executor: closing the client: %s", exc)
            if cluster is not None:
                try:
                    cluster.close()
                except Exception as exc:  # noqa: BLE001
                    log.debug("dask executor: closing the LocalCluster: %s", exc)

    # -- the connection and the task function ---------------------------------------------------
    def _check_connection(self) -> None:
        """:raises ClusterError: the client is no longer connected to the scheduler."""
        status = self.client_.status
        if status not in ("running", "newly-created"):
            self.lost_ = True
            raise ClusterError(f"lost the connection to the dask scheduler at {self.address_} (client {status}); "
                               f"the simulations in flight were not recorded: run the same command again to "
                               f"resume once the scheduler and its workers are back")

    def _publish(self, fn: Callable[[Any], Any]) -> str:
        """The hash naming ``fn``, left with the scheduler the first time (see the module docstring)."""
        known = self.tokens_.get(id(fn))
        if known is not None and known[0] is fn:
            return known[1]
        import cloudpickle

        payload = cloudpickle.dumps(fn)
        token = hashlib.sha256(payload).hexdigest()[:16]
        self.tokens_[id(fn)] = (fn, token)  # holding fn keeps its id from being reused
        while len(self.tokens_) > _PUBLISHED_MAX:
            self.tokens_.popitem(last=False)
        if token not in self.published_:
            self._check_connection()
            self.client_.set_metadata(_fn_metadata_key(self.session_, token), payload)
            self.published_[token] = True
            while len(self.published_) > _PUBLISHED_MAX:
                old, _ = self.published_.popitem(last=False)
                self.client_.set_metadata(_fn_metadata_key(self.session_, old), None)
        return token

    # -- tasks --------------------------------------------------------------------------------------
    def submit(self, fn: Callable[[Any], Any], item: Any) -> TaskHandle:
        """Start ``fn(item)`` on the cluster; see :meth:`suspid.interfaces.Executor.submit`.

        :raises RuntimeError: outside a ``with`` block.
        :raises ClusterError: the connection to the scheduler is lost.
        """
        if self.client_ is None:
            raise RuntimeError("dask executor: submit needs the executor entered (`with executor:`)")
        self.n_submitted_ += 1
        return self._submit(fn, self._publish(fn), item, f"task {self.n_submitted_}")

    def _submit(self, fn: Callable[[Any], Any], token: str, item: Any, label: str) -> TaskHandle:
        opts = self.opts_
        key = f"suspid-{_label(fn)}-{label.split()[-1]}-{uuid.uuid4().hex[:12]}"
        future = self.client_.submit(_call, self.session_, token, item, key=key, pure=False,
                                     retries=opts.retries or None, resources=dict(opts.resources) or None)
        handle = TaskHandle(fn, item, future=future)
        handle.label = label
        return handle

    def wait_first(self, handles: Sequence[TaskHandle], timeout: float | None = None
                   ) -> list[tuple[TaskHandle, Any]]:
        """The finished ones of ``handles`` (see :meth:`suspid.interfaces.Executor.wait_first`).

        Waits in slices of at most a second, checking the connection between them.
        Without ``timeout``, none finishing for ``result_timeout_s`` is a lost cluster.

        :raises ClusterError: the connection is lost, a task was lost or cancelled by the cluster,
            a result could not be fetched within ``timeout_s``, or (no ``timeout``) nothing finished
            within ``result_timeout_s``.
        """
        from distributed import wait

        limit = self.opts_.result_timeout_s if timeout is None else timeout
        deadline = time.monotonic() + limit
        while True:
            self._check_connection()
            ready = [h for h in handles if h.done or h.future.done()]
            if ready:
                return [(h, self._outcome(h)) for h in ready]
            left = min(1.0, deadline - time.monotonic())
            if left <= 0 and timeout is None:
                raise ClusterError(f"dask executor: no task finished for result_timeout_s={limit:g} s "
                                   f"({len(handles)} waiting) on the cluster at {self.address_}; see its "
                                   f"dashboard {self.dashboard_link}, or raise executor.options.result_timeout_s "
                                   f"for longer simulations")
            if left <= 0:
                return []
            try:
                wait([h.future for h in handles], timeout=left, return_when="FIRST_COMPLETED")
            except (TimeoutError, concurrent.futures.CancelledError):  # cancelled: reported by _outcome
                pass

    def _outcome(self, h: TaskHandle) -> Any:
        """A finished task's result or exception, fetched once; the cluster then forgets it."""
        if h.done:
            return h.outcome
        future, timeout = h.future, self.opts_.timeout_s
        try:
            if future.status == "finished":
                outcome = future.result(timeout=timeout)
            elif future.status == "error":
                outcome = _error_outcome(h.label, future.exception(timeout=timeout), future.traceback(timeout=timeout))
            else:
                raise ClusterError(f"dask executor: {h.label} was {future.status} by the cluster without a result "
                                   f"(a scheduler restarted, or the connection lost); the simulations in flight "
                                   f"were not recorded: run the same command again to resume")
        except _TRANSFER_ERRORS as exc:
            self._check_connection()
            self.lost_ = True
            raise ClusterError(f"lost the connection to the dask cluster at {self.address_} while fetching the "
                               f"result of {h.label} (within timeout_s={timeout:g}: {type(exc).__name__}: {exc}); "
                               f"the simulations in flight were not recorded: run the same command again to "
                               f"resume once the scheduler and its workers are back") from None
        future.release()  # a result still held when its worker dies would be recomputed
        h.done, h.outcome, h.future = True, outcome, None
        return outcome

    def _cancel(self, handles: list[TaskHandle]) -> None:
        """Cancel tasks not finished, when the cluster is still there to hear it (never raises)."""
        futures = [h.future for h in handles if h.future is not None]
        try:
            if futures and self.client_ is not None and self.client_.status == "running":
                self.client_.cancel(futures)
        except Exception as exc:  # noqa: BLE001 - the cluster went away meanwhile
            log.debug("dask executor: cancelling: %s", exc)

    def map_unordered(self, fn: Callable[[Any], Any], items: Sequence[Any]) -> Iterator[tuple[int, Any]]:
        """Apply ``fn`` to every item on the cluster; yield ``(index, result or exception)`` as tasks finish.

        A task's own exception is yielded after ``retries`` more tries; a task
        whose workers kept dying yields a ``WorkerLostError``. A failure of the
        cluster raises ``ClusterError`` (module docstring), also when no task
        finishes for ``result_timeout_s``. Closing the iterator early cancels
        the tasks not finished yet.

        :raises RuntimeError: outside a ``with`` block.
        """
        if self.client_ is None:
            raise RuntimeError("dask executor: map_unordered needs the executor entered (`with executor:`)")
        return self._run(fn, list(items))

    def _run(self, fn: Callable[[Any], Any], items: list[Any]) -> Iterator[tuple[int, Any]]:
        if not items:
            return
        token = self._publish(fn)
        pending = {}
        try:
            for i, item in enumerate(items):
                pending[self._submit(fn, token, item, f"task {i}")] = i
            while pending:
                for h, outcome in self.wait_first(list(pending)):  # raises after result_timeout_s without progress
                    yield pending.pop(h), outcome
        finally:
            self._cancel(list(pending))


HANDSHAKE_MAX_BYTES = 1 << 20
"""A dask handshake is a few hundred bytes; a first frame longer than this is another protocol."""


def parse_scheduler_address(address: str, source: str, key: str | None) -> tuple[str, str, int]:
    """``(scheme, host, port)`` of a scheduler address (``tcp://host:port``, ``host:port``, ``tls://...``);
    ``(scheme, location, 0)`` for the schemes without a TCP port (``inproc://``, ``ucx://``, ``ws://``).

    :raises ConfigError: the address is malformed (no port, a port that is not a number or out of
        1-65535, a scheme dask has no comm for), naming it and where it came from.
    """
    from distributed.comm import registry as comm_registry
    from distributed.comm.addressing import parse_address, parse_host_port

    expected = "expected tcp://host:port (the scheduler's port, 8786 by default)"
    try:
        scheme, location = parse_address(address)
        comm_registry.get_backend(scheme)
        if scheme not in ("tcp", "tls"):
            return scheme, location, 0
        host, port = parse_host_port(location)
    except (ValueError, TypeError) as exc:
        raise ConfigError(f"'{address}' (from {source}) is not a dask scheduler address ({exc}); {expected}",
                          key=key) from None
    if not 0 < int(port) < 65536:
        raise ConfigError(f"'{address}' (from {source}): port {port} is out of 1-65535; {expected}", key=key)
    return scheme, host, int(port)


def probe_scheduler(address: str, source: str, timeout_s: float, key: str | None) -> None:
    """Check that a TCP scheduler address speaks dask before :class:`distributed.Client` connects to it.

    A dask scheduler sends its handshake (one frame: an 8-byte little-endian length, then at most a
    few kilobytes) as soon as a connection is accepted. ``distributed`` reads that frame without a
    time limit and allocates whatever length the first 8 bytes say, so a service of another kind
    (an HTTP server, the scheduler's dashboard port) would make the client wait for ever, or fail
    with a ``MemoryError`` when the service answers with text (``HTTP/1.1 ...`` read as a length).
    Here the first frame is read on a plain socket, within ``timeout_s`` in all, and its length
    checked. Other schemes (``tls://``: encrypted before any frame) are only parsed.

    :raises ConfigError: the address is malformed, nothing listens there, or what listens is not a
        dask scheduler; one line naming the address and where it came from.
    """
    scheme, host, port = parse_scheduler_address(address, source, key)
    if scheme != "tcp":
        return
    deadline = time.monotonic() + timeout_s
    not_dask = f"the service at {address} (from {source}) is not a dask scheduler"
    try:
        sock = socket.create_connection((host, port), timeout=timeout_s)
    except OSError as exc:
        raise ConfigError(f"cannot connect to the dask scheduler at {address} (from {source}) "
                          f"within timeout_s={timeout_s:g}: {exc.strerror or exc}", key=key) from None
    with sock:
        def receive(n: int) -> bytes:
            data = b""
            while len(data) < n:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise TimeoutError
                sock.settimeout(left)
                chunk = sock.recv(n - len(data))
                if not chunk:
                    raise ConnectionResetError
                data += chunk
            return data

        try:
            head = receive(8)
        except TimeoutError:
            raise ConfigError(f"{not_dask}: it accepted the connection but sent no dask handshake within "
                              f"timeout_s={timeout_s:g} (the scheduler's port, 8786 by default, not its "
                              f"dashboard's?)", key=key) from None
        except OSError as exc:
            raise ConfigError(f"{not_dask}: it closed the connection without a dask handshake "
                              f"({exc.strerror or type(exc).__name__})", key=key) from None
        (length,) = struct.unpack("<Q", head)
        if not 0 < length <= HANDSHAKE_MAX_BYTES:
            try:
                sock.settimeout(0.2)
                head += sock.recv(64)
            except OSError:
                pass
            first = head.split(b"\n")[0].decode("ascii", "replace").strip()
            raise ConfigError(f"{not_dask}: it answered {first[:60]!r}, not the dask protocol", key=key)
        try:
            receive(length)
        except OSError:   # TimeoutError included
            raise ConfigError(f"{not_dask}: its first message did not arrive whole within "
                              f"timeout_s={timeout_s:g}", key=key) from None


@contextlib.contextmanager
def _quiet_dask_logs(quiet: bool) -> Iterator[None]:
    """Inside: dask's loggers silent (when ``quiet``), their levels restored after."""
    if not quiet:
        yield
        return
    names = ["distributed"] + [n for n in logging.root.manager.loggerDict if n.startswith("distributed.")]
    levels = {n: logging.getLogger(n).level for n in names}
    for n in names:
        logging.getLogger(n).setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        for n, level in levels.items():
            logging.getLogger(n).setLevel(level)


def _error_outcome(label: str, exc: BaseException, tb: Any) -> BaseException:
    """What a task that raised gives: its exception, a WorkerLostError (its workers kept dying).

    :raises ClusterError: the worker could not import what the task needs.
    """
    from distributed.scheduler import KilledWorker

    exc = exc.with_traceback(tb)
    if isinstance(exc, ClusterError):
        raise exc
    if isinstance(exc, KilledWorker):
        error = WorkerLostError(f"dask executor: {label} was given up because the workers running it "
                                f"kept dying ({exc})")
        error.__cause__ = exc
        return error
    return exc


@hookimpl
def suspid_register_executors(register):
    register(DaskExecutor)
