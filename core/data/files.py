"""Track and acceleration files: CSV and HDF5 readers and writers, and their checks.

CSV layout, one file per segment
--------------------------------
Track segment (``*.csv``)::

    # suspid track segment
    # name: seg-001
    # speed_mps: 83.333
    distance_m,vertical_m,lateral_m,cross_level_m,gauge_m
    0.00,0.0012,-0.0003,0.0001,0.0
    0.25,...

- ``#`` lines before the header are comments; ``# key: value`` lines give
  metadata: ``name`` (default: the file name without extension) and
  ``speed_mps`` (constant speed, m/s).
- The header names the columns; order is free. Required: ``distance_m`` and
  the four channels ``vertical_m``, ``lateral_m``, ``cross_level_m``,
  ``gauge_m``, all in metres. Optional: ``speed_mps``, a speed record (one
  value per distance sample, variable speed); the speed must come from this
  column or from the metadata.
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

Accelerations (``format = "suspid-accelerations"``)::

    /                         attrs: format, version = 1, channels = channel names
    /segments                 attrs: order = segment names in order
    /segments/<name>/accelerations   (n_channels, n_t) m/s^2; attrs: fs_hz

A simulation file (``simulation.h5``, :mod:`suspid.workflows.simulate`) is an
accelerations file with, in addition, ``/y`` (n_segments, n_channels,
n_freqs) dB and ``/freqs`` (n_freqs,) Hz.

Errors: a malformed file raises :class:`suspid.errors.DataError` with one
line naming the file and what is wrong.
"""
from __future__ import annotations

import csv
import io
import math
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from suspid.errors import DataError
from suspid.interfaces import IRREGULARITY_CHANNELS, Response, TrackSegment

CSV_TRACK_COLUMNS = ("distance_m", "vertical_m", "lateral_m", "cross_level_m", "gauge_m")
"""Required columns of a track CSV file (channels in the order of IRREGULARITY_CHANNELS)."""


# ---------------------------------------------------------------------------------------------- checks
def _fail(path: Path | str, message: str) -> DataError:
    return DataError(f"{path}: {message}")


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


# ---------------------------------------------------------------------------------------------- CSV
def _read_csv(path: Path) -> tuple[dict[str, str], list[str], np.ndarray]:
    """Metadata, header and values (float array rows x columns) of a suspid CSV file."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise _fail(path, "file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise _fail(path, f"cannot read the file: {exc}") from None
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
            raise _fail(path, f"line {n}: '{bad.strip()}' is not a number") from None
    values = np.array(rows, dtype=float).reshape(len(rows), len(header))
    return meta, header, values


def _is_float(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False


def read_track_csv(path: str | Path) -> TrackSegment:
    """Read one track segment from a CSV file (layout in the module docstring)."""
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
                       meta={"file": str(path)})
    return check_segment(seg, path)


def write_track_csv(segment: TrackSegment, path: str | Path) -> Path:
    """Write one track segment as CSV (layout in the module docstring); returns the path."""
    path = Path(path)
    check_segment(segment, path)
    path.parent.mkdir(parents=True, exist_ok=True)
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
    lines.append(",".join(columns))
    table = np.column_stack(data)
    lines += [",".join(repr(float(c)) for c in row) for row in table]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def read_accelerations_csv(path: str | Path, channels: Sequence[str] | None = None) -> Response:
    """Read one record of accelerations from a CSV file (layout in the module docstring).

    :param channels: expected channels; the record is reordered to them and a
        missing one raises DataError.
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
    r = Response(tuple(names), float(fs), a, meta.get("segment", path.stem))
    return check_response(r, path, channels)


