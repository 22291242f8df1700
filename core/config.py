"""YAML configuration: safe loading, ``--set`` overrides, typed validation.

A config names its plugins by registered name and gives each an ``options``
section that the plugin validates itself (its ``Options`` pydantic model)::

    name: quickstart
    seed: 1
    simulator: {plugin: exudyn-train, options: {solver: frequency}}
    parameters:                     # which parameters to identify, with bounds
      k_secondary_z: {lower: 0.3e6, upper: 0.9e6}
    objective: {plugin: overlap}
    surrogate: {plugin: gpy-kriging}

Every error is a :class:`~suspid.errors.ConfigError` naming the file, the key
path (``simulator.options.step``), the YAML line where one exists, and what
was expected. Relative paths resolve against the config file's folder; plugin
authors get the same behaviour by typing a field as :data:`ConfigPath`.
"""

from __future__ import annotations

import copy
import math
import re
import warnings
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import yaml
from pydantic import BaseModel, Field, PrivateAttr, ValidationError, model_validator

from suspid import registry
from suspid.data.plausibility import Doubt, refused, speed_doubts
from suspid.errors import ConfigError, DataWarning, UnknownPluginError
from suspid.fleet.options import FleetSection
from suspid.infra.seeds import seed_for
from suspid.method.floor import density_problem
from suspid.method.identifiability import IdentifiabilityOptions
from suspid.method.objective import validate_weights
from suspid.method.weights import EFFICIENT_NEEDS_REFERENCE
from suspid.method.spectra import SpectraOptions
from suspid.optimize.design import DesignOptions, default_n_initial
from suspid.optimize.ego import EGOOptions
from suspid.options import Section, against, key_error, raise_validation_error
from suspid.sections import (W_REF_MEASURED, DataSection, DiagnoseOptions, ExecutorSection, Limits, MonitorOptions, NoiseSection,
                             ObjectiveSection, OptimizerSection, OutputSection, ParameterBounds, PluginSection, SimulatorSection,
                             StudyOptions, SurrogateSection)
from suspid.elements import check_groups, declared_parameters, kind_of  # kind_of: also for suspid.workflows.verdict
from suspid.interfaces import ElementSimulator
from suspid.method.localisation import LocalisationOptions


def _with_seed(options: BaseModel, seed: int) -> BaseModel:
    """``options`` with ``seed`` set to ``seed`` unless the user gave one (seeds derive from the run seed)."""
    if "seed" in type(options).model_fields and "seed" not in options.model_fields_set:
        return options.model_copy(update={"seed": seed})
    return options


