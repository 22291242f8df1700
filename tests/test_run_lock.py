"""One run per run directory (a lock between real processes) and one config per run directory."""

from __future__ import annotations

import json
import multiprocessing as mp
import signal
from pathlib import Path

import pytest

from suspid.errors import RunDirError, SuspidError
from suspid.infra.ledger import Evaluation, Ledger
from suspid.infra.lock import OWNER_FILE, RunLock, check_same_config, config_identity, open_run_dir

FORK = mp.get_context("fork")   # real processes, without the start-up time of a new interpreter


def _hold(run_dir: str, held, go) -> None:
    with open_run_dir(run_dir, config_name="alpha") as ledger:
        ledger.put(Evaluation("k1", {"x": 1.0}, J=1.0, psi=[1.0]))
        held.set()
        go.wait(timeout=60)                  # a long run: until the test lets it go


def assert_one_line(exc: BaseException, *fragments: str) -> None:
    msg = str(exc)
    assert isinstance(exc, SuspidError) and "\n" not in msg, msg
    for f in fragments:
        assert f in msg, f"{f!r} not in {msg!r}"


@pytest.fixture
def holder(tmp_path):
    """A second process that holds the run directory ``tmp_path/run`` (config 'alpha') until ``go`` is set."""
    held, go = FORK.Event(), FORK.Event()
    proc = FORK.Process(target=_hold, args=(str(tmp_path / "run"), held, go))
    proc.start()
    assert held.wait(timeout=60)
    proc.go = go
    yield proc
    if proc.is_alive():
        proc.kill()
    proc.join(timeout=10)


def test_a_second_process_is_refused_with_the_holders_pid_and_config(tmp_path, holder):
    run = tmp_path / "run"
    with pytest.raises(RunDirError) as err:
        RunLock(run, config_name="beta").acquire()
    assert_one_line(err.value, f"run directory {run} is in use by process {holder.pid} (config alpha)",
                    "wait for it or use another output.dir")


def test_fresh_is_refused_while_another_process_runs_and_deletes_nothing(tmp_path, holder):
    run = tmp_path / "run"
    with pytest.raises(RunDirError):
        with open_run_dir(run, config_name="alpha", fresh=True):
            pass
    assert Ledger(run / "ledger.sqlite").count() == 1          # the running process's result is still there


@pytest.mark.parametrize("how", ["released", "killed"])
def test_the_directory_is_free_once_the_holder_ends_however_it_ends(tmp_path, holder, how):
    if how == "released":
        holder.go.set()
    else:
        holder.kill()                                          # SIGKILL, no clean-up: the OS drops the lock
    holder.join(timeout=10)
    assert holder.exitcode == (0 if how == "released" else -signal.SIGKILL)
    assert (tmp_path / "run" / ".lock").exists()
    with open_run_dir(tmp_path / "run", config_name="alpha") as ledger:
        assert ledger.count() == 1                             # and resumes what the holder committed


def _contend(run_dir: str, start, done) -> str:
    try:
        lock = RunLock(run_dir, config_name="racer").acquire()
    except RunDirError as exc:
        start.wait(timeout=60)
        done.wait(timeout=60)
        return f"refused: {exc}"
    start.wait(timeout=60)                                     # hold until the other one has tried
    done.wait(timeout=60)
    lock.release()
    return "ran"


def _racer(run_dir, start, done, queue):
    start.wait(timeout=60)                                     # both try at the same moment
    queue.put(_contend(run_dir, start, done))


def test_two_processes_starting_together_exactly_one_runs(tmp_path):
    ctx = FORK
    start, done, queue = ctx.Barrier(3), ctx.Barrier(3), ctx.Queue()
    procs = [ctx.Process(target=_racer, args=(str(tmp_path / "run"), start, done, queue)) for _ in range(2)]
    for p in procs:
        p.start()
    start.wait(timeout=60)
    start.wait(timeout=60)
    done.wait(timeout=60)
    results = sorted(queue.get(timeout=60) for _ in procs)
    for p in procs:
        p.join(timeout=30)
    assert results[0] == "ran" and results[1].startswith("refused: run directory")
    assert "(config racer)" in results[1]


def _try(run_dir: str, queue) -> None:
    try:
        RunLock(run_dir).acquire()
        queue.put("acquired")
    except RunDirError as exc:
        queue.put(str(exc))


