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
from pathlib import Path
from typing import Annotated, Any, Literal, Mapping, Sequence

import yaml
from pydantic import (AfterValidator, BaseModel, ConfigDict, Field, ValidationError,
                      ValidationInfo, field_validator)

from suspid import registry
from suspid.errors import ConfigError, UnknownPluginError


# -- paths relative to the config file -------------------------------------------
def _against(path: str | Path, base: str | Path | None) -> Path:
    """``path`` with ``~`` expanded; a relative path is taken from the folder ``base`` when given."""
    p = Path(path).expanduser()
    return Path(base) / p if base is not None and not p.is_absolute() else p


def _resolve_path(value: Path, info: ValidationInfo) -> Path:
    return _against(value, (info.context or {}).get("base_dir") if info.context is not None else None)


ConfigPath = Annotated[Path, AfterValidator(_resolve_path)]
"""A path field: relative values resolve against the folder of the config file."""


class Section(BaseModel):
    """Base of config sections: unknown keys are errors."""

    model_config = ConfigDict(extra="forbid")


class PluginSection(Section):
    """A section that selects a plugin by registered name."""

    plugin: str
    options: dict[str, Any] = Field(default_factory=dict)


class SimulatorSection(PluginSection):
    plugin: str = "exudyn-train"


class ObjectiveSection(PluginSection):
    plugin: str = "overlap"
    weights: list[float] | dict[str, float] | None = Field(
        default=None, description="α_k of eq. 5: a list in channel order or channel -> weight; default 1/n")


class SurrogateSection(PluginSection):
    plugin: str = "gpy-kriging"


class ExecutorSection(PluginSection):
    plugin: str = "serial"


class ParameterBounds(Section):
    """Bounds of one identified parameter (SI units); missing bounds keep the simulator's."""

    lower: float | None = None
    upper: float | None = None


class OutputSection(Section):
    dir: ConfigPath | None = Field(default=None, description="run directory; default runs/<name>/")
    figure_channel: str | None = Field(default=None, description="channel of Figure 1; default: first carbody vertical")


class DataSection(Section):
    """Where the measurements come from.

    ``source: experiment`` builds the numerical experiment of paper §3.3 on a
    synthetic track; ``source: measured`` reads measured accelerations and the
    matching track geometry from files.
    """

    source: Literal["experiment", "measured"] = "experiment"
    track: dict[str, Any] = Field(default_factory=dict, description="synthetic track options (experiment)")
    w_ref: dict[str, float] = Field(default_factory=dict, description="known 'damaged' parameters (experiment)")
    reference: dict[str, Any] = Field(default_factory=dict,
                                      description="how the reference-date measurements for the noise model are made")
    measurement: dict[str, Any] = Field(
        default_factory=dict, description="how the measurement-date 'measurements' are simulated (experiment), "
        "e.g. simulator_options with a hidden effect")
    measurements: ConfigPath | None = Field(default=None, description="measured data file or folder")
    track_file: ConfigPath | None = Field(default=None, description="measured track geometry file or folder")

    @field_validator("measurements", "track_file")
    @classmethod
    def _exists(cls, value: Path | None) -> Path | None:
        if value is not None and not value.exists():
            raise ValueError(f"file not found: {value}")
        return value


class Config(Section):
    """The whole run configuration (validated)."""

    name: str = Field(default="suspid-run", min_length=1, pattern=r"^[A-Za-z0-9_.\-]+$")
    seed: int = Field(default=0, ge=0)
    simulator: SimulatorSection = Field(default_factory=SimulatorSection)
    parameters: dict[str, ParameterBounds | None] = Field(default_factory=dict)
    data: DataSection = Field(default_factory=DataSection)
    spectra: dict[str, Any] = Field(default_factory=dict)
    noise: dict[str, Any] = Field(default_factory=dict)
    objective: ObjectiveSection = Field(default_factory=ObjectiveSection)
    surrogate: SurrogateSection = Field(default_factory=SurrogateSection)
    design: dict[str, Any] = Field(default_factory=dict)
    ego: dict[str, Any] = Field(default_factory=dict)
    executor: ExecutorSection = Field(default_factory=ExecutorSection)
    identifiability: dict[str, Any] = Field(default_factory=dict)
    study: dict[str, Any] = Field(default_factory=dict)
    monitor: dict[str, Any] = Field(default_factory=dict)
    diagnose: dict[str, Any] = Field(default_factory=dict)
    output: OutputSection = Field(default_factory=OutputSection)

    # set by load_config, not by the user
    source_file: Path | None = Field(default=None, exclude=True)

    def resolve(self, path: str | Path) -> Path:
        """``path`` with ``~`` expanded; relative paths are taken from the config file's folder."""
        return _against(path, self.source_file.parent if self.source_file is not None else None)

    def run_dir(self) -> Path:
        """The run directory: ``output.dir`` or ``runs/<name>/`` beside the config."""
        if self.output.dir is not None:
            return self.output.dir
        base = self.source_file.parent if self.source_file else Path.cwd()
        return base / "runs" / self.name


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


