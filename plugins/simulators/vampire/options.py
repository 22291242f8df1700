"""Options of the ``vampire`` simulator: the ``simulator.options`` section of a config.

Every model forbids unknown keys. Paths in the working directory (run file,
track file, export, expected outputs, logs) are relative and may not contain
``..``; absolute paths are refused. See ``docs/vampire.md`` for a full example.
"""

from __future__ import annotations

import codecs
import math
import re
import string
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from suspid.options import ConfigPath

from .templates import is_name, safe_relpath, scan

STANDARD_GRAVITY = 9.80665
"""m/s² per g (standard gravity, 3rd CGPM 1901; ISO 80000-3)."""

BUILTIN_VALUES: dict[str, str] = {
    "segment": "segment name",
    "speed": "segment speed in m/s",
    "speed_kmh": "segment speed in km/h",
    "duration": "expected record length in s (segment length / speed)",
    "length": "segment length in m",
    "x_start": "first distance written in the track file, m",
    "x_end": "last distance written in the track file, m",
    "dx": "distance step of the track file, m",
    "n_track_rows": "number of data rows of the track file",
    "fs": "output sampling rate in Hz (option fs; an error when fs is not set)",
    "run_file": "the run file, relative to the working directory",
    "track_file": "the track irregularity file, relative to the working directory",
    "export_file": "the export file to read, relative to the working directory",
    "workdir": "absolute path of the working directory",
}
"""Template values every run provides besides the parameters and ``values``."""

COMMAND_FIELDS: dict[str, str] = {
    "python": "the Python interpreter running suspid (for wrapper scripts)",
    "workdir": "absolute path of the working directory (also the command's cwd)",
    "template_dir": "absolute path of the template directory",
    "run_file": "run file relative to the working directory",
    "run_path": "absolute path of the run file",
    "track_file": "track file relative to the working directory",
    "track_path": "absolute path of the track file",
    "export_file": "export file relative to the working directory",
    "export_path": "absolute path of the export file",
    "segment": "segment name",
}
"""``{field}`` placeholders of ``command`` and ``env`` values."""

DEFAULT_ERROR_PATTERNS = [
    r"(?i)licen[cs]e.*\b(error|fail\w*|expired|denied|not (available|found|valid)|unavailable|invalid)",
    r"(?i)^\s*(\*+\s*)?(fatal|error)\b",
]
"""Regular expressions searched in stdout, stderr and ``log_files``; a match fails the run.

Vampire's own messages are not public: adjust these to what your installation
prints (a licence failure that still exits with code 0 is the case to catch).
"""

STDOUT_NAME = "_suspid_stdout.log"
STDERR_NAME = "_suspid_stderr.log"
RUN_INFO_NAME = "_suspid_run.json"
RESERVED_NAMES = (STDOUT_NAME, STDERR_NAME, RUN_INFO_NAME)
"""Files the adapter writes into every working directory besides the templates."""


def command_fields(text: str, what: str) -> list[str]:
    """Names of the ``{field}`` placeholders in ``text``; ``{{``/``}}`` are literal braces.

    :raises ValueError: for an unknown field, a conversion, a format spec or
        attribute/index access.
    """
    try:
        parsed = list(string.Formatter().parse(text))
    except ValueError as exc:
        raise ValueError(f"{what}: {exc} in {text!r} (write '{{{{' for a literal brace)") from None
    names = []
    for _, name, spec, conversion in parsed:
        if name is None:
            continue
        if name not in COMMAND_FIELDS or spec or conversion:
            raise ValueError(f"{what}: unknown placeholder '{{{name}}}' in {text!r}; known: "
                             + ", ".join("{" + f + "}" for f in COMMAND_FIELDS))
        names.append(name)
    return names


def _check_format(spec: str, what: str) -> str:
    try:
        format(1.5, spec)
    except (ValueError, TypeError) as exc:
        raise ValueError(f"{what}: invalid number format {spec!r} ({exc})") from None
    return spec


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid")