def test_the_lock_is_reentrant_in_one_process_and_records_the_holder(tmp_path):
    run = tmp_path / "run"
    with RunLock(run, config_name="alpha", config_digest="d1"):
        with RunLock(run, config_name="alpha"):                 # a nested call of the same run
            pass
        info = RunLock.holder(run)
        assert info["config_name"] == "alpha" and info["config_digest"] == "d1" and info["pid"] > 0
        queue = FORK.Queue()
        other = FORK.Process(target=_try, args=(str(run), queue))
        other.start()
        assert "is in use by process" in queue.get(timeout=60)   # still held after the inner exit
        other.join(timeout=10)
    assert RunLock.holder(run) == {}                            # released: no stale record


# ------------------------------------------------------------------------------------------ one config
ALPHA = config_identity("alpha", "/projects/a/alpha.yaml")


@pytest.mark.parametrize("owner, digest, force, refused", [
    (None, ALPHA, False, None),                                              # a new directory
    ({"config_digest": ALPHA}, ALPHA, False, None),                          # the same config resumes
    ({"config_digest": ALPHA}, config_identity("alpha", "/moved/alpha.yaml"), False, None),  # project moved
    ({"config_digest": ALPHA, "config_name": "alpha", "config_file": "alpha.yaml"},
     config_identity("beta", "beta.yaml"), False, "holds the run of another config 'alpha' (alpha.yaml)"),
    ({"config_digest": ALPHA, "config_name": "alpha"}, config_identity("alpha", "copy.yaml"), False,
     "holds the run of another config 'alpha'; use another output.dir, or --force to replace it"),
    ({"config_digest": ALPHA}, config_identity("beta"), True, None),        # --force takes it over
    ("{not json", ALPHA, False, "cannot read which config owns this run directory"),
    ("{not json", ALPHA, True, None),
])
def test_check_same_config(tmp_path, owner, digest, force, refused):
    run = tmp_path / "run"
    run.mkdir()
    if owner is not None:
        (run / OWNER_FILE).write_text(owner if isinstance(owner, str) else json.dumps(owner))
    before = (run / OWNER_FILE).read_bytes() if owner is not None else None
    if refused:
        with pytest.raises(RunDirError) as err:
            check_same_config(run, digest, force, config_name="beta")
        assert_one_line(err.value, refused)
        assert (run / OWNER_FILE).read_bytes() == before       # the owner record is kept
    else:
        check_same_config(run, digest, force, config_name="beta")
        assert json.loads((run / OWNER_FILE).read_text())["config_digest"] in (digest, ALPHA)


def test_fresh_on_another_configs_directory_is_refused_before_anything_is_cleared(tmp_path):
    run = tmp_path / "run"
    with open_run_dir(run, config_name="alpha", config_file="alpha.yaml") as ledger:
        ledger.put(Evaluation("k1", {"x": 1.0}, J=1.0, psi=[1.0]))
    with pytest.raises(RunDirError) as err:
        with open_run_dir(run, config_name="beta", config_file="beta.yaml", fresh=True):
            pass
    assert_one_line(err.value, f"run directory {run} holds the run of another config 'alpha'")
    assert Ledger(run / "ledger.sqlite").count() == 1
    with open_run_dir(run, config_name="beta", config_file="beta.yaml", fresh=True, force=True) as ledger:
        assert ledger.count() == 0


def test_fresh_sets_a_damaged_ledger_aside_inside_the_run(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    (run / "ledger.sqlite").write_text("this is not a ledger")
    with pytest.raises(SuspidError, match="not an SQLite database"):
        with open_run_dir(run, config_name="alpha"):
            pass
    said = []
    with open_run_dir(run, config_name="alpha", fresh=True, log=said.append) as ledger:
        assert ledger.count() == 0
    assert len(said) == 1 and "moved to" in said[0]
    assert len([p for p in run.iterdir() if ".damaged-" in p.name]) == 1


def test_a_run_directory_that_cannot_be_created_is_one_line(tmp_path):
    (tmp_path / "file").write_text("x")
    with pytest.raises(RunDirError) as err:
        RunLock(Path(tmp_path / "file" / "run")).acquire()
    assert_one_line(err.value, "cannot create the lock file of the run directory")