def write_accelerations_csv(response: Response, path: str | Path, with_time: bool = True) -> Path:
    """Write one record of accelerations as CSV (layout in the module docstring); returns the path."""
    path = Path(path)
    check_response(response, path)
    path.parent.mkdir(parents=True, exist_ok=True)
    a = np.asarray(response.accelerations, dtype=float)
    lines = ["# suspid accelerations", f"# segment: {response.segment}", f"# fs_hz: {float(response.fs)!r}"]
    columns = (["time_s"] if with_time else []) + list(response.channels)
    lines.append(",".join(columns))
    data = a.T
    if with_time:
        data = np.column_stack([np.arange(a.shape[1]) / response.fs, data])
    lines += [",".join(repr(float(c)) for c in row) for row in data]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


# ---------------------------------------------------------------------------------------------- HDF5
TRACK_FORMAT = "suspid-track"
ACCELERATIONS_FORMAT = "suspid-accelerations"
FORMAT_VERSION = 1


def _h5():
    import h5py

    return h5py


def _open(path: Path, fmt: str):
    h5py = _h5()
    try:
        f = h5py.File(path, "r")
    except FileNotFoundError:
        raise _fail(path, "file not found") from None
    except OSError as exc:
        raise _fail(path, f"not a readable HDF5 file ({str(exc).splitlines()[0]})") from None
    found = f.attrs.get("format")
    if isinstance(found, bytes):
        found = found.decode()
    if found != fmt:
        f.close()
        raise _fail(path, f"format attribute is {found!r}, expected '{fmt}'")
    if "segments" not in f:
        f.close()
        raise _fail(path, "no /segments group")
    return f


def _order(f, path: Path) -> list[str]:
    group = f["segments"]
    order = [o.decode() if isinstance(o, bytes) else str(o) for o in group.attrs.get("order", [])]
    names = set(group.keys())
    if not order:
        return sorted(names)
    missing = [n for n in order if n not in names]
    if missing:
        raise _fail(path, f"/segments order names segment(s) that are absent: {', '.join(missing)}")
    return order


