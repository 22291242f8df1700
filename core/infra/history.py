"""The history of a run directory: every run's own outputs kept, the latest one at the top.

A run directory (``output.dir``, default ``runs/<name>/``) is shared by every
run of a config of that name: the same config with another seed, more EGO
iterations, another objective. Each run is named by its *run id*,
:func:`run_id_of`: a digest of its resolved config (what ``config.yaml``
holds). Running the same config again gives the same id, so an interrupted run
resumes exactly; any change gives another id, and a run of its own.

Layout::

    <run dir>/ledger.sqlite          every evaluation of J of every run (content-keyed: shared)
    <run dir>/history/<run id>/      one run's config.yaml, noise_model.npz, result.json, report.md, PNGs
    <run dir>/result.json, ...       copies of the latest finished run's files (hard links where possible)
    <run dir>/latest.json            {"run_id", "history", "files", "finished"} of that run

A run writes only into its own ``history/<run id>/``; once it has finished,
:func:`publish` puts its files at the top of the run directory, each one
atomically, ``latest.json`` last. A finished run's files are never replaced by
another run's; only a run of the same config (the same id) writes them again.
The ledger keeps the optimiser records of every run apart
(:meth:`suspid.infra.ledger.Ledger.select_run`).

Run directories written before this history existed hold one run's outputs at
the top and no ``latest.json``: :func:`begin` first copies them into
``history/<their run id>/`` (the id of their ``config.yaml``).
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
import time
from pathlib import Path
from typing import Any, Mapping

import yaml

from suspid.infra.files import write_json
from suspid.infra.ledger import Ledger, stable_hash

HISTORY_DIR = "history"
LATEST_FILE = "latest.json"
RUN_OUTPUTS = ("config.yaml", "noise_model.npz", "result.json", "report.md", "*.png")
"""The files of one run (patterns), in its history folder and, for the latest run, at the top."""


def run_id_of(resolved: Mapping[str, Any]) -> str:
    """The run id of a resolved config (the mapping ``config.yaml`` holds): 12 hex digits of its digest."""
    return stable_hash("run", dict(resolved))[:12]


def history_dir(run_dir: str | Path, run_id: str) -> Path:
    """``<run dir>/history/<run id>/``: where the run ``run_id`` writes its outputs."""
    return Path(run_dir) / HISTORY_DIR / run_id


def latest(run_dir: str | Path) -> dict[str, Any] | None:
    """What ``latest.json`` records (the latest finished run), or None (no run finished, or unreadable)."""
    try:
        data = json.loads((Path(run_dir) / LATEST_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) and isinstance(data.get("run_id"), str) else None


def _outputs(folder: Path) -> list[Path]:
    return sorted({p for pattern in RUN_OUTPUTS for p in folder.glob(pattern) if p.is_file()})


def _link_or_copy(src: Path, dst: Path) -> None:
    """``dst`` becomes ``src``'s content atomically: a hard link (no second copy on the disk) or a copy,
    made under a temporary name beside ``dst`` and moved over it."""
    fd, tmp = tempfile.mkstemp(prefix=f".{dst.name}.", suffix=".tmp", dir=dst.parent)
    os.close(fd)
    try:
        os.unlink(tmp)
        try:
            os.link(src, tmp)
        except OSError:   # no hard links here (another file system, FAT, a share)
            shutil.copy2(src, tmp)
        os.replace(tmp, dst)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def _legacy_id(run_dir: Path) -> str | None:
    """The run id of the outputs at the top of a run directory written before the history (its config.yaml)."""
    try:
        resolved = yaml.safe_load((run_dir / "config.yaml").read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError):
        return None
    return run_id_of(resolved) if isinstance(resolved, dict) else None


def begin(run_dir: str | Path, run_id: str, ledger: Ledger) -> Path:
    """Before a run writes anything: keep the outputs of a run directory older than the history, select
    the run's records in the ledger; returns the run's own folder (created)."""
    run_dir = Path(run_dir)
    previous = None
    if latest(run_dir) is None and (run_dir / "result.json").is_file():   # a finished run of before the history
        previous = _legacy_id(run_dir) or "earlier"
        kept = history_dir(run_dir, previous)
        if not kept.exists():
            kept.mkdir(parents=True)
            for p in _outputs(run_dir):
                _link_or_copy(p, kept / p.name)
        _write_latest(run_dir, previous, [p.name for p in _outputs(kept)])
    elif latest(run_dir) is None:
        previous = _legacy_id(run_dir)   # an unfinished run of before the history: its ledger records
    ledger.select_run(run_id, previous)
    out = history_dir(run_dir, run_id)
    out.mkdir(parents=True, exist_ok=True)
    return out


def _write_latest(run_dir: Path, run_id: str, files: list[str]) -> None:
    write_json(run_dir / LATEST_FILE, {"run_id": run_id, "history": f"{HISTORY_DIR}/{run_id}", "files": files,
                                       "finished": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())})


def publish(run_dir: str | Path, run_id: str) -> None:
    """Put a finished run's files at the top of the run directory (each atomically, ``latest.json`` last);
    the previous latest run's files that this run has not are removed from the top (its history keeps them)."""
    run_dir = Path(run_dir)
    own = history_dir(run_dir, run_id)
    files = [p.name for p in _outputs(own)]
    for name in files:
        _link_or_copy(own / name, run_dir / name)
    before = latest(run_dir)
    stale = set(before.get("files", []) if before else []) - set(files)
    for name in sorted(stale):
        if Path(name).name == name and (run_dir / HISTORY_DIR / before["run_id"] / name).is_file():
            with contextlib.suppress(OSError):
                (run_dir / name).unlink()
    _write_latest(run_dir, run_id, files)
