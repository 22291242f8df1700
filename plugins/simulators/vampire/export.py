"""Reading the ASCII export of a run into a :class:`~suspid.interfaces.Response`.

Two forms (:class:`ExportOptions`):

- ``table``: a header line of column names, then rows of numbers, one
  abscissa column (time or distance) and one column per channel;
- ``blocks``: per channel a title line, a line with the number of pairs n,
  then n lines ``x ; y``.

Every problem is a :class:`~suspid.errors.SimulatorError` whose message starts
with ``file:line`` where a line is to blame. Numbers may use a Fortran ``D``
exponent (``1.0D+03``); Fortran overflow fields (``*****``) are malformed.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from suspid.errors import SimulatorError
from suspid.interfaces import Response, TrackSegment

from .options import ChannelSpec, ExportOptions

_FORTRAN_D = re.compile(r"^([+-]?(?:\d+\.?\d*|\.\d+))[dD]([+-]?\d+)$")


@dataclass
class ExportData:
    """Raw columns of an export file.

    :ivar path: the file.
    :ivar x: ``(n,)`` abscissa as written (before ``x_scale``).
    :ivar lines: ``(n,)`` line number (from 1) of each sample, for messages.
    :ivar columns: column name -> ``(n,)`` values as written (before units).
    """

    path: Path
    x: np.ndarray
    lines: np.ndarray
    columns: dict[str, np.ndarray]


def _number(token: str, where: str, what: str) -> float:
    text = token.strip()
    match = _FORTRAN_D.match(text)
    if match:
        text = f"{match.group(1)}e{match.group(2)}"
    try:
        return float(text)
    except ValueError:
        raise SimulatorError(f"{where}: cannot read {what} from {token.strip()!r}") from None


def _read_lines(path: Path) -> list[str]:
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise SimulatorError(f"{path}: cannot read the export ({exc.strerror or exc})") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        text = data.decode("latin-1")
    return text.splitlines()


def read_export(path: Path, opts: ExportOptions, columns: Sequence[str]) -> ExportData:
    """Parse an export file and return the abscissa and the requested ``columns``.

    :param columns: column names (table form) or block titles (block form).
    :raises SimulatorError: naming the file (and line) of any problem.
    """
    path = Path(path)
    lines = _read_lines(path)
    if opts.form == "table":
        return _read_table(path, lines, opts, columns)
    return _read_blocks(path, lines, opts, columns)


def _split(line: str, delimiter: str | None) -> list[str]:
    return [t.strip() for t in line.split(delimiter)] if delimiter else line.split()


def _read_table(path: Path, lines: list[str], opts: ExportOptions, columns: Sequence[str]) -> ExportData:
    def skip(line: str) -> bool:
        stripped = line.strip()
        return not stripped or any(stripped.startswith(p) for p in opts.comment_prefixes)

    i = opts.skip_lines
    while i < len(lines) and skip(lines[i]):
        i += 1
    if i >= len(lines):
        raise SimulatorError(f"{path}: no header line found (after skipping {opts.skip_lines} lines)")
    header = _split(lines[i], opts.delimiter)
    header_line = i + 1
    wanted = [opts.x_column, *columns]
    index = {}
    for name in wanted:
        hits = [k for k, h in enumerate(header) if h == name]
        if not hits:
            raise SimulatorError(f"{path}:{header_line}: no column '{name}' in the header; columns are "
                                 + ", ".join(repr(h) for h in header))
        if len(hits) > 1:
            raise SimulatorError(f"{path}:{header_line}: column '{name}' appears {len(hits)} times in the header")
        index[name] = hits[0]
    values: dict[str, list[float]] = {name: [] for name in wanted}
    rows: list[int] = []
    for k in range(i + 1, len(lines)):
        line = lines[k]
        if skip(line):
            continue
        fields = _split(line, opts.delimiter)
        where = f"{path}:{k + 1}"
        if len(fields) != len(header):
            raise SimulatorError(f"{where}: {len(fields)} fields where the header has {len(header)} "
                                 f"(truncated or malformed row {line.strip()[:60]!r})")
        for name in wanted:
            values[name].append(_number(fields[index[name]], where, f"column '{name}'"))
        rows.append(k + 1)
    if not rows:
        raise SimulatorError(f"{path}: header but no data rows")
    return ExportData(path, np.asarray(values[opts.x_column]), np.asarray(rows),
                      {name: np.asarray(values[name]) for name in columns})


def _read_blocks(path: Path, lines: list[str], opts: ExportOptions, columns: Sequence[str]) -> ExportData:
    blocks: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
    k = opts.skip_lines
    n_lines = len(lines)
    while k < n_lines:
        if not lines[k].strip():
            k += 1
            continue
        title, title_line = lines[k].strip(), k + 1
        k += 1
        while k < n_lines and not lines[k].strip():
            k += 1
        if k >= n_lines:
            raise SimulatorError(f"{path}:{title_line}: block '{title}' has no count line (file truncated?)")
        count_text = lines[k].strip()
        if not re.fullmatch(r"\d+", count_text):
            raise SimulatorError(f"{path}:{k + 1}: block '{title}': expected the number of pairs, got "
                                 f"{count_text[:60]!r}")
        count = int(count_text)
        k += 1
        xs, ys, rows = [], [], []
        while len(xs) < count:
            if k >= n_lines:
                raise SimulatorError(f"{path}: block '{title}' (line {title_line}) declares {count} pairs but the "
                                     f"file ends after {len(xs)} (truncated output?)")
            line = lines[k]
            k += 1
            if not line.strip():
                continue
            where = f"{path}:{k}"
            parts = line.split(opts.pair_separator)
            if len(parts) != 2:
                raise SimulatorError(f"{where}: block '{title}': expected 'x {opts.pair_separator} y', got "
                                     f"{line.strip()[:60]!r}")
            xs.append(_number(parts[0], where, f"x of block '{title}'"))
            ys.append(_number(parts[1], where, f"value of block '{title}'"))
            rows.append(k)
        if title in blocks:
            raise SimulatorError(f"{path}:{title_line}: block '{title}' appears twice")
        blocks[title] = (np.asarray(xs), np.asarray(ys), np.asarray(rows))
    missing = [c for c in columns if c not in blocks]
    if missing:
        raise SimulatorError(f"{path}: no block titled {', '.join(repr(m) for m in missing)}; blocks are "
                             + (", ".join(repr(b) for b in blocks) or "none"))
    x0, _, rows0 = blocks[columns[0]]
    for name in columns[1:]:
        x, _, rows = blocks[name]
        if x.shape != x0.shape or not np.allclose(x, x0, rtol=1e-9, atol=0):
            raise SimulatorError(f"{path}: block '{name}' (from line {rows[0] if len(rows) else '?'}) has another "
                                 f"abscissa than block '{columns[0]}'")
    return ExportData(path, x0, rows0, {name: blocks[name][1] for name in columns})


def to_response(data: ExportData, channels: Sequence[ChannelSpec], opts: ExportOptions, segment: TrackSegment,
                fs_expected: float | None = None) -> Response:
    """Check an export's samples and convert them to a :class:`Response` in m/s².

    Checks: at least 2 samples; the abscissa is finite and strictly
    increasing; steps are uniform within ``uniform_rtol``; the sampling rate
    matches ``fs_expected`` (Hz) when given; every value is finite; the record
    lasts ``segment.duration()`` within the tolerances.

    :raises SimulatorError: naming the file and, where one is to blame, the line.
    """
    path = data.path
    n = data.x.size
    if n < 2:
        raise SimulatorError(f"{path}: {n} sample(s); at least 2 are needed")
    x = data.x * opts.x_scale
    bad = np.flatnonzero(~np.isfinite(x))
    if bad.size:
        raise SimulatorError(f"{path}:{data.lines[bad[0]]}: non-finite {opts.x_kind}")
    if opts.x_kind == "distance":
        t = (x - x[0]) / float(np.mean(segment.speed))
    else:
        t = x
    steps = np.diff(t)
    back = np.flatnonzero(steps <= 0)
    if back.size:
        j = back[0] + 1
        raise SimulatorError(f"{path}:{data.lines[j]}: {opts.x_kind} does not increase "
                             f"({float(data.x[j - 1])!r} then {float(data.x[j])!r})")
    typical = float(np.median(steps))
    off = np.abs(steps - typical) > opts.uniform_rtol * typical
    if off.any():
        j = np.flatnonzero(off)[0] + 1
        raise SimulatorError(f"{path}:{data.lines[j]}: non-uniform sampling: a step of {steps[j - 1]:.6g} s where "
                             f"the typical step is {typical:.6g} s")
    dt = (t[-1] - t[0]) / (n - 1)
    fs = 1.0 / dt
    if fs_expected is not None and abs(fs - fs_expected) > opts.uniform_rtol * fs_expected:
        raise SimulatorError(f"{path}: sampling rate {fs:.6g} Hz, expected {fs_expected:g} Hz (option fs)")
    out = np.empty((len(channels), n))
    for i, ch in enumerate(channels):
        values = data.columns[ch.column]
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise SimulatorError(f"{path}:{data.lines[bad[0]]}: non-finite value {float(values[bad[0]])!r} in "
                                 f"'{ch.column}'")
        out[i] = values * ch.to_si
    duration = n / fs
    if opts.check_duration:
        expected = segment.duration()
        if abs(duration - expected) > max(opts.duration_atol_s, opts.duration_rtol * expected):
            raise SimulatorError(f"{path}: the record lasts {duration:.4g} s ({n} samples at {fs:.6g} Hz), expected "
                                 f"{expected:.4g} s for segment '{segment.name}' (truncated output?)")
    return Response(channels=tuple(c.name for c in channels), fs=float(fs), accelerations=out, segment=segment.name)
