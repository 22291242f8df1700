"""Track and acceleration files: CSV and HDF5 readers and writers, and their checks.

Why one module of about 900 lines: this is the documented data layout of
suspid, and the readers and writers of both formats share every check
(shapes, rates, duplicates, plausibility); keeping them together keeps the
layout, its checks and their wording in one place. Its sections follow the
layout: CSV, HDF5, checks, writers.

CSV layout, one file per segment
--------------------------------
Track segment (``*.csv``)::

    # suspid track segment
    # name: seg-001
    # speed_mps: 83.333
    distance_m,vertical_m,lateral_m,cross_level_m,gauge_m
    0.00,0.0012,-0.0003,0.0001,0.0
    0.25,...

- UTF-8 text (a byte-order mark, as spreadsheet programs write, is skipped).
- ``#`` lines before the header are comments; ``# key: value`` lines give
  metadata: ``name`` (default: the file name without extension) and
  ``speed_mps`` (constant speed, m/s).
- The header names the columns; order is free. Required: ``distance_m`` and
  the four channels ``vertical_m``, ``lateral_m``, ``cross_level_m``,
  ``gauge_m``, all in metres. Optional: ``speed_mps``, a speed record (one
  value per distance sample, variable speed); the speed must come from this
  column or from the metadata. Optional: ``curvature_per_m`` (design
  curvature 1 / radius, 1/m, positive for a left-hand curve) and ``cant_m``
  (design cant, m, right rail above the left), the ``TrackSegment.curvature``
  and ``cant`` of curved track (straight, untilted track without them).
- Distance increases with a uniform step (relative tolerance 1e-6); at least
  two rows; every value finite.

Measured (or simulated) accelerations (``*.csv``)::

    # suspid accelerations
    # segment: seg-001
    # fs_hz: 100
    time_s,carbody_front_vertical,carbody_front_lateral,...
    0.00,0.013,-0.002,...

- Columns: one per channel, in m/s^2, named by the channel; an optional
  ``time_s`` column (s, uniformly increasing from the first sample).
- The sampling rate comes from ``# fs_hz:`` or from the ``time_s`` column;
  with both they must agree (relative 1e-6). ``segment`` defaults to the
  file name without extension.

HDF5 layout
-----------
Track (``format = "suspid-track"``)::

    /                         attrs: format, version = 1
    /segments                 attrs: order = segment names in order
    /segments/<name>/distance        (n_x,) m
    /segments/<name>/irregularities  (4, n_x) m; attrs: channels = IRREGULARITY_CHANNELS
    /segments/<name>/speed           () or (n_x,) m/s
    /segments/<name>/curvature       (n_x,) 1/m, optional (as curvature_per_m of the CSV layout)
    /segments/<name>/cant            (n_x,) m, optional (as cant_m)

Files are written in the HDF5 1.10 format (readable by HDF5 >= 1.10), whose
metadata carry checksums, and array datasets with a Fletcher-32 checksum
(chunked), so that a damaged byte is found when the file is read, not taken
for data. Files without checksums (written by other programs) are read too,
but a damaged one may then read as plausible numbers, and damaged metadata of
the older format can even make the HDF5 library loop forever.

Accelerations (``format = "suspid-accelerations"``)::

    /                         attrs: format, version = 1, channels = channel names
    /segments                 attrs: order = segment names in order
    /segments/<name>/accelerations   (n_channels, n_t) m/s^2; attrs: fs_hz

A simulation file (``simulation.h5``, :mod:`suspid.workflows.simulate`) is an
accelerations file with, in addition, ``/y`` (n_segments, n_channels,
n_freqs) dB and ``/freqs`` (n_freqs,) Hz.

Checks
------
Every reader raises :class:`suspid.errors.DataError` with one line naming the
file (and the segment, dataset or attribute) for a malformed file: unreadable
or damaged, wrong types (an HDF5 attribute or dataset that is not what the
layout says, complex or text data), non-finite values, non-uniform steps, and
a segment name given twice (two files, or an HDF5 ``order`` listing it twice:
a record counted twice would double its weight in J, and a second track of
the same name would replace the first).

Records of one data set must share one sampling rate (relative 0.5 %,
:data:`FS_TOLERANCE`): a rate a little off shifts every spectrum in frequency.

Plausibility (:func:`check_plausibility`, run by every reader, the policy of
:mod:`suspid.data.plausibility`). Values beyond :data:`ABSURD` (1e6 in SI
units) cannot come from a sensor: a damaged file (flipped bits) is an error.
Values no train in service can give are an error naming the file, the channel
and what was expected, unless the check is named in ``accept``
(``data.accept`` of a config): an acceleration channel vibrating beyond its
kind's limit (mm/s^2 read as m/s^2), a constant or dead channel, a track
channel beyond any track open to traffic in the D1 band (mm read as m), a
speed above the rail speed record (km/h read as m/s). Values that are
possible but unusual give a :class:`suspid.errors.DataWarning` (one line
``warning: ...`` in the command line), or an error with ``strict=True``.
"""
from __future__ import annotations

import csv
import errno
import io
import math
import os
import shutil
from pathlib import Path
from typing import Any, Collection, Iterable, Sequence

import numpy as np

from suspid.data.plausibility import (ABSURD, Doubt, acceleration_doubts, d1_rms, judge, speed_doubts, speed_statistic,
                                      track_doubts, vibration_rms)
