"""Reading a recording onto one uniform time grid, in SI units, one channel at a time.

The first mapped acceleration channel sets the grid (its start, its median
step, or ``recording.fs_hz``). Every other channel is copied when it lies on
that grid and interpolated linearly onto it otherwise; a channel sampled
faster than the grid is low-pass filtered first (8th-order Butterworth at
0.4 fs, forward-backward, so no phase shift and no aliasing). Samples that fall
into a gap of a channel's time stamps (a step longer than ``gap_factor``
nominal steps) or outside its record are NaN: the quality checks count them as
dropouts. Values are multiplied by the declared unit's factor and sign, never
by a guessed one; a unit the file states that differs from the declared one
is a warning.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np
from scipy import signal as sps

from suspid import registry
from suspid.errors import ConfigError, DataError
from suspid.infra.arrays import available_memory, human_bytes
from suspid.interfaces import Reader, Signal
from suspid.options import parse_options

from .options import (ACCELERATION_UNITS, LENGTH_UNITS, SPEED_UNITS, IngestOptions, RecordingSection,
                      TrackRecordSection, canonical_unit)


@dataclass
class Grid:
    """The uniform time grid of the ingested recording: sample j at ``t0 + j / fs`` s."""

    t0: float
    fs: float
    n: int

    @property
    def time(self) -> np.ndarray:
        return self.t0 + np.arange(self.n) / self.fs


@dataclass
class ChannelInfo:
    """What was found while reading one channel."""

    name: str            # in the file
    file_unit: str
    declared_unit: str
    factor: float        # to SI, sign included
    fs_file: float       # the channel's own sampling rate, Hz
    jitter: float        # std of the time step / nominal step (0 for a uniform record)
    n_gaps: int          # steps longer than gap_factor nominal steps
    resampled: bool


@dataclass
class Recording:
    """A recording on one grid: accelerations ``(n_channels, n)`` m/s^2, speed and distance ``(n,)``.

    NaN marks a dropout (a gap, or a NaN in the file).
    """

    path: Path
    reader: str
    grid: Grid
    channels: tuple[str, ...]           # simulator channel names, rows of accelerations
    accelerations: np.ndarray
    speed: np.ndarray                   # m/s
    distance: np.ndarray                # m, odometry
    info: dict[str, ChannelInfo] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)


def reader_class(path: Path, fmt: str | None, key: str) -> type[Reader]:
    """The reader named ``fmt``, or the one whose extensions include the file's."""
    if fmt is not None:
        try:
            return registry.get("reader", fmt)
        except Exception as exc:
            raise ConfigError(str(exc), key=f"{key}.format") from None
    suffix = path.suffix.lower()
    for name in registry.names("reader"):
        cls = registry.get("reader", name)
        if suffix in getattr(cls, "extensions", ()):
            return cls
    known = ", ".join(f"{n} ({' '.join(registry.get('reader', n).extensions)})" for n in registry.names("reader"))
    raise ConfigError(f"no reader for extension '{suffix}' of {path}; give {key}.format, one of: {known}",
                      key=f"{key}.format")


def open_reader(path: Path, fmt: str | None, options: dict, key: str) -> Reader:
    """A reader for ``path``, its options validated by its ``Options`` model (key ``<key>.options``)."""
    cls = reader_class(path, fmt, key)
    opts = parse_options(cls.Options, options, f"{key}.options").model_dump() if cls.Options else dict(options)
    return cls(path, **opts)


