"""Options models and the one error formatter of every config section.

Every section of a config, and every plugin's ``options``, is a pydantic
model that rejects unknown keys (:class:`Section`). Whatever validates it (the
config loader, a plugin author's code, a function of the numerical core called
with a plain mapping) turns the first pydantic error into one line through
:func:`raise_validation_error`, so the same kind of mistake reads the same in
every section::

    quickstart.yaml:14, key 'ego.max_itr': unknown key; expected one of: batch, max_iter, ...
    quickstart.yaml:9, key 'design.n_initial': Input should be greater than or equal to 2 (got -3)

Paths: a field typed :data:`ConfigPath` resolves a relative path against the
folder of the config file.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Mapping, TypeVar, get_origin

from pydantic import AfterValidator, BaseModel, ConfigDict, ValidationError, ValidationInfo

from suspid.errors import ConfigError

M = TypeVar("M", bound=BaseModel)


class Section(BaseModel):
    """Base of config sections and options models: unknown keys are errors."""

    model_config = ConfigDict(extra="forbid")


def against(path: str | Path, base: str | Path | None) -> Path:
    """``path`` with ``~`` expanded; a relative path is taken from the folder ``base`` when given."""
    p = Path(path).expanduser()
    return Path(base) / p if base is not None and not p.is_absolute() else p


def _resolve_path(value: Path, info: ValidationInfo) -> Path:
    return against(value, (info.context or {}).get("base_dir") if info.context is not None else None)


ConfigPath = Annotated[Path, AfterValidator(_resolve_path)]
"""A path field: relative values resolve against the folder of the config file."""


# -- the one error formatter ----------------------------------------------------------------
def _allowed_keys(model: type[BaseModel], loc: tuple) -> list[str] | None:
    """Field names of the (nested) model at ``loc``, for 'unknown key' messages."""
    skip_key = False
    for part in loc:
        if isinstance(part, int) or skip_key:
            skip_key = False
            continue  # an item of a list, or a key of a mapping, of models: same model
        field = model.model_fields.get(str(part))
        if field is None:
            return None
        annotation = field.annotation
        candidates = [annotation, *getattr(annotation, "__args__", ())]
        for c in list(candidates):
            candidates += list(getattr(c, "__args__", ()))
        skip_key = any(get_origin(c) is dict for c in candidates)
        nested = [c for c in candidates if isinstance(c, type) and issubclass(c, BaseModel)]
        if not nested:
            return None
        model = nested[0]
    return sorted(n for n, f in model.model_fields.items() if not f.exclude)   # not what load_config sets


def _clean_loc(loc: tuple) -> tuple:
    """Field names and list indices only: drops pydantic's union-member tags such as 'constrained-float'."""
    return tuple(p for p in loc if isinstance(p, int) or str(p).isidentifier())


def describe(error: Mapping[str, Any], model: type[BaseModel], loc: tuple) -> str:
    """What was expected, for one pydantic error at ``loc`` inside ``model``."""
    if error["type"] == "extra_forbidden":
        allowed = _allowed_keys(model, loc[:-1])
        if allowed == []:
            return "unknown key; expected no keys here"
        return "unknown key" + (f"; expected one of: {', '.join(allowed)}" if allowed else "")
    msg = str(error["msg"]).removeprefix("Value error, ")
    if error["type"] != "missing" and "input" in error:
        got = repr(error["input"])
        if not isinstance(error["input"], (dict, list)) or len(got) <= 60:
            msg += f" (got {got})"
    return msg


def line_of(lines: Mapping[tuple, int], key_path: tuple) -> int | None:
    """The YAML line of ``key_path`` or of its nearest parent that has one."""
    for n in range(len(key_path), 0, -1):
        if key_path[:n] in lines:
            return lines[key_path[:n]]
    return None


def key_error(message: str, key: str, file: str | None = None,
              lines: Mapping[tuple, int] | None = None) -> ConfigError:
    """A :class:`ConfigError` for the dotted ``key`` (``monitor.campaigns.2.date``), with its YAML line."""
    parts = tuple(int(p) if p.isdigit() else p for p in key.split("."))
    return ConfigError(message, file=file, key=key, line=line_of(lines or {}, parts))


def raise_validation_error(exc: ValidationError, model: type[BaseModel], file: str | None = None,
                           lines: Mapping[tuple, int] | None = None, prefix: tuple = ()) -> None:
    """Raise the first error of a pydantic ``exc`` as a one-line :class:`ConfigError`.

    :param model: the model that was validated (for the list of expected keys).
    :param file: the config file, when there is one.
    :param lines: YAML line numbers by key path, for ``file:line``.
    :param prefix: the key path of the validated section inside the config file.
    """
    error = exc.errors()[0]
    loc = _clean_loc(tuple(error["loc"]))
    full = tuple(prefix) + loc
    more = len(exc.errors()) - 1
    detail = describe(error, model, loc) + (f" (+{more} more error{'s' * (more > 1)})" if more else "")
    raise ConfigError(detail, file=file, key=".".join(map(str, full)) or None,
                      line=line_of(lines or {}, full)) from None


def parse_options(model: type[M], data: M | Mapping[str, Any] | None, section: str, *,
                  file: str | None = None, context: Mapping[str, Any] | None = None) -> M:
    """``data`` validated as ``model``: an instance passes through, ``None`` gives the defaults.

    What a plugin or a function of the numerical core calls on options it is
    given as a plain mapping; the config loader uses the same formatter.

    :param model: the pydantic model class.
    :param data: an instance of ``model``, a mapping of its fields, or ``None``.
    :param section: the key path of the section (``spectra``, ``simulator.options``), for the message.
    :raises ConfigError: naming ``section.<field>`` and the first problem.
    """
    if isinstance(data, model):
        return data
    if data is None:
        data = {}
    if not isinstance(data, Mapping):
        raise ConfigError(f"expected a mapping of options, got {type(data).__name__}", file=file, key=section)
    try:
        return model.model_validate(dict(data), context=dict(context) if context else None)
    except ValidationError as exc:
        raise_validation_error(exc, model, file, None, tuple(section.split(".")) if section else ())
