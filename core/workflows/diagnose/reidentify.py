"""The models compared: the base model and the one augmented with the named effect (``augmented.yaml``).

Overview: ``docs/diagnose.md``, "How it works", step 5.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np
import yaml

from suspid.config import Config
from suspid.infra.files import canonical, write_text
from suspid.infra.lock import open_run_dir
from suspid.sections import OutputSection
from suspid.workflows.analysis import errors_percent
from suspid.workflows.identify import run
from suspid.workflows.problem import build_problem
from suspid.workflows.tasks import simulate_spectra

from .fit import Candidate
from .locate import DiscrepancyMap


@dataclass
class Stage:
    """One model of the comparison: its problem (data, noise model), parameters, spectra and map."""

    label: str
    config: Config
    problem: Any
    w: dict[str, float]
    y_sim: np.ndarray
    result: dict[str, Any] | None = None
    dmap: DiscrepancyMap | None = None
    fit: Any = None                      # the joint least-squares fit behind ``w`` (:class:`.joint.JointFit`)

    def gap(self) -> dict[str, Any]:
        """The map's gap measures, the suspension ``w`` (with its errors when w_ref is known) and, when ``w`` was
        fitted under D, the identification's own ``w_opt`` under ``identified``."""
        out = self.dmap.gap() if self.dmap is not None else {}
        out["w"] = {k: float(v) for k, v in self.w.items()}
        w_ref = getattr(self.problem, "w_ref", None)
        if w_ref and self.w:
            out["errors_percent"] = errors_percent(self.problem, np.array([self.w[n] for n in self.problem.names]))
            out["w_ref"] = {k: float(w_ref[k]) for k in self.w if k in w_ref}
        if self.fit is not None:
            out["suspension_fit"] = self.fit.as_dict()
        if self.result is not None:
            # the re-identification's trust as its run judged it: yes only where every required check ran there,
            # a component it did not judge is not assessed (None), never yes
            w_opt = self.result.get("w_opt") or {}
            trust = self.result.get("trustworthy") or {}
            out["identified"] = {"w": w_opt, "errors_percent": self.result.get("errors_percent"),
                                 "trustworthy": {n: trust.get(n) for n in w_opt},
                                 "not_assessed": self.result.get("not_assessed_reasons") or {
                                     n: ["the identification reported no trust"] for n in w_opt if trust.get(n) is None}}
        return out


def _with_output(config: Config, run_dir: Path) -> Config:
    return config.model_copy(update={"output": OutputSection(dir=run_dir, figure_channel=config.output.figure_channel)})


def make_stage(label: str, config: Config, identify: bool, run_dir: Path, *, fresh: bool, progress: bool,
               log: Callable[[str], None]) -> Stage:
    """The model of ``config`` at its identified parameters (a full run in ``run_dir``) or at the nominal ones."""
    cfg = _with_output(config, run_dir)
    if identify:
        log(f"{label}: identification (suspid run in {run_dir})")
        out = run(cfg, fresh=fresh, progress=progress, log=log)
        problem, result, w = out.problem, out.to_dict(), dict(out.w_opt)
    else:
        with open_run_dir(run_dir, config_name=cfg.name, config_file=cfg.source_file, fresh=fresh,
                          log=log) as ledger:
            problem, result, w = build_problem(cfg, ledger, log), None, {}
            problem.noise_model.save(run_dir / "noise_model.npz")
    y_sim = simulate_spectra(problem.simulator, w, problem.segments, cfg.spectra)[0]
    return Stage(label, cfg, problem, w, y_sim, result)


def augmented_data(config: Config, effects: list[tuple[str, dict[str, Any]]], noise_path: Path, run_dir: Path,
                   corrections: list[dict[str, Any]] = ()) -> dict[str, Any]:
    """The config (as data) with ``effects`` ``[(name, parameters)]`` appended to the simulator's effects,
    ``corrections`` to ``data.corrections`` and the base run's noise model; its output in ``run_dir``."""
    data = config.model_dump(mode="json", exclude={"source_file"})
    if "seed" not in config.data.track.model_fields_set:   # derived from the run seed: written, it would be fixed
        data["data"]["track"].pop("seed", None)            # at its default, and the file run on another track
    options = dict(data["simulator"].get("options") or {})
    options["effects"] = list(options.get("effects") or []) + [{"name": name, **canonical(params)}
                                                               for name, params in effects]
    data["simulator"]["options"] = options
    if corrections:
        data["data"]["corrections"] = list(data["data"].get("corrections") or []) + [canonical(c) for c in corrections]
    data["noise"] = {**(data.get("noise") or {}), "path": str(noise_path)}
    data["name"] = config.name if config.name.endswith("-augmented") else f"{config.name}-augmented"
    data["output"] = {"dir": str(run_dir), "figure_channel": config.output.figure_channel}
    return data


def augmented_config(config: Config, effects: list[tuple[str, dict[str, Any]]], out_dir: Path, noise_path: Path,
                     path: Path | None = None, run_dir: Path | None = None,
                     corrections: list[dict[str, Any]] = ()) -> Config:
    """The augmented model's config as a typed copy of ``config`` (:meth:`~suspid.config.Config.with_`: the
    named effects, the sensor corrections and the base run's noise model set, validated again), with
    ``augmented.yaml`` written beside it for the user (:func:`write_augmented`) and named as its source: the
    file is not read back."""
    path = write_augmented(config, effects, out_dir, noise_path, path, run_dir, corrections)
    data = augmented_data(config, effects, noise_path, run_dir or out_dir / "after", corrections)
    keys = {"simulator.options.effects": data["simulator"]["options"]["effects"], "noise.path": data["noise"]["path"],
            "name": data["name"], "output": data["output"]}
    if corrections:
        keys["data.corrections"] = data["data"]["corrections"]
    derived = config.with_(keys)
    derived.source_file = path.resolve()   # the run directory's owner is that file, as when it was read back
    return derived


def write_augmented(config: Config, effects: Candidate | list[tuple[str, dict[str, Any]]], out_dir: Path,
                    noise_path: Path, path: Path | None = None, run_dir: Path | None = None,
                    corrections: list[dict[str, Any]] = ()) -> Path:
    """``augmented.yaml``: the config with the named effects (``[(name, parameters)]``, or one candidate), the
    sensor corrections of the measured records (``data.corrections``) and the base run's noise model; output
    in ``out_dir/after`` unless ``run_dir``."""
    if isinstance(effects, Candidate):
        effects = [(effects.effect, effects.parameters)]
    data = augmented_data(config, effects, noise_path, run_dir or out_dir / "after", corrections)
    path = path or out_dir / "augmented.yaml"
    path.parent.mkdir(parents=True, exist_ok=True)
    names = ", ".join([f"'{n}'" for n, _ in effects] + [f"a tilt of {c['channel']}" for c in corrections])
    header = (f"# Written by suspid diagnose from {config.source_file}:\n"
              f"# the model with the named effects {names} and their fitted parameters,\n"
              f"# and the noise model of the base run (the measurements and B are unchanged).\n")
    return write_text(path, header + yaml.safe_dump(data, sort_keys=False))