def abscissa(sig: Signal, path: Path) -> np.ndarray | None:
    """The explicit index of a signal (checked), or None for a uniform one."""
    if sig.index is None:
        if sig.step is None or not sig.step > 0:
            raise DataError(f"{path}: channel '{sig.name}' has neither an index nor a positive step")
        if sig.values.size < 2:
            raise DataError(f"{path}: channel '{sig.name}' has {sig.values.size} samples, at least 2 are needed")
        return None
    idx = np.asarray(sig.index, dtype=np.float64)
    if idx.shape != sig.values.shape:
        raise DataError(f"{path}: channel '{sig.name}' has {sig.values.size} samples but its index has {idx.size}")
    if idx.size < 2:
        raise DataError(f"{path}: channel '{sig.name}' has fewer than 2 samples")
    if not np.all(np.diff(idx) > 0):
        i = int(np.flatnonzero(~(np.diff(idx) > 0))[0])
        raise DataError(f"{path}: the index of channel '{sig.name}' must increase, but sample {i + 1} "
                        f"({idx[i + 1]:g}) follows {idx[i]:g}")
    return idx


CHUNK = 1 << 18
"""Samples processed at a time by the whole-record loops (2 MiB of float64): working buffers stay small."""


def _timing(sig: Signal, idx: np.ndarray | None, gap_factor: float) -> tuple[float, float, float, np.ndarray]:
    """(start, nominal step, jitter, indices k of the gaps between sample k and k + 1).

    The nominal step is the median of the steps (of each chunk's median when the record is longer than
    :data:`CHUNK`); the jitter is the standard deviation of the regular steps over the nominal one.
    """
    if idx is None:
        return float(sig.start), float(sig.step), 0.0, np.empty(0, dtype=np.int64)
    starts = range(0, idx.size - 1, CHUNK)
    nominal = float(np.median([np.median(np.diff(idx[a:a + CHUNK + 1])) for a in starts]))
    gaps, s1, s2, m = [], 0.0, 0.0, 0
    for a in starts:
        dt = np.diff(idx[a:a + CHUNK + 1])
        g = np.flatnonzero(dt > gap_factor * nominal)
        gaps.append(g + a)
        dev = np.delete(dt, g) - nominal
        s1, s2, m = s1 + float(dev.sum()), s2 + float(dev @ dev), m + dev.size
    jitter = float(np.sqrt(max(s2 / m - (s1 / m) ** 2, 0.0)) / nominal) if m else 0.0
    return float(idx[0]), nominal, jitter, np.concatenate(gaps)


def lowpass(values: np.ndarray, fs_in: float, fs_out: float) -> np.ndarray:
    """Anti-alias filter before going to the slower rate ``fs_out`` (NaN kept as NaN)."""
    bad = ~np.isfinite(values)
    x = np.where(bad, 0.0, values) if bad.any() else values
    sos = sps.butter(8, 0.4 * fs_out, fs=fs_in, output="sos")
    y = sps.sosfiltfilt(sos, x)
    if bad.any():
        y[bad] = np.nan
    return y


def _count_at_or_before(grid: Grid, tau: float) -> int:
    """Number of grid samples whose time ``t0 + j / fs`` is at most ``tau`` (0 .. grid.n)."""
    j = min(max(int(np.floor((tau - grid.t0) * grid.fs)), -1), grid.n - 1)   # the last such j, up to rounding
    while j + 1 < grid.n and grid.t0 + (j + 1) / grid.fs <= tau:
        j += 1
    while j >= 0 and grid.t0 + j / grid.fs > tau:
        j -= 1
    return j + 1


