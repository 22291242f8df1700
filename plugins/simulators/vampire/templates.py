"""Strict ``{{ name }}`` templates and safe relative paths inside a working directory.

A template directory holds the user's Vampire project (vehicle file, run file,
anything else it needs). Every text file in it may contain placeholders
``{{ name }}`` (spaces optional); rendering is strict:

- a placeholder whose name has no value is an error naming the file and line;
- a ``{{`` or ``}}`` left over (unclosed, split over lines, not a name) is an
  error naming the file and line;
- there is no escape syntax: Vampire files have no use for ``{{``.

Files are snapshotted once (:func:`load_templates`), so that the hash used in
:meth:`VampireSimulator.identity` and the files actually rendered agree.
"""

from __future__ import annotations

import codecs
import fnmatch
import hashlib
import os
import re
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Iterable, Mapping

from suspid.errors import ConfigError

_PLACEHOLDER = re.compile(r"\{\{(.*?)\}\}")
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def is_name(text: str) -> bool:
    """True when ``text`` is a valid placeholder name (a Python-style identifier)."""
    return bool(_NAME.match(text))


# -- paths --------------------------------------------------------------------------
def safe_relpath(text: str, what: str) -> str:
    """Check a path meant to stay inside a working directory; returns it in POSIX form.

    Rejected: empty paths, absolute paths (``/x``, ``C:\\x``, ``\\\\server\\x``)
    and any ``..`` component. Backslashes count as separators.

    :param text: the path as the user wrote it.
    :param what: what the path is, for the error message (``"export.file"``).
    :raises ValueError: with a message naming ``what`` (pydantic turns it into
        a config error with the key path).
    """
    raw = str(text).strip()
    if not raw:
        raise ValueError(f"{what}: empty path")
    posix = raw.replace("\\", "/")
    if posix.startswith("/") or re.match(r"^[A-Za-z]:", posix):
        raise ValueError(f"{what}: '{raw}' is absolute; give a path relative to the working directory")
    parts = [p for p in PurePosixPath(posix).parts if p not in ("", ".")]
    if ".." in parts:
        raise ValueError(f"{what}: '{raw}' contains '..'; paths must stay inside the working directory")
    if not parts:
        raise ValueError(f"{what}: '{raw}' names the working directory itself, not a file")
    return "/".join(parts)


def inside(workdir: Path, relpath: str) -> Path:
    """``workdir / relpath``, checked (after resolving links) to lie inside ``workdir``.

    :raises ConfigError: when the resolved path escapes (e.g. through a link).
    """
    root = workdir.resolve()
    target = (root / relpath).resolve()
    if target != root and root not in target.parents:
        raise ConfigError(f"path '{relpath}' resolves to {target}, outside the working directory {root}")
    return target


# -- placeholders ---------------------------------------------------------------------
def scan(text: str, source: str) -> list[tuple[str, int]]:
    """Placeholders in ``text`` as ``(name, line)`` pairs, line numbers from 1.

    :param source: the file (or option) the text comes from, for messages.
    :raises ConfigError: on a malformed placeholder or a leftover ``{{``/``}}``.
    """
    found: list[tuple[str, int]] = []
    for lineno, line in enumerate(text.splitlines(), 1):
        for match in _PLACEHOLDER.finditer(line):
            inner = match.group(1).strip()
            if not is_name(inner):
                raise ConfigError(f"invalid placeholder '{match.group(0)}': expected '{{{{ name }}}}' with a "
                                  f"name of letters, digits and '_'", file=source, line=lineno)
            found.append((inner, lineno))
        rest = _PLACEHOLDER.sub("", line)
        for token in ("{{", "}}"):
            if token in rest:
                raise ConfigError(f"unmatched '{token}' (a placeholder must open and close on one line)",
                                  file=source, line=lineno)
    return found


def render(text: str, values: Mapping[str, str], source: str) -> str:
    """Replace every ``{{ name }}`` in ``text`` by ``values[name]``.

    :raises ConfigError: naming ``source`` and the line for an unknown name or
        a leftover brace pair.
    """
    for name, lineno in scan(text, source):
        if name not in values:
            raise ConfigError(f"unknown placeholder '{{{{ {name} }}}}'; known: {', '.join(sorted(values))}",
                              file=source, line=lineno)
    return _PLACEHOLDER.sub(lambda m: values[m.group(1).strip()], text)


