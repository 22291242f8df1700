"""Executors: serial, processes and dask give the same results; dead workers; no process left.

Task functions live at module level (here or in ``suspid.testing``) so that
worker processes can import them by reference: spawned workers, the pool's and
the LocalCluster's, start with the driver's ``sys.path``, which holds this
folder. The quarter-car workload adds the template's ``src`` folder to
``sys.path`` itself in the workers (in the driver the ``quarter_car`` fixture
does).
"""

from __future__ import annotations

import multiprocessing
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from suspid import registry
from suspid.errors import ConfigError, PluginError
from suspid.plugins.executors._common import WorkerLostError
from suspid.testing import DieOnce, check_executor, collect, square
from suspid.plugins.executors.dask import DaskExecutor, DaskOptions, scheduler_address
from suspid.plugins.executors.processes import ProcessExecutor, ProcessOptions, default_workers
from suspid.plugins.executors.serial import SerialExecutor
from suspid.method.spectra import compute_spectra
from suspid.testing import sample_segments

TEMPLATE_SRC = str(Path(__file__).resolve().parents[1] / "examples" / "plugin-template" / "src")
SPECTRA = {"f_min_hz": 0.5, "f_max_hz": 20.0, "n_freqs": 60}
"""Spectra grid of the workload: 0.33 Hz cells, about 10 lines each on 30 s records."""

PARALLEL = [(ProcessExecutor, {"workers": 2}), (DaskExecutor, {"n_workers": 2})]


# -- workload and tasks (module level: pickled by reference) ------------------------------------
class QuarterCarJ:
    """J(w) = -mean over samples, channels, frequencies of (Y(w) - Y(w_ref))², dB².

    Y are the spectra (``suspid.method.spectra``) of the template's quarter car run
    over ``segments``; the object carries the segments and Y(w_ref), so an
    executor has to ship data to its workers too.
    """

    def __init__(self, segments, w_ref: dict[str, float]):
        self.segments = segments
        self.y_ref = self.spectra(w_ref)

    def spectra(self, w: dict[str, float]) -> np.ndarray:
        """``(n_segments, 2, 60)`` in dB."""
        if TEMPLATE_SRC not in sys.path:  # a worker process
            sys.path.append(TEMPLATE_SRC)
        from suspid_quartercar import QuarterCar

        y, _ = compute_spectra(QuarterCar().simulate(w, self.segments), SPECTRA)
        return y

    def __call__(self, w: dict[str, float]) -> float:
        return float(-np.mean((self.spectra(w) - self.y_ref) ** 2))


def die_on_negative(item: tuple[float, float]) -> float:
    """Item ``(delay_s, x)``: after ``delay_s`` seconds, ``x * x``, or for a negative ``x`` the end of its process."""
    delay_s, x = item
    time.sleep(delay_s)
    if x < 0:
        os._exit(1)
    return x * x


class KillerAndNeighbour:
    """Items ``"killer"``, ``"neighbour"`` or anything else (returned at once), with no timing assumptions.

    Attempts are counted with files in ``folder``. On its first two attempts
    the neighbour sleeps (it is ended with the pool) and the killer ends its
    process as soon as the neighbour of the same attempt runs: both are lost
    together. Later, the neighbour returns ``"neighbour"`` at once and the
    killer ends its process at once.
    """

    def __init__(self, folder: str | os.PathLike):
        self.folder = str(folder)

    def _attempt(self, who: str) -> int:
        n = 1
        while True:
            try:
                with open(os.path.join(self.folder, f"{who}-{n}"), "x"):
                    return n
            except FileExistsError:
                n += 1

    def __call__(self, who: str) -> str:
        if who not in ("killer", "neighbour"):
            return who
        n = self._attempt(who)
        if who == "neighbour":
            if n <= 2:
                time.sleep(60)
            return who
        deadline = time.monotonic() + 30
        while n <= 2 and not os.path.exists(os.path.join(self.folder, f"neighbour-{n}")):
            if time.monotonic() > deadline:
                return "the neighbour never came"
            time.sleep(0.01)
        os._exit(1)