def onto_grid(sig: Signal, idx: np.ndarray | None, grid: Grid, gap_factor: float,
              out: np.ndarray | None = None) -> tuple[np.ndarray, bool]:
    """``sig.values`` on ``grid`` (NaN in gaps and outside the record); returns (values, resampled).

    Written into ``out`` (``(grid.n,)``, allocated when None) :data:`CHUNK` samples at a time, so that
    the only whole-record arrays are the signal's own and ``out``.
    """
    start, step, _, gaps = _timing(sig, idx, gap_factor)
    values = sig.values
    n = values.size
    same = (idx is None or gaps.size == 0) and abs(step * grid.fs - 1.0) < 1e-9 and \
        abs(start - grid.t0) * grid.fs < 1e-6
    if out is None:
        out = np.empty(grid.n)
    if same:
        m = min(n, grid.n)
        out[:m] = values[:m]
        out[m:] = np.nan
        return out, False
    if 1.0 / step > 1.05 * grid.fs:
        values = lowpass(values, 1.0 / step, grid.fs)
    first, last = (float(idx[0]), float(idx[-1])) if idx is not None else (start, start + (n - 1) * step)
    for a in range(0, grid.n, CHUNK):
        t = grid.t0 + np.arange(a, min(a + CHUNK, grid.n)) / grid.fs
        if idx is not None:
            k0, k1 = np.searchsorted(idx, [t[0], t[-1]])
        else:
            k0, k1 = np.floor((t[0] - start) / step), np.ceil((t[-1] - start) / step)
        k0, k1 = int(np.clip(k0 - 1, 0, n - 1)), int(np.clip(k1 + 1, 0, n - 1)) + 1
        t_src = idx[k0:k1] if idx is not None else start + np.arange(k0, k1) * step
        o = out[a:a + t.size]
        o[:] = np.interp(t, t_src, values[k0:k1])
        o[(t < first - 1e-9) | (t > last + 1e-9)] = np.nan
    for k in gaps:  # samples strictly inside a gap of the source
        out[_count_at_or_before(grid, idx[k]):_count_at_or_before(grid, idx[k + 1])] = np.nan
    return out, True


def grid_arrays(path: Path, channel: str, grid: Grid, n_channels: int) -> np.ndarray:
    """The ``(n_channels, grid.n)`` array of the recording on its grid, when it can fit in memory.

    A time channel whose stamps lie far apart (a stamp of a later day, a damaged one) makes a grid of
    billions of samples: that is an error naming the file and the span, not an "out of memory" later.
    The whole ingest holds about ``n_channels + 3`` rows of the grid (the speed, the distance, a copy).
    """
    need = 8.0 * grid.n * (n_channels + 3)
    total = available_memory()
    problem = total is not None and need > total
    if not problem:
        try:
            return np.empty((n_channels, grid.n))
        except MemoryError:
            problem = True
    raise DataError(f"{path}: channel '{channel}' spans {grid.n / grid.fs:.6g} s at {grid.fs:g} Hz, {grid.n} "
                    f"samples per channel ({human_bytes(need)} in all), more than the memory available"
                    f"{f' ({human_bytes(total)})' if total else ''}: are its time stamps in seconds, "
                    f"without a jump (a sparse or damaged time channel)?")


def _unit_warning(where: str, file_unit: str, declared: str, table: dict[str, float]) -> str | None:
    fu = canonical_unit(file_unit) if file_unit else ""
    if fu and fu != declared:
        note = "" if fu not in table else f" (a factor {table[fu] / table[declared]:g} apart)"
        return (f"{where}: the file gives the unit '{file_unit}' but the config declares '{declared}'{note}; "
                f"the declared unit is used")
    return None


