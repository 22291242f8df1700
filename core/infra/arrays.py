"""Arrays read from files, their declared sizes checked before anything is allocated.

A file declares the shape and type of each array before its bytes: an ``.npy`` header (a noise model's
``.npz``, the run ledger's arrays), an HDF5 dataset, a MAT variable, the rows and columns of a CSV file. A
damaged or altered file can declare a ``(200000, 200000)`` float64 array (320 GB) in a file of 1 MB, and
numpy allocates what the header declares before it reads a byte: the run would end in "out of memory",
naming neither the file nor the cause. Every reader of suspid asks here first:

- :func:`check_fits`: the memory the array would take against the memory this process can still have
  (the machine's available memory, and the address-space limit ``RLIMIT_AS`` where one is set);
- :class:`CheckedNpz`: every member of an ``.npz`` archive, its declared shape and type against the bytes
  the archive holds for it (and :meth:`CheckedNpz.expect`, against the shape its reader expects);
- :func:`load_npy_bytes`: one ``.npy`` image held in memory (the ledger's arrays), likewise.

Each refusal is a :class:`~suspid.errors.DataError`, one line naming the file, what it declares and what was
expected.
"""

from __future__ import annotations

import math
import os
import resource
import zipfile
from dataclasses import dataclass
from io import BytesIO
from pathlib import Path
from typing import IO, Any, Sequence

import numpy as np
from numpy.lib import format as npy

from suspid.errors import DataError

__all__ = ["available_memory", "human_bytes", "declared", "nbytes", "check_fits", "check_bytes", "check_text", "npy_header",
           "CheckedNpz", "npy_bytes_problem", "load_npy_bytes"]

MAX_HEADER = 10_000
"""Largest ``.npy`` header read, bytes (numpy's own default limit)."""


def human_bytes(n: float) -> str:
    """``320 GB``, ``1.0 MB``, ``6.4 kB``, ``512 B`` (powers of 1000, as disks and ``ls -lh --si`` count)."""
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.1f} {unit}" if n / scale < 10 else f"{n / scale:.0f} {unit}"
    return f"{int(n)} B"