@pytest.fixture
def workload(quarter_car):
    """``(task, design)``: the quarter-car J and 10 parameter vectors in the default parameters' bounds."""
    bounds = {p.name: (p.lower, p.upper) for p in quarter_car().parameters()}
    names = quarter_car().default_parameters()
    rng = np.random.default_rng(9)
    design = [{n: float(rng.uniform(*bounds[n])) for n in names} for _ in range(10)]
    w_ref = {p.name: p.nominal for p in quarter_car().parameters() if p.name in names}
    return QuarterCarJ(sample_segments(2, length_m=1500.0, speed_mps=50.0), w_ref), design


# -- no process left behind ------------------------------------------------------------------------
def _children() -> dict[int, str]:
    """Child processes of this one: pid -> command line (multiprocessing's resource tracker left out)."""
    kids = {p.pid: p.name for p in multiprocessing.active_children()}
    proc = Path("/proc")
    if proc.is_dir():
        me = os.getpid()
        for entry in proc.iterdir():
            if not entry.name.isdigit():
                continue
            try:
                stat = (entry / "stat").read_text()
                ppid = int(stat.rsplit(")", 1)[1].split()[1])
                cmd = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            except (OSError, ValueError, IndexError):
                continue  # ended meanwhile
            if ppid == me:
                kids[int(entry.name)] = cmd
    return {pid: cmd for pid, cmd in kids.items() if "resource_tracker" not in cmd}


@pytest.fixture(autouse=True)
def no_leftover_processes():
    """Every test must end every process it started (dask workers, pool workers)."""
    before = set(_children())
    yield
    deadline = time.monotonic() + 15.0
    while True:
        left = {pid: cmd for pid, cmd in _children().items() if pid not in before}
        if not left or time.monotonic() > deadline:
            break
        time.sleep(0.1)
    assert not left, f"processes left behind: {left}"


# -- registration and options ----------------------------------------------------------------------
def test_executors_registered_through_entry_points():
    assert registry.get("executor", "serial") is SerialExecutor
    assert registry.get("executor", "processes") is ProcessExecutor
    assert registry.get("executor", "dask") is DaskExecutor
    _, failures = registry.plugins()
    assert [f.name for f in failures if f.name in {"serial", "processes", "dask"}] == []