def read_recording(opts: IngestOptions, sim_channels: Sequence[str]) -> Recording:
    """Read the mapped channels and the speed (or distance) of ``opts.recording`` onto one grid."""
    rec: RecordingSection = opts.recording
    q = opts.quality
    warnings: list[str] = []
    with open_reader(rec.path, rec.format, rec.options, "recording") as reader:
        wanted = [rec.channels[c].name for c in sim_channels]
        motion = rec.speed.name if rec.speed is not None else rec.distance.name
        available = set(reader.channels())
        for c, name in zip([*sim_channels, "speed" if rec.speed else "distance"], [*wanted, motion]):
            if name not in available:
                shown = ", ".join(sorted(available)[:40])
                key = f"recording.{c}.name" if c in ("speed", "distance") else f"recording.channels.{c}.name"
                raise DataError(f"{rec.path}: no channel '{name}' (mapped to {c}, key {key}); channels in the "
                                f"file: {shown}")
        reader.select([*wanted, motion])
        info: dict[str, ChannelInfo] = {}
        acc = None
        grid = None
        for row, (c, name) in enumerate(zip(sim_channels, wanted)):
            m = rec.channels[c]
            sig = reader.read(name)
            idx = abscissa(sig, rec.path)
            start, step, jitter, gaps = _timing(sig, idx, q.gap_factor)
            if grid is None:
                fs = rec.fs_hz or 1.0 / step
                end = float(idx[-1]) if idx is not None else start + (sig.values.size - 1) * step
                grid = Grid(start, float(fs), int(np.floor((end - start) * fs + 1e-9)) + 1)
                acc = grid_arrays(rec.path, name, grid, len(sim_channels))
            _, resampled = onto_grid(sig, idx, grid, q.gap_factor, out=acc[row])
            acc[row] *= m.factor
            info[c] = ChannelInfo(name, sig.unit, m.unit, m.factor, 1.0 / step, jitter, int(gaps.size), resampled)
            w = _unit_warning(f"channel {c} ('{name}')", sig.unit, m.unit, ACCELERATION_UNITS)
            if w:
                warnings.append(w)
            del sig, idx
        sig = reader.read(motion)
        idx = abscissa(sig, rec.path)
        _, step, jitter, gaps = _timing(sig, idx, q.gap_factor)
        values, _ = onto_grid(sig, idx, grid, q.gap_factor)
        if rec.speed is not None:
            speed = values
            speed *= SPEED_UNITS[rec.speed.unit]
            w = _unit_warning(f"speed ('{motion}')", sig.unit, rec.speed.unit, SPEED_UNITS)
            distance = integrate_speed(speed, grid.fs)
        else:
            distance = values
            distance *= LENGTH_UNITS[rec.distance.unit]
            w = _unit_warning(f"distance ('{motion}')", sig.unit, rec.distance.unit, LENGTH_UNITS)
            speed = speed_from_distance(distance, grid.fs)
            distance = fill_nan(distance)
        if w:
            warnings.append(w)
        info["speed" if rec.speed is not None else "distance"] = ChannelInfo(
            motion, sig.unit, (rec.speed or rec.distance).unit, 1.0, 1.0 / step, jitter, int(gaps.size),
            True)
        reader_name = type(reader).name
    return Recording(rec.path, reader_name, grid, tuple(sim_channels), acc, speed, distance, info, warnings)


def fill_nan(x: np.ndarray) -> np.ndarray:
    """``x`` with NaN runs replaced by linear interpolation (ends held)."""
    bad = ~np.isfinite(x)
    if not bad.any():
        return x
    good = np.flatnonzero(~bad)
    if good.size == 0:
        raise DataError("the speed (or distance) channel holds no finite value")
    y = x.copy()
    y[bad] = np.interp(np.flatnonzero(bad), good, x[good])
    return y


def integrate_speed(speed: np.ndarray, fs: float) -> np.ndarray:
    """Odometry distance (m) from the speed (m/s): trapezoidal rule, NaN bridged by interpolation."""
    v = fill_nan(speed)
    d = np.empty_like(v)
    d[0] = 0.0
    np.add(v[1:], v[:-1], out=d[1:])
    d[1:] *= 0.5 / fs
    carry = 0.0
    for a in range(1, d.size, CHUNK):   # in place, a chunk at a time: no whole-record temporary
        part = d[a:a + CHUNK]
        np.cumsum(part, out=part)
        part += carry
        carry = float(part[-1])
    return d


def speed_from_distance(distance: np.ndarray, fs: float, smooth_s: float = 0.5) -> np.ndarray:
    """Speed (m/s) from an odometry distance: central differences over ``smooth_s``."""
    d = fill_nan(distance)
    k = max(1, int(round(smooth_s * fs / 2)))
    v = np.empty_like(d)
    np.subtract(d[2 * k:], d[:-2 * k], out=v[k:-k])
    v[k:-k] *= fs / (2 * k)
    v[:k], v[-k:] = v[k], v[-k - 1]
    v[~np.isfinite(distance)] = np.nan
    return v


