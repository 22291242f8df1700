"""``tdms``: NI TDMS files through npTDMS.

Channels are named ``group/channel``. The file is opened in streaming mode
(``TdmsFile.open``: metadata only) and each channel's data is read when asked
for. The abscissa comes from the waveform properties ``wf_increment`` and
``wf_start_offset``, or from a channel named by the ``index`` option; the
unit from ``unit_string``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from pydantic import Field, PositiveFloat

from suspid.errors import DataError
from suspid.interfaces import Reader, Signal
from suspid.options import Section

from ._common import as_float, check_channel, check_exists, library_errors, optional_library, unknown_channel


class TdmsOptions(Section):
    """``recording.options`` of the ``tdms`` reader."""

    index: str | None = Field(default=None, description="channel (group/channel) of the abscissa")
    step: PositiveFloat | None = Field(default=None, description="sampling step for channels without "
                                       "waveform properties")


class TdmsReader(Reader):
    """NI TDMS through npTDMS."""

    name: ClassVar[str] = "tdms"
    extensions: ClassVar[tuple[str, ...]] = (".tdms",)
    Options: ClassVar[type] = TdmsOptions

    def __init__(self, path, **options) -> None:
        super().__init__(Path(path), **options)
        self.opts = TdmsOptions(**options)
        self._f: Any = None

    def _file(self) -> Any:
        if self._f is None:
            check_exists(self.path)
            nptdms = optional_library("nptdms", "npTDMS", self.path)
            with library_errors(self.path, "TDMS", "nptdms"):   # npTDMS raises several types for a file that is not TDMS
                self._f = nptdms.TdmsFile.open(str(self.path))
        return self._f

    def channels(self) -> list[str]:
        f = self._file()
        with library_errors(self.path, "TDMS", "nptdms"):
            return [f"{g.name}/{c.name}" for g in f.groups() for c in g.channels()
                    if f"{g.name}/{c.name}" != self.opts.index]

    def _channel(self, name: str) -> Any:
        f = self._file()
        group, _, chan = name.partition("/")
        try:
            return f[group][chan]
        except KeyError:
            raise unknown_channel(self.path, name, self.channels()) from None

    def _values(self, name: str) -> tuple[np.ndarray, Any]:
        """A channel's values as float64, its declared length (the file's metadata) checked first."""
        ch = self._channel(name)
        with library_errors(self.path, "TDMS", "nptdms"):
            n, dtype = len(ch), getattr(ch, "dtype", None)
        check_channel(self.path, name, (n,), dtype if isinstance(dtype, np.dtype) else np.float64)
        with library_errors(self.path, "TDMS", "nptdms"):
            return as_float(ch[:], self.path, name), ch

    def read(self, channel: str) -> Signal:
        values, ch = self._values(channel)
        with library_errors(self.path, "TDMS", "nptdms"):
            unit = str(ch.properties.get("unit_string", ""))
            if self.opts.index:
                return Signal(channel, values, unit, index=self._values(self.opts.index)[0])
            step = ch.properties.get("wf_increment", self.opts.step)
        if step is None:
            raise DataError(f"{self.path}: channel '{channel}' has no wf_increment property; give recording "
                            f"option 'index' (a channel) or 'step'")
        return Signal(channel, values, unit, step=float(step), start=float(ch.properties.get("wf_start_offset", 0.0)))

    def close(self) -> None:
        if self._f is not None:
            self._f.close()
            self._f = None