def test_dask_module_does_not_import_dask():
    code = ("import sys, suspid.plugins.executors.dask; "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in {'dask', 'distributed'}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


def test_options_defaults_and_errors():
    assert ProcessOptions().workers == default_workers() >= 1
    assert ProcessExecutor().n_workers == default_workers()
    assert DaskOptions().threads_per_worker == 1 and DaskOptions().processes is True
    with pytest.raises(ConfigError, match=r"executor\.options\.workers"):
        ProcessExecutor(workers=0).__enter__()
    with pytest.raises(ConfigError, match=r"executor\.options\.nope"):
        ProcessExecutor(nope=1).n_workers
    with pytest.raises(ConfigError, match=r"executor\.options\.adress"):
        DaskExecutor(adress="tcp://x:1").__enter__()
    for cls in (ProcessExecutor, DaskExecutor):
        with pytest.raises(RuntimeError, match="entered"):
            cls().map_unordered(square, [1])


def test_scheduler_address_order(monkeypatch):
    for var in ("SUSPID_DASK_SCHEDULER", "DASK_SCHEDULER_ADDRESS"):
        monkeypatch.delenv(var, raising=False)
    assert scheduler_address(DaskOptions()) == (None, "LocalCluster")
    monkeypatch.setenv("DASK_SCHEDULER_ADDRESS", "tcp://b:8786")
    assert scheduler_address(DaskOptions()) == ("tcp://b:8786", "DASK_SCHEDULER_ADDRESS")
    monkeypatch.setenv("SUSPID_DASK_SCHEDULER", "tcp://a:8786")
    assert scheduler_address(DaskOptions()) == ("tcp://a:8786", "SUSPID_DASK_SCHEDULER")
    assert scheduler_address(DaskOptions(address="tcp://c:8786")) == ("tcp://c:8786", "executor.options.address")


def test_dask_without_distributed_says_what_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # makes `import distributed` fail
    with pytest.raises(PluginError, match=r"pip install 'suspid\[dask\]'"):
        DaskExecutor().__enter__()


def test_dask_unreachable_scheduler_is_a_config_error():
    with pytest.raises(ConfigError, match=r"cannot connect to the dask scheduler at tcp://127\.0\.0\.1:9 "
                                          r"\(from executor\.options\.address\)"):
        DaskExecutor(address="tcp://127.0.0.1:9", timeout_s=1).__enter__()
    with pytest.raises(ConfigError, match="allowed_failures applies to a LocalCluster only"):
        DaskExecutor(address="tcp://127.0.0.1:9", allowed_failures=1).__enter__()


# -- conformance -----------------------------------------------------------------------------------
@pytest.mark.parametrize("cls, options, worker_death", [(SerialExecutor, {}, False),
                                                        *[(c, o, True) for c, o in PARALLEL]],
                         ids=["serial", "processes", "dask"])
def test_conformance(cls, options, worker_death):
    check_executor(cls, options, worker_death=worker_death)


# -- the same J values on a real workload, also when a worker dies ---------------------------------
@pytest.mark.parametrize("cls, options", PARALLEL, ids=["processes", "dask"])
def test_same_J_as_serial_also_after_a_worker_dies(cls, options, workload, tmp_path):
    task, design = workload
    with SerialExecutor() as serial:
        expected = collect(serial, task, design)
    assert all(isinstance(j, float) and j <= 0.0 for j in expected.values()), expected
    assert len(set(expected.values())) == len(design)  # the workload does depend on w
    with cls(**options) as executor:
        assert executor.n_workers == 2
        assert collect(executor, task, design) == expected  # exactly, not approximately
        dies = DieOnce(task, victim=4, marker=tmp_path / "died")
        assert collect(executor, dies, list(enumerate(design))) == expected
    assert (tmp_path / "died").exists()


# -- a task that kills every worker it runs on is given up, with its index -------------------------
def test_processes_gives_up_on_a_task_that_always_kills_its_worker(tmp_path):
    items = ["neighbour", "killer", "other"]
    with ProcessExecutor(workers=2, max_retries=1) as executor:
        got = collect(executor, KillerAndNeighbour(tmp_path), items)
        assert collect(executor, square, [4.0]) == {0: 16.0}  # the pool still works afterwards
    # lost twice together, over max_retries=1: each run again on its own; only the killer dies alone
    assert isinstance(got[1], WorkerLostError), got
    assert "task 1 was lost 3 times" in str(got[1]) and "max_retries=1" in str(got[1])
    assert got[0] == "neighbour" and got[2] == "other"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["killer-1", "killer-2", "killer-3",
                                                           "neighbour-1", "neighbour-2", "neighbour-3"]


def test_dask_gives_up_on_a_task_that_always_kills_its_worker():
    items = [(0.0, 1.0), (0.0, 2.0), (0.3, -1.0)]  # the killer last: no task waits behind it on its worker
    with DaskExecutor(n_workers=2, allowed_failures=1, timeout_s=30) as executor:
        got = collect(executor, die_on_negative, items)
    assert isinstance(got[2], WorkerLostError) and "task 2 was given up" in str(got[2]), got
    assert got[0] == 1.0 and got[1] == 4.0


def test_dask_local_workers_run_without_the_profiler_unless_asked():
    import dask

    for profile in (False, True):
        with DaskExecutor(n_workers=1, timeout_s=30, **({"profile": True} if profile else {})) as executor:
            seen = executor.client_.run(dask.config.get, "distributed.worker.profile.enabled")
        assert list(seen.values()) == [profile]


# -- an existing scheduler: from the environment, resources ----------------------------------------
def test_dask_existing_scheduler_from_env_and_resources(monkeypatch):
    from distributed import LocalCluster

    # threads, not processes: quick to start, and nothing here is CPU-bound
    with LocalCluster(n_workers=1, threads_per_worker=2, processes=False, dashboard_address=":0",
                      resources={"seat": 1}) as cluster:
        monkeypatch.setenv("SUSPID_DASK_SCHEDULER", cluster.scheduler_address)
        with DaskExecutor() as executor:
            assert executor.cluster_ is None  # connected, not started
            assert executor.n_workers == 2  # threads
            assert collect(executor, square, [1, 2, 3]) == {0: 1, 1: 4, 2: 9}
        with DaskExecutor(resources={"seat": 1}) as executor:
            assert executor.n_workers == 1  # one seat
            assert collect(executor, square, [1, 2, 3]) == {0: 1, 1: 4, 2: 9}
        with pytest.raises(ConfigError, match=r"no worker .* holds the resources licence=1"):
            DaskExecutor(resources={"licence": 1}, timeout_s=5).__enter__()
        assert len(cluster.scheduler_info["workers"]) == 1  # still there: not ours to close
