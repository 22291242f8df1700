"""``mdf4``: ASAM MDF 4 files (``.mf4``) through asammdf.

Channels are read one at a time (``MDF.get``), with their own time stamps
(the master channel of their group) and the unit the file stores; physical
values (the file's conversion rules applied).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from suspid.errors import DataError
from suspid.interfaces import Reader, Signal
from suspid.options import Section

from ._common import as_float, check_exists, optional_library, unknown_channel


class Mdf4Options(Section):
    """``recording.options`` of the ``mdf4`` reader (none yet: time stamps and units come from the file)."""


class Mdf4Reader(Reader):
    """ASAM MDF 4 through asammdf."""

    name: ClassVar[str] = "mdf4"
    extensions: ClassVar[tuple[str, ...]] = (".mf4", ".mdf")
    Options: ClassVar[type] = Mdf4Options

    def __init__(self, path, **options) -> None:
        super().__init__(Path(path), **options)
        self._mdf: Any = None

    def _file(self) -> Any:
        if self._mdf is None:
            check_exists(self.path)
            asammdf = optional_library("asammdf", "asammdf", self.path)
            try:
                self._mdf = asammdf.MDF(str(self.path))
            except Exception as exc:  # asammdf raises many types for a file that is not MDF
                raise DataError(f"{self.path}: not a readable MDF file ({str(exc).splitlines()[0]})") from None
        return self._mdf

    def channels(self) -> list[str]:
        mdf = self._file()
        masters = {mdf.groups[i].channels[mdf.masters_db[i]].name for i in mdf.masters_db} \
            if hasattr(mdf, "masters_db") else set()
        return [n for n in mdf.channels_db if n not in masters]

    def read(self, channel: str) -> Signal:
        mdf = self._file()
        if channel not in mdf.channels_db:
            raise unknown_channel(self.path, channel, self.channels())
        sig = mdf.get(channel)
        unit = sig.unit if isinstance(sig.unit, str) else str(sig.unit or "")
        return Signal(channel, as_float(sig.samples, self.path, channel), unit,
                      index=np.asarray(sig.timestamps, dtype=np.float64))

    def close(self) -> None:
        if self._mdf is not None:
            self._mdf.close()
            self._mdf = None