class ParameterSpec(_Model):
    """One identifiable parameter, in SI units.

    The value written into the templates is ``value * scale`` formatted with
    ``format`` (or the options' ``number_format``), so a vehicle file in kN/m
    takes an SI stiffness in N/m with ``scale: 1.0e-3``.
    """

    name: str = Field(min_length=1, description="name used in configs and in w")
    unit: str = Field(description="SI unit of nominal, lower, upper (e.g. N/m)")
    nominal: float
    lower: float
    upper: float
    placeholder: str | None = Field(default=None, description="template name; default: name")
    scale: float = Field(default=1.0, description="factor from SI to the unit of the template file")
    format: str | None = Field(default=None, description="format spec, e.g. '.6g'; default number_format")
    description: str = ""

    @model_validator(mode="after")
    def _check(self) -> "ParameterSpec":
        if not all(math.isfinite(v) for v in (self.nominal, self.lower, self.upper, self.scale)):
            raise ValueError(f"parameter '{self.name}': nominal, lower, upper and scale must be finite")
        if not self.lower < self.upper:
            raise ValueError(f"parameter '{self.name}': lower {self.lower:g} must be below upper {self.upper:g}")
        if not self.lower <= self.nominal <= self.upper:
            raise ValueError(f"parameter '{self.name}': nominal {self.nominal:g} outside "
                             f"[{self.lower:g}, {self.upper:g}]")
        if not is_name(self.template_name):
            raise ValueError(f"parameter '{self.name}': '{self.template_name}' is not a valid placeholder name; "
                             f"set placeholder to letters, digits and '_'")
        if self.format is not None:
            _check_format(self.format, f"parameter '{self.name}' format")
        return self

    @property
    def template_name(self) -> str:
        """The placeholder name in the templates."""
        return self.placeholder or self.name


class ChannelSpec(_Model):
    """One output channel: where it is in the export and in which unit."""

    name: str = Field(min_length=1, description="suspid channel name")
    column: str = Field(min_length=1, description="header name (table form) or block title (block form)")
    unit: Literal["g", "m/s2"] = Field(default="m/s2", description="unit in the export file")
    scale: float = Field(default=1.0, description="extra factor, e.g. -1 to flip a sign convention")

    @field_validator("unit", mode="before")
    @classmethod
    def _unit_aliases(cls, value):
        aliases = {"m/s^2": "m/s2", "m/s²": "m/s2", "m s-2": "m/s2", "G": "g"}
        return aliases.get(value, value)

    @property
    def to_si(self) -> float:
        """Factor from export values to m/s²."""
        return self.scale * (STANDARD_GRAVITY if self.unit == "g" else 1.0)


class TrackSigns(_Model):
    """Sign factors applied before writing (Vampire's sign conventions are not public).

    suspid's conventions are in :data:`suspid.interfaces.IRREGULARITY_CHANNELS`.
    """

    vertical: Literal[1, -1] = 1
    lateral: Literal[1, -1] = 1
    cross_level: Literal[1, -1] = 1
    gauge: Literal[1, -1] = 1


class TrackFileOptions(_Model):
    """The track irregularity file, in Vampire's 6-field layout.

    Each row: distance (m), cross level (mm), curvature irregularity (1/km),
    lateral (mm), vertical (mm), gauge variation (mm).
    """

    file: str = Field(default="track.dat", description="name in the working directory")
    header: list[str] = Field(default_factory=list,
                              description="lines written before the data; may use {{ placeholders }}")
    delimiter: str = Field(default=" ", min_length=1)
    distance_format: str = ".3f"
    value_format: str = ".4f"
    curvature_format: str = ".6f"
    distance_origin: Literal["zero", "segment"] = Field(
        default="zero", description="zero: distances start at 0; segment: the segment's own distances")
    curvature: Literal["zero", "from_lateral"] = Field(
        default="zero", description="zero, or the second derivative of the lateral irregularity in 1/km")
    signs: TrackSigns = Field(default_factory=TrackSigns)
    newline: Literal["lf", "crlf"] = "lf"

    @field_validator("file")
    @classmethod
    def _file(cls, value: str) -> str:
        return safe_relpath(value, "track.file")

    @field_validator("distance_format", "value_format", "curvature_format")
    @classmethod
    def _fmt(cls, value: str) -> str:
        return _check_format(value, "track format")

    @field_validator("delimiter")
    @classmethod
    def _delim(cls, value: str) -> str:
        if "\n" in value or "\r" in value or any(c.isdigit() or c in "+-.eE" for c in value):
            raise ValueError(f"delimiter {value!r} would make the numbers unreadable")
        return value

    @field_validator("header")
    @classmethod
    def _header(cls, lines: list[str]) -> list[str]:
        for i, line in enumerate(lines):
            if "\n" in line or "\r" in line:
                raise ValueError(f"track.header[{i}] must be one line")
            scan(line, f"track.header[{i}]")
        return lines