def write_track_h5(segments: Sequence[TrackSegment], path: str | Path) -> Path:
    """Write track segments to HDF5 (layout in the module docstring); returns the path."""
    path = Path(path)
    h5py = _h5()
    names = [s.name for s in segments]
    if len(set(names)) != len(names):
        raise _fail(path, "segment names must be unique")
    for s in segments:
        check_segment(s, path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with h5py.File(path, "w") as f:
        f.attrs["format"] = TRACK_FORMAT
        f.attrs["version"] = FORMAT_VERSION
        group = f.create_group("segments")
        group.attrs["order"] = names
        for s in segments:
            g = group.create_group(s.name)
            g.create_dataset("distance", data=np.asarray(s.distance, dtype=float))
            d = g.create_dataset("irregularities", data=np.asarray(s.irregularities, dtype=float))
            d.attrs["channels"] = list(IRREGULARITY_CHANNELS)
            d.attrs["units"] = "m"
            g.create_dataset("speed", data=np.asarray(s.speed, dtype=float))
    return path


def read_track_h5(path: str | Path) -> list[TrackSegment]:
    """Read track segments from HDF5 (layout in the module docstring)."""
    path = Path(path)
    out = []
    with _open(path, TRACK_FORMAT) as f:
        for name in _order(f, path):
            g = f["segments"][name]
            for key in ("distance", "irregularities", "speed"):
                if key not in g:
                    raise _fail(path, f"segment '{name}': missing dataset '{key}'")
            irr = g["irregularities"]
            channels = [c.decode() if isinstance(c, bytes) else str(c) for c in irr.attrs.get("channels", [])]
            if channels and tuple(channels) != IRREGULARITY_CHANNELS:
                raise _fail(path, f"segment '{name}': irregularity channels {channels}, expected "
                                  f"{list(IRREGULARITY_CHANNELS)}")
            speed = np.asarray(g["speed"][()], dtype=float)
            seg = TrackSegment(name, np.asarray(g["distance"][()], dtype=float), np.asarray(irr[()], dtype=float),
                               float(speed) if speed.ndim == 0 else speed, meta={"file": str(path)})
            out.append(check_segment(seg, path))
    if not out:
        raise _fail(path, "no segments")
    return out


def write_accelerations_h5(responses: Sequence[Response], path: str | Path, mode: str = "w") -> Path:
    """Write records of accelerations to HDF5 (layout in the module docstring); returns the path.

    All records must have the same channels. ``mode="a"`` adds to an existing file's root.
    """
    path = Path(path)
    h5py = _h5()
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
    path.parent.mkdir(parents=True, exist_ok=True)
    with h5py.File(path, mode) as f:
        f.attrs["format"] = ACCELERATIONS_FORMAT
        f.attrs["version"] = FORMAT_VERSION
        f.attrs["channels"] = list(channels)
        if "segments" in f:
            del f["segments"]
        group = f.create_group("segments")
        group.attrs["order"] = names
        for r in responses:
            d = group.create_group(r.segment).create_dataset(
                "accelerations", data=np.asarray(r.accelerations, dtype=float))
            d.attrs["fs_hz"] = float(r.fs)
            d.attrs["units"] = "m/s^2"
    return path


def read_accelerations_h5(path: str | Path, channels: Sequence[str] | None = None) -> list[Response]:
    """Read records of accelerations from HDF5 (layout in the module docstring).

    :param channels: expected channels; records are reordered to them and a missing one raises.
    """
    path = Path(path)
    out = []
    with _open(path, ACCELERATIONS_FORMAT) as f:
        names = [c.decode() if isinstance(c, bytes) else str(c) for c in f.attrs.get("channels", [])]
        if not names:
            raise _fail(path, "no 'channels' attribute at the root")
        for seg in _order(f, path):
            g = f["segments"][seg]
            if "accelerations" not in g:
                raise _fail(path, f"segment '{seg}': missing dataset 'accelerations'")
            d = g["accelerations"]
            if "fs_hz" not in d.attrs:
                raise _fail(path, f"segment '{seg}': accelerations have no 'fs_hz' attribute")
            r = Response(tuple(names), float(d.attrs["fs_hz"]), np.asarray(d[()], dtype=float), seg)
            out.append(check_response(r, path, channels))
    if not out:
        raise _fail(path, "no records")
    return out


# ---------------------------------------------------------------------------------------------- any path
def read_track(path: str | Path) -> list[TrackSegment]:
    """Track segments from an HDF5 file (``.h5``/``.hdf5``), a CSV file, or a folder of CSV files
    (sorted by file name)."""
    path = Path(path)
    if path.is_dir():
        files = sorted(path.glob("*.csv"))
        if not files:
            raise _fail(path, "folder holds no .csv track files")
        return [read_track_csv(p) for p in files]
    if path.suffix.lower() in (".h5", ".hdf5"):
        return read_track_h5(path)
    return [read_track_csv(path)]


def read_accelerations(path: str | Path, channels: Sequence[str] | None = None) -> list[Response]:
    """Records from an HDF5 file, a CSV file or a folder of CSV files (sorted by file name)."""
    path = Path(path)
    if path.is_dir():
        files = sorted(path.glob("*.csv"))
        if not files:
            raise _fail(path, "folder holds no .csv acceleration files")
        return [read_accelerations_csv(p, channels) for p in files]
    if path.suffix.lower() in (".h5", ".hdf5"):
        return read_accelerations_h5(path, channels)
    return [read_accelerations_csv(path, channels)]


def write_track(segments: Iterable[TrackSegment], path: str | Path) -> Path:
    """Write segments to ``path``: HDF5 for a ``.h5``/``.hdf5`` name, else a folder of CSV files."""
    path = Path(path)
    segments = list(segments)
    if path.suffix.lower() in (".h5", ".hdf5"):
        return write_track_h5(segments, path)
    for s in segments:
        write_track_csv(s, path / f"{s.name}.csv")
    return path
