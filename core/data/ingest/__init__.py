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

import os

import yaml

from suspid.config import apply_overrides, build_simulator, load_config, read_yaml
from suspid.errors import ConfigError
from suspid.infra.files import write_text
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
        file, base = str(path.resolve()), path.resolve().parent     # messages name it by its absolute path
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
        if opts.reference is None:
            return run_ingest(opts, simulator, out, log, f_max_hz=cfg.spectra.f_max_hz)
        if opts.reference.track.band != opts.track.band:
            raise ConfigError(f"the reference date's track record is declared as {opts.reference.track.band.describe()}"
                              f", the measurement date's as {opts.track.band.describe()}: a two-date config has "
                              f"one data.track_band", key="reference.track.band")
        log("measurement date")
        result = run_ingest(opts, simulator, out / "measurement", log, f_max_hz=cfg.spectra.f_max_hz)
        log("reference date")
        result.reference = run_ingest(opts.for_reference(), simulator, out / "reference", log,
                                      f_max_hz=cfg.spectra.f_max_hz)
    except ConfigError as exc:
        if exc.file is None:   # a key of the ingest file, found while running: name the file
            raise ConfigError(exc.detail, file=file, key=exc.key) from None
        raise
    result.config_path = write_two_date_config(opts, out, result)
    log(f"wrote {result.config_path}")
    return result


TWO_DATE_CONFIG = "two-dates.yaml"
"""The config a two-date ingest writes in its output folder."""


def write_two_date_config(opts: IngestOptions, out: Path, result: IngestResult) -> Path:
    """``<out>/two-dates.yaml``: the ingest's ``config`` with ``data`` and ``noise.reference`` on both dates.

    Everything of the source config is kept (simulator, parameters, spectra, objective, ...) but its data
    section, which becomes the measurement date's files (with ``track_band``, and the source's ``strict``,
    ``accept`` and ``corrections``), and ``noise.reference``, the reference date's; paths are relative to
    ``out``. Written atomically.
    """
    src: dict[str, Any] = read_yaml(opts.config)[0] if opts.config is not None else {}
    src_dir = opts.config.resolve().parent if opts.config is not None else out

    def rel(p: Path) -> str:
        return os.path.relpath(Path(p).resolve(), out.resolve())

    old = dict(src.get("data") or {})
    data: dict[str, Any] = {"source": "measured", "measurements": rel(result.measurements_path),
                            "track_file": rel(result.track_path)}
    if opts.track.band.filter != "full":
        data["track_band"] = opts.track.band.model_dump(mode="json", exclude_defaults=True) | {
            "filter": opts.track.band.filter}
    data |= {k: old[k] for k in ("strict", "accept", "corrections") if k in old}
    noise = {k: v for k, v in dict(src.get("noise") or {}).items() if k not in ("path", "reference")}
    noise["reference"] = {"measurements": rel(result.reference.measurements_path),
                          "track_file": rel(result.reference.track_path)}
    config = {"name": src.get("name", "two-dates")} | {k: v for k, v in src.items() if k not in
                                                        ("name", "data", "noise", "study", "monitor")}
    config |= {"data": data, "noise": noise}
    output = dict(config.get("output") or {})
    if "dir" in output:   # the source's run directory stays where it pointed
        output["dir"] = rel(src_dir / output["dir"])
        config["output"] = output
    head = (f"# Two-date identification on the recordings ingested by suspid ingest: the reference date "
            f"({opts.reference.recording.path.name}) and the measurement date ({opts.recording.path.name}).\n"
            f"# suspid validate {TWO_DATE_CONFIG} && suspid run {TWO_DATE_CONFIG}\n")
    path = out / TWO_DATE_CONFIG
    write_text(path, head + yaml.safe_dump(config, sort_keys=False))
    return path
