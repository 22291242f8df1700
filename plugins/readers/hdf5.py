"""``hdf5``: generic HDF5 recordings, one 1-D dataset per channel.

Channels are the dataset paths (``acc/ACC_Z_K1``; a dataset at the root is
just its name). The unit comes from a ``unit`` or ``units`` attribute. The
abscissa is a dataset (``index: time``), a ``step`` option, or the dataset's
own ``dt``/``step`` attribute (and ``t0``/``start``). Datasets are read one
at a time straight from the file.
"""

from __future__ import annotations

from pathlib import Path
from typing import ClassVar

import h5py
import numpy as np
from pydantic import Field, PositiveFloat

from suspid.errors import DataError
from suspid.interfaces import Reader, Signal
from suspid.options import Section

from ._common import as_float, check_channel, check_exists, library_errors, unknown_channel


class Hdf5Options(Section):
    """``recording.options`` of the ``hdf5`` reader."""

    index: str | None = Field(default=None, description="dataset of the abscissa (time in s, or distance in m)")
    step: PositiveFloat | None = Field(default=None, description="uniform sampling step when there is no "
                                       "index dataset and no dt attribute")


def _text(value) -> str:
    if isinstance(value, bytes):
        return value.decode(errors="replace")
    if isinstance(value, np.ndarray):
        return _text(value.reshape(-1)[0]) if value.size else ""
    return str(value)


def datasets(f: h5py.File) -> list[str]:
    """Paths of every 1-D (or n x 1) numeric dataset, in file order."""
    out: list[str] = []

    def visit(name, obj):
        if isinstance(obj, h5py.Dataset) and np.issubdtype(obj.dtype, np.number) and (
                obj.ndim == 1 or (obj.ndim == 2 and 1 in obj.shape)):
            out.append(name)
    f.visititems(visit)
    return out


class Hdf5Reader(Reader):
    """One 1-D dataset per channel."""

    name: ClassVar[str] = "hdf5"
    extensions: ClassVar[tuple[str, ...]] = (".h5", ".hdf5")
    Options: ClassVar[type] = Hdf5Options

    def __init__(self, path, **options) -> None:
        super().__init__(Path(path), **options)
        self.opts = Hdf5Options(**options)
        self._f: h5py.File | None = None

    def _file(self) -> h5py.File:
        if self._f is None:
            check_exists(self.path)
            with library_errors(self.path, "HDF5"):
                self._f = h5py.File(self.path, "r")
        return self._f

    def channels(self) -> list[str]:
        f = self._file()
        with library_errors(self.path, "HDF5"):
            return [c for c in datasets(f) if c != self.opts.index]

    def _dataset(self, channel: str):
        f = self._file()
        obj = f.get(channel)
        if not isinstance(obj, h5py.Dataset):
            raise unknown_channel(self.path, channel, self.channels())
        return obj

    def _values(self, channel: str) -> tuple[np.ndarray, h5py.Dataset]:
        """A dataset's values as float64, its declared size checked first."""
        d = self._dataset(channel)
        check_channel(self.path, channel, d.shape, d.dtype)
        with library_errors(self.path, "HDF5"):
            return as_float(d[()], self.path, channel), d

    def read(self, channel: str) -> Signal:
        values, d = self._values(channel)
        unit = _text(d.attrs.get("unit", d.attrs.get("units", "")))
        if self.opts.index:
            return Signal(channel, values, unit, index=self._values(self.opts.index)[0])
        step = self.opts.step or d.attrs.get("dt", d.attrs.get("step"))
        if step is None:
            raise DataError(f"{self.path}: channel '{channel}' has no abscissa: give recording option 'index' "
                            f"(a dataset) or 'step', or a 'dt' attribute")
        start = float(np.asarray(d.attrs.get("t0", d.attrs.get("start", 0.0))).reshape(-1)[0])
        return Signal(channel, values, unit, step=float(np.asarray(step).reshape(-1)[0]), start=start)

    def close(self) -> None:
        if self._f is not None:
            self._f.close()
            self._f = None