class Config(Section):
    """The whole run configuration, every section validated and typed."""

    name: str = Field(default="suspid-run", min_length=1, pattern=r"^[A-Za-z0-9_.\-]+$")
    seed: int = Field(default=0, ge=0, lt=2**32)
    simulator: SimulatorSection = Field(default_factory=SimulatorSection)
    parameters: dict[str, ParameterBounds | None] = Field(default_factory=dict)
    data: DataSection = Field(default_factory=DataSection)
    spectra: SpectraOptions = Field(default_factory=SpectraOptions)
    noise: NoiseSection = Field(default_factory=NoiseSection)
    objective: ObjectiveSection = Field(default_factory=ObjectiveSection)
    surrogate: SurrogateSection = Field(default_factory=SurrogateSection)
    design: DesignOptions = Field(default_factory=DesignOptions)
    ego: EGOOptions = Field(default_factory=EGOOptions)
    optimizer: OptimizerSection = Field(default_factory=OptimizerSection)
    executor: ExecutorSection = Field(default_factory=ExecutorSection)
    identifiability: IdentifiabilityOptions = Field(default_factory=IdentifiabilityOptions)
    study: StudyOptions | None = None
    monitor: MonitorOptions | None = None
    diagnose: DiagnoseOptions = Field(default_factory=DiagnoseOptions)
    limits: dict[str, Limits] = Field(default_factory=dict, description="acceptable domain per identified "
                                      "parameter or element group, for the maintenance verdict")
    localisation: LocalisationOptions = Field(default_factory=LocalisationOptions)
    output: OutputSection = Field(default_factory=OutputSection)
    fleet: FleetSection | None = None

    # set by load_config, not by the user
    source_file: Path | None = Field(default=None, exclude=True)
    _lines: dict[tuple, int] = PrivateAttr(default_factory=dict)  # YAML line of each key path
    _notes: list[str] = PrivateAttr(default_factory=list)  # what the dry run changed (validate and report.md say it)
    _raw: dict[str, Any] | None = PrivateAttr(default=None)  # the data it was validated from (Config.with_)
    _base_dir: Path | None = PrivateAttr(default=None)         # where that data's relative paths resolve
    _options: dict[tuple, str] = PrivateAttr(default_factory=dict)  # key path -> the --set option that gave it

    @model_validator(mode="after")
    def _derive_seeds(self) -> "Config":
        """Sections with their own ``seed`` get one derived from the run seed unless the config gives it."""
        self.design = _with_seed(self.design, seed_for(self.seed, "design"))
        self.ego = _with_seed(self.ego, seed_for(self.seed, "ego"))
        return self

    def resolve(self, path: str | Path) -> Path:
        """``path`` with ``~`` expanded; relative paths are taken from the config file's folder."""
        return against(path, self.source_file.parent if self.source_file is not None else None)

    def run_dir(self) -> Path:
        """The run directory: ``output.dir`` or ``runs/<name>/`` beside the config."""
        if self.output.dir is not None:
            return self.output.dir
        base = self.source_file.parent if self.source_file else Path.cwd()
        return base / "runs" / self.name

    def error(self, message: str, key: str) -> ConfigError:
        """A one-line :class:`ConfigError` naming this config's file, ``key`` and its YAML line (or the ``--set``
        option that gave the value of ``key``)."""
        return from_option(key_error(message, key, self.file, self._lines), self._options)

    def with_(self, *updates: Mapping[str, Any], **keys: Any) -> "Config":
        """A copy with ``updates`` (``{"key.path": value}`` mappings with typed values, applied in order), then
        ``keys`` (top-level keys) set, validated again as the config was loaded (:func:`derive`): seeds derived
        anew, plugins' options checked, nothing read from a file.

        :raises ConfigError: the derived config is invalid (naming the key).
        """
        return derive(self, *updates, keys)

    @property
    def file(self) -> str:
        """The config file, for error messages."""
        return str(self.source_file) if self.source_file else "<config>"


# -- YAML with line numbers ------------------------------------------------------
def _line_map(node: yaml.Node, file: str, path: tuple = ()) -> dict[tuple, int]:
    """Key path -> 1-based YAML line; rejects duplicate keys (PyYAML silently keeps the last)."""
    lines = {path: node.start_mark.line + 1}
    if isinstance(node, yaml.MappingNode):
        seen: set = set()
        for key_node, value_node in node.value:
            key = key_node.value
            if key in seen:
                raise ConfigError(f"duplicate key '{key}'", file=file,
                                  key=".".join(map(str, path + (key,))), line=key_node.start_mark.line + 1)
            seen.add(key)
            lines.update(_line_map(value_node, file, path + (key,)))
            lines[path + (key,)] = key_node.start_mark.line + 1
    elif isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            lines.update(_line_map(item, file, path + (i,)))
    return lines


MAX_DEPTH = 64
"""Deepest nesting of mappings and sequences a config may have."""
MAX_VALUES = 100_000
"""Most values a config may expand to, aliases expanded (a config has a few hundred)."""


class ConfigLoader(yaml.SafeLoader):
    """YAML's safe loader that also reads ``14.68e6`` and ``1e-4`` as numbers.

    PyYAML follows YAML 1.1, where a float needs a dot and a signed exponent:
    ``3.3e5`` and ``1e3`` would be strings, and a config value such as a vehicle
    parameter written that way would be refused as "not a number". YAML 1.2 (and
    every engineer) reads them as floats.
    """


ConfigLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$"),
    list("-+0123456789."))


def parse_yaml(text: str) -> Any:
    """A YAML document with :class:`ConfigLoader` (safe; exponents with or without sign are floats)."""
    return yaml.load(text, Loader=ConfigLoader)


