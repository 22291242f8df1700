"""``mat``: MATLAB files, one numeric vector per channel.

Version 5 files are read through :func:`scipy.io.loadmat`, one variable at a
time (``variable_names=[...]``); version 7.3 files are HDF5 and are read
through h5py, one dataset at a time. MATLAB stores no units: the config
declares them. The abscissa is a variable (``index: t``) or a ``step``.
"""

from __future__ import annotations

import struct
from pathlib import Path
from typing import ClassVar

import h5py
import numpy as np
import scipy.io
from pydantic import Field, PositiveFloat

from suspid.errors import DataError
from suspid.interfaces import Reader, Signal
from suspid.options import Section

from ._common import as_float, check_channel, check_exists, library_errors, unknown_channel
from .hdf5 import datasets

HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


class MatOptions(Section):
    """``recording.options`` of the ``mat`` reader."""

    index: str | None = Field(default=None, description="variable of the abscissa (time in s, or distance in m)")
    step: PositiveFloat | None = Field(default=None, description="uniform sampling step when there is no "
                                       "index variable")


def v5_cut(path: Path) -> str | None:
    """Where a MATLAB version 5 file is cut short, or None when its elements fill it exactly.

    The file is a 128-byte header and then elements, each an 8-byte tag (type, byte count) and its data
    (padded to 8 bytes, except a compressed one). scipy lists the variables of a truncated file up to
    the cut without a word; a mapped channel would then be reported as absent.
    """
    size = path.stat().st_size
    with open(path, "rb") as fh:
        head = fh.read(128)
        if len(head) < 128:
            return f"{size} bytes, shorter than the 128-byte MATLAB header"
        if head[126:128] not in (b"IM", b"MI"):   # not version 5 (a version 4 file has no such header)
            return None
        order = "<" if head[126:128] == b"IM" else ">"
        offset = 128
        while offset < size:
            fh.seek(offset)
            tag = fh.read(8)
            if len(tag) < 8:
                return f"the element at byte {offset} is cut"
            kind, n = struct.unpack(order + "II", tag)
            if kind >> 16:      # a small element: its data are in the tag
                offset += 8
                continue
            end = offset + 8 + (n if kind == 15 else (n + 7) // 8 * 8)   # 15: miCOMPRESSED, not padded
            if end > size:
                return f"the variable at byte {offset} needs {end} bytes, the file has {size}"
            offset = end
    return None


def is_v73(path: Path) -> bool:
    """True for a MATLAB v7.3 file (HDF5 with a 512-byte MATLAB header)."""
    with open(path, "rb") as fh:
        fh.seek(512)
        return fh.read(8) == HDF5_SIGNATURE


class MatReader(Reader):
    """MATLAB v5 (scipy.io) and v7.3 (h5py) files."""

    name: ClassVar[str] = "mat"
    extensions: ClassVar[tuple[str, ...]] = (".mat",)
    Options: ClassVar[type] = MatOptions

    def __init__(self, path, **options) -> None:
        super().__init__(Path(path), **options)
        self.opts = MatOptions(**options)
        self._h5: h5py.File | None = None
        self._names: list[str] | None = None
        self._shapes: dict[str, tuple[int, ...]] = {}

    def _open(self) -> list[str]:
        if self._names is None:
            check_exists(self.path)
            if is_v73(self.path):
                with library_errors(self.path, "MATLAB 7.3 (HDF5)"):
                    self._h5 = h5py.File(self.path, "r")
                    self._names = [n for n in datasets(self._h5) if not n.startswith("#")]
            else:
                with library_errors(self.path, "MATLAB"):   # scipy raises several types for a file that is not MAT
                    info = scipy.io.whosmat(str(self.path))
                    cut = v5_cut(self.path)
                if cut:
                    raise DataError(f"{self.path}: damaged or truncated MATLAB file ({cut})")
                self._names = [name for name, shape, cls in info
                               if cls in ("double", "single", "int8", "int16", "int32", "int64", "uint8",
                                          "uint16", "uint32", "uint64") and len(shape) == 2 and min(shape) == 1]
                self._shapes = {name: shape for name, shape, _ in info}
        return self._names

    def channels(self) -> list[str]:
        return [n for n in self._open() if n != self.opts.index]

    def _vector(self, name: str) -> np.ndarray:
        names = self._open()
        if name not in names:
            raise unknown_channel(self.path, name, [n for n in names if n != self.opts.index])
        if self._h5 is not None:    # the declared size checked before the values are read
            d = self._h5[name]
            check_channel(self.path, name, d.shape, d.dtype)
        else:
            check_channel(self.path, name, self._shapes[name])
        with library_errors(self.path, "MATLAB"):
            if self._h5 is not None:
                return as_float(d[()], self.path, name)
            return as_float(scipy.io.loadmat(str(self.path), variable_names=[name])[name], self.path, name)

    def read(self, channel: str) -> Signal:
        values = self._vector(channel)
        if self.opts.index:
            return Signal(channel, values, "", index=self._vector(self.opts.index))
        if self.opts.step is None:
            raise DataError(f"{self.path}: the mat reader needs the abscissa: recording option 'index' "
                            f"(a variable) or 'step'")
        return Signal(channel, values, "", step=self.opts.step)

    def close(self) -> None:
        if self._h5 is not None:
            self._h5.close()
            self._h5 = None
