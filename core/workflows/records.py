"""Typed results that are written as JSON: a dataclass whose fields are the file's keys, in the file's order.

A :class:`Record` is the typed form of one JSON object (``result.json``, ``diagnosis.json``, ...):
:meth:`Record.to_json` gives the object, key for key and in field order, and :meth:`Record.from_json`
reads it back. A field is described by :func:`key` when its JSON key differs from its name, when the key
is left out of the file while its value is None (a finding that only some runs have), when its value is
a nested record (or a list of them), or when it is not part of the file at all (a live run's objects).

A record with a ``SCHEMA_VERSION`` writes it as the file's last key, ``schema_version``. Files written
before a key (or the version) existed still load: a missing key reads as the field's default (None where
it has none). Keys a record does not know are kept, and written back after its own. A file of a newer
version than the code's is refused (:class:`~suspid.errors.DataError`: upgrade suspid).
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import MISSING, dataclass, field
from pathlib import Path
from typing import Any, Callable, ClassVar, Mapping

from suspid.errors import DataError

__all__ = ["Record", "key", "pairs", "read_json"]


def key(name: str | None = None, *, omit_none: bool = False, record: type | None = None,
        items: type | None = None, read: Callable[[Any], Any] | None = None, json: bool = True,
        default: Any = MISSING, default_factory: Any = MISSING) -> Any:
    """A record field.

    :param name: its JSON key (default: the field's name).
    :param omit_none: leave the key out of the file while the value is None.
    :param record: the value is that :class:`Record` (``items``: a list of them).
    :param read: converts the value read from JSON (e.g. :func:`pairs`).
    :param json: False: not written (a live run's objects: the problem, the optimiser's result).
    """
    meta = {"key": name, "omit_none": omit_none, "record": record, "items": items, "read": read, "json": json}
    live = {} if json else {"compare": False, "repr": False}   # a live run's objects: not part of the result
    if default is MISSING and default_factory is MISSING:
        return field(metadata=meta, **live)
    if default_factory is not MISSING:
        return field(default_factory=default_factory, metadata=meta, **live)
    return field(default=default, metadata=meta, **live)


def read_json(path: Path) -> dict[str, Any]:
    """The JSON object of a result file.

    :raises DataError: the file is missing or not JSON, naming it.
    """
    try:
        return json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise DataError(f"{path}: cannot read it as a result file ({exc})") from None


def pairs(mapping: Mapping[str, Any] | None) -> dict[str, tuple[float, float]] | None:
    """``name -> [a, b]`` as read from JSON to ``name -> (a, b)``."""
    return None if mapping is None else {n: (float(v[0]), float(v[1])) for n, v in mapping.items()}


def plain(value: Any) -> Any:
    """``value`` as JSON data: records by :meth:`Record.to_json`, tuples as lists."""
    if isinstance(value, Record):
        return value.to_json()
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    return value


@dataclass(kw_only=True)
class Record:
    """A dataclass written as one JSON object (module docstring)."""

    extra: dict[str, Any] = field(default_factory=dict, repr=False, compare=False,
                                  metadata={"key": None, "json": False})
    """Keys of the file this record does not know (a later version's), written back after its own."""

    SCHEMA_VERSION: ClassVar[int | None] = None
    """The version of the file's layout, written as ``schema_version`` (None: not versioned on its own)."""

    def to_json(self) -> dict[str, Any]:
        """The JSON object: every field's key in field order (None-valued optional keys left out)."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            meta = f.metadata
            if not meta.get("json", True):
                continue
            value = getattr(self, f.name)
            if value is None and meta.get("omit_none"):
                continue
            out[meta.get("key") or f.name] = plain(value)
        out.update(self.extra)
        if self.SCHEMA_VERSION is not None:
            out["schema_version"] = self.SCHEMA_VERSION
        return out

    @classmethod
    def known_keys(cls) -> set[str]:
        """The JSON keys this record reads."""
        keys = {"schema_version"} if cls.SCHEMA_VERSION is not None else set()
        for f in dataclasses.fields(cls):
            if f.metadata.get("json", True):
                keys.add(f.metadata.get("key") or f.name)
        return keys

    @classmethod
    def load_file(cls, path: Path, **live: Any) -> "Record":
        """The record of a JSON file (:meth:`from_json`); a newer version or a bad file is a one-line
        :class:`~suspid.errors.DataError` naming the file."""
        try:
            return cls.from_json(read_json(path), **live)
        except DataError as exc:
            raise DataError(str(exc) if str(path) in str(exc) else f"{path}: {exc}") from None

    @classmethod
    def from_json(cls, data: Mapping[str, Any], **live: Any) -> "Record":
        """The record of a JSON object (missing keys read as the field's default, or None).

        :param live: values of the fields that are not in the file (``json=False``).
        :raises DataError: the file's ``schema_version`` is newer than this code's.
        """
        version = data.get("schema_version")
        if cls.SCHEMA_VERSION is not None and version is not None and version > cls.SCHEMA_VERSION:
            raise DataError(f"{cls.__name__}: schema_version {version} is newer than this suspid reads "
                             f"({cls.SCHEMA_VERSION}); upgrade suspid")
        values: dict[str, Any] = {}
        for f in dataclasses.fields(cls):
            meta = f.metadata
            if f.name == "extra" or not meta.get("json", True):
                if f.name in live:
                    values[f.name] = live[f.name]
                continue
            name = meta.get("key") or f.name
            if name not in data:
                if f.default is MISSING and f.default_factory is MISSING:
                    values[f.name] = None   # a file written before the key existed
                continue
            raw = data[name]
            if raw is not None and meta.get("record") is not None:
                raw = meta["record"].from_json(raw)
            elif raw is not None and meta.get("items") is not None:
                raw = [meta["items"].from_json(r) for r in raw]
            elif meta.get("read") is not None:
                raw = meta["read"](raw)
            values[f.name] = raw
        known = cls.known_keys()
        return cls(**values, extra={k: v for k, v in data.items() if k not in known})