@dataclass
class TrackRecord:
    """The track record in metres on its own uniform distance grid ``x0 + k dx``."""

    path: Path
    x0: float
    dx: float
    irregularities: np.ndarray   # (4, n) m, rows as IRREGULARITY_CHANNELS, NaN where the record has none
    present: tuple[str, ...]
    curvature: np.ndarray | None = None   # (n,) 1/m, positive: left-hand curve; None: not recorded
    cant: np.ndarray | None = None        # (n,) m, right rail above the left; None: not recorded

    def at(self, values: np.ndarray, x: np.ndarray) -> np.ndarray:
        """``values`` (one of the record's ``(n,)`` rows) at track distances ``x`` (m), NaN outside."""
        x_src = self.x0 + np.arange(values.size) * self.dx
        return np.interp(x, x_src, values, left=np.nan, right=np.nan)


def read_track_record(section: TrackRecordSection, quantities: Sequence[str]) -> tuple[TrackRecord, list[str]]:
    """The mapped track quantities in metres on one uniform distance grid (the vertical one's)."""
    warnings: list[str] = []
    du = LENGTH_UNITS[section.distance_unit]
    with open_reader(section.path, section.format, section.options, "track") as reader:
        names = {q: section.channels[q].name for q in quantities if q in section.channels}
        available = set(reader.channels())
        for q, name in names.items():
            if name not in available:
                raise DataError(f"{section.path}: no channel '{name}' (mapped to track {q}, key "
                                f"track.channels.{q}.name); channels in the "
                                f"file: {', '.join(sorted(available)[:40])}")
        reader.select(list(names.values()) + [c.name for c in (section.curvature, section.cant)
                                               if c is not None and c.name in available])
        out = None
        x0 = dx = 0.0
        for row, q in enumerate(quantities):
            if q not in names:
                continue
            sig = reader.read(names[q])
            idx = abscissa(sig, section.path)
            start, step, jitter, gaps = _timing(sig, idx, 1.5)
            if out is None:
                x0, dx = start * du, step * du
                n = sig.values.size if idx is None else int(np.floor((idx[-1] - idx[0]) / step + 1e-9)) + 1
                out = np.full((len(quantities), n), np.nan)
            grid = Grid(x0 / du, 1.0 / (dx / du), out.shape[1])
            onto_grid(sig, idx, grid, 1.5, out=out[row])
            out[row] *= LENGTH_UNITS[section.channels[q].unit]
            if jitter > 1e-3:
                warnings.append(f"track record: the distance step of '{names[q]}' varies by {100 * jitter:.2g} % "
                                f"(resampled onto a uniform grid)")
            w = _unit_warning(f"track {q} ('{names[q]}')", sig.unit, section.channels[q].unit, LENGTH_UNITS)
            if w:
                warnings.append(w)
        design = {}
        for key, ch in (("curvature", section.curvature), ("cant", section.cant)):
            if ch is None:
                continue
            if ch.name not in available:
                raise DataError(f"{section.path}: no channel '{ch.name}' (key track.{key}.name); channels in the "
                                f"file: {', '.join(sorted(available)[:40])}")
            sig = reader.read(ch.name)
            row = np.empty(out.shape[1])
            onto_grid(sig, abscissa(sig, section.path), Grid(x0 / du, 1.0 / (dx / du), out.shape[1]), 1.5, out=row)
            design[key] = ch.to_curvature(row) if key == "curvature" else row * ch.sign * LENGTH_UNITS[ch.unit]
    missing = [q for q in quantities if q not in names]
    if missing:
        warnings.append(f"track record: no channel mapped for {', '.join(missing)}; written as zeros")
        for q in missing:
            out[list(quantities).index(q)] = 0.0
    return TrackRecord(section.path, x0, dx, out, tuple(names), **design), warnings