from suspid.errors import DataError
from suspid.infra.arrays import check_bytes, check_fits, check_text, declared, human_bytes
from suspid.infra.files import atomic_open, write_text
from suspid.interfaces import IRREGULARITY_CHANNELS, Response, TrackSegment

CSV_TRACK_COLUMNS = ("distance_m", "vertical_m", "lateral_m", "cross_level_m", "gauge_m")
"""Required columns of a track CSV file (channels in the order of IRREGULARITY_CHANNELS)."""

FS_TOLERANCE = 0.005
"""Relative tolerance on the sampling rates of the records of one data set."""


# ---------------------------------------------------------------------------------------------- checks
def _fail(path: Path | str, message: str) -> DataError:
    return DataError(f"{path}: {message}")


def _os_reason(exc: OSError) -> str:
    """The reason of an OSError without the path it repeats (``permission denied``)."""
    return (exc.strerror or str(exc).splitlines()[0] or type(exc).__name__).lower()


def _show(value: Any, limit: int = 40) -> str:
    """A short printable form of a value from a file (one line, at most ``limit`` characters)."""
    text = value.decode(errors="replace") if isinstance(value, bytes) else str(value)
    text = repr(text[:limit] + ("..." if len(text) > limit else ""))
    return text


def check_segment(seg: TrackSegment, where: Path | str) -> TrackSegment:
    """Validate a track segment's arrays; raises DataError naming ``where``."""
    x = np.asarray(seg.distance, dtype=float)
    irr = np.asarray(seg.irregularities, dtype=float)
    v = np.asarray(seg.speed, dtype=float)
    if x.ndim != 1 or x.size < 2:
        raise _fail(where, f"segment '{seg.name}': at least 2 distance samples are needed, got {x.size}")
    if irr.shape != (len(IRREGULARITY_CHANNELS), x.size):
        raise _fail(where, f"segment '{seg.name}': irregularities of shape {irr.shape} do not match "
                           f"{len(IRREGULARITY_CHANNELS)} channels x {x.size} distance samples")
    if not np.all(np.isfinite(x)) or not np.all(np.isfinite(irr)):
        raise _fail(where, f"segment '{seg.name}': NaN or inf in distance or irregularities")
    step = np.diff(x)
    if not np.all(step > 0):
        i = int(np.flatnonzero(step <= 0)[0])
        raise _fail(where, f"segment '{seg.name}': distance must increase, but sample {i + 1} "
                           f"({x[i + 1]:g} m) follows {x[i]:g} m")
    if np.ptp(step) > 1e-6 * abs(step.mean()):
        raise _fail(where, f"segment '{seg.name}': distance step must be uniform, it varies from "
                           f"{step.min():g} to {step.max():g} m")
    if v.ndim not in (0, 1) or (v.ndim == 1 and v.size != x.size):
        raise _fail(where, f"segment '{seg.name}': speed must be a number or one value per distance sample "
                           f"({x.size}), got shape {v.shape}")
    if not np.all(np.isfinite(v)) or np.any(v <= 0):
        raise _fail(where, f"segment '{seg.name}': speed must be positive and finite")
    for label, values in (("curvature", seg.curvature), ("cant", seg.cant)):
        if values is None:
            continue
        a = np.asarray(values, dtype=float)
        if a.shape != x.shape or not np.all(np.isfinite(a)):
            raise _fail(where, f"segment '{seg.name}': {label} must be one finite value per distance sample "
                               f"({x.size}), got shape {a.shape}")
    return seg


def check_response(r: Response, where: Path | str, channels: Sequence[str] | None = None) -> Response:
    """Validate a record of accelerations; with ``channels``, reorder to them (missing ones raise)."""
    a = np.asarray(r.accelerations, dtype=float)
    if a.ndim != 2 or a.shape[0] != len(r.channels):
        raise _fail(where, f"segment '{r.segment}': accelerations of shape {a.shape} do not match "
                           f"{len(r.channels)} channels")
    if a.shape[1] < 2:
        raise _fail(where, f"segment '{r.segment}': at least 2 samples are needed")
    if not (math.isfinite(r.fs) and r.fs > 0):
        raise _fail(where, f"segment '{r.segment}': sampling rate must be positive, got {r.fs!r}")
    if not np.all(np.isfinite(a)):
        ch, j = np.argwhere(~np.isfinite(a))[0]
        raise _fail(where, f"segment '{r.segment}': NaN or inf in channel '{r.channels[ch]}' at sample {j}")
    if len(set(r.channels)) != len(r.channels):
        raise _fail(where, f"segment '{r.segment}': repeated channel names")
    if channels is not None:
        missing = [c for c in channels if c not in r.channels]
        if missing:
            raise _fail(where, f"segment '{r.segment}': missing channel(s) {', '.join(missing)}")
        idx = [list(r.channels).index(c) for c in channels]
        r = Response(tuple(channels), float(r.fs), a[idx], r.segment)
    return r


def _absurd(where: Path | str, label: str, channel: str, values: np.ndarray, unit: str) -> None:
    big = np.abs(values) > ABSURD
    if big.any():
        j = int(np.flatnonzero(big)[0])
        raise _fail(where, f"{label}: channel '{channel}' holds {values[j]:.3g} {unit} at sample {j}, "
                           f"beyond any sensor (|value| > {ABSURD:g}): a damaged file?")


