"""``csv``: long delimited text recordings (a header line of channel names, one row per sample).

Lines starting with ``#`` before the header are comments. Units may follow a
name in brackets (``ACC_Z_K1 [mm/s^2]``); the channel is then named without
them. The abscissa is a column (``index: time_s``) or a uniform ``step``.
The file is parsed in chunks of rows into preallocated columns, keeping only
the columns that :meth:`CsvReader.select` named; :meth:`CsvReader.read` hands
a column over (it is not kept), so that a long recording is held once.
"""

from __future__ import annotations

import itertools
import re
from pathlib import Path
from typing import ClassVar, Sequence

import numpy as np
from pydantic import Field, PositiveFloat, PositiveInt

from suspid.errors import DataError
from suspid.interfaces import Reader, Signal
from suspid.options import Section

from suspid.infra.arrays import check_fits, check_text, human_bytes

from ._common import check_exists, unknown_channel

TEXT = "delimited text: a header line of channel names, one row per sample"
MAX_LINE = 1 << 20
"""Longest line of a recording, bytes: thousands of columns of numbers (a file without newlines is no text)."""
BLOCK = 1 << 20
"""Bytes read at a time when the rows are counted."""

_UNIT = re.compile(r"^(.*?)\s*[\[(]([^\])]*)[\])]\s*$")


class CsvOptions(Section):
    """``recording.options`` of the ``csv`` reader."""

    delimiter: str = Field(default=",", min_length=1, max_length=1, description="column separator")
    index: str | None = Field(default=None, description="column of the abscissa (time in s, or distance in m)")
    step: PositiveFloat | None = Field(default=None, description="uniform sampling step when there is no "
                                       "index column (s, or m for a track record)")
    chunk_rows: PositiveInt = Field(default=200_000, description="rows parsed at a time")


class CsvReader(Reader):
    """Delimited text, one row per sample."""

    name: ClassVar[str] = "csv"
    extensions: ClassVar[tuple[str, ...]] = (".csv", ".txt")
    Options: ClassVar[type] = CsvOptions

    def __init__(self, path, **options) -> None:
        super().__init__(Path(path), **options)
        self.opts = CsvOptions(**options)
        self._columns: dict[str, np.ndarray] = {}
        self._header: list[str] | None = None
        self._units: dict[str, str] = {}
        self._skip = 0

    def _read_header(self) -> list[str]:
        if self._header is None:
            check_exists(self.path)
            check_text(self.path, TEXT)
            with open(self.path, "rb") as fh:     # lines read with a bound: a file without newlines is no header
                for n in itertools.count():
                    raw = fh.readline(MAX_LINE + 1)
                    if not raw:
                        raise DataError(f"{self.path}: no header line (column names) found")
                    if len(raw) > MAX_LINE:
                        raise self._long_line(n + 1)
                    line = raw.decode("utf-8", errors="replace")
                    if line.strip() and not line.lstrip().startswith("#"):
                        break
            names = []
            for raw in line.rstrip("\r\n").split(self.opts.delimiter):
                raw = raw.strip().strip('"')
                m = _UNIT.match(raw)
                name, unit = (m.group(1).strip(), m.group(2).strip()) if m else (raw, "")
                names.append(name)
                self._units[name] = unit
            if len(set(names)) != len(names):
                raise DataError(f"{self.path}: repeated column names in the header")
            self._header, self._skip = names, n + 1
        return self._header

    def channels(self) -> list[str]:
        return [c for c in self._read_header() if c != self.opts.index]

    def select(self, channels: Sequence[str]) -> None:
        header = self._read_header()
        wanted = list(dict.fromkeys([*channels, *([self.opts.index] if self.opts.index else [])]))
        for c in wanted:
            if c not in header:
                raise unknown_channel(self.path, c, header)
        wanted = [c for c in wanted if c not in self._columns]
        if not wanted:
            return
        cols = [header.index(c) for c in wanted]
        n_rows = self._count_rows()      # first: the columns are filled in place
        check_fits(str(self.path), f"{len(wanted)} columns of its {n_rows} rows", (len(wanted), n_rows), np.float64)
        data = [np.empty(n_rows) for _ in wanted]
        with open(self.path, encoding="utf-8", errors="replace") as fh:
            lines = itertools.islice(fh, self._skip, None)
            row, filled = self._skip + 1, 0
            while True:
                chunk = list(itertools.islice(lines, self.opts.chunk_rows))
                if not chunk:
                    break
                try:
                    block = np.loadtxt(chunk, delimiter=self.opts.delimiter, usecols=cols, ndmin=2,
                                       comments="#", dtype=np.float64)
                except ValueError as exc:
                    raise DataError(f"{self.path}: rows {row}-{row + len(chunk) - 1}: "
                                    f"{str(exc).splitlines()[0]}") from None
                m = min(block.shape[0], n_rows - filled)
                for j, column in enumerate(data):
                    column[filled:filled + m] = block[:m, j]
                filled += m
                row += len(chunk)
        for c, column in zip(wanted, data):
            self._columns[c] = column[:filled]

    def _long_line(self, line: int | str) -> DataError:
        return DataError(f"{self.path}: line {line} is longer than {human_bytes(MAX_LINE)}: not a delimited text "
                         f"recording (expected {TEXT})")

    def _count_rows(self) -> int:
        """The rows after the header (an upper bound: blank and comment lines count too), the whole file checked
        on the way in blocks of bytes: no NUL byte, no line longer than :data:`MAX_LINE`."""
        lines, run, offset = 0, 0, 0
        with open(self.path, "rb") as fh:
            while chunk := fh.read(BLOCK):
                nul = chunk.find(b"\0")
                if nul >= 0:
                    line = lines + chunk.count(b"\n", 0, nul) + 1
                    raise DataError(f"{self.path}: not text: a NUL byte on line {line} (byte {offset + nul}; a binary "
                                    f"or damaged file, expected {TEXT})")
                ends = np.flatnonzero(np.frombuffer(chunk, np.uint8) == ord("\n"))
                if not ends.size:
                    run += len(chunk)
                    if run > MAX_LINE:
                        raise self._long_line(lines + 1)
                    offset += len(chunk)
                    continue
                lengths = np.diff(ends, prepend=-1 - run)   # of each line this block ends, newline included
                if lengths.max() > MAX_LINE + 1:
                    raise self._long_line(lines + 1 + int(np.argmax(lengths > MAX_LINE + 1)))
                run = len(chunk) - int(ends[-1]) - 1
                lines += int(ends.size)
                offset += len(chunk)
        return max(lines + (run > 0) - self._skip, 0)

    def read(self, channel: str) -> Signal:
        if channel not in self._columns:
            self.select([channel])
        # the reader hands the column over (a second read parses the file again): the caller's copy on
        # its grid is then the only one in memory
        values = self._columns.pop(channel) if channel != self.opts.index else self._columns[channel]
        if self.opts.index:
            return Signal(channel, values, self._units.get(channel, ""), index=self._columns[self.opts.index])
        if self.opts.step is None:
            raise DataError(f"{self.path}: the csv reader needs the abscissa: recording option 'index' "
                            f"(a column) or 'step'")
        return Signal(channel, values, self._units.get(channel, ""), step=self.opts.step)

    def close(self) -> None:
        self._columns.clear()