def _check_shape(text: str, file: str) -> None:
    """Refuse, in linear time, YAML nested too deeply or expanding to too many values through aliases.

    A 1 KB document of nested aliases (a "billion laughs") expands to billions of
    values; 20 000 nested brackets exhaust the parser's recursion. The event
    stream is read once, iteratively, and the expanded size of every anchored
    node is counted once (an alias adds the size of its anchor).
    """
    depth, sizes, open_sizes, open_anchors = 0, {}, [0], []
    for event in yaml.parse(text, Loader=yaml.SafeLoader):
        if isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
            depth += 1
            if depth > MAX_DEPTH:
                raise ConfigError(f"YAML nested deeper than {MAX_DEPTH} levels", file=file,
                                  line=event.start_mark.line + 1)
            open_sizes.append(1)
            open_anchors.append(event.anchor)
        elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
            depth -= 1
            size, anchor = open_sizes.pop(), open_anchors.pop()
            if anchor is not None:
                sizes[anchor] = size
            open_sizes[-1] += size
        elif isinstance(event, yaml.ScalarEvent):
            if event.anchor is not None:
                sizes[event.anchor] = 1
            open_sizes[-1] += 1
        elif isinstance(event, yaml.AliasEvent):
            open_sizes[-1] += sizes.get(event.anchor, 1)
        if open_sizes[-1] > MAX_VALUES or sum(open_sizes) > MAX_VALUES:
            raise ConfigError(f"YAML expands to more than {MAX_VALUES} values (aliases expanded); "
                              f"a config needs far fewer", file=file,
                              line=getattr(event, "start_mark", None) and event.start_mark.line + 1)


def read_yaml(path: Path) -> tuple[dict[str, Any], dict[tuple, int]]:
    """Safe-load a YAML mapping and the line of every key path.

    A UTF-8 byte-order mark (what spreadsheet programs write) is accepted. Errors name the file by its
    absolute path.
    """
    file = str(Path(path).resolve())
    try:
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise ConfigError("config file not found", file=file) from None
    except IsADirectoryError:
        raise ConfigError("expected a YAML file, got a directory", file=file) from None
    except UnicodeDecodeError as exc:
        raise ConfigError(f"not a UTF-8 text file ({exc.reason} at byte {exc.start})", file=file) from None
    except OSError as exc:
        raise ConfigError(f"cannot read config: {exc.strerror or exc}", file=file) from None
    try:
        _check_shape(text, file)
        node = yaml.compose(text, Loader=ConfigLoader)
        data = parse_yaml(text)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        raise ConfigError(f"YAML syntax error: {exc.problem or exc}", file=file,
                          line=mark.line + 1 if mark else None) from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"YAML error: {exc}", file=file) from None
    except (ValueError, TypeError, OverflowError) as exc:  # e.g. an impossible date such as 2026-13-01
        raise ConfigError(f"YAML value error: {exc}", file=file) from None
    if data is None:
        data, node = {}, None
    if not isinstance(data, dict):
        raise ConfigError(f"the top level must be a mapping of sections, got {type(data).__name__}", file=file)
    return data, (_line_map(node, file) if node is not None else {})


def apply_overrides(data: dict[str, Any], overrides: Sequence[str], file: str) -> dict[str, Any]:
    """Apply ``--set key.path=value`` overrides (values parsed as YAML scalars or flows).

    :raises ConfigError: naming the ``--set`` option (not the file: the value is not in it).
    """
    data = copy.deepcopy(data)
    for item in overrides:
        if "=" not in item:
            raise ConfigError("expected key.path=value", option=f"--set {item}")
        key, raw = item.split("=", 1)
        try:
            value = parse_yaml(raw) if raw.strip() else ""
        except yaml.YAMLError:
            value = raw
        try:
            set_path(data, key, value, file)
        except ConfigError as exc:
            raise ConfigError(exc.detail, option=f"--set {item}") from None
    return data