def _doubts_response(r: Response, where: Path | str) -> list[Doubt]:
    label = f"segment '{r.segment}'"
    a = np.asarray(r.accelerations, dtype=float)
    doubts = []
    for name, values in zip(r.channels, a):
        _absurd(where, label, name, values, "m/s^2")
        doubts += [Doubt(f"{label}: {d.message}", d.check)
                   for d in acceleration_doubts(name, vibration_rms(values), bool(np.ptp(values) == 0))]
    return doubts


def _doubts_segment(seg: TrackSegment, where: Path | str) -> list[Doubt]:
    label = f"segment '{seg.name}'"
    irr = np.asarray(seg.irregularities, dtype=float)
    x = np.asarray(seg.distance, dtype=float)
    for name, values in zip(IRREGULARITY_CHANNELS, irr):
        _absurd(where, label, name, values, "m")
    found = [d for name, values in zip(IRREGULARITY_CHANNELS, irr)
             for d in track_doubts(name, d1_rms(values, float(x[1] - x[0])))]
    found = ([d for d in found if d.check] or found)[:1]     # one channel says it: the unit of the file
    doubts = [Doubt(f"{label}: {d.message}", d.check) for d in found]
    doubts += [Doubt(f"{label}: {d.message}", d.check)
               for d in speed_doubts(speed_statistic(seg.speed))]
    return doubts


def check_plausibility(item: TrackSegment | Response, where: Path | str, *, strict: bool = False,
                       accept: Collection[str] = ()) -> list[str]:
    """Check that a validated segment or record holds values a sensor on a train can give.

    Called by every reader; call it yourself on data made in memory. The policy and its limits are
    :mod:`suspid.data.plausibility`'s.

    :param item: a track segment (irregularities in m, speed in m/s) or a record (m/s^2).
    :param where: the file (or a label) the messages name.
    :param strict: unusual values raise DataError instead of a warning.
    :param accept: checks whose impossible values are used anyway, with a warning (``data.accept``).
    :returns: the messages of the warnings issued (each sent once as a
        :class:`~suspid.errors.DataWarning`).
    :raises DataError: a value beyond :data:`ABSURD` (a damaged file), an impossible value whose check
        is not accepted, or with ``strict`` an unusual one; one line naming ``where``.
    """
    doubts = _doubts_response(item, where) if isinstance(item, Response) else _doubts_segment(item, where)
    return judge(doubts, where, accept=accept, strict=strict)


def check_unique_segments(items: Iterable[tuple[Path | str, str]], what: str = "segment") -> None:
    """Refuse a segment name given twice.

    A record given twice would count twice in J; of two tracks with one name only one could be used.

    :param items: ``(file, segment name)`` in reading order.
    :raises DataError: naming the second file, the segment and the first file.
    """
    seen: dict[str, Path | str] = {}
    for where, name in items:
        if name in seen:
            raise _fail(where, f"{what} '{name}' is also in {seen[name]}: each segment may be given once")
        seen[name] = where


def check_same_rate(records: Sequence[tuple[Path | str, Response]]) -> None:
    """Refuse records of one data set whose sampling rates differ by more than :data:`FS_TOLERANCE`.

    :raises DataError: naming the file, the rate found and the rate of the first record.
    """
    if not records:
        return
    f0, r0 = records[0]
    for f, r in records[1:]:
        if abs(r.fs - r0.fs) > FS_TOLERANCE * r0.fs:
            raise _fail(f, f"segment '{r.segment}': sampling rate {r.fs:g} Hz differs by "
                           f"{100 * abs(r.fs / r0.fs - 1):.3g} % from the {r0.fs:g} Hz of segment "
                           f"'{r0.segment}' in {f0}; the records of one data set share one rate "
                           f"(within {100 * FS_TOLERANCE:g} %): a wrong fs_hz?")