def read_yaml(path: Path) -> tuple[dict[str, Any], dict[tuple, int]]:
    """Safe-load a YAML mapping and the line of every key path."""
    file = str(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError("config file not found", file=file) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"cannot read config: {exc}", file=file) from None
    try:
        node = yaml.compose(text, Loader=yaml.SafeLoader)
        data = yaml.safe_load(text)
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
    """Apply ``--set key.path=value`` overrides (values parsed as YAML scalars or flows)."""
    data = copy.deepcopy(data)
    for item in overrides:
        if "=" not in item:
            raise ConfigError(f"--set expects key.path=value, got '{item}'", file=file)
        key, raw = item.split("=", 1)
        parts = key.strip().split(".")
        if not all(parts):
            raise ConfigError(f"--set has an empty key in '{key}'", file=file, key=key)
        try:
            value = yaml.safe_load(raw) if raw.strip() else ""
        except yaml.YAMLError:
            value = raw
        node: Any = data
        for depth, part in enumerate(parts[:-1]):
            here = ".".join(parts[: depth + 1])
            if isinstance(node, dict):
                node = node.setdefault(part, {})
            elif isinstance(node, list) and part.isdigit() and int(part) < len(node):
                node = node[int(part)]
            else:
                raise ConfigError(f"--set {key}: '{here}' is not a mapping that can hold '{parts[depth + 1]}'",
                                  file=file, key=key)
        last = parts[-1]
        if isinstance(node, dict):
            node[last] = value
        elif isinstance(node, list) and last.isdigit() and int(last) < len(node):
            node[int(last)] = value
        else:
            raise ConfigError(f"--set {key}: the parent of '{last}' is not a mapping", file=file, key=key)
    return data


# -- error translation -----------------------------------------------------------
def _allowed_keys(model: type[BaseModel], loc: tuple) -> list[str] | None:
    """Field names of the (nested) model at ``loc``, for 'unknown key' messages."""
    for part in loc:
        field = model.model_fields.get(str(part)) if isinstance(part, str) else None
        if field is None:
            return None
        annotation = field.annotation
        candidates = [annotation, *getattr(annotation, "__args__", ())]
        nested = [c for c in candidates if isinstance(c, type) and issubclass(c, BaseModel)]
        if not nested:
            return None
        model = nested[0]
    return sorted(model.model_fields)


def _describe(error: dict[str, Any], model: type[BaseModel], loc: tuple) -> str:
    if error["type"] == "extra_forbidden":
        allowed = _allowed_keys(model, loc[:-1])
        return "unknown key" + (f"; expected one of: {', '.join(allowed)}" if allowed else "")
    msg = error["msg"]
    if msg.startswith("Value error, "):
        msg = msg[len("Value error, "):]
    if error["type"] not in {"missing"} and "input" in error and not isinstance(error["input"], (dict, list)):
        msg += f" (got {error['input']!r})"
    return msg


def raise_validation_error(exc: ValidationError, model: type[BaseModel], file: str, lines: Mapping[tuple, int],
                           prefix: tuple = ()) -> None:
    """Raise the first error of a pydantic ``exc`` as a one-line :class:`ConfigError`.

    :param model: the model that was validated (for the list of expected keys).
    :param lines: YAML line numbers by key path (:func:`load_yaml`), for ``file:line``.
    :param prefix: the key path of the validated section inside the config file.
    """
    error = exc.errors()[0]
    loc = tuple(error["loc"])
    full = prefix + loc
    line = None
    for n in range(len(full), 0, -1):
        if full[:n] in lines:
            line = lines[full[:n]]
            break
    more = len(exc.errors()) - 1
    detail = _describe(error, model, loc) + (f" (+{more} more error{'s' * (more > 1)})" if more else "")
    raise ConfigError(detail, file=file, key=".".join(map(str, full)) or None, line=line) from None


def override_arguments(mapping: Mapping[str, Any]) -> list[str]:
    """``{"key.path": value}`` as ``--set`` arguments ``["key.path=<YAML flow value>"]`` for :func:`load_config`."""
    return [f"{k}={yaml.safe_dump(v, default_flow_style=True).strip().removesuffix('...').strip()}"
            for k, v in mapping.items()]