def option_paths(overrides: Sequence[str]) -> dict[tuple, str]:
    """Key path (``("ego", "max_iter")``) -> the ``--set`` option that set it, for :func:`from_option`."""
    return {tuple(item.split("=", 1)[0].strip().split(".")): f"--set {item}" for item in overrides if "=" in item}


def from_option(exc: ConfigError, options: Mapping[tuple, str]) -> ConfigError:
    """``exc`` naming the ``--set`` option that gave the value of its key (or of a parent of it), else ``exc``:
    a value given on the command line has no line in the file."""
    if exc.key is None or exc.option is not None:
        return exc
    parts = tuple(exc.key.split("."))
    for path, option in options.items():
        if parts[:len(path)] == path:    # the key inside a value the option set (--set a={b: 1}) is named too
            return ConfigError(exc.detail, option=option if len(parts) == len(path) else f"{option}, key '{exc.key}'")
    return exc


def set_path(data: dict[str, Any], key: str, value: Any, file: str) -> None:
    """Set ``key`` (``a.b.0.c``: mappings and list indices) of ``data`` to ``value`` in place."""
    parts = key.strip().split(".")
    if not all(parts):
        raise ConfigError(f"an empty key in '{key}'", file=file, key=key)
    node: Any = data
    for depth, part in enumerate(parts[:-1]):
        here = ".".join(parts[: depth + 1])
        if isinstance(node, dict):
            node = node.setdefault(part, {})
        elif isinstance(node, list) and part.isdigit() and int(part) < len(node):
            node = node[int(part)]
        else:
            raise ConfigError(f"'{here}' is not a mapping that can hold '{parts[depth + 1]}'", file=file, key=key)
    last = parts[-1]
    if isinstance(node, dict):
        node[last] = value
    elif isinstance(node, list) and last.isdigit() and int(last) < len(node):
        node[int(last)] = value
    else:
        raise ConfigError(f"the parent of '{last}' is not a mapping", file=file, key=key)


def override_arguments(mapping: Mapping[str, Any]) -> list[str]:
    """``{"key.path": value}`` as ``--set`` arguments ``["key.path=<YAML flow value>"]`` for :func:`load_config`."""
    return [f"{k}={yaml.safe_dump(v, default_flow_style=True).strip().removesuffix('...').strip()}"
            for k, v in mapping.items()]


def validate_options(cls: type, options: Mapping[str, Any], *, file: str, key: str,
                     lines: Mapping[tuple, int] | None = None, base_dir: Path | None = None,
                     seed: int | None = None) -> dict[str, Any]:
    """Validate a plugin's ``options`` with its ``Options`` model; returns the validated options.

    Plugins without an ``Options`` model get their options back unchanged.

    :param seed: for an ``Options`` model with a ``seed`` field that the user left out: the
        seed derived from the run seed (so that every random draw follows the config's seed).
    """
    model = getattr(cls, "Options", None)
    if model is None:
        return dict(options)
    options = dict(options)
    if seed is not None and "seed" in model.model_fields and "seed" not in options:
        options["seed"] = seed
    try:
        validated = model.model_validate(options, context={"base_dir": base_dir})
    except ValidationError as exc:
        raise_validation_error(exc, model, file, lines or {}, tuple(key.split(".")))
    return validated.model_dump()  # plain data: hashable identity, picklable, YAML-dumpable


def load_config(source: str | Path | Mapping[str, Any], overrides: Sequence[str] = (), *,
                check_plugins: bool = True, base_dir: str | Path | None = None) -> Config:
    """Read, override and validate a config: every section is resolved into its typed model.

    :param source: the YAML file, or a mapping with the same content (a notebook's dict).
    :param overrides: ``key.path=value`` strings, as ``--set`` takes them.
    :param check_plugins: also resolve plugins by name, validate their options
        (executor included), check the parameter names against the simulator,
        the channel weights and the figure channel.
    :param base_dir: the folder relative paths of a mapping resolve against
        (default: the current folder); a file's own folder otherwise.
    :raises ConfigError: on the first problem, naming file, key and line.
    """
    if check_plugins:
        registry.registry()  # plugin load errors first (strict mode), whatever the config says
    if isinstance(source, Mapping):
        file, path, lines = "<mapping>", None, {}
        data = copy.deepcopy(dict(source))
        folder = Path(base_dir).resolve() if base_dir is not None else Path.cwd()
    else:
        path = Path(source)
        file = str(path.resolve())          # messages name the file by its absolute path, as Config.file does
        data, lines = read_yaml(path)
        if not data:
            raise ConfigError(EMPTY_CONFIG, file=file)
        folder = path.resolve().parent
    data = apply_overrides(data, overrides, file)
    return _validated(data, file, path, lines, folder, check_plugins, option_paths(overrides))