def _written(path: Path, write: Any) -> Path:
    """Run ``write()`` (an atomic write of ``path``); an OSError becomes one DataError line."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write()
    except OSError as exc:
        raise _fail(path, f"cannot write the file ({_os_reason(exc)})") from exc
    return path


# ---------------------------------------------------------------------------------------------- CSV
CSV_MEMORY_FACTOR = 6
"""Bytes :func:`_read_csv` holds per byte of the file at most: the text, its lines, the rows as Python floats
(about 32 bytes for 10 characters of text), the array."""


def _read_csv(path: Path) -> tuple[dict[str, str], list[str], np.ndarray]:
    """Metadata, header and values (float array rows x columns) of a suspid CSV file.

    A file that is not text (NUL bytes), or too large for the memory available, is refused before it is read.
    """
    try:
        size = check_text(path, "a suspid CSV file: # metadata lines, a header, rows of numbers")
        check_bytes(str(path), f"reading its {human_bytes(size)} of text", size * CSV_MEMORY_FACTOR)
        text = path.read_text(encoding="utf-8-sig")   # -sig: skip the byte-order mark spreadsheets write
    except FileNotFoundError:
        raise _fail(path, "file not found") from None
    except IsADirectoryError:
        raise _fail(path, "is a folder, not a file") from None
    except UnicodeDecodeError as exc:
        raise _fail(path, f"not UTF-8 text (byte 0x{exc.object[exc.start]:02x} at position {exc.start}); "
                          f"save it as UTF-8") from None
    except OSError as exc:
        raise _fail(path, f"cannot read the file ({_os_reason(exc)})") from None
    meta: dict[str, str] = {}
    lines = text.splitlines()
    i = 0
    while i < len(lines) and (not lines[i].strip() or lines[i].lstrip().startswith("#")):
        body = lines[i].lstrip().lstrip("#").strip()
        if ":" in body:
            key, value = body.split(":", 1)
            meta[key.strip()] = value.strip()
        i += 1
    if i >= len(lines):
        raise _fail(path, "no header line (column names) found")
    reader = csv.reader(io.StringIO("\n".join(lines[i:])))
    n = i + 1
    try:
        header = [h.strip() for h in next(reader)]
        if len(set(header)) != len(header):
            raise _fail(path, f"repeated column names in the header: {header}")
        rows = []
        for n, row in enumerate(reader, start=i + 2):
            if not row or all(not c.strip() for c in row):
                continue
            if len(row) != len(header):
                raise _fail(path, f"line {n}: {len(row)} values, but the header has {len(header)} columns")
            try:
                rows.append([float(c) for c in row])
            except ValueError:
                bad = next(c for c in row if not _is_float(c))
                raise _fail(path, f"line {n}: {_show(bad.strip())} is not a number") from None
    except csv.Error as exc:
        raise _fail(path, f"line {n}: not CSV ({exc})") from None
    values = np.array(rows, dtype=float).reshape(len(rows), len(header))
    return meta, header, values


def _is_float(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False


def read_track_csv(path: str | Path, *, strict: bool = False,
                   accept: Collection[str] = ()) -> TrackSegment:
    """Read one track segment from a CSV file (layout and checks in the module docstring).

    :param strict: unusual values raise DataError instead of a warning (:func:`check_plausibility`).
    :param accept: checks whose impossible values are used anyway (``data.accept``; :func:`check_plausibility`).
    """
    path = Path(path)
    meta, header, values = _read_csv(path)
    missing = [c for c in CSV_TRACK_COLUMNS if c not in header]
    if missing:
        raise _fail(path, f"missing column(s) {', '.join(missing)}; required: {', '.join(CSV_TRACK_COLUMNS)}")
    col = {h: values[:, i] for i, h in enumerate(header)}
    if not np.all(np.isfinite(values)):
        r, c = np.argwhere(~np.isfinite(values))[0]
        raise _fail(path, f"NaN or inf in column '{header[c]}' at data row {r + 1}")
    if "speed_mps" in col:
        speed: float | np.ndarray = col["speed_mps"].copy()
        if "speed_mps" in meta:
            raise _fail(path, "speed given twice (metadata and column speed_mps)")
    elif "speed_mps" in meta:
        try:
            speed = float(meta["speed_mps"])
        except ValueError:
            raise _fail(path, f"speed_mps '{meta['speed_mps']}' is not a number") from None
    else:
        raise _fail(path, "no speed: add a '# speed_mps: <m/s>' line or a speed_mps column")
    irr = np.array([col[c] for c in CSV_TRACK_COLUMNS[1:]])
    seg = TrackSegment(meta.get("name", path.stem), col["distance_m"].copy(), irr, speed,
                       meta={"file": str(path)}, curvature=_optional(col, "curvature_per_m"),
                       cant=_optional(col, "cant_m"))
    check_segment(seg, path)
    check_plausibility(seg, path, strict=strict, accept=accept)
    return seg


def _optional(col: dict[str, np.ndarray], name: str) -> np.ndarray | None:
    return col[name].copy() if name in col else None


def write_track_csv(segment: TrackSegment, path: str | Path) -> Path:
    """Write one track segment as CSV (layout in the module docstring), atomically; returns the path."""
    path = Path(path)
    check_segment(segment, path)
    x = np.asarray(segment.distance, dtype=float)
    irr = np.asarray(segment.irregularities, dtype=float)
    v = np.asarray(segment.speed, dtype=float)
    columns = list(CSV_TRACK_COLUMNS)
    data = [x, *irr]
    lines = ["# suspid track segment", f"# name: {segment.name}"]
    if v.ndim == 0:
        lines.append(f"# speed_mps: {float(v)!r}")
    else:
        columns.append("speed_mps")
        data.append(v)
    for name, values in (("curvature_per_m", segment.curvature), ("cant_m", segment.cant)):
        if values is not None:
            columns.append(name)
            data.append(np.asarray(values, dtype=float))
    lines.append(",".join(columns))
    table = np.column_stack(data)
    lines += [",".join(repr(float(c)) for c in row) for row in table]
    return _written(path, lambda: write_text(path, "\n".join(lines) + "\n"))


def read_accelerations_csv(path: str | Path, channels: Sequence[str] | None = None, *,
                           strict: bool = False,
                           accept: Collection[str] = ()) -> Response:
    """Read one record of accelerations from a CSV file (layout and checks in the module docstring).

    :param channels: expected channels; the record is reordered to them and a
        missing one raises DataError.
    :param strict: unusual values raise DataError instead of a warning (:func:`check_plausibility`).
    :param accept: checks whose impossible values are used anyway (``data.accept``; :func:`check_plausibility`).
    """
    path = Path(path)
    meta, header, values = _read_csv(path)
    names = [h for h in header if h != "time_s"]
    if not names:
        raise _fail(path, "no channel columns")
    if values.shape[0] < 2:
        raise _fail(path, f"at least 2 samples are needed, got {values.shape[0]}")
    fs = None
    if "fs_hz" in meta:
        try:
            fs = float(meta["fs_hz"])
        except ValueError:
            raise _fail(path, f"fs_hz '{meta['fs_hz']}' is not a number") from None
        if not (math.isfinite(fs) and fs > 0):
            raise _fail(path, f"fs_hz must be positive, got {meta['fs_hz']}")
    if "time_s" in header:
        t = values[:, header.index("time_s")]
        if not np.all(np.isfinite(t)):
            raise _fail(path, "NaN or inf in column 'time_s'")
        dt = np.diff(t)
        if not np.all(dt > 0):
            i = int(np.flatnonzero(dt <= 0)[0])
            raise _fail(path, f"time must increase, but sample {i + 1} ({t[i + 1]:g} s) follows {t[i]:g} s")
        if np.ptp(dt) > 1e-6 * dt.mean():
            raise _fail(path, f"time step must be uniform, it varies from {dt.min():g} to {dt.max():g} s")
        fs_t = 1.0 / dt.mean()
        if fs is not None and abs(fs_t - fs) > 1e-6 * fs:
            raise _fail(path, f"fs_hz = {fs:g} disagrees with the time column ({fs_t:g} Hz)")
        fs = fs_t
    if fs is None:
        raise _fail(path, "no sampling rate: add a '# fs_hz: <Hz>' line or a time_s column")
    a = np.array([values[:, header.index(n)] for n in names])
    r = check_response(Response(tuple(names), float(fs), a, meta.get("segment", path.stem)), path, channels)
    check_plausibility(r, path, strict=strict, accept=accept)
    return r


def write_accelerations_csv(response: Response, path: str | Path, with_time: bool = True) -> Path:
    """Write one record of accelerations as CSV (layout in the module docstring), atomically; returns the path."""
    path = Path(path)
    check_response(response, path)
    a = np.asarray(response.accelerations, dtype=float)
    lines = ["# suspid accelerations", f"# segment: {response.segment}", f"# fs_hz: {float(response.fs)!r}"]
    columns = (["time_s"] if with_time else []) + list(response.channels)
    lines.append(",".join(columns))
    data = a.T
    if with_time:
        data = np.column_stack([np.arange(a.shape[1]) / response.fs, data])
    lines += [",".join(repr(float(c)) for c in row) for row in data]
    return _written(path, lambda: write_text(path, "\n".join(lines) + "\n"))


# ---------------------------------------------------------------------------------------------- HDF5
TRACK_FORMAT = "suspid-track"
ACCELERATIONS_FORMAT = "suspid-accelerations"
FORMAT_VERSION = 1


def _h5():
    """h5py, imported on first use: reading CSV files does not need it."""
    import h5py

    return h5py


def _describe(value: Any) -> str:
    if isinstance(value, (str, bytes)):
        return f"the text {_show(value)}"
    a = np.asarray(value)
    return f"{a.dtype} values of shape {a.shape}" if a.ndim else f"{_show(value)} ({a.dtype})"


def _text(value: Any) -> str | None:
    """A text attribute as str, or None when it is not text."""
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value[()]
    if isinstance(value, bytes):
        return value.decode(errors="replace")
    return str(value) if isinstance(value, str) else None


def _text_list(value: Any, path: Path, what: str) -> list[str]:
    """A list-of-names attribute (one text is a list of one); anything else raises naming ``what``."""
    if value is None:
        return []
    one = _text(value)
    if one is not None:
        return [one]
    a = np.asarray(value)
    items = [_text(v) for v in a.ravel()] if a.dtype.kind in "OSU" else [None]
    if a.ndim != 1 or any(v is None for v in items):
        raise _fail(path, f"{what} must be a list of names, got {_describe(value)}")
    return [v for v in items if v is not None]


def _attr_float(attrs: Any, key: str, path: Path, where: str) -> float:
    value = attrs[key]
    a = np.asarray(value)
    if a.dtype.kind not in "iuf" or a.size != 1:
        raise _fail(path, f"{where}: attribute '{key}' must be one real number, got {_describe(value)}")
    return float(a.reshape(()))


def _fits_shape(shape: Sequence[int], pattern: Sequence[int | None]) -> bool:
    """``shape`` is ``pattern``, whose None entries stand for any length."""
    return len(shape) == len(pattern) and all(p is None or p == s for s, p in zip(shape, pattern))


def _dataset(group: Any, key: str, path: Path, shapes: Sequence[tuple[int | None, ...]] = (), meaning: str = ""
             ) -> np.ndarray:
    """The real-valued contents of ``group[key]``; anything else raises naming the dataset.

    Its declared shape is checked before it is read: against ``shapes`` (the shapes it may have, given the
    segment's other datasets; ``meaning`` says what the axes are) and, as float64, against the memory available
    (:func:`suspid.infra.arrays.check_fits`): a damaged file's absurd shape is one error, not an allocation.
    """
    h5py = _h5()
    where = f"{group.name}/{key}"
    if key not in group:
        raise _fail(path, f"segment '{group.name.rsplit('/', 1)[-1]}': missing dataset '{key}'")
    d = group[key]
    if not isinstance(d, h5py.Dataset):
        raise _fail(path, f"{where} is a group, expected a dataset")
    kind = d.dtype.kind
    if kind == "c":
        raise _fail(path, f"{where}: complex values ({d.dtype}); expected real numbers")
    if kind not in "iuf":
        raise _fail(path, f"{where}: values of type {d.dtype} (not numbers); expected real numbers")
    if shapes and not any(_fits_shape(d.shape, s) for s in shapes):
        shown = " or ".join("(" + ", ".join("n" if a is None else str(a) for a in s) + (",)" if len(s) == 1 else ")")
                            for s in shapes)
        raise _fail(path, f"{where} declares {declared(d.shape, d.dtype)}, expected shape {shown} ({meaning})")
    check_fits(str(path), f"dataset {where}", d.shape, np.float64)
    return np.asarray(d[()], dtype=float)


def _open(path: Path, fmt: str) -> Any:
    h5py = _h5()
    try:
        f = h5py.File(path, "r")
    except FileNotFoundError:
        raise _fail(path, "file not found") from None
    except IsADirectoryError:
        raise _fail(path, "is a folder, not a file") from None
    except PermissionError:   # (h5py's own text repeats the path over several clauses)
        raise _fail(path, "cannot read the file (permission denied)") from None
    except OSError as exc:
        raise _fail(path, f"not a readable HDF5 file ({str(exc).splitlines()[0]})") from None
    try:
        raw = f.attrs.get("format")
        found = _text(raw)
        if raw is None:
            raise _fail(path, f"no format attribute at the root, expected '{fmt}'")
        if found != fmt:
            raise _fail(path, f"format attribute is {_show(found) if found is not None else _describe(raw)}, "
                              f"expected '{fmt}'")
        if not isinstance(f.get("segments"), h5py.Group):
            raise _fail(path, "no /segments group")
    except BaseException as exc:
        _close(f)
        if isinstance(exc, _H5_FAULTS):
            raise _damaged(path, exc) from exc
        raise
    return f


_H5_FAULTS = (OSError, KeyError, RuntimeError, TypeError, ValueError)
"""What h5py raises, anywhere, on a damaged file (truncated, flipped bits)."""


def _damaged(path: Path, exc: BaseException) -> DataError:
    detail = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    return _fail(path, f"damaged or unreadable HDF5 file ({type(exc).__name__}: {detail})")


def _close(f: Any) -> None:
    try:
        f.close()
    except Exception:   # closing a damaged file can fail too; the error being raised names it
        pass


class _Reading:
    """``with _Reading(path, fmt) as f``: an open HDF5 file whose low-level errors become one DataError.

    A damaged file (truncated, flipped bits) can fail anywhere inside h5py with
    OSError, KeyError, RuntimeError, TypeError or ValueError; each names the file.
    """

    def __init__(self, path: Path, fmt: str) -> None:
        self.path, self.fmt = path, fmt

    def __enter__(self) -> Any:
        self.f = _open(self.path, self.fmt)
        return self.f

    def __exit__(self, kind: Any, exc: BaseException | None, tb: Any) -> bool:
        _close(self.f)
        if isinstance(exc, _H5_FAULTS):
            raise _damaged(self.path, exc) from exc
        return False


def _order(f: Any, path: Path) -> list[str]:
    group = f["segments"]
    order = _text_list(group.attrs.get("order"), path, "/segments attribute 'order'")
    names = set(group.keys())
    if not order:
        return sorted(names)
    seen: dict[str, int] = {}
    for i, name in enumerate(order):
        if name in seen:
            raise _fail(path, f"/segments attribute 'order' lists segment '{name}' twice (entries {seen[name] + 1} "
                              f"and {i + 1}): each segment may be given once")
        seen[name] = i
    missing = [n for n in order if n not in names]
    if missing:
        raise _fail(path, f"/segments order names segment(s) that are absent: {', '.join(missing)}")
    unlisted = sorted(names - set(order))
    if unlisted:
        raise _fail(path, f"/segments holds segment(s) that its 'order' attribute does not list: "
                          f"{', '.join(unlisted)}")
    return order


def _write_h5(path: Path, fill: Any, append: bool = False, size: int | None = None) -> Path:
    """Write an HDF5 file atomically: built in memory by ``fill(f)``, then written by ``atomic_open``.

    In memory (h5py's ``core`` driver), because h5py's own writes to disk fail
    badly on a full disk: an error while closing, then a crash (SIGSEGV) of the
    interpreter. A write of the finished image fails like any Python write,
    and the previous file stays.

    With ``size`` (bytes of array data, a new file only), the file is written straight into
    ``atomic_open``'s temporary file instead (h5py's file-object driver, every write a Python write),
    once the disk is known to have room for it: a large file is then never held in memory (the
    image and its copy as bytes would be two copies of the data).
    """
    h5py = _h5()

    if size is not None and not append:
        def write_through() -> None:
            free = shutil.disk_usage(path.parent).free
            if free < 1.1 * size + (16 << 20):
                raise OSError(errno.ENOSPC, f"only {free / 2 ** 20:.0f} megabytes free on the disk, about "
                                            f"{1.1 * size / 2 ** 20 + 16:.0f} needed")
            with atomic_open(path, "w+b") as fh, h5py.File(fh, "w", libver=("v110", "latest")) as f:
                fill(f)

        return _written(path, write_through)

    def write() -> None:
        source = path if append and path.exists() else f"{path}.in-memory"
        mode = "r+" if source == path else "w"
        with h5py.File(source, mode, driver="core", backing_store=False, libver=("v110", "latest")) as f:
            fill(f)
            f.flush()
            image = f.id.get_file_image()
        with atomic_open(path, "wb") as fh:
            fh.write(image)

    return _written(path, write)


def _fixed(text: str | Sequence[str]) -> Any:
    """Text attributes as fixed-length UTF-8 bytes, kept in the checksummed object header.

    Variable-length strings live in a global heap without checksums, and a
    damaged one can make the HDF5 library loop forever when it is read.
    """
    if isinstance(text, str):
        return np.bytes_(text.encode())
    items = [s.encode() for s in text]
    return np.array(items, dtype=f"S{max([len(s) for s in items] + [1])}")


def _array(group: Any, key: str, values: Any) -> Any:
    """A float dataset; arrays carry a Fletcher-32 checksum, so that a flipped bit is found on reading."""
    a = np.asarray(values, dtype=float)
    if a.ndim == 0:
        return group.create_dataset(key, data=a)
    return group.create_dataset(key, data=a, chunks=True, fletcher32=True)


def write_track_h5(segments: Sequence[TrackSegment], path: str | Path) -> Path:
    """Write track segments to HDF5 (layout in the module docstring), atomically; returns the path."""
    path = Path(path)
    names = [s.name for s in segments]
    if len(set(names)) != len(names):
        raise _fail(path, "segment names must be unique")
    for s in segments:
        check_segment(s, path)

    def fill(f: Any) -> None:
        f.attrs["format"] = _fixed(TRACK_FORMAT)
        f.attrs["version"] = FORMAT_VERSION
        group = f.create_group("segments")
        group.attrs["order"] = _fixed(names)
        for s in segments:
            g = group.create_group(s.name)
            _array(g, "distance", s.distance)
            d = _array(g, "irregularities", s.irregularities)
            d.attrs["channels"] = _fixed(IRREGULARITY_CHANNELS)
            d.attrs["units"] = _fixed("m")
            _array(g, "speed", s.speed)
            for key in ("curvature", "cant"):
                if getattr(s, key) is not None:
                    _array(g, key, getattr(s, key))

    return _write_h5(path, fill)


def read_track_h5(path: str | Path, *, strict: bool = False,
                  accept: Collection[str] = ()) -> list[TrackSegment]:
    """Read track segments from HDF5 (layout and checks in the module docstring).

    :param strict: unusual values raise DataError instead of a warning (:func:`check_plausibility`).
    :param accept: checks whose impossible values are used anyway (``data.accept``; :func:`check_plausibility`).
    """
    path = Path(path)
    out = []
    with _Reading(path, TRACK_FORMAT) as f:
        for name in _order(f, path):
            g = f["segments"][name]
            if not isinstance(g, _h5().Group):
                raise _fail(path, f"/segments/{name} is a dataset, expected a group")
            x = _dataset(g, "distance", path)
            n = (len(x),) if x.ndim == 1 else x.shape       # check_segment names any other shape
            data = {"distance": x,
                    "irregularities": _dataset(g, "irregularities", path, [(len(IRREGULARITY_CHANNELS), *n)],
                                               "irregularity channels x points of distance"),
                    "speed": _dataset(g, "speed", path, [(), n], "one speed, or one per point of distance")}
            channels = _text_list(g["irregularities"].attrs.get("channels"), path,
                                  f"/segments/{name}/irregularities attribute 'channels'")
            if channels and tuple(channels) != IRREGULARITY_CHANNELS:
                raise _fail(path, f"segment '{name}': irregularity channels {channels}, expected "
                                  f"{list(IRREGULARITY_CHANNELS)}")
            speed = data["speed"]
            curve = {key: _dataset(g, key, path, [n], "one per point of distance") if key in g else None
                     for key in ("curvature", "cant")}
            seg = TrackSegment(name, data["distance"], data["irregularities"],
                               float(speed) if speed.ndim == 0 else speed, meta={"file": str(path)}, **curve)
            out.append(check_segment(seg, path))
    if not out:
        raise _fail(path, "no segments")
    for seg in out:
        check_plausibility(seg, path, strict=strict, accept=accept)
    return out


def write_accelerations_h5(responses: Sequence[Response], path: str | Path, mode: str = "w", *,
                           extra: Any = None, in_memory: bool = True) -> Path:
    """Write records of accelerations to HDF5 (layout in the module docstring), atomically; returns the path.

    All records must have the same channels. ``mode="a"`` adds to an existing file's root.

    :param extra: ``extra(f)`` is called with the open ``h5py.File`` to add more
        datasets or attributes before the file is moved into place.
    :param in_memory: False writes a new file straight to disk once the free space is checked (for
        records too large to hold twice more in memory; see ``_write_h5``).
    """
    path = Path(path)
    if mode not in ("w", "a"):
        raise ValueError(f"mode must be 'w' or 'a', got {mode!r}")
    if not responses:
        raise _fail(path, "no records to write")
    channels = tuple(responses[0].channels)
    names = [r.segment for r in responses]
    if len(set(names)) != len(names) or not all(names):
        raise _fail(path, "records need unique, non-empty segment names")
    for r in responses:
        check_response(r, path)
        if tuple(r.channels) != channels:
            raise _fail(path, f"record '{r.segment}' has channels {list(r.channels)}, expected {list(channels)}")

    def fill(f: Any) -> None:
        f.attrs["format"] = _fixed(ACCELERATIONS_FORMAT)
        f.attrs["version"] = FORMAT_VERSION
        f.attrs["channels"] = _fixed(channels)
        if "segments" in f:
            del f["segments"]
        group = f.create_group("segments")
        group.attrs["order"] = _fixed(names)
        for r in responses:
            d = _array(group.create_group(r.segment), "accelerations", r.accelerations)
            d.attrs["fs_hz"] = float(r.fs)
            d.attrs["units"] = _fixed("m/s^2")
        if extra is not None:
            extra(f)

    size = None if in_memory else sum(np.asarray(r.accelerations).nbytes for r in responses)
    return _write_h5(path, fill, append=mode == "a", size=size)


def read_accelerations_h5(path: str | Path, channels: Sequence[str] | None = None, *,
                          strict: bool = False,
                          accept: Collection[str] = ()) -> list[Response]:
    """Read records of accelerations from HDF5 (layout and checks in the module docstring).

    :param channels: expected channels; records are reordered to them and a missing one raises.
    :param strict: unusual values raise DataError instead of a warning (:func:`check_plausibility`).
    :param accept: checks whose impossible values are used anyway (``data.accept``; :func:`check_plausibility`).
    """
    path = Path(path)
    out = []
    with _Reading(path, ACCELERATIONS_FORMAT) as f:
        names = _text_list(f.attrs.get("channels"), path, "root attribute 'channels'")
        if not names:
            raise _fail(path, "no 'channels' attribute at the root")
        for seg in _order(f, path):
            g = f["segments"][seg]
            if not isinstance(g, _h5().Group):
                raise _fail(path, f"/segments/{seg} is a dataset, expected a group")
            a = _dataset(g, "accelerations", path, [(len(names), None)], "the root's channels x samples")
            if "fs_hz" not in g["accelerations"].attrs:
                raise _fail(path, f"segment '{seg}': accelerations have no 'fs_hz' attribute")
            fs = _attr_float(g["accelerations"].attrs, "fs_hz", path, f"/segments/{seg}/accelerations")
            out.append(check_response(Response(tuple(names), fs, a, seg), path, channels))
    if not out:
        raise _fail(path, "no records")
    for r in out:
        check_plausibility(r, path, strict=strict, accept=accept)
    check_same_rate([(path, r) for r in out])
    return out


# ---------------------------------------------------------------------------------------------- any path
def _is_dir(path: Path) -> bool:
    try:
        return path.is_dir()
    except OSError as exc:
        raise _fail(path, f"cannot access ({_os_reason(exc)})") from None


def _csv_files(folder: Path, what: str) -> list[Path]:
    """The ``*.csv`` files of a folder sorted by name; hidden files (``.name``) are left out."""
    try:
        names = sorted(n for n in os.listdir(folder) if n.endswith(".csv") and not n.startswith("."))
    except OSError as exc:
        raise _fail(folder, f"cannot list the folder ({_os_reason(exc)})") from None
    if not names:
        raise _fail(folder, f"folder holds no .csv {what} files")
    return [folder / n for n in names]


def _is_h5(path: Path) -> bool:
    return path.suffix.lower() in (".h5", ".hdf5")


def read_track(path: str | Path, *, strict: bool = False,
               accept: Collection[str] = ()) -> list[TrackSegment]:
    """Track segments from an HDF5 file (``.h5``/``.hdf5``), a CSV file, or a folder of CSV files
    (sorted by file name); a segment name given twice raises DataError naming both files.

    :param strict: unusual values raise DataError instead of a warning (:func:`check_plausibility`).
    :param accept: checks whose impossible values are used anyway (``data.accept``; :func:`check_plausibility`).
    """
    path = Path(path)
    if _is_dir(path):
        found = [(p, read_track_csv(p, strict=strict, accept=accept)) for p in _csv_files(path, "track")]
        check_unique_segments(((p, s.name) for p, s in found), "track segment")
        return [s for _, s in found]
    if _is_h5(path):
        return read_track_h5(path, strict=strict, accept=accept)
    return [read_track_csv(path, strict=strict, accept=accept)]


def read_accelerations_records(path: str | Path, channels: Sequence[str] | None = None, *,
                               strict: bool = False,
                               accept: Collection[str] = ()) -> list[tuple[Path, Response]]:
    """Records with the file each came from: an HDF5 file, a CSV file or a folder of CSV files.

    Checks the set as a whole: a segment given twice and sampling rates that
    differ by more than :data:`FS_TOLERANCE` raise DataError naming both files.

    :param channels: expected channels; records are reordered to them and a missing one raises.
    :param strict: unusual values raise DataError instead of a warning (:func:`check_plausibility`).
    :param accept: checks whose impossible values are used anyway (``data.accept``; :func:`check_plausibility`).
    """
    path = Path(path)
    if _is_dir(path):
        records = [(p, read_accelerations_csv(p, channels, strict=strict, accept=accept))
                   for p in _csv_files(path, "acceleration")]
    elif _is_h5(path):
        records = [(path, r) for r in read_accelerations_h5(path, channels, strict=strict, accept=accept)]
    else:
        records = [(path, read_accelerations_csv(path, channels, strict=strict, accept=accept))]
    check_unique_segments(((p, r.segment) for p, r in records), "record of segment")
    check_same_rate(records)
    return records


def read_accelerations(path: str | Path, channels: Sequence[str] | None = None, *,
                       strict: bool = False,
                       accept: Collection[str] = ()) -> list[Response]:
    """Records from an HDF5 file, a CSV file or a folder of CSV files (sorted by file name);
    checked as in :func:`read_accelerations_records`."""
    return [r for _, r in read_accelerations_records(path, channels, strict=strict, accept=accept)]


def write_track(segments: Iterable[TrackSegment], path: str | Path) -> Path:
    """Write segments to ``path``: HDF5 for a ``.h5``/``.hdf5`` name, else a folder of CSV files."""
    path = Path(path)
    segments = list(segments)
    if _is_h5(path):
        return write_track_h5(segments, path)
    check_unique_segments(((path / f"{s.name}.csv", s.name) for s in segments), "track segment")
    for s in segments:
        write_track_csv(s, path / f"{s.name}.csv")
    return path
