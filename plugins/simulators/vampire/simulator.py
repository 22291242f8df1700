"""The ``vampire`` simulator: Vampire (or any program with the same contract) through files.

One run is one parameter vector on one segment:

1. a fresh working directory ``<work_root>/<segment>-<hash>``, the hash being
   of everything the run depends on (templates, options, w, segment data);
2. the template directory rendered into it, the track file written;
3. the command run there (argument list, no shell, time limit, process tree
   killed on timeout), stdout and stderr saved to files;
4. success: exit code 0, no error pattern in the logs, the export and every
   expected output present and non-empty, the export readable and sane;
5. the export read into a :class:`~suspid.interfaces.Response`.

Runs of one call's segments go in parallel up to ``max_concurrent`` (licence
seats); the seats are shared by every call on one simulator instance.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
import shutil
import sys
import tempfile
import threading
import time
from concurrent.futures import FIRST_EXCEPTION, ThreadPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Mapping, Sequence

import numpy as np

from suspid.errors import ConfigError, SimulatorError
from suspid.options import parse_options
from suspid.interfaces import Parameter, Response, Simulator, TrackSegment

from . import export as export_mod
from .options import RESERVED_NAMES, RUN_INFO_NAME, STDERR_NAME, STDOUT_NAME, Options
from .runner import run_command
from .templates import TemplateSet, check_names, inside, load_templates, render, scan
from .trackfile import check_segment, track_rows, write_track_file

_IDENTITY_EXCLUDE = {"work_root", "keep_workdirs", "max_concurrent", "timeout_s", "kill_grace_s", "on_error",
                     "template_dir"}
"""Options that do not change results, left out of :meth:`VampireSimulator.identity`. The
template directory enters through the digest of its files, not its path, so a project moved
elsewhere keeps its cached results."""


class _Cancelled(Exception):
    """A run stopped because another run of the same call failed (on_error: raise)."""


class _KeyedLocks:
    """One lock per key, so that two runs with identical inputs never share a directory at once."""

    def __init__(self) -> None:
        self._guard = threading.Lock()
        self._locks: dict[str, list] = {}

    def __call__(self, key: str):
        locks = self

        class _Held:
            def __enter__(self_inner):
                with locks._guard:
                    entry = locks._locks.setdefault(key, [threading.Lock(), 0])
                    entry[1] += 1
                entry[0].acquire()

            def __exit__(self_inner, *exc):
                with locks._guard:
                    entry = locks._locks[key]
                    entry[0].release()
                    entry[1] -= 1
                    if entry[1] == 0:
                        del locks._locks[key]

        return _Held()


_WORKDIR_LOCKS = _KeyedLocks()
_CLASS_LOCK = threading.Lock()


@dataclass
class _Job:
    index: int
    segment: TrackSegment
    workdir: Path
    key: str
    values: dict[str, str]
    rows: np.ndarray
    w: dict[str, float]


def _slug(text: str) -> str:
    slug = re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("._")[:40]
    return slug or "segment"


def _tail(path: Path, n_lines: int = 5, n_chars: int = 400) -> str:
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return ""
    tail = " | ".join(line.strip() for line in text.strip().splitlines()[-n_lines:])
    return tail[-n_chars:]


class VampireSimulator(Simulator):
    """Vampire (Vampire Pro) as a black box through templates, a command line and an ASCII export.

    Options: :class:`~suspid.plugins.simulators.vampire.options.Options`;
    documentation: ``docs/vampire.md``. Parameters and channels are declared
    in the options (the adapter knows nothing of the vehicle); parameter
    values are SI, accelerations come back in m/s² at the export's rate.
    """

    name: ClassVar[str] = "vampire"
    Options: ClassVar[type] = Options

    # -- validated state (built on first use; constructors only store) --------------------
    def _opts(self) -> Options:
        opts = self.__dict__.get("_opts_")
        if opts is None:
            opts = parse_options(Options, dict(self.options), "simulator.options")
            self.__dict__["_opts_"] = opts
        return opts

    def _templates(self) -> TemplateSet:
        tset = self.__dict__.get("_templates_")
        if tset is None:
            opts = self._opts()
            tset = load_templates(opts.template_dir, opts.template_encoding, opts.copy_only)
            self._check_templates(opts, tset)
            self.__dict__["_templates_"] = tset
        return tset

    @staticmethod
    def _check_templates(opts: Options, tset: TemplateSet) -> None:
        known = opts.template_values()
        header_uses = [(n, f"track.header[{i}]", 1) for i, line in enumerate(opts.track.header)
                       for n, _ in scan(line, f"track.header[{i}]")]
        check_names(tset.uses() + header_uses, known)
        for p in opts.parameters:
            if p.template_name not in tset.names:
                raise ConfigError(f"parameter '{p.name}' has no placeholder '{{{{ {p.template_name} }}}}' in any "
                                  f"file of {tset.root}; it would not change the run",
                                  key="simulator.options.parameters")
        if "fs" in tset.names and opts.fs is None:
            use = next((u for u in tset.uses() if u[0] == "fs"))
            raise ConfigError("the templates use '{{ fs }}' but the option fs is not set", file=use[1], line=use[2])
        relpaths = {f.relpath for f in tset.files}
        for rel, what in [(opts.track.file, "track.file"), *[(r, "reserved") for r in RESERVED_NAMES]]:
            if rel in relpaths:
                raise ConfigError(f"the template directory has a file '{rel}' that the adapter writes itself "
                                  f"({what}); rename one of them", file=str(tset.root / rel))

    def _seats(self) -> threading.BoundedSemaphore:
        with _CLASS_LOCK:
            seats = self.__dict__.get("_seats_")
            if seats is None:
                seats = threading.BoundedSemaphore(self._opts().max_concurrent)
                self.__dict__["_seats_"] = seats
        return seats

    def _work_root(self) -> Path:
        with _CLASS_LOCK:
            root = self.__dict__.get("_work_root_")
            if root is None:
                opts = self._opts()
                if opts.work_root is not None:
                    root = Path(opts.work_root).resolve()
                    root.mkdir(parents=True, exist_ok=True)
                else:
                    root = Path(tempfile.mkdtemp(prefix="suspid-vampire-")).resolve()
                self.__dict__["_work_root_"] = root
        return root

    def __getstate__(self) -> dict[str, Any]:
        """Pickle only the options (locks and semaphores do not cross processes)."""
        return {"options": self.options}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)

    # -- Simulator interface ----------------------------------------------------------------
    def parameters(self) -> list[Parameter]:
        """The parameters declared in the options, SI units."""
        return [Parameter(p.name, p.unit, p.nominal, p.lower, p.upper, p.description)
                for p in self._opts().parameters]

    def channels(self) -> list[str]:
        """The channel names declared in the options, in order."""
        return [c.name for c in self._opts().channels]

    def identity(self) -> dict[str, Any]:
        """Plugin name, result-relevant options (JSON) and the SHA-256 of the template directory's files."""
        opts = self._opts()
        return {"plugin": self.name,
                "options": opts.model_dump(mode="json", exclude=_IDENTITY_EXCLUDE),
                "templates": self._templates().digest}

    def simulate(self, w: Mapping[str, float], segments: Sequence[TrackSegment]) -> list[Response]:
        """Run the command once per segment with parameters ``w`` (SI; others nominal).

        :returns: one Response per segment, in order, accelerations
            ``(n_channels, n_t)`` in m/s².
        :raises SimulatorError: when a run fails, naming the segment, the
            working directory and the file or exit status to blame. With
            ``on_error: raise`` the first failure stops the call's other runs
            (killed, not started); with ``finish`` they complete first and the
            message lists every failure.
        :raises ConfigError: for unknown parameter names or template problems.
        :raises DataError: for a segment the adapter cannot run.
        """
        opts = self._opts()
        self._templates()
        values = self._values(w, opts)
        identity = self.identity()
        jobs = [self._job(i, seg, values, opts, identity) for i, seg in enumerate(segments)]
        if not jobs:
            return []
        cancel = threading.Event()
        results: list[Response | None] = [None] * len(jobs)
        errors: list[tuple[int, SimulatorError]] = []
        pool = ThreadPoolExecutor(max_workers=min(opts.max_concurrent, len(jobs)),
                                  thread_name_prefix="suspid-vampire")
        try:
            futures = {pool.submit(self._run_job, job, cancel, opts): job for job in jobs}
            pending = set(futures)
            while pending:
                done, pending = wait(pending, return_when=FIRST_EXCEPTION)
                for fut in done:
                    job = futures[fut]
                    try:
                        results[job.index] = fut.result()
                    except _Cancelled:
                        pass
                    except SimulatorError as exc:
                        errors.append((job.index, exc))
                        if opts.on_error == "raise":
                            cancel.set()
        except BaseException:
            cancel.set()  # KeyboardInterrupt or an unexpected error: stop every run of this call
            raise
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
        if errors:
            errors.sort(key=lambda e: e[0])
            first = errors[0][1]
            if len(errors) == 1:
                raise first
            others = "; ".join(str(e) for _, e in errors[1:])
            raise SimulatorError(f"{first} [+{len(errors) - 1} more failed: {others}]") from first
        return [r for r in results if r is not None]

    # -- one run -------------------------------------------------------------------------------
    def _values(self, w: Mapping[str, float], opts: Options) -> dict[str, float]:
        known = {p.name for p in opts.parameters}
        unknown = sorted(set(w) - known)
        if unknown:
            raise ConfigError(f"unknown parameter(s) {', '.join(unknown)} for simulator 'vampire'; known: "
                              f"{', '.join(sorted(known))}")
        values = {}
        for p in opts.parameters:
            v = float(w.get(p.name, p.nominal))
            if not math.isfinite(v):
                raise SimulatorError(f"parameter '{p.name}' = {v!r} is not finite")
            values[p.name] = v
        return values

    def _job(self, index: int, segment: TrackSegment, w: dict[str, float], opts: Options,
             identity: dict[str, Any]) -> _Job:
        check_segment(segment)
        rows = track_rows(segment, opts.track)
        speed = float(np.mean(segment.speed))
        x = np.asarray(segment.distance, dtype=float)
        h = hashlib.sha256()
        h.update(json.dumps([identity, {k: repr(v) for k, v in sorted(w.items())},
                             segment.name, repr(speed)], sort_keys=True).encode())
        for arr in (x, np.asarray(segment.irregularities, dtype=float)):
            h.update(np.ascontiguousarray(arr, dtype="<f8").tobytes())
        key = h.hexdigest()
        workdir = self._work_root() / f"{_slug(segment.name)}-{key[:16]}"
        fmt = opts.number_format
        values: dict[str, str] = {}
        for p in opts.parameters:
            values[p.template_name] = format(w[p.name] * p.scale, p.format or fmt)
        for k, v in opts.values.items():
            values[k] = format(v, fmt) if isinstance(v, float) else str(v)
        builtins: dict[str, Any] = {
            "segment": segment.name, "speed": speed, "speed_kmh": speed * 3.6,
            "duration": segment.duration(), "length": segment.length,
            "x_start": float(rows[0, 0]), "x_end": float(rows[-1, 0]), "dx": segment.dx,
            "n_track_rows": len(rows), "run_file": opts.run_file or "", "track_file": opts.track.file,
            "export_file": opts.export.file, "workdir": str(workdir),
        }
        if opts.fs is not None:
            builtins["fs"] = opts.fs
        for k, v in builtins.items():
            values[k] = format(v, fmt) if isinstance(v, float) else str(v)
        return _Job(index, segment, workdir, key, values, rows, w)

    def _command(self, job: _Job, opts: Options) -> tuple[list[str], dict[str, str]]:
        wd = job.workdir
        fields = {
            "python": sys.executable, "workdir": str(wd), "template_dir": str(Path(opts.template_dir).resolve()),
            "run_file": opts.run_file or "", "run_path": str(wd / opts.run_file) if opts.run_file else "",
            "track_file": opts.track.file, "track_path": str(wd / opts.track.file),
            "export_file": opts.export.file, "export_path": str(wd / opts.export.file),
            "segment": job.segment.name,
        }
        argv = [arg.format(**fields) for arg in opts.command]
        env = dict(os.environ)
        env.update({k: v.format(**fields) for k, v in opts.env.items()})
        return argv, env

    def _prepare(self, job: _Job, opts: Options) -> None:
        wd = job.workdir
        if wd.exists():
            shutil.rmtree(wd)  # a stale directory of an interrupted run with the same inputs
        wd.mkdir(parents=True)
        self._templates().render_into(wd, job.values)
        header = [render(line, job.values, f"track.header[{i}]") for i, line in enumerate(opts.track.header)]
        write_track_file(inside(wd, opts.track.file), job.rows, opts.track, header, opts.template_encoding)

    def _run_job(self, job: _Job, cancel: threading.Event, opts: Options) -> Response:
        seg = job.segment.name
        wd = job.workdir
        with _WORKDIR_LOCKS(str(wd)):
            if cancel.is_set():
                raise _Cancelled()
            seats = self._seats()
            while not seats.acquire(timeout=0.1):
                if cancel.is_set():
                    raise _Cancelled()
            outcome = "failed"
            try:
                try:
                    self._prepare(job, opts)
                    argv, env = self._command(job, opts)
                    info = {"segment": seg, "w": job.w, "argv": argv, "env_overrides": list(opts.env),
                            "key": job.key, "started_at": time.time()}
                    (wd / RUN_INFO_NAME).write_text(json.dumps(info, indent=1))
                    result = run_command(argv, wd, env, opts.timeout_s, wd / STDOUT_NAME, wd / STDERR_NAME,
                                         grace_s=opts.kill_grace_s, kill_leftovers=opts.kill_leftovers,
                                         cancel=cancel)
                except OSError as exc:
                    raise SimulatorError(f"cannot prepare or start the run: {exc}") from None
                finally:
                    seats.release()
                if result.cancelled:
                    outcome = "cancelled"
                    raise _Cancelled()
                response = self._check(job, result, opts)
                outcome = "ok"
                return response
            except SimulatorError as exc:
                kept = opts.keep_workdirs in ("always", "failed")
                where = f"workdir {wd}" + ("" if kept else ", removed")
                raise SimulatorError(f"vampire run for segment '{seg}' failed: {exc} ({where})") from None
            finally:
                keep = opts.keep_workdirs == "always" or (opts.keep_workdirs == "failed" and outcome == "failed")
                if not keep and wd.exists():
                    shutil.rmtree(wd, ignore_errors=True)

    def _check(self, job: _Job, result, opts: Options) -> Response:
        wd = job.workdir
        if result.timed_out:
            raise SimulatorError(f"timed out after {opts.timeout_s:g} s; process tree killed "
                                 f"(stderr: {result.stderr})")
        if result.returncode != 0:
            tail = _tail(result.stderr) or _tail(result.stdout)
            raise SimulatorError(f"exit code {result.returncode}" + (f"; end of output: {tail!r}" if tail else ""))
        self._scan_logs(wd, [result.stdout, result.stderr], opts)
        outputs = [opts.export.file, *opts.expected_outputs]
        for rel in outputs:
            matches = sorted(wd.glob(rel)) if any(c in rel for c in "*?[") else [wd / rel]
            if not matches or not matches[0].exists():
                raise SimulatorError(f"expected output '{rel}' is missing in {wd}")
            for path in matches:
                inside(wd, str(path.relative_to(wd)))
                if path.is_file() and path.stat().st_size == 0:
                    raise SimulatorError(f"{path}: expected output is empty")
        columns = [c.column for c in opts.channels]
        data = export_mod.read_export(inside(wd, opts.export.file), opts.export, columns)
        return export_mod.to_response(data, opts.channels, opts.export, job.segment, opts.fs)

    @staticmethod
    def _scan_logs(wd: Path, logs: list[Path], opts: Options) -> None:
        patterns = [re.compile(p) for p in opts.error_patterns]
        files = list(logs)
        for rel in opts.log_files:
            files += sorted(p for p in wd.glob(rel) if p.is_file())
        for path in files:
            try:
                text = path.read_text(encoding="utf-8", errors="replace")
            except OSError:
                continue
            for lineno, line in enumerate(text.splitlines(), 1):
                for pat in patterns:
                    if pat.search(line):
                        raise SimulatorError(f"{path}:{lineno}: error pattern {pat.pattern!r} matches "
                                             f"{line.strip()[:200]!r}")

