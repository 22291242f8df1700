"""Helpers shared by the built-in readers."""

from __future__ import annotations

import gc
import importlib
import logging
import sys
import traceback
import warnings
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator, Sequence

import numpy as np

from suspid.errors import DataError, DataWarning, SuspidError
from suspid.infra.arrays import check_fits


def optional_library(module: str, package: str, path: Path) -> Any:
    """Import the library of an optional format, or a DataError saying what to install."""
    try:
        return importlib.import_module(module)
    except ImportError:
        raise DataError(f"{path}: reading this format needs the package '{package}' "
                        f"(pip install 'suspid[ingest]')") from None


def unknown_channel(path: Path, channel: str, available: Sequence[str]) -> DataError:
    """The one error for a channel that is not in the file."""
    shown = ", ".join(list(available)[:40]) + (", ..." if len(available) > 40 else "")
    return DataError(f"{path}: no channel '{channel}' in the file; channels: {shown or 'none'}")


def check_exists(path: Path) -> None:
    if not path.is_file():
        raise DataError(f"{path}: file not found")


def check_channel(path: Path, channel: str, shape: Sequence[int], dtype: Any = np.float64) -> None:
    """Refuse a channel whose declared size (the file's shape and type, before it is read) this process could
    not hold together with its float64 copy (:func:`suspid.infra.arrays.check_fits`): a damaged file's absurd
    length is one error naming the file and the channel, not an allocation."""
    copies = 1.0 if np.dtype(dtype) == np.float64 else 1.0 + 8.0 / max(np.dtype(dtype).itemsize, 1)
    check_fits(str(path), f"channel '{channel}'", shape, dtype, copies=copies)


def as_float(values: Any, path: Path, channel: str) -> np.ndarray:
    """A 1-D float64 array of a channel's samples (a column or row vector is flattened)."""
    a = np.asarray(values)
    if a.ndim == 2 and 1 in a.shape:
        a = a.reshape(-1)
    if a.ndim != 1:
        raise DataError(f"{path}: channel '{channel}' has shape {a.shape}, expected one value per sample")
    if not np.issubdtype(a.dtype, np.number):
        raise DataError(f"{path}: channel '{channel}' is not numeric ({a.dtype})")
    return a.astype(np.float64, copy=False)


DAMAGE_MESSAGES = ("less data than expected", "metadata is incomplete", "cropping data", "not a multiple of")
"""Words (lower case) of a library's logged warnings that mean the file is cut short or damaged (npTDMS's
truncation messages); its other warnings (a property string not in UTF-8, a scaling it does not support)
are passed on as :class:`~suspid.errors.DataWarning`."""


class _Silenced(logging.Filter):
    """Keeps a library's log records from the console and remembers its warnings."""

    def __init__(self) -> None:
        super().__init__()
        self.warnings: list[str] = []

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno >= logging.WARNING:
            self.warnings.append(record.getMessage())
        return False


def _forget(exc: BaseException) -> None:
    """Drop the frames of ``exc``'s traceback now, with the finalizers they run kept quiet.

    An object the library was building when it failed (asammdf's ``MDF4`` on a truncated file)
    lives on in those frames, and its ``__del__`` fails on the missing parts: Python would print
    that as an "Exception ignored in ..." traceback after the one-line error.
    """
    hook = sys.unraisablehook
    sys.unraisablehook = lambda unraisable: None
    try:
        traceback.clear_frames(exc.__traceback__)   # the locals of the library's frames, `self` among them
        exc.__traceback__ = None
        gc.collect()
    finally:
        sys.unraisablehook = hook


@contextmanager
def library_errors(path: Path, what: str, logger: str | None = None) -> Iterator[None]:
    """Inside, whatever a format's library raises on a damaged file is one DataError naming the file.

    A truncated file or overwritten bytes fail anywhere inside the library, with any exception type
    (ValueError, KeyError, OSError, struct.error, ...); each becomes ``<path>: damaged or unreadable
    <what> file (<type>: <reason>)``. suspid's own errors pass through. Warnings the library logs
    under ``logger`` that mean a cut file (:data:`DAMAGE_MESSAGES`: npTDMS reads a truncated file on,
    saying it "has less data than expected") are refused the same way: a recording is used whole, or
    not at all; its other warnings become :class:`~suspid.errors.DataWarning`.
    """
    silenced = _Silenced()
    loggers = [logging.getLogger(n) for n in list(logging.root.manager.loggerDict)
               if logger and (n == logger or n.startswith(logger + "."))]
    for log in loggers:
        log.addFilter(silenced)
    try:
        yield
    except SuspidError:
        raise
    except MemoryError:
        raise DataError(f"{path}: out of memory while reading this {what} file") from None
    except Exception as exc:  # noqa: BLE001 - the library's failure on this file, whatever its type
        kind = type(exc).__name__ if type(exc).__module__ == "builtins" else \
            f"{type(exc).__module__.split('.')[0]}.{type(exc).__name__}"      # struct.error, not just error
        reason = f"{kind}: {str(exc).splitlines()[0] if str(exc) else ''}".rstrip(": ")
        _forget(exc)
        raise DataError(f"{path}: damaged or unreadable {what} file ({reason[:200]})") from None
    finally:
        for log in loggers:
            log.removeFilter(silenced)
    damage = [w for w in silenced.warnings if any(m in w.lower() for m in DAMAGE_MESSAGES)]
    if damage:
        raise DataError(f"{path}: damaged or truncated {what} file ({damage[0][:200]})")
    for other in silenced.warnings:      # e.g. a property string not in UTF-8, an unsupported scaling
        warnings.warn(f"{path}: {other[:200]}", DataWarning, stacklevel=3)
