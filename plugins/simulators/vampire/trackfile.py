"""Track irregularity files in Vampire's 6-field layout.

Public descriptions of Vampire's track files give the fields of a
row: distance (m), cross level (mm), curvature irregularity (1/km), lateral
(mm), vertical (mm), gauge variation (mm). Header lines, extension and sign
conventions are not public, so they are options (:class:`TrackFileOptions`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from suspid.errors import DataError
from suspid.interfaces import IRREGULARITY_CHANNELS, TrackSegment

from .options import TrackFileOptions

FIELDS = ("distance", "cross_level", "curvature", "lateral", "vertical", "gauge")
"""Columns of a row, in file order. Units: m, mm, 1/km, mm, mm, mm."""


def check_segment(segment: TrackSegment) -> None:
    """Check what the adapter needs of a segment.

    :raises DataError: naming the segment, when its name is not one line, the distance is not a
        strictly increasing ``(n_x,)`` array with n_x >= 2, the irregularities
        are not a finite ``(4, n_x)`` array, or the speed is not a positive
        constant (a speed record must not vary by more than 0.1 %; the adapter
        passes one speed to the run file).
    """
    x = np.asarray(segment.distance, dtype=float)
    irr = np.asarray(segment.irregularities, dtype=float)
    where = f"segment '{segment.name}'"
    if any(c in segment.name for c in "\r\n\0"):
        raise DataError(f"{where}: the name must be one line (it is written into the run files)")
    if x.ndim != 1 or x.size < 2 or not np.all(np.isfinite(x)) or not np.all(np.diff(x) > 0):
        raise DataError(f"{where}: distance must be a finite, strictly increasing (n_x,) array with n_x >= 2")
    if irr.shape != (len(IRREGULARITY_CHANNELS), x.size):
        raise DataError(f"{where}: irregularities have shape {irr.shape}, expected "
                        f"({len(IRREGULARITY_CHANNELS)}, {x.size})")
    if not np.all(np.isfinite(irr)):
        raise DataError(f"{where}: irregularities contain non-finite values")
    v = np.asarray(segment.speed, dtype=float)
    if not np.all(np.isfinite(v)) or np.any(v <= 0):
        raise DataError(f"{where}: speed must be positive and finite")
    if v.ndim and np.ptp(v) > 1e-3 * float(np.mean(v)):
        raise DataError(f"{where}: speed varies from {v.min():.3f} to {v.max():.3f} m/s; the vampire adapter "
                        f"runs each segment at one constant speed (split the segment)")


def track_rows(segment: TrackSegment, opts: TrackFileOptions) -> np.ndarray:
    """The rows of the track file for ``segment``.

    :returns: ``(n_x, 6)`` array in file units, columns as :data:`FIELDS`.
    """
    x = np.asarray(segment.distance, dtype=float)
    irr = np.asarray(segment.irregularities, dtype=float)
    ch = {name: irr[i] for i, name in enumerate(IRREGULARITY_CHANNELS)}
    s = opts.signs
    lateral_m = s.lateral * ch["lateral"]
    if opts.curvature == "from_lateral":
        # second derivative of the lateral position, 1/m -> 1/km
        curvature = np.gradient(np.gradient(lateral_m, x), x) * 1e3
    else:
        curvature = np.zeros_like(x)
    distance = x - x[0] if opts.distance_origin == "zero" else x
    return np.column_stack([
        distance,
        s.cross_level * ch["cross_level"] * 1e3,
        curvature,
        lateral_m * 1e3,
        s.vertical * ch["vertical"] * 1e3,
        s.gauge * ch["gauge"] * 1e3,
    ])


def write_track_file(path: Path, rows: np.ndarray, opts: TrackFileOptions, header: list[str],
                     encoding: str = "utf-8") -> None:
    """Write ``rows`` (``(n_x, 6)``, file units) after the already rendered ``header`` lines.

    Header characters that ``encoding`` cannot represent are replaced by ``?``.
    """
    specs = [opts.distance_format, opts.value_format, opts.curvature_format,
             opts.value_format, opts.value_format, opts.value_format]
    row_format = opts.delimiter.join("{:" + spec + "}" for spec in specs)
    newline = "\r\n" if opts.newline == "crlf" else "\n"
    lines = list(header) + [row_format.format(*row) for row in rows.tolist()]
    with open(path, "w", encoding=encoding, errors="replace", newline="") as fh:
        fh.write(newline.join(lines) + newline)

