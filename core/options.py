"""Validation of the option models of the numerical core (spectra, noise, KDE objectives).

The config layer validates whole config files (:mod:`suspid.config`); the
functions of the numerical core also accept plain mappings when called from
code, and turn a pydantic error into a one-line :class:`~suspid.errors.ConfigError`
that names the key path (``spectra.f_max_hz``).
"""

from __future__ import annotations

from typing import Any, Mapping, TypeVar

from pydantic import BaseModel, ValidationError

from suspid.errors import ConfigError

M = TypeVar("M", bound=BaseModel)


def parse_options(model: type[M], data: M | Mapping[str, Any] | None, section: str) -> M:
    """``data`` validated as ``model``: an instance passes through, ``None`` gives the defaults.

    :param model: the pydantic model class.
    :param data: an instance of ``model``, a mapping of its fields, or ``None``.
    :param section: the key path of the section, for the error message.
    :raises ConfigError: naming ``section.<field>`` and the first problem.
    """
    if isinstance(data, model):
        return data
    if data is None:
        data = {}
    if not isinstance(data, Mapping):
        raise ConfigError(f"expected a mapping of options, got {type(data).__name__}", key=section)
    try:
        return model.model_validate(dict(data))
    except ValidationError as exc:
        error = exc.errors()[0]
        # keep field names and list indices; drop union-member tags such as 'constrained-float'
        loc = ".".join(str(part) for part in error["loc"]
                       if isinstance(part, int) or str(part).isidentifier())
        msg = error["msg"].removeprefix("Value error, ")
        if "input" in error and not isinstance(error["input"], (dict, list)):
            msg += f" (got {error['input']!r})"
        raise ConfigError(msg, key=f"{section}.{loc}" if loc else section) from None