class ExportOptions(_Model):
    """The ASCII export of the results that the command leaves in the working directory.

    ``form: table``: optional lines to skip, then a header line of column
    names, then one row of numbers per sample (an abscissa column ``x_column``
    and one column per channel). ``form: blocks``: per channel a title line,
    a line with the number of pairs n, then n lines ``x ; y``.
    """

    file: str = Field(default="results.txt", description="relative path in the working directory")
    form: Literal["table", "blocks"] = "table"
    skip_lines: int = Field(default=0, ge=0, description="lines to skip before the header or first block")
    comment_prefixes: list[str] = Field(default_factory=lambda: ["#"],
                                        description="table form: lines starting with these are skipped")
    delimiter: str | None = Field(default=None, description="table form: column separator; null = whitespace")
    x_column: str = Field(default="Time", description="table form: header name of the abscissa")
    x_kind: Literal["time", "distance"] = "time"
    x_scale: float = Field(default=1.0, gt=0, description="factor from the abscissa to s (or m)")
    pair_separator: str = Field(default=";", min_length=1, description="block form: separator of x and y")
    uniform_rtol: float = Field(default=0.01, gt=0, lt=1,
                                description="largest relative deviation of a time step from the mean step")
    check_duration: bool = True
    duration_rtol: float = Field(default=0.02, ge=0)
    duration_atol_s: float = Field(default=0.25, ge=0)

    @field_validator("file")
    @classmethod
    def _file(cls, value: str) -> str:
        return safe_relpath(value, "export.file")

    @field_validator("comment_prefixes")
    @classmethod
    def _prefixes(cls, value: list[str]) -> list[str]:
        if any(not p for p in value):
            raise ValueError("comment prefixes must not be empty strings")
        return value


