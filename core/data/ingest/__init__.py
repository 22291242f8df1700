"""``suspid ingest``: long recordings of a data-acquisition system cut into measured-data segments.

Public entry point: :func:`suspid.ingest` (the API) and ``suspid ingest
INGEST.yaml`` (the CLI). :func:`load_ingest` reads and validates an ingest
file; :func:`run` does the work (:mod:`suspid.data.ingest.workflow`). The method
and every config key are in ``docs/ingest.md``.
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

from pydantic import ValidationError

from suspid.config import apply_overrides, build_simulator, load_config, read_yaml
from suspid.errors import ConfigError
from suspid.options import raise_validation_error

from .options import IngestOptions
from .workflow import IngestResult, run_ingest

__all__ = ["IngestOptions", "IngestResult", "load_ingest", "run"]


def load_ingest(source: str | Path | Mapping[str, Any], overrides: Sequence[str] = ()
                ) -> tuple[IngestOptions, Path, str]:
    """An ingest file (or mapping) validated: ``(options, folder relative paths resolve against, file name)``.

    :raises suspid.errors.ConfigError: one line naming the file, the key path and what was expected.
    """
    if isinstance(source, Mapping):
        data, lines, file, base = copy.deepcopy(dict(source)), {}, "<mapping>", Path.cwd()
    else:
        path = Path(source)
        data, lines = read_yaml(path)
        file, base = str(path), path.resolve().parent
    data = apply_overrides(data, overrides, file)
    try:
        opts = IngestOptions.model_validate(data, context={"base_dir": base})
    except ValidationError as exc:
        raise_validation_error(exc, IngestOptions, file, lines)
    return opts, base, file


def run(source: str | Path | Mapping[str, Any], overrides: Sequence[str] = (), *, out_dir: str | Path | None = None,
        log: Callable[[str], None] = lambda s: None) -> IngestResult:
    """Load the ingest file, the simulator of its ``config`` (for the channel names), and ingest."""
    opts, base, file = load_ingest(source, overrides)
    cfg = load_config(opts.config if opts.config is not None else {})
    simulator = build_simulator(cfg)
    out = Path(out_dir) if out_dir is not None else opts.output_dir(base)
    try:
        return run_ingest(opts, simulator, out, log, f_max_hz=cfg.spectra.f_max_hz)
    except ConfigError as exc:
        if exc.file is None:   # a key of the ingest file, found while running: name the file
            raise ConfigError(exc.detail, file=file, key=exc.key) from None
        raise
