"""Wheel and rail profile files in Vampire's ``.whe`` / ``.rai`` layout (a utility).

Layout, as read by the open-source CONTACT project (its Vampire profile
reader); all lengths in millimetres:

- line 1: ``WHEELPROFILE`` or ``RAILPROFILE``;
- line 2: a title of at most 80 characters;
- line 3: wheels ``TREADDATUM EUROPEAN|US1|US2|CUSTOM x``, rails
  ``GAUGEPOINT EUROPEAN|US|CUSTOM h``;
- line 4: wheels ``FLANGEBACK d``, rails ``GAUGE w``;
- then one row per point: ``y_left z_left y_right z_right``, separated by
  spaces or commas; anything after ``"``, ``!`` or ``%`` is a comment.

Coordinates are kept as written: no mirroring, reordering or datum shift
(those conventions belong to the program reading the file).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from suspid.errors import DataError

KEYWORDS = {"wheel": ("WHEELPROFILE", "TREADDATUM", "FLANGEBACK"),
            "rail": ("RAILPROFILE", "GAUGEPOINT", "GAUGE")}
"""kind -> (first line, line-3 keyword, line-4 keyword)."""

DATUMS = {"wheel": ("EUROPEAN", "US1", "US2", "CUSTOM"), "rail": ("EUROPEAN", "US", "CUSTOM")}
"""Datum names allowed on line 3 for each kind."""

TITLE_MAX = 80


@dataclass
class Profile:
    """A wheel or rail profile pair (left and right).

    :ivar kind: ``"wheel"`` (``.whe``) or ``"rail"`` (``.rai``).
    :ivar title: one line, at most 80 characters.
    :ivar datum: tread datum (wheel) or gauge point (rail) name, e.g. ``EUROPEAN``.
    :ivar datum_value: mm, the number after ``CUSTOM``; ``None`` otherwise.
    :ivar spacing: mm, flange-back distance (wheel) or gauge (rail).
    :ivar points: ``(n, 4)`` mm, rows ``y_left, z_left, y_right, z_right``.
    """

    kind: Literal["wheel", "rail"]
    title: str
    datum: str
    datum_value: float | None
    spacing: float
    points: np.ndarray

    @property
    def left(self) -> np.ndarray:
        """``(n, 2)`` mm: y, z of the left profile."""
        return self.points[:, 0:2]

    @property
    def right(self) -> np.ndarray:
        """``(n, 2)`` mm: y, z of the right profile."""
        return self.points[:, 2:4]


def _float(text: str, where: str, what: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise DataError(f"{where}: expected {what}, got {text!r}") from None


def read_profile(path: str | Path) -> Profile:
    """Read a ``.whe`` or ``.rai`` file.

    :raises DataError: naming the file and line of the first problem.
    """
    path = Path(path)
    try:
        lines = path.read_text(encoding="latin-1").splitlines()
    except OSError as exc:
        raise DataError(f"{path}: cannot read profile ({exc.strerror or exc})") from None
    if len(lines) < 4:
        raise DataError(f"{path}: a profile needs 4 header lines, the file has {len(lines)} lines")
    first = lines[0].strip().upper()
    kinds = {v[0]: k for k, v in KEYWORDS.items()}
    if first not in kinds:
        raise DataError(f"{path}:1: expected WHEELPROFILE or RAILPROFILE, got {lines[0].strip()!r}")
    kind = kinds[first]
    _, datum_kw, spacing_kw = KEYWORDS[kind]
    title = lines[1].rstrip()
    words = lines[2].split()
    if len(words) < 2 or words[0].upper() != datum_kw:
        raise DataError(f"{path}:3: expected '{datum_kw} {'|'.join(DATUMS[kind])}', got {lines[2].strip()!r}")
    datum = words[1].upper()
    if datum not in DATUMS[kind]:
        raise DataError(f"{path}:3: unknown {datum_kw} {words[1]!r}; expected one of {', '.join(DATUMS[kind])}")
    datum_value = None
    if datum == "CUSTOM":
        if len(words) != 3:
            raise DataError(f"{path}:3: {datum_kw} CUSTOM needs one number (mm)")
        datum_value = _float(words[2], f"{path}:3", f"a number after {datum_kw} CUSTOM")
    elif len(words) != 2:
        raise DataError(f"{path}:3: unexpected text after {datum_kw} {datum}: {' '.join(words[2:])!r}")
    words = lines[3].split()
    if len(words) != 2 or words[0].upper() != spacing_kw:
        raise DataError(f"{path}:4: expected '{spacing_kw} <mm>', got {lines[3].strip()!r}")
    spacing = _float(words[1], f"{path}:4", f"a number after {spacing_kw}")
    rows = []
    for lineno, line in enumerate(lines[4:], 5):
        data = re.split(r"[\"!%]", line, maxsplit=1)[0].replace(",", " ").split()
        if not data:
            continue
        if len(data) != 4:
            raise DataError(f"{path}:{lineno}: expected 4 numbers (y_left z_left y_right z_right), got {len(data)}")
        rows.append([_float(d, f"{path}:{lineno}", "a number") for d in data])
    if len(rows) < 2:
        raise DataError(f"{path}: a profile needs at least 2 points, found {len(rows)}")
    points = np.asarray(rows)
    if not np.all(np.isfinite(points)):
        raise DataError(f"{path}: non-finite coordinates")
    return Profile(kind=kind, title=title, datum=datum, datum_value=datum_value, spacing=spacing, points=points)


def write_profile(path: str | Path, profile: Profile, number_format: str = ".4f") -> None:
    """Write ``profile`` as a ``.whe`` or ``.rai`` file (numbers in mm with ``number_format``).

    :raises DataError: for a title longer than 80 characters or on several
        lines, an unknown datum, a missing CUSTOM value, or points that are not
        a finite ``(n, 4)`` array with n >= 2.
    """
    if profile.kind not in KEYWORDS:
        raise DataError(f"profile kind must be 'wheel' or 'rail', got {profile.kind!r}")
    first, datum_kw, spacing_kw = KEYWORDS[profile.kind]
    if len(profile.title) > TITLE_MAX or "\n" in profile.title or "\r" in profile.title:
        raise DataError(f"profile title must be one line of at most {TITLE_MAX} characters: {profile.title!r}")
    datum = profile.datum.upper()
    if datum not in DATUMS[profile.kind]:
        raise DataError(f"unknown {datum_kw} {profile.datum!r}; expected one of {', '.join(DATUMS[profile.kind])}")
    if (datum == "CUSTOM") != (profile.datum_value is not None):
        raise DataError(f"{datum_kw}: a value is needed with CUSTOM and only with CUSTOM")
    points = np.asarray(profile.points, dtype=float)
    if points.ndim != 2 or points.shape[1] != 4 or points.shape[0] < 2 or not np.all(np.isfinite(points)):
        raise DataError(f"profile points must be a finite (n, 4) array with n >= 2, got shape {points.shape}")
    datum_line = f"{datum_kw} {datum}" + (f" {profile.datum_value:{number_format}}" if datum == "CUSTOM" else "")
    lines = [first, profile.title, datum_line, f"{spacing_kw} {profile.spacing:{number_format}}"]
    lines += [" ".join(f"{v:{number_format}}" for v in row) for row in points.tolist()]
    Path(path).write_text("\n".join(lines) + "\n", encoding="latin-1")