class Options(_Model):
    """Options of :class:`~suspid.plugins.simulators.vampire.VampireSimulator`."""

    template_dir: ConfigPath = Field(description="the user's Vampire project with {{ placeholders }}")
    run_file: str | None = Field(default=None, description="the run file inside the template directory")
    parameters: list[ParameterSpec] = Field(min_length=1)
    channels: list[ChannelSpec] = Field(min_length=1)
    command: list[str] = Field(min_length=1, description="argument list with {field} placeholders; no shell")
    env: dict[str, str] = Field(default_factory=dict, description="environment overrides ({field} allowed)")
    values: dict[str, str | int | float] = Field(default_factory=dict,
                                                 description="other template values by placeholder name")
    number_format: str = Field(default=".10g", description="format spec of numbers in templates")
    fs: float | None = Field(default=None, gt=0, description="expected output sampling rate, Hz")
    timeout_s: float = Field(default=3600.0, gt=0, description="wall-clock limit of one run, s")
    kill_grace_s: float = Field(default=5.0, ge=0, description="SIGTERM to SIGKILL delay, s")
    kill_leftovers: bool = Field(default=True,
                                 description="after a normal exit, end processes the command left behind")
    max_concurrent: int = Field(default=1, ge=1, description="licence seats: runs at the same time")
    keep_workdirs: Literal["always", "failed", "never"] = "failed"
    work_root: ConfigPath | None = Field(default=None, description="where working directories go; default temp")
    track: TrackFileOptions = Field(default_factory=TrackFileOptions)
    export: ExportOptions = Field(default_factory=ExportOptions)
    error_patterns: list[str] = Field(default_factory=lambda: list(DEFAULT_ERROR_PATTERNS))
    log_files: list[str] = Field(default_factory=list, description="globs of logs to search for error patterns")
    expected_outputs: list[str] = Field(default_factory=list,
                                        description="files (globs) that must exist and be non-empty")
    on_error: Literal["raise", "finish"] = Field(
        default="raise", description="raise: a failing segment stops this point's other runs at once; "
                                     "finish: they run to the end, then every failure is reported")
    template_encoding: str = "utf-8"
    copy_only: list[str] = Field(default_factory=list, description="globs of template files copied verbatim")

    @field_validator("keep_workdirs", mode="before")
    @classmethod
    def _keep(cls, value):
        if isinstance(value, bool):
            return "always" if value else "never"
        return value

    @field_validator("run_file")
    @classmethod
    def _run_file(cls, value: str | None) -> str | None:
        return None if value is None else safe_relpath(value, "run_file")

    @field_validator("expected_outputs", "log_files")
    @classmethod
    def _relpaths(cls, value: list[str]) -> list[str]:
        return [safe_relpath(v, "output path") for v in value]

    @field_validator("number_format")
    @classmethod
    def _number_format(cls, value: str) -> str:
        return _check_format(value, "number_format")

    @field_validator("error_patterns")
    @classmethod
    def _patterns(cls, value: list[str]) -> list[str]:
        for p in value:
            try:
                re.compile(p, re.MULTILINE)
            except re.error as exc:
                raise ValueError(f"error pattern {p!r} is not a regular expression: {exc}") from None
        return value

    @field_validator("template_encoding")
    @classmethod
    def _encoding(cls, value: str) -> str:
        try:
            codecs.lookup(value)
        except LookupError:
            raise ValueError(f"unknown encoding {value!r}") from None
        return value

    @field_validator("template_dir")
    @classmethod
    def _template_dir(cls, value):
        if not value.is_dir():
            raise ValueError(f"template directory not found: {value}")
        return value

    @model_validator(mode="after")
    def _consistent(self) -> "Options":
        names = [p.name for p in self.parameters]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise ValueError(f"duplicate parameter names: {', '.join(sorted(dup))}")
        taken: dict[str, str] = {k: "a built-in value" for k in BUILTIN_VALUES}
        for p in self.parameters:
            if p.template_name in taken:
                raise ValueError(f"placeholder '{p.template_name}' of parameter '{p.name}' is already "
                                 f"{taken[p.template_name]}")
            taken[p.template_name] = f"parameter '{p.name}'"
        for key, value in self.values.items():
            if not is_name(key):
                raise ValueError(f"values: '{key}' is not a valid placeholder name")
            if isinstance(value, str) and any(c in value for c in "\r\n\0"):
                raise ValueError(f"values: '{key}' must be one line")
            if key in taken:
                raise ValueError(f"values: '{key}' is already {taken[key]}")
        channels = [c.name for c in self.channels]
        if len(set(channels)) != len(channels):
            raise ValueError(f"duplicate channel names in {channels}")
        used = [f for arg in self.command for f in command_fields(arg, "command")]
        used += [f for k, v in self.env.items() for f in command_fields(v, f"env.{k}")]
        if {"run_file", "run_path"} & set(used) and self.run_file is None:
            raise ValueError("command uses {run_file} or {run_path}: set run_file")
        if self.run_file is not None and not (self.template_dir / self.run_file).is_file():
            raise ValueError(f"run_file '{self.run_file}' is not a file of the template directory "
                             f"{self.template_dir}")
        header_names = [n for i, line in enumerate(self.track.header) for n, _ in scan(line, f"track.header[{i}]")]
        if "fs" in header_names and self.fs is None:
            raise ValueError("track.header uses {{ fs }}: set fs")
        return self

    def template_values(self) -> set[str]:
        """Every placeholder name the templates may use."""
        return set(BUILTIN_VALUES) | {p.template_name for p in self.parameters} | set(self.values)
