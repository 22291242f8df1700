"""``suspid ingest``: from a long recording to segments in the documented measured-data layout.

Steps: read the mapped channels onto one time grid in SI units
(:mod:`~suspid.data.ingest.load`), check them (:mod:`~suspid.data.ingest.quality`),
align the track record (:mod:`~suspid.data.ingest.align`), cut segments at
quasi-constant speed (:mod:`~suspid.data.ingest.segment`), write the segments with
their provenance and the quality report (:mod:`~suspid.data.ingest.report`). The
output folder is touched only once the inputs have been read and checked, and
then the whole new set (segments, reports, figures) is written in a folder
beside the previous one and swapped in only once it is complete and read back
(:func:`staged_output`): an ingest that fails or is interrupted leaves the
previous one as it was.
"""

from __future__ import annotations

import contextlib
import difflib
import errno
import os
import shutil
import tempfile
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator, Sequence

import h5py
import numpy as np

import suspid
from suspid.data.files import (check_response, read_accelerations, read_track, write_accelerations_csv,
                               write_accelerations_h5, write_track_csv, write_track_h5)
from suspid.data.plausibility import CHECKS
from suspid.errors import ConfigError, DataError, DataWarning
from suspid.indicators.recordings import write_indicators
from suspid.infra.files import write_text
from suspid.interfaces import IRREGULARITY_CHANNELS, Response, Simulator, TrackSegment

from . import report as _report
from .align import Alignment, align
from .load import Recording, TrackRecord, read_recording, read_track_record
from .options import G, STATIC_G_TOLERANCE, IngestOptions, kind_of
from .quality import check_recording, check_track_record, excluded_mask
from .segment import Excluded, Window, cut

Log = Callable[[str], None]

CHECK_WORDS = {"dropouts": "dropout", "clipping": "clipping (saturated sensor)", "flat": "flat line",
               "spikes": "spikes"}


@dataclass
class IngestResult:
    """What :func:`suspid.ingest` did.

    :ivar out_dir: the output folder (``ingest.md``, ``ingest.json``, the figures, the segments).
    :ivar track_path: the track segments (``data.track_file`` of a measured-data config).
    :ivar measurements_path: the accelerations (``data.measurements``).
    :ivar offset_m: track distance = odometry distance + offset_m.
    :ivar peak_ratio: the alignment's confidence (correlation peak / highest other peak).
    :ivar segments: the names of the segments written.
    :ivar warnings: one line per problem of the quality report.
    :ivar report: the content of ``ingest.json``.
    :ivar reference: with ``reference:`` in the ingest file, the reference date's result (its own folder).
    :ivar config_path: with ``reference:``, the two-date config written (``two-dates.yaml``).
    :ivar config_warnings: with ``reference:``, what a run of that config will not assess for want of data
        (:func:`suspid.workflows.checks.data_shortfalls`: too few reference segments, no limits), one line each.
    """

    out_dir: Path
    track_path: Path
    measurements_path: Path
    offset_m: float
    peak_ratio: float
    segments: list[str]
    warnings: list[str]
    report: dict[str, Any] = field(repr=False, default_factory=dict)
    reference: "IngestResult | None" = None      # the reference date's ingest (two-date ingest)
    config_path: Path | None = None              # the two-date config written (two-date ingest)
    config_warnings: list[str] = field(default_factory=list)   # what a run of it will not assess

    def to_dict(self) -> dict[str, Any]:
        """Equals ``ingest.json``."""
        return self.report


def check_mapping(opts: IngestOptions, sim_channels: Sequence[str], simulator: str) -> None:
    """Every simulator channel is mapped, and only those."""
    mapped = opts.recording.channels
    missing = [c for c in sim_channels if c not in mapped]
    extra = [c for c in mapped if c not in sim_channels]
    if extra:   # first: a misspelt key is also a missing channel, and the key is what to correct
        close = difflib.get_close_matches(extra[0], missing, n=1)
        raise ConfigError(f"'{extra[0]}' is not a channel of simulator '{simulator}'"
                          f"{f' (did you mean {close[0]}?)' if close else ''}; its channels: "
                          f"{', '.join(sim_channels)}", key=f"recording.channels.{extra[0]}")
    if missing:
        raise ConfigError(f"no mapping for simulator channel(s) {', '.join(missing)} (simulator '{simulator}' "
                          f"has channels {', '.join(sim_channels)}); map each to a recorded channel, or "
                          f"configure the simulator's sensors to the recorded ones", key="recording.channels")