EMPTY_CONFIG = ("the config is empty (no sections); a config names at least the parameters to identify under "
                "parameters: (`suspid parameters` lists a simulator's)")


def _validated(data: dict[str, Any], file: str, path: Path | None, lines: dict[tuple, int], folder: Path,
               check_plugins: bool, options: Mapping[tuple, str] | None = None) -> Config:
    """``data`` (a config as read, overrides applied) validated into a :class:`Config` (:func:`load_config`).

    :param options: key path -> the ``--set`` option that gave its value (its errors name the option).
    """
    options = dict(options or {})
    try:
        try:
            config = Config.model_validate(data, context={"base_dir": folder})
        except ValidationError as exc:
            raise_validation_error(exc, Config, file, lines)
        config.source_file = path.resolve() if path is not None else None
        config._lines = lines
        config._raw = copy.deepcopy(data)
        config._base_dir = folder
        config._options = options
        if check_plugins:
            check_config_plugins(config)
    except ConfigError as exc:
        raise from_option(exc, options) from None
    return config


def loaded(source: str | Path | Mapping[str, Any], overrides: Sequence[str], config: Config) -> Config:
    """``config`` when it can be derived (:meth:`Config.with_`), else the same config loaded again from
    ``source`` with ``overrides`` (a config built without :func:`load_config`)."""
    return config if config._raw is not None else load_config(source, overrides)


def derive(config: Config, *updates: Mapping[str, Any]) -> Config:
    """``config`` with ``updates`` (``"key.path" -> value``, typed values: no YAML text; one mapping after the
    other, each in order) applied to the data it was loaded from, validated again as :func:`load_config` validates (seeds derived, plugins' options
    checked): what ``load_config(source, overrides)`` with those keys set gives, without reading the file
    again. :meth:`Config.with_` calls it.

    :raises ConfigError: the derived config is invalid (naming the key).
    """
    if config._raw is None:
        raise ConfigError("this config was not loaded by load_config: it cannot be derived", file=config.file)
    data = copy.deepcopy(config._raw)
    for mapping in updates:
        for path, value in mapping.items():
            set_path(data, path, copy.deepcopy(value), config.file)
    return _validated(data, config.file, config.source_file, config._lines, config._base_dir, check_plugins=True,
                      options=config._options)


def plugin_class(kind: str, section: PluginSection, key: str, config: Config) -> type:
    """Resolve a plugin section's name to its class, or a ConfigError listing the available ones."""
    try:
        return registry.get(kind, section.plugin)
    except UnknownPluginError as exc:
        raise config.error(str(exc), f"{key}.plugin") from None


