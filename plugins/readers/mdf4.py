"""``mdf4``: ASAM MDF 4 files (``.mf4``) through asammdf.

Channels are read one at a time (``MDF.get``), with their own time stamps
(the master channel of their group) and the unit the file stores; physical
values (the file's conversion rules applied). MDF stores a data group record
by record (all its channels interleaved), and asammdf keeps the group's
record buffer alive behind each channel it returns: a channel is therefore
read in slices of ``chunk_records`` records copied into its own array, so
that a one-hour group is never in memory whole. The file is handed to asammdf
as an open stream rather than a path: from a path asammdf maps the whole file
into memory, and every page it touches then counts in the process's resident
memory (the whole file, by the last channel).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from pydantic import Field, PositiveInt

from suspid.errors import DataError
from suspid.interfaces import Reader, Signal
from suspid.options import Section

from ._common import as_float, check_channel, check_exists, library_errors, optional_library, unknown_channel


class Mdf4Options(Section):
    """``recording.options`` of the ``mdf4`` reader (time stamps and units come from the file)."""

    chunk_records: PositiveInt = Field(default=65_536, description="records read at a time")


class Mdf4Reader(Reader):
    """ASAM MDF 4 through asammdf."""

    name: ClassVar[str] = "mdf4"
    extensions: ClassVar[tuple[str, ...]] = (".mf4", ".mdf")
    Options: ClassVar[type] = Mdf4Options

    def __init__(self, path, **options) -> None:
        super().__init__(Path(path), **options)
        self.opts = Mdf4Options(**options)
        self._mdf: Any = None
        self._stream: Any = None

    def _file(self) -> Any:
        if self._mdf is None:
            check_exists(self.path)
            asammdf = optional_library("asammdf", "asammdf", self.path)
            try:
                with library_errors(self.path, "MDF"):   # asammdf raises many types for a damaged file
                    self._stream = open(self.path, "rb")
                    self._mdf = asammdf.MDF(self._stream)   # a stream, not a path: no memory map of the file
            except DataError:
                self.close()
                raise
        return self._mdf

    def channels(self) -> list[str]:
        mdf = self._file()
        with library_errors(self.path, "MDF"):
            masters = {mdf.groups[i].channels[mdf.masters_db[i]].name for i in mdf.masters_db} \
                if hasattr(mdf, "masters_db") else set()
            return [n for n in mdf.channels_db if n not in masters]

    def read(self, channel: str) -> Signal:
        mdf = self._file()
        if channel not in mdf.channels_db:
            raise unknown_channel(self.path, channel, self.channels())
        group, index = mdf.channels_db[channel][0]
        n = int(mdf.groups[group].channel_group.cycles_nr)
        check_channel(self.path, channel, (2, n))     # its values and time stamps, before they are allocated
        step = self.opts.chunk_records
        values, times, unit = np.empty(n), np.empty(n), ""
        with library_errors(self.path, "MDF"):
            for start in range(0, max(n, 1), step):
                sig = mdf.get(channel, group=group, index=index, record_offset=start,
                              record_count=min(step, n - start))
                m = len(sig.samples)
                values[start:start + m] = as_float(sig.samples, self.path, channel)
                times[start:start + m] = sig.timestamps
                unit = sig.unit if isinstance(sig.unit, str) else str(sig.unit or "")
                del sig
        return Signal(channel, values, unit, index=times)

    def close(self) -> None:
        if self._mdf is not None:
            self._mdf.close()
            self._mdf = None
        if self._stream is not None:
            self._stream.close()
            self._stream = None
