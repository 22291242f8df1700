"""Helpers shared by the built-in readers."""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from suspid.errors import DataError


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