def check_config_plugins(config: Config) -> None:
    """Resolve every plugin by name and validate its options; check parameters, weights, figure channel.

    Plugins' options become validated plain data (workers receive them as they are).
    A plugin whose ``Options`` has a ``seed`` gets one derived from the run seed
    unless the config gives it.
    """
    base_dir = config.source_file.parent if config.source_file else None
    for kind in ("simulator", "objective", "surrogate", "executor"):
        section: PluginSection = getattr(config, kind)
        cls = plugin_class(kind, section, kind, config)
        section.options = validate_options(cls, section.options, file=config.file, key=f"{kind}.options",
                                           lines=config._lines, base_dir=base_dir,
                                           seed=seed_for(config.seed, kind))
    check_optimizer_section(config, base_dir)
    sim_cls = type(build_simulator(config))
    for date in ("reference", "measurement"):  # the simulator of a date of the numerical experiment
        extra = getattr(config.data, date).simulator_options
        if extra:
            validate_options(sim_cls, dict(config.simulator.options) | extra, file=config.file,
                             key=f"data.{date}.simulator_options", lines=config._lines, base_dir=base_dir)
    simulator = build_simulator(config)
    check_parameters(config, simulator)
    if config.data.source == "measured" and config.data.w_ref:   # measured data have no known truth to use
        raise config.error(W_REF_MEASURED, "data.w_ref")
    check_nuisance(config, simulator)
    check_limits(config, simulator)
    check_speeds(config)
    channels = simulator.channels()
    channel_weights(config, channels)
    if config.objective.weights == "efficient" and (
            config.noise.path is not None if config.data.source == "experiment" else config.noise.reference is None):
        raise config.error(EFFICIENT_NEEDS_REFERENCE, "objective.weights")
    figure_channel(config, channels)
    problem = density_problem(config.noise.sensor_noise_density, channels)
    if problem is not None:
        raise config.error(problem, "noise.sensor_noise_density")
    for i, name in enumerate(config.diagnose.effects or []):
        if name not in registry.names("effect"):
            raise config.error(f"unknown effect '{name}'; effects: {', '.join(registry.names('effect'))}",
                               f"diagnose.effects.{i}")


def judge_value(config: Config, doubts: Sequence[Doubt], key: str) -> None:
    """Findings about a value of the config (``key``) judged by the policy of measured data
    (:func:`suspid.data.plausibility.judge`): the impossible refused unless ``data.accept`` names its check, the
    unusual a warning (an error with ``data.strict``), in the same words, after the config's file, line and key.

    :raises ConfigError: the first refused finding.
    """
    refusal = refused(doubts, accept=config.data.accept)
    if refusal is not None:
        raise config.error(refusal, key)
    messages = [d.message + (f" (accepted: {d.check} in data.accept)" if d.check else "") for d in doubts]
    if config.data.strict and any(d.check is None for d in doubts):
        raise config.error(next(m for m, d in zip(messages, doubts) if d.check is None) + " (refused in strict mode)",
                           key)
    for message in messages:
        warnings.warn(str(config.error(message, key)), DataWarning, stacklevel=3)


def check_speeds(config: Config) -> None:
    """The speed of a numerical experiment (``data.track``) is judged as a track file's speed is: a train faster
    than any that has run is refused with the words a track file at that speed gets."""
    if config.data.source != "experiment":
        return      # measured data: every segment's speed is judged in its file
    track = config.data.track
    key = "data.track.speed_mps" if track.speed_mps is not None else "data.track.speed_kmh"
    judge_value(config, speed_doubts(track.speed), key)


def check_optimizer_section(config: Config, base_dir: Path | None) -> None:
    """Resolve ``optimizer.plugin`` and validate its options (seeded from the run seed).

    An optimiser with an ``options_section`` (the ``ego`` plugin: ``ego:``) takes that
    section as its options when ``optimizer.options`` is empty; options given there are
    validated over it and written back, so that the section and the options agree.
    """
    section = config.optimizer
    cls = plugin_class("optimizer", section, "optimizer", config)
    home = getattr(cls, "options_section", None)
    if home and isinstance(getattr(config, home, None), BaseModel):
        current = getattr(config, home)
        options = current.model_dump() | dict(section.options)
        validated = validate_options(cls, options, file=config.file, key="optimizer.options",
                                     lines=config._lines, base_dir=base_dir)
        setattr(config, home, type(current).model_validate(validated))
        section.options = validated
        return
    section.options = validate_options(cls, section.options, file=config.file, key="optimizer.options",
                                       lines=config._lines, base_dir=base_dir)


def optimizer_budget(config: Config, q: int) -> int:
    """``optimizer.budget``, or what the paper's loop may spend: m0 + m1 (+ the refinement's points)."""
    if config.optimizer.budget is not None:
        return config.optimizer.budget
    m0 = config.design.n_initial if config.design.n_initial is not None else default_n_initial(q)
    ego = config.ego
    return m0 + ego.max_iter + (ego.refine.max_iter if ego.refine.enabled else 0)


