"""Writing output files safely, and the one JSON canonical form.

Every file suspid writes goes to a temporary file in the same folder and is
then moved over the target with :func:`os.replace`, which is atomic on POSIX
and Windows: a full disk, a read-only folder or a kill during the write leaves
the previous good file intact, never a truncated one. Files that a later
date needs (the noise model, the ledger's companions) are also flushed to
disk (fsync) before the move.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from pathlib import Path
from typing import IO, Any, Iterator, Mapping

import numpy as np


def _file_mode() -> int:
    """The mode of a newly created file under this process's umask (0644 with the usual 022)."""
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


_FILE_MODE = _file_mode()


def canonical(obj: Any) -> Any:
    """JSON-able canonical form: sorted mappings, floats to 17 significant digits, arrays as lists,
    paths as strings, pydantic models as their JSON dump; anything else as its ``repr``."""
    if hasattr(obj, "model_dump"):
        return canonical(obj.model_dump(mode="json"))
    if isinstance(obj, Mapping):
        return {str(k): canonical(v) for k, v in sorted(obj.items(), key=lambda kv: str(kv[0]))}
    if isinstance(obj, (list, tuple)):
        return [canonical(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return [canonical(v) for v in obj.tolist()]
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(repr(float(obj)))
    if isinstance(obj, Path):
        return str(obj)
    return obj if obj is None or isinstance(obj, str) else repr(obj)


@contextlib.contextmanager
def atomic_open(path: str | Path, mode: str = "w", *, fsync: bool = False, **kwargs: Any) -> Iterator[IO]:
    """Open a temporary file beside ``path`` for writing; on success it replaces ``path`` atomically.

    On any error the temporary file is removed and ``path`` is left as it was.

    :param mode: ``"w"`` (text, UTF-8 unless ``encoding`` is given) or ``"wb"``.
    :param fsync: flush the data to disk before the move (files a later run depends on).
    """
    path = Path(path)
    if "b" not in mode:
        kwargs.setdefault("encoding", "utf-8")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.chmod(tmp, _FILE_MODE)  # mkstemp makes the file private (0600): give it an ordinary file's mode
        with os.fdopen(fd, mode, **kwargs) as fh:
            yield fh
            fh.flush()
            if fsync:
                os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def write_text(path: str | Path, text: str, *, fsync: bool = False) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically; returns ``path``."""
    with atomic_open(path, "w", fsync=fsync) as fh:
        fh.write(text)
    return Path(path)


def write_json(path: str | Path, obj: Any, *, fsync: bool = False) -> Path:
    """Write ``obj`` as indented JSON atomically (keys in their given order; numpy values converted)."""
    return write_text(path, json.dumps(obj, indent=2, default=_json_default) + "\n", fsync=fsync)


def _json_default(obj: Any) -> Any:
    if isinstance(obj, (np.generic, np.ndarray, Path)) or hasattr(obj, "model_dump"):
        return canonical(obj)
    raise TypeError(f"{type(obj).__name__} is not JSON serialisable")


def pyplot() -> Any:
    """matplotlib.pyplot on the Agg backend (files only, no display needed).

    Imported here, on first use, because matplotlib takes about a second to
    import and only the figure-writing steps need it.
    """
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig: Any, path: str | Path, dpi: int = 110) -> Path:
    """Save a matplotlib figure as PNG atomically and close it; returns ``path``."""
    plt = pyplot()
    try:
        with atomic_open(path, "wb") as fh:
            fig.savefig(fh, dpi=dpi, format="png")
    finally:
        plt.close(fig)
    return Path(path)