def validate_options(cls: type, options: Mapping[str, Any], *, file: str, key: str,
                     lines: Mapping[tuple, int] | None = None, base_dir: Path | None = None) -> dict[str, Any]:
    """Validate a plugin's ``options`` with its ``Options`` model; returns the validated options.

    Plugins without an ``Options`` model get their options back unchanged.
    """
    model = getattr(cls, "Options", None)
    if model is None:
        return dict(options)
    try:
        validated = model.model_validate(dict(options), context={"base_dir": base_dir})
    except ValidationError as exc:
        raise_validation_error(exc, model, file, lines or {}, tuple(key.split(".")))
    return validated.model_dump()  # plain data: hashable identity, picklable, YAML-dumpable


def load_config(path: str | Path, overrides: Sequence[str] = (), *, check_plugins: bool = True) -> Config:
    """Read, override and validate a config file.

    :param path: the YAML file.
    :param overrides: ``key.path=value`` strings from ``--set``.
    :param check_plugins: also resolve plugins by name, validate their options
        and check the parameter names against the simulator.
    :raises ConfigError: on the first problem, naming file, key and line.
    """
    path = Path(path)
    file = str(path)
    if check_plugins:
        registry.registry()  # plugin load errors first (strict mode), whatever the config says
    data, lines = read_yaml(path)
    data = apply_overrides(data, overrides, file)
    base_dir = path.resolve().parent
    try:
        config = Config.model_validate(data, context={"base_dir": base_dir})
    except ValidationError as exc:
        raise_validation_error(exc, Config, file, lines)
    config.source_file = path.resolve()
    if check_plugins:
        check_config_plugins(config, lines)
    return config


def plugin_class(kind: str, section: PluginSection, key: str, file: str, lines: Mapping[tuple, int] = {}) -> type:
    """Resolve a plugin section's name to its class, or a ConfigError listing the available ones."""
    try:
        return registry.get(kind, section.plugin)
    except UnknownPluginError as exc:
        raise ConfigError(str(exc), file=file, key=f"{key}.plugin", line=lines.get((key, "plugin"))) from None


def check_config_plugins(config: Config, lines: Mapping[tuple, int] = {}) -> None:
    """Resolve every plugin by name, validate its options, check parameter names and bounds."""
    file = str(config.source_file) if config.source_file else "<config>"
    base_dir = config.source_file.parent if config.source_file else None
    for kind, key in (("simulator", "simulator"), ("objective", "objective"), ("surrogate", "surrogate")):
        section: PluginSection = getattr(config, key)
        cls = plugin_class(kind, section, key, file, lines)
        section.options = validate_options(cls, section.options, file=file, key=f"{key}.options",
                                           lines=lines, base_dir=base_dir)
    simulator = build_simulator(config)
    check_parameters(config, simulator, lines)


def build_simulator(config: Config):
    """Instantiate the configured simulator (cheap: constructors only store options)."""
    cls = registry.get("simulator", config.simulator.plugin)
    return cls(**config.simulator.options)


def check_parameters(config: Config, simulator, lines: Mapping[tuple, int] = {}) -> None:
    """Identified parameter names must be the simulator's; lower < upper after defaults."""
    file = str(config.source_file) if config.source_file else "<config>"
    known = {p.name: p for p in simulator.parameters()}
    for group, names in (("parameters", config.parameters), ("data.w_ref", config.data.w_ref)):
        for name in names:
            if name not in known:
                raise ConfigError(
                    f"unknown parameter '{name}' for simulator '{config.simulator.plugin}'; "
                    f"known: {', '.join(sorted(known))}",
                    file=file, key=f"{group}.{name}", line=lines.get(tuple(group.split(".")) + (name,)))
    bounds = identified_bounds(config, simulator)
    for name in config.parameters:
        lower, upper = bounds[name]
        if not lower < upper:
            raise ConfigError(f"lower bound {lower:g} must be below upper bound {upper:g} ({known[name].unit})",
                              file=file, key=f"parameters.{name}", line=lines.get(("parameters", name)))
    for name, value in config.data.w_ref.items():
        lower, upper = bounds.get(name, (known[name].lower, known[name].upper))
        if not lower <= value <= upper:
            raise ConfigError(f"w_ref value {value:g} lies outside the admissible interval "
                              f"[{lower:g}, {upper:g}] {known[name].unit}",
                              file=file, key=f"data.w_ref.{name}", line=lines.get(("data", "w_ref", name)))


def identified_bounds(config: Config, simulator) -> dict[str, tuple[float, float]]:
    """Name -> (lower, upper) in SI units of the identified parameters, in order.

    An empty ``parameters:`` section identifies the simulator's default set.
    """
    known = {p.name: p for p in simulator.parameters()}
    names = list(config.parameters) or simulator.default_parameters()
    out = {}
    for name in names:
        bounds = config.parameters.get(name)
        lower = bounds.lower if bounds and bounds.lower is not None else known[name].lower
        upper = bounds.upper if bounds and bounds.upper is not None else known[name].upper
        out[name] = (float(lower), float(upper))
    return out