def channel_weights(config: Config, channels: Sequence[str]) -> np.ndarray:
    """α_k of eq. 5 from ``objective.weights``, ``(n_channels,)`` normalised to sum 1; default 1/n."""
    try:
        return validate_weights(config.objective.weights, channels)
    except ConfigError as exc:
        raise config.error(exc.detail, "objective.weights") from None


def figure_channel(config: Config, channels: Sequence[str]) -> int:
    """Index of the channel of Figure 1: ``output.figure_channel``, or the first carbody vertical one."""
    wanted = config.output.figure_channel
    if wanted is not None:
        if wanted not in channels:
            raise config.error(f"unknown channel '{wanted}'; channels are {', '.join(channels)}",
                               "output.figure_channel")
        return list(channels).index(wanted)
    for i, c in enumerate(channels):
        if "carbody" in c and "vertical" in c:
            return i
    return 0


def build_simulator(config: Config):
    """Instantiate the configured simulator (cheap: constructors only store options)."""
    cls = registry.get("simulator", config.simulator.plugin)
    return cls(**config.simulator.options)


def check_parameters(config: Config, simulator) -> None:
    """Identified parameter names must be the simulator's; lower < upper after defaults."""
    file, lines = config.file, config._lines
    known = {p.name: p for p in declared_parameters(simulator)}
    for group, names in (("parameters", config.parameters), ("data.w_ref", config.data.w_ref)):
        for name, message in check_groups(simulator, list(names), where=group):   # element groups: kind[tag,...]
            raise ConfigError(message, file=file, key=f"{group}.{name}",
                              line=lines.get(tuple(group.split(".")) + (name,)))
        for name in names:
            if name not in known:
                raise ConfigError(
                    f"unknown parameter '{name}' for simulator '{config.simulator.plugin}'; "
                    f"known: {', '.join(sorted(n for n in known if '[' not in n))}"
                    + (" and element groups kind[tag,...] (see `suspid observability`)" if len(known) > len(
                        [n for n in known if '[' not in n]) else ""),
                    file=file, key=f"{group}.{name}", line=lines.get(tuple(group.split(".")) + (name,)))
    kinds = config.localisation.kinds
    if kinds is not None:
        have = list(dict.fromkeys(e.kind for e in simulator.elements())) if isinstance(simulator, ElementSimulator) \
            else []
        bad = [k for k in kinds if k not in have]
        if bad:
            raise ConfigError(f"kind(s) {', '.join(bad)} have no elements declared by simulator "
                              f"'{config.simulator.plugin}' (kinds with elements: {', '.join(have) or 'none'})",
                              file=file, key="localisation.kinds", line=lines.get(("localisation", "kinds")))
    bounds = identified_bounds(config, simulator)
    for name in config.parameters:
        lower, upper = bounds[name]
        if not (math.isfinite(lower) and math.isfinite(upper)):
            raise ConfigError(f"bounds must be finite numbers, got [{lower:g}, {upper:g}] ({known[name].unit})",
                              file=file, key=f"parameters.{name}", line=lines.get(("parameters", name)))
        domain = known[name].domain
        if not (domain[0] < lower and upper < domain[1]):
            raise ConfigError(f"bounds [{lower:g}, {upper:g}] leave the physical domain ({domain[0]:g}, "
                              f"{domain[1]:g}) {known[name].unit} of this parameter",
                              file=file, key=f"parameters.{name}", line=lines.get(("parameters", name)))
        if not lower < upper:
            raise ConfigError(f"lower bound {lower:g} must be below upper bound {upper:g} ({known[name].unit})",
                              file=file, key=f"parameters.{name}", line=lines.get(("parameters", name)))
    for name, value in config.data.w_ref.items():
        lower, upper = bounds.get(name, (known[name].lower, known[name].upper))
        if not lower <= value <= upper:
            raise ConfigError(f"w_ref value {value:g} lies outside the admissible interval "
                              f"[{lower:g}, {upper:g}] {known[name].unit}",
                              file=file, key=f"data.w_ref.{name}", line=lines.get(("data", "w_ref", name)))