def check_names(uses: Iterable[tuple[str, str, int]], known: Iterable[str]) -> None:
    """Every used name must be known.

    :param uses: ``(name, source, line)`` triples.
    :raises ConfigError: for the first unknown name, with file and line.
    """
    known = set(known)
    for name, source, lineno in uses:
        if name not in known:
            raise ConfigError(f"unknown placeholder '{{{{ {name} }}}}'; known: {', '.join(sorted(known))}",
                              file=source, line=lineno)


# -- template directories ----------------------------------------------------------------
@dataclass(frozen=True)
class TemplateFile:
    """One file of a template directory.

    :ivar relpath: POSIX path relative to the template directory.
    :ivar data: the file's bytes.
    :ivar text: decoded text to render, or ``None`` for a file copied verbatim.
    :ivar placeholders: ``(name, line)`` pairs found in ``text``.
    """

    relpath: str
    data: bytes
    text: str | None
    placeholders: tuple[tuple[str, int], ...] = ()


@dataclass(frozen=True)
class TemplateSet:
    """A snapshot of a template directory.

    :ivar root: the directory.
    :ivar files: its files, sorted by path.
    :ivar digest: SHA-256 (hex) of every path and content; edited templates
        give another digest, so cached results are not reused.
    """

    root: Path
    files: tuple[TemplateFile, ...]
    encoding: str
    digest: str = ""
    names: frozenset[str] = field(default_factory=frozenset)

    def uses(self) -> list[tuple[str, str, int]]:
        """Every placeholder use as ``(name, file, line)``."""
        return [(name, str(self.root / f.relpath), line) for f in self.files for name, line in f.placeholders]

    def render_into(self, workdir: Path, values: Mapping[str, str]) -> None:
        """Write every file, rendered, under ``workdir`` (which must exist).

        :raises ConfigError: for an unknown placeholder (file and line) or a
            path that would leave ``workdir``.
        """
        for f in self.files:
            target = inside(workdir, f.relpath)
            target.parent.mkdir(parents=True, exist_ok=True)
            if f.text is None:
                target.write_bytes(f.data)
            else:
                rendered = render(f.text, values, str(self.root / f.relpath))
                target.write_bytes(rendered.encode(self.encoding))


def load_templates(root: Path, encoding: str = "utf-8", copy_only: Iterable[str] = ()) -> TemplateSet:
    """Read a template directory.

    Files matching a glob of ``copy_only`` (matched against the relative POSIX
    path and the file name) are copied verbatim; every other file must decode
    in ``encoding`` and is rendered. Linked files are read through the link;
    linked directories are refused (their content would silently be left out
    or could loop).

    :raises ConfigError: for a missing or empty directory, a linked directory,
        a file that is not text, or a malformed placeholder (file and line).
    """
    root = Path(root)
    if not root.is_dir():
        raise ConfigError(f"template directory not found: {root}", key="simulator.options.template_dir")
    codecs.lookup(encoding)
    globs = list(copy_only)
    files: list[TemplateFile] = []
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames.sort()
        for d in dirnames:
            if os.path.islink(os.path.join(dirpath, d)):
                raise ConfigError(f"linked directory in the template directory: {os.path.join(dirpath, d)}; "
                                  f"copy its files in instead", key="simulator.options.template_dir")
        for name in sorted(filenames):
            path = Path(dirpath) / name
            rel = path.relative_to(root).as_posix()
            data = path.read_bytes()
            if any(fnmatch.fnmatchcase(rel, g) or fnmatch.fnmatchcase(name, g) for g in globs):
                files.append(TemplateFile(rel, data, None))
                continue
            try:
                text = data.decode(encoding)
            except UnicodeDecodeError as exc:
                raise ConfigError(f"not a text file in encoding {encoding} (byte {exc.start}); list it under "
                                  f"copy_only to copy it without rendering, or set template_encoding",
                                  file=str(path)) from None
            files.append(TemplateFile(rel, data, text, tuple(scan(text, str(path)))))
    if not files:
        raise ConfigError(f"template directory {root} has no files", key="simulator.options.template_dir")
    files.sort(key=lambda f: f.relpath)
    h = hashlib.sha256()
    for f in files:
        h.update(f.relpath.encode() + b"\0" + str(len(f.data)).encode() + b"\0" + f.data)
        h.update(b"\0verbatim" if f.text is None else b"\0rendered")
    names = frozenset(n for f in files for n, _ in f.placeholders)
    return TemplateSet(root=root, files=tuple(files), encoding=encoding, digest=h.hexdigest(), names=names)