def _meminfo_available() -> int | None:
    """``MemAvailable`` of ``/proc/meminfo``, bytes (Linux), else the free physical pages."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        return None


def _address_space_left() -> int | None:
    """What ``RLIMIT_AS`` still allows this process to map, bytes (None without a limit)."""
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft == resource.RLIM_INFINITY:
        return None
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            size = next(int(line.split()[1]) * 1024 for line in fh if line.startswith("VmSize:"))
    except (OSError, ValueError, StopIteration):
        size = 0
    return max(soft - size, 0)


def available_memory() -> int | None:
    """Bytes this process can still allocate: the least of the machine's available memory and what its
    address-space limit leaves; None when the system says neither."""
    known = [v for v in (_meminfo_available(), _address_space_left()) if v is not None]
    return min(known) if known else None


def declared(shape: Sequence[int], dtype: Any) -> str:
    """``shape (200000, 200000) float64 (320 GB)``: what a file declares, in words."""
    dt = np.dtype(dtype)
    return f"shape {tuple(int(s) for s in shape)} {dt} ({human_bytes(nbytes(shape, dt))})"


def nbytes(shape: Sequence[int], dtype: Any) -> int:
    """Bytes of an array of ``shape`` and ``dtype``, in Python integers (no overflow on absurd shapes)."""
    return math.prod(int(s) for s in shape) * np.dtype(dtype).itemsize


def check_fits(where: str, what: str, shape: Sequence[int], dtype: Any, *, copies: float = 1.0) -> None:
    """Refuse an array this process could not hold, before allocating it.

    :param where: the file, as the message starts; :param what: the array (``array 'mean'``).
    :param copies: how many arrays of that size the reader holds at once (a CSV's column and its parsed block).
    :raises DataError: ``<where>: <what> declares shape (...) float64 (320 GB), more than the 2.1 GB of memory
        available (...)``.
    """
    need = nbytes(shape, dtype) * copies
    free = available_memory()
    if free is not None and need > free:
        times = f" (held {copies:g} times: {human_bytes(need)})" if copies != 1 else ""
        raise DataError(f"{where}: {what} declares {declared(shape, dtype)}{times}, more than the "
                        f"{human_bytes(free)} of memory available (a damaged file, or one too large for this machine)")


def check_bytes(where: str, what: str, need: float) -> None:
    """Refuse to read what would take ``need`` bytes (``what``: ``reading its 2.1 GB of text``) when this
    process cannot have them.

    :raises DataError: ``<where>: <what> needs about 13 GB, more than the 2.1 GB of memory available``.
    """
    free = available_memory()
    if free is not None and need > free:
        raise DataError(f"{where}: {what} needs about {human_bytes(need)}, more than the {human_bytes(free)} of "
                        f"memory available (a damaged file, or one too large for this machine)")


TEXT_PROBE = 1 << 20
"""Bytes of a text file looked at for NUL bytes before it is parsed (text never holds one)."""


def check_text(path: str | Path, expected: str = "delimited text") -> int:
    """Refuse a file that is not text, before any of it is parsed: a NUL byte among its first
    :data:`TEXT_PROBE` bytes (a binary file, a damaged one, a sparse file of zeros) is one error naming the file.

    :returns: the file's size, bytes.
    :raises DataError: ``<path>: not text: a NUL byte on line 1 (byte 0 of its 2.1 GB; ...)``.
    """
    path = Path(path)
    size = path.stat().st_size
    with open(path, "rb") as fh:
        head = fh.read(TEXT_PROBE)
    at = head.find(b"\0")
    if at >= 0:
        line = head.count(b"\n", 0, at) + 1
        raise DataError(f"{path}: not text: a NUL byte on line {line} (byte {at} of its {human_bytes(size)}; a binary "
                        f"or damaged file, expected {expected})")
    return size


def npy_header(fp: IO[bytes]) -> tuple[tuple[int, ...], np.dtype, int]:
    """The shape, type and header length (bytes) of the ``.npy`` image at ``fp`` (positioned at its start).

    :raises ValueError: not an ``.npy`` image, an unreadable header, or an object (pickled) type; the reason.
    """
    start = fp.tell()
    try:
        version = npy.read_magic(fp)
        reader = npy.read_array_header_1_0 if version == (1, 0) else npy.read_array_header_2_0
        shape, _, dtype = reader(fp, max_header_size=MAX_HEADER)
    except (ValueError, OSError, EOFError, SyntaxError, TypeError) as exc:
        raise ValueError(f"not a readable array ({str(exc).splitlines()[0][:120]})") from None
    if dtype.hasobject:
        raise ValueError(f"holds Python objects ({dtype}), expected numbers")
    return tuple(int(s) for s in shape), dtype, fp.tell() - start


@dataclass(frozen=True)
class Declared:
    """What an archive member declares: its shape and type, and the bytes the archive holds for its data."""

    shape: tuple[int, ...]
    dtype: np.dtype
    stored: int


class CheckedNpz:
    """An ``.npz`` archive whose members are read only once their declared sizes were checked: against the
    shape the reader expects (:meth:`expect`), the bytes the archive holds for each, and the memory available.

    ``with CheckedNpz(path, "noise model file") as npz: npz.expect("mean", (4, 200), "channels x frequencies");
    mean = npz.load("mean")``. Opening reads the members' headers only; nothing is allocated for a member before
    :meth:`load` has checked it.

    :raises DataError: not a zip archive or a member that is not an array (on opening), a member of another
        shape than expected (:meth:`expect`), one that declares more bytes than the file holds for it or more
        than the memory available (:meth:`load`); the message names the file and the member.
    """

    def __init__(self, path: str | Path, what: str) -> None:
        self.path, self.what = Path(path), what
        self.where = f"{what} {self.path}"
        try:
            self._zip = zipfile.ZipFile(self.path)
        except FileNotFoundError:
            raise DataError(f"{self.where} not found") from None
        except (OSError, zipfile.BadZipFile, ValueError, EOFError) as exc:
            raise DataError(f"{self.where} is not a readable .npz file ({exc})") from None
        try:
            self.members: dict[str, Declared] = {}
            for info in self._zip.infolist():
                if info.filename.endswith(".npy"):
                    name = info.filename[:-4]
                    with self._zip.open(info) as fp:
                        try:
                            shape, dtype, header = npy_header(fp)
                        except ValueError as exc:
                            raise DataError(f"{self.where}: array '{name}' {exc}") from None
                    self.members[name] = Declared(shape, dtype, info.file_size - header)
        except (zipfile.BadZipFile, OSError, EOFError, ValueError) as exc:
            self.close()
            raise DataError(f"{self.where} is not a readable .npz file ({exc})") from None
        except BaseException:
            self.close()
            raise

    def __enter__(self) -> "CheckedNpz":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def close(self) -> None:
        self._zip.close()

    @property
    def files(self) -> list[str]:
        """The names of the arrays, as ``np.load``'s ``NpzFile.files``."""
        return list(self.members)

    def _holds(self, name: str) -> str:
        """``""``, or what the file holds for a member that declares more (or fewer) bytes than that."""
        m = self.members[name]
        return "" if m.stored == nbytes(m.shape, m.dtype) else f"the file holds {human_bytes(max(m.stored, 0))} for it"

    def expect(self, name: str, shape: Sequence[int], meaning: str) -> None:
        """Refuse member ``name`` unless it declares ``shape`` (``meaning`` says what its axes are)."""
        got, want = self.members[name], tuple(int(s) for s in shape)
        if got.shape != want:
            holds = self._holds(name)
            raise DataError(f"{self.where}: array '{name}' declares {declared(got.shape, got.dtype)}, expected "
                            f"shape {want} ({meaning}){'; ' + holds if holds else ''}")

    def load(self, name: str) -> np.ndarray:
        """Member ``name``, read once its declared size matches the bytes the file holds for it and fits in
        the memory available."""
        m = self.members[name]
        holds = self._holds(name)
        if holds:
            raise DataError(f"{self.where}: array '{name}' declares {declared(m.shape, m.dtype)} but {holds} "
                            f"(a damaged or altered file)")
        check_fits(self.where, f"array '{name}'", m.shape, m.dtype)
        try:
            with self._zip.open(f"{name}.npy") as fp:
                return npy.read_array(fp, allow_pickle=False, max_header_size=MAX_HEADER)
        except (zipfile.BadZipFile, OSError, EOFError, ValueError) as exc:
            raise DataError(f"{self.where}: array '{name}' is damaged ({str(exc).splitlines()[0][:120]})") from None


def npy_bytes_problem(blob: bytes) -> str | None:
    """What is wrong with the ``.npy`` image ``blob`` (an unreadable header, an object type, more or fewer
    bytes declared than it holds: ``declares shape (...) float64 (320 GB) but holds 1.0 MB``), else None."""
    try:
        shape, dtype, header = npy_header(BytesIO(blob))
    except ValueError as exc:
        return str(exc)
    if len(blob) - header != nbytes(shape, dtype):
        return f"declares {declared(shape, dtype)} but holds {human_bytes(max(len(blob) - header, 0))}"
    return None


def load_npy_bytes(blob: bytes, where: str) -> np.ndarray:
    """The ``.npy`` image ``blob``, read once :func:`npy_bytes_problem` finds nothing wrong with it (so that a
    damaged header cannot make numpy allocate what it declares).

    :raises DataError: ``<where>: <the problem>``.
    """
    problem = npy_bytes_problem(blob)
    if problem is not None:
        raise DataError(f"{where}: {problem}")
    return npy.read_array(BytesIO(blob), allow_pickle=False, max_header_size=MAX_HEADER)