def check_rates(rec: Recording, opts: IngestOptions, f_max_hz: float) -> None:
    """Refuse a channel the file samples below the Nyquist rate of the spectra's top frequency.

    Interpolated onto the common grid such a channel would have no content between half its own rate
    and ``f_max_hz``, which the identification compares: a guess suspid does not make.

    :raises DataError: naming the channel, its rate and the rate needed.
    """
    for c in rec.channels:
        info = rec.info[c]
        if info.fs_file < 2.0 * f_max_hz * (1.0 - 1e-6):
            raise DataError(f"{opts.recording.path}: channel {c} ('{info.name}') is sampled at {info.fs_file:.4g} Hz, "
                            f"below 2 x spectra.f_max_hz = {2 * f_max_hz:.4g} Hz of the config: it holds nothing "
                            f"above {info.fs_file / 2:.4g} Hz and is not interpolated; lower spectra.f_max_hz to "
                            f"{info.fs_file / 2:.4g} Hz or less, or leave the channel out of the simulator's sensors")


def static_gravity(rec: Recording, opts: IngestOptions) -> list[str]:
    """Detect a static 1 g (or -1 g) on a vertical channel and remove it (in place), or refuse it.

    A vertical accelerometer that measures gravity reads about +-9.81 m/s^2 on average; the dynamic
    acceleration the identification compares has a zero mean. A mean within
    :data:`STATIC_G_TOLERANCE` of +-1 g is that offset: ``quality.strict`` refuses it, otherwise
    +-1 g (standard gravity) is subtracted and the residual mean reported.

    :returns: one warning per channel corrected.
    :raises DataError: ``quality.strict`` and a channel carries 1 g.
    """
    out = []
    for row, c in enumerate(rec.channels):
        if "vertical" not in c:
            continue
        a = rec.accelerations[row]
        mean = float(np.nanmean(a[:: max(1, a.size // 1_000_000)])) if np.isfinite(a).any() else 0.0
        if abs(abs(mean) - G) > STATIC_G_TOLERANCE * G:
            continue
        m = opts.recording.channels[c]
        sign = 1.0 if mean > 0 else -1.0
        if opts.quality.strict:
            raise DataError(f"{opts.recording.path}: channel {c} ('{m.name}') carries a static {sign:+.0f} g "
                            f"(mean {mean:.3f} m/s^2): remove gravity from it, or ingest without "
                            f"--strict (quality.strict) to have it removed")
        a -= sign * G
        out.append(f"channel {c} ('{m.name}'): a static {sign:+.0f} g (mean {mean:.3f} m/s^2) was removed "
                   f"(residual mean {mean - sign * G:.3f} m/s^2)")
    return out


def alignment_channel(opts: IngestOptions, channels: Sequence[str]) -> str | None:
    """``alignment.channel``, or the first mapped vertical axlebox, then bogie, channel."""
    if opts.alignment.channel is not None:
        if opts.alignment.channel not in channels:
            raise ConfigError(f"'{opts.alignment.channel}' is not a mapped channel; mapped: {', '.join(channels)}",
                              key="alignment.channel")
        return opts.alignment.channel
    for kind in ("axlebox", "bogie"):
        for c in channels:
            if kind_of(c, [kind]) and "vertical" in c:
                return c
    return None


def _motion_reasons(rec: Recording, opts: IngestOptions) -> dict[str, np.ndarray]:
    v = rec.speed
    return {"speed unknown (dropout of the speed or distance channel)": ~np.isfinite(v),
            f"below {opts.segments.min_speed_kmh:g} km/h (station, manoeuvre)":
                np.isfinite(v) & (v * 3.6 < opts.segments.min_speed_kmh)}


def design_reasons(rec: Recording, track: TrackRecord, offset: float, opts: IngestOptions) -> dict[str, np.ndarray]:
    """Reason -> ``(n,)`` samples whose track lies outside the curvature and cant limits of ``segments``."""
    seg = opts.segments
    out = {}
    x = rec.distance + offset
    for what, values, lo, hi, unit in (("curvature", track.curvature, seg.min_curvature_per_m,
                                        seg.max_curvature_per_m, "1/m"),
                                       ("cant", track.cant, seg.min_cant_m, seg.max_cant_m, "m")):
        if values is None or (lo is None and hi is None):
            continue
        a = np.abs(track.at(values, x))
        with np.errstate(invalid="ignore"):
            if hi is not None:
                key = "curvature_per_m" if what == "curvature" else "cant_m"
                out[f"|{what}| above segments.max_{key} = {hi:g} {unit}"] = a > hi
            if lo is not None:
                key = "curvature_per_m" if what == "curvature" else "cant_m"
                out[f"|{what}| below segments.min_{key} = {lo:g} {unit}"] = a < lo
    return out


def _track_segment(w: Window, name: str, rec: Recording, track: TrackRecord, offset: float, dx: float
                   ) -> TrackSegment | None:
    """The track under the odometry reference point during window ``w``, at its mean speed; None when
    the record does not cover it."""
    fs = rec.grid.fs
    duration = (w.i1 - w.i0) / fs
    v = (rec.distance[w.i1] - rec.distance[w.i0]) / duration if w.i1 < rec.distance.size else w.v_mean
    n = int(round(v * duration / dx)) + 1
    x = rec.distance[w.i0] + offset + np.arange(n) * dx
    n_src = track.irregularities.shape[1]
    k0, k1 = int(np.floor((x[0] - track.x0) / track.dx)), int(np.ceil((x[-1] - track.x0) / track.dx)) + 1
    if x[0] < track.x0 or k1 > n_src:
        return None
    x_src = track.x0 + np.arange(k0, k1) * track.dx       # the stretch of the record under the segment
    irr = np.array([np.interp(x, x_src, row[k0:k1]) for row in track.irregularities])
    if not np.all(np.isfinite(irr)):
        return None
    design = {k: np.interp(x, x_src, getattr(track, k)[k0:k1]) for k in ("curvature", "cant")
              if getattr(track, k) is not None}
    if not all(np.all(np.isfinite(d)) for d in design.values()):
        return None
    return TrackSegment(name, x - x[0], irr, float(v), meta={"track_start_m": float(x[0])}, **design)


def _provenance(rec: Recording, w: Window, seg: TrackSegment, al: Alignment) -> dict[str, Any]:
    g = rec.grid
    return {"source": str(rec.path), "source_format": rec.reader,
            "t_start_s": g.t0 + w.i0 / g.fs, "t_end_s": g.t0 + w.i1 / g.fs,
            "odometer_start_m": float(rec.distance[w.i0]), "track_start_m": seg.meta["track_start_m"],
            "offset_m": al.offset_m, "offset_peak_ratio": al.peak_ratio,
            "speed_min_mps": w.v_min, "speed_max_mps": w.v_max,
            "ingested_by": f"suspid {suspid.__version__}"}


def _with_provenance(tmp: Path, final: Path, prov: dict[str, Any]) -> None:
    """Move a written CSV to ``final`` (atomically) with ``# key: value`` provenance lines after the
    second comment line."""
    lines = tmp.read_text(encoding="utf-8").split("\n")
    extra = [f"# {k}: {v}" for k, v in prov.items()]
    write_text(final, "\n".join(lines[:2] + extra + lines[2:]))
    tmp.unlink()


def write_segments(opts: IngestOptions, out: Path, segs: list[TrackSegment], resps: list[Response],
                   provs: list[dict[str, Any]]) -> tuple[Path, Path]:
    """Write track and accelerations in the documented layout, with provenance; returns both paths.

    ``out`` is the staging folder of :func:`staged_output`, not the output folder itself.
    """
    out.mkdir(parents=True, exist_ok=True)
    if opts.output.format == "hdf5":
        paths = (out / "track.h5", out / "accelerations.h5")
        # the accelerations go straight to disk: an in-memory image would hold them twice more
        writers = (lambda p: write_track_h5(segs, p), lambda p: write_accelerations_h5(resps, p, in_memory=False))
        for path, write in zip(paths, writers):
            fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=out)
            os.close(fd)
            try:
                write(Path(tmp))
                with h5py.File(tmp, "a") as f:
                    f.attrs["source"] = str(opts.recording.path)
                    for s, prov in zip(segs, provs):
                        for k, v in prov.items():
                            f["segments"][s.name].attrs[k] = v
                os.replace(tmp, path)
            except BaseException:
                Path(tmp).unlink(missing_ok=True)
                raise
        return paths
    track_dir, acc_dir = out / "track", out / "accelerations"
    for d in (track_dir, acc_dir):
        d.mkdir(exist_ok=True)
    for s, r, prov in zip(segs, resps, provs):
        tmp = track_dir / f".{s.name}.csv.tmp"
        write_track_csv(s, tmp)
        _with_provenance(tmp, track_dir / f"{s.name}.csv", prov)
        tmp = acc_dir / f".{s.name}.csv.tmp"
        write_accelerations_csv(r, tmp)
        _with_provenance(tmp, acc_dir / f"{s.name}.csv", prov)
    return track_dir, acc_dir


OUTPUT_NAMES = ("track", "accelerations", "track.h5", "accelerations.h5", "ingest.json", "ingest.md",
                "speed.png", "alignment.png", "spectrogram_*.png")
"""What an ingest writes in its output folder (patterns): the set one ingest replaces by the next."""

STAGE_PREFIX, OLD_PREFIX = ".ingest-new-", ".ingest-old-"
_NO_ROOM = {getattr(errno, name) for name in ("ENOSPC", "EFBIG", "EDQUOT") if hasattr(errno, name)}


def _outputs(folder: Path) -> list[Path]:
    """The entries of ``folder`` that an ingest wrote (:data:`OUTPUT_NAMES`)."""
    return sorted({p for pattern in OUTPUT_NAMES for p in folder.glob(pattern)})


def swap_in(stage: Path, out: Path) -> None:
    """Replace the ingest outputs of ``out`` by those written in ``stage``, as one set.

    Everything was written and read back in ``stage`` (a folder inside ``out``,
    so on the same file system); the swap is renames only, which need no room
    on the disk: the previous set is moved into a ``.ingest-old-*`` folder, the
    new one moved in, then the previous one deleted. A rename that fails puts
    the previous set back, so ``out`` holds either the previous set or the new
    one, never a mix.
    """
    old = Path(tempfile.mkdtemp(prefix=OLD_PREFIX, dir=out))
    moved: list[tuple[Path, Path]] = []
    try:
        for p in _outputs(out):
            os.replace(p, old / p.name)
            moved.append((old / p.name, p))
        for p in sorted(stage.iterdir()):
            os.replace(p, out / p.name)
            moved.append((out / p.name, p))
    except BaseException:
        for now, before in reversed(moved):
            with contextlib.suppress(OSError):
                os.replace(now, before)
        with contextlib.suppress(OSError):
            old.rmdir()
        raise
    shutil.rmtree(old, ignore_errors=True)
    for left in [*out.glob(f"{STAGE_PREFIX}*"), *out.glob(f"{OLD_PREFIX}*")]:   # of an ingest killed earlier
        if left != stage:
            shutil.rmtree(left, ignore_errors=True)


@contextlib.contextmanager
def staged_output(out: Path) -> Iterator[Path]:
    """A new folder inside ``out`` to write a whole ingest in; swapped in (:func:`swap_in`) when the block ends
    without an error, deleted in every case, so that a failing or interrupted ingest leaves the previous
    segments and reports of ``out`` as they were. Warnings and errors raised in the block (the read-back's
    checks) name the files where they end up, in ``out``.

    :raises DataError: a write failed (a full disk, a file-size limit, permissions): one line naming ``out``.
    """
    try:
        out.mkdir(parents=True, exist_ok=True)
        stage = Path(tempfile.mkdtemp(prefix=STAGE_PREFIX, dir=out))
    except OSError as exc:
        raise DataError(f"{out}: cannot create the output folder ({exc.strerror or exc})") from None
    try:
        with warnings.catch_warnings(record=True) as caught:   # the read-back's: re-issued naming `out`
            yield stage
        for w in caught:
            warnings.warn_explicit(str(w.message).replace(str(stage), str(out)), w.category, w.filename, w.lineno)
        swap_in(stage, out)
    except (OSError, DataError) as exc:
        cause = exc if isinstance(exc, OSError) else exc.__cause__   # suspid's writers name the staged file
        if not isinstance(cause, OSError):
            if isinstance(exc, DataError) and str(stage) in str(exc):
                raise type(exc)(str(exc).replace(str(stage), str(out))) from None
            raise
        reason = (cause.strerror or str(cause)).lower() + (" (disk full or a file-size limit?)"
                                                           if cause.errno in _NO_ROOM else "")
        raise DataError(f"{out}: cannot write the ingest: {reason}; the previous segments and reports in it, "
                        f"if any, are kept") from None
    finally:
        shutil.rmtree(stage, ignore_errors=True)


def check_written(track_path: Path, acc_path: Path, segs: list[TrackSegment], resps: list[Response],
                  channels: Sequence[str]) -> None:
    """Read back what `suspid validate` and `suspid run` will read: every track segment, and the first
    record of accelerations (HDF5: the segment order), without holding all the records twice. The layout
    is checked, not the plausibility: the quality checks judged that on the recording (``quality.accept``)."""
    names = [s.name for s in segs]
    if acc_path.is_dir():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DataWarning)
            first = read_accelerations(acc_path / f"{names[0]}.csv", channels, accept=CHECKS)[0]
        order = sorted(p.stem for p in acc_path.glob("*.csv"))
    else:
        with h5py.File(acc_path, "r") as f:
            order = [o.decode() if isinstance(o, bytes) else str(o) for o in f["segments"].attrs["order"]]
        first = read_accelerations_h5_first(acc_path, names[0], channels)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        track_names = [s.name for s in read_track(track_path, accept=CHECKS)]
    if (track_names != names or sorted(order) != sorted(names)
            or first.accelerations.shape != resps[0].accelerations.shape):
        raise DataError(f"{acc_path}: the segments written could not be read back")


def read_accelerations_h5_first(path: Path, name: str, channels: Sequence[str]) -> Response:
    """One record of an accelerations HDF5 file, checked as the reader checks it."""
    with h5py.File(path, "r") as f:
        d = f["segments"][name]["accelerations"]
        names = [c.decode() if isinstance(c, bytes) else str(c) for c in f.attrs["channels"]]
        r = Response(tuple(names), float(d.attrs["fs_hz"]), np.asarray(d[()], dtype=float), name)
    return check_response(r, path, channels)


def run_ingest(opts: IngestOptions, simulator: Simulator, out: Path, log: Log = lambda s: None, *,
               f_max_hz: float | None = None) -> IngestResult:
    """The whole ingest (module docstring) for ``simulator``'s channels; ``out`` is the output folder.

    :param f_max_hz: the top frequency of the spectra the segments are for (``spectra.f_max_hz`` of the
        config): a channel the file samples at less than twice it is refused (:func:`check_rates`).
    """
    channels = list(simulator.channels())
    check_mapping(opts, channels, simulator.name)
    log(f"reading {opts.recording.path}")
    rec = read_recording(opts, channels)
    if f_max_hz is not None:
        check_rates(rec, opts, f_max_hz)
    warnings = list(rec.warnings)
    warnings += static_gravity(rec, opts)
    g = rec.grid
    v_min = opts.segments.min_speed_kmh / 3.6
    moving = np.isfinite(rec.speed) & (rec.speed >= v_min)
    total_moving = float(np.sum(np.diff(rec.distance)[moving[1:]])) if g.n > 1 else 0.0
    if total_moving < opts.segments.length_m:
        raise DataError(f"{opts.recording.path}: the recording covers {total_moving:.0f} m at "
                        f"{opts.segments.min_speed_kmh:g} km/h or more, shorter than one segment "
                        f"(segments.length_m = {opts.segments.length_m:g} m)")
    log("quality checks")
    quality, qwarn = check_recording(rec, opts, moving)
    warnings += qwarn
    bad_by = excluded_mask(quality, opts, g.fs, g.n)
    log(f"reading the track record {opts.track.path}")
    track, twarn = read_track_record(opts.track, IRREGULARITY_CHANNELS)
    warnings += twarn + check_track_record(track, opts)
    ach = alignment_channel(opts, channels)
    usable = moving & ~np.logical_or.reduce([np.zeros(g.n, bool), *bad_by.values()])
    log("aligning the track record")
    al = align(rec.distance, rec.speed, rec.accelerations[channels.index(ach)] if ach else np.full(g.n, np.nan),
               usable, track, opts.alignment, ach, v_min, simulator)
    if al.searched_m is not None and al.searched_m > opts.alignment.search_m:
        warnings.append(f"alignment: the correlation peak lay at the edge of the offsets searched "
                        f"(alignment.guess_m +- {opts.alignment.search_m:g} m); the search was widened to +- "
                        f"{al.searched_m:g} m and found offset {al.offset_m:.2f} m: check it, or set "
                        f"alignment.guess_m near it")
    if al.method == "correlation":
        if al.rho < 0:
            warnings.append(f"alignment: the correlation peak is negative ({al.rho:.2f}): is the sign of "
                            f"channel {ach} right?")
        if al.peak_ratio < opts.alignment.min_peak_ratio:
            raise DataError(f"{opts.track.path}: alignment is ambiguous: the correlation peak at offset "
                            f"{al.offset_m:.2f} m is only {al.peak_ratio:.2f} times the next one "
                            f"(alignment.min_peak_ratio = {opts.alignment.min_peak_ratio:g}); check the "
                            f"channel, alignment.lever_m and the track units, or give alignment.offset_m")
    x_src_end = track.x0 + (track.irregularities.shape[1] - 1) * track.dx
    reasons = _motion_reasons(rec, opts)
    for check, mask in bad_by.items():
        where = ", ".join(c for c, cq in quality.items() if len(cq.masks.get(check, ())))
        reasons[f"{CHECK_WORDS[check]} in {where}"] = mask
    reasons["outside the track record"] = ((rec.distance + al.offset_m < track.x0)
                                           | (rec.distance + al.offset_m > x_src_end))
    reasons.update(design_reasons(rec, track, al.offset_m, opts))
    windows, excluded = cut(rec.distance, rec.speed, reasons, opts.segments, g.fs)
    dx = opts.track.step_m or track.dx
    segs, resps, provs, kept = [], [], [], []
    width = max(3, len(str(len(windows))))
    for w in windows:
        name = f"{opts.segments.prefix}-{len(segs) + 1:0{width}d}"
        seg = _track_segment(w, name, rec, track, al.offset_m, dx)
        if seg is None:
            excluded.append(Excluded("track record has gaps or ends under this segment", w.i0, w.i1))
            continue
        segs.append(seg)
        resps.append(Response(tuple(channels), g.fs, rec.accelerations[:, w.i0:w.i1], name))   # a view
        provs.append(_provenance(rec, w, seg, al))
        kept.append(w)
    del track   # the segments hold what is written of it
    excluded.sort(key=lambda e: e.i0)
    if not segs:
        seconds: dict[str, float] = {}
        for e in excluded:
            seconds[e.reason] = seconds.get(e.reason, 0.0) + (e.i1 - e.i0) / g.fs
        why = "; ".join(f"{r} ({s:.0f} s)" for r, s in sorted(seconds.items(), key=lambda kv: -kv[1]))
        raise DataError(f"{opts.recording.path}: no segment of {opts.segments.length_m:g} m could be cut; "
                        f"excluded: {why or 'nothing usable'}")
    if (rec.speed[np.isfinite(rec.speed)] > 150).any():
        warnings.append(f"speed: above 540 km/h somewhere: is the declared unit "
                        f"'{(opts.recording.speed or opts.recording.distance).unit}' right?")
    log(f"writing {len(segs)} segments to {out}")
    with staged_output(out) as stage:    # the previous outputs of `out` are replaced only by a complete set
        staged_track, staged_acc = write_segments(opts, stage, segs, resps, provs)
        check_written(staged_track, staged_acc, segs, resps, channels)
        track_path, acc_path = out / staged_track.name, out / staged_acc.name
        rep = _report.build(opts, rec, quality, al, kept, segs, provs, excluded, warnings, track_path, acc_path,
                            out)
        figures = _report.figures(opts, rec, al, kept, excluded, stage) if opts.quality.figures else []
        rep["figures"] = [str(p.name) for p in figures]
        _report.write(rep, stage)
        write_indicators(stage, simulator, segs, resps)   # EN 14363 / EN 12299 of every ingested recording
    return IngestResult(out, track_path, acc_path, al.offset_m, al.peak_ratio, [s.name for s in segs],
                        warnings, rep)