def check_nuisance(config: Config, simulator) -> None:
    """``identifiability.model_error.nuisance.parameters`` and ``.calibration.parameters``: the simulator's, not
    identified, low < high in its domain (a calibration range may be null: the simulator's bounds)."""
    known = {p.name: p for p in declared_parameters(simulator)}
    identified = set(config.parameters) or set(simulator.default_parameters())
    me = config.identifiability.model_error
    for section, given in (("nuisance", me.nuisance.parameters), ("calibration", me.calibration.parameters)):
        for name, ends in given.items():
            key = f"identifiability.model_error.{section}.parameters.{name}"
            line = config._lines.get(tuple(key.split(".")))
            if name not in known:
                raise ConfigError(f"unknown parameter '{name}' for simulator '{config.simulator.plugin}'; "
                                  f"known: {', '.join(sorted(known))}", file=config.file, key=key, line=line)
            if name in identified:
                raise ConfigError(f"'{name}' is identified: a {section} parameter is one the run does not identify",
                                  file=config.file, key=key, line=line)
            if ends is not None:
                _check_range(name, ends, known[name], key, line, config)


def check_limits(config: Config, simulator) -> None:
    """``limits:`` keys name a parameter of the simulator or an element group of one (``c_yaw[bogie2]``);
    a nominal override keeps the sign of the simulator's nominal value (a change in % must mean the same)."""
    known = {p.name: p for p in simulator.parameters()}
    for name, limits in config.limits.items():
        key = f"limits.{name}"
        line = config._lines.get(("limits", name))
        if name not in known and kind_of(name) not in known:
            raise ConfigError(f"unknown parameter '{name}' for simulator '{config.simulator.plugin}' (a parameter "
                              f"or a group such as {kind_of(name)}[bogie1]); known: {', '.join(sorted(known))}",
                              file=config.file, key=key, line=line)
        if not re.fullmatch(r"[A-Za-z_][\w.\-/]*(\[[\w.\-]+(,[\w.\-]+)*\])?", name):
            raise ConfigError(f"'{name}' is not a parameter or group name (kind or kind[group,side])",
                              file=config.file, key=key, line=line)
        if "[" in name and isinstance(simulator, ElementSimulator):   # a group the simulator declares
            for _, message in check_groups(simulator, [name], where="limits"):
                raise ConfigError(message, file=config.file, key=key, line=line)
        p = known.get(name) or known[kind_of(name)]
        if limits.nominal is not None and p.nominal != 0 and (limits.nominal > 0) != (p.nominal > 0):
            raise ConfigError(f"nominal {limits.nominal:g} has the opposite sign of the simulator's "
                              f"{p.nominal:g} {p.unit}", file=config.file, key=f"{key}.nominal",
                              line=config._lines.get(("limits", name, "nominal"), line))


def _check_range(name: str, ends: tuple[float, float], parameter, key: str, line: int | None, config: Config) -> None:
    """low < high inside ``parameter``'s physical domain."""
    low, high = ends
    domain = parameter.domain
    if not (domain[0] < low < high < domain[1]):
        raise ConfigError(f"expected low < high inside the physical domain ({domain[0]:g}, {domain[1]:g}) "
                          f"{parameter.unit}, got [{low:g}, {high:g}]", file=config.file, key=key, line=line)


def identified_bounds(config: Config, simulator) -> dict[str, tuple[float, float]]:
    """Name -> (lower, upper) in SI units of the identified parameters, in order.

    An empty ``parameters:`` section gives the simulator's default set (what ``observability`` and ``stability``
    analyse; the commands that identify refuse it, :func:`suspid.workflows.checks.check_identified`).
    """
    known = {p.name: p for p in declared_parameters(simulator)}
    names = list(config.parameters) or simulator.default_parameters()
    out = {}
    for name in names:
        bounds = config.parameters.get(name)
        lower = bounds.lower if bounds and bounds.lower is not None else known[name].lower
        upper = bounds.upper if bounds and bounds.upper is not None else known[name].upper
        out[name] = (float(lower), float(upper))
    return out
