"""What values a sensor on a train can give: impossible ones are refused, unusual ones are warned about.

One policy for every way data come in: the readers of measured files
(``suspid validate`` and ``suspid run``, :mod:`suspid.data.files`) and
``suspid ingest`` (:mod:`suspid.data.ingest`). A value no train in service can
produce is an error, one line naming the file, the channel and what was
expected, unless the user names the check in ``data.accept`` (a config) or
``quality.accept`` (an ingest file): the data are then used, with a warning.
Values that are possible but unusual are a warning (an error with
``data.strict``). Values beyond :data:`ABSURD` (1e6 in SI units) are a damaged
file, never accepted.

The checks, by the name ``accept`` takes:

``implausible_amplitude``
    The vibration (the rms about the mean, so that the 1 g a DC-coupled
    vertical accelerometer reads does not count) of an acceleration channel
    beyond what its place on a train can see in service
    (:data:`ACCELERATION_LIMITS`, by the channel's kind, a word of its name),
    or the irregularity of a track channel in the EN 13848 D1 wavelength band
    (3 to 25 m) beyond :data:`TRACK_D1_RMS_LIMIT`. Values in mm/s^2 read as
    m/s^2, mm read as m, a declared unit that contradicts the file, MAT data
    stored in other units: each is about 1000 times too large.
``dead_channel``
    An acceleration channel that is constant (all zero: disconnected) or
    whose vibration is below :data:`DEAD_RMS` (1e-5 m/s^2), under the
    electronic noise of any accelerometer: no working sensor on a running
    train is that quiet.
``implausible_speed``
    A train speed above :data:`SPEED_LIMIT` (160 m/s): faster than the rail
    speed record (574.8 km/h, TGV V150, 2007); km/h read as m/s.

The limits, from public figures:

- Carbody: the ride-characteristic limits of EN 14363 (acceptance of
  running characteristics) on the carbody's accelerations are of the order of
  0.5-0.75 m/s^2 rms and 2.5-3 m/s^2 peak (0.4-10 Hz); in service they are
  0.05-0.5 m/s^2 rms. Unusual above 2 m/s^2 rms, impossible above 20 m/s^2
  (2 g rms, some thirty times the acceptance limit).
- Bogie frame: the instability criterion of EN 14363 (after UIC 515) on the
  frame's lateral acceleration is (12 - m_bogie / 5 t) m/s^2 peak, half that
  rms; broad-band frame accelerations are 1-5 m/s^2 rms at 300 km/h. Unusual
  above 20 m/s^2, impossible above 200 m/s^2 (20 g rms).
- Axlebox (unsprung): tens of m/s^2 rms, peaks of some hundred m/s^2 at wheel
  flats and rail joints. Unusual above 500 m/s^2, impossible above 2000 m/s^2.
  A channel of no known kind gets the axlebox's limits (the widest).
- Track: the EN 13848-5 immediate action limits on isolated defects of
  longitudinal level and alignment in the D1 band are a few tens of mm mean to
  peak, the lowest on the fastest lines; a recording car's D1 rms is 0.5-3 mm
  on high-speed lines (the published German spectra give 1-2 mm, the worst US
  class FRA 1 about 8 mm). Unusual above 15 mm rms, impossible above 50 mm:
  every stretch beyond the immediate action limit of any line, i.e. closed
  to traffic. The band leaves out the long wavelengths of the line's own
  vertical alignment, which a synthetic spectrum with 1/Omega^2 growth makes
  large without being an irregularity a recording car reports.
- Speed: commercial services run at up to 350 km/h (97 m/s): unusual above
  100 m/s, impossible above 160 m/s.
"""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Collection, Literal, Sequence

import numpy as np
from scipy import signal

from suspid.errors import DataError, DataWarning

Check = Literal["implausible_amplitude", "dead_channel", "implausible_speed"]
"""A check that ``data.accept`` / ``quality.accept`` can name."""
CHECKS: tuple[str, ...] = Check.__args__

ABSURD = 1e6
"""Largest magnitude of an irregularity (m) or acceleration (m/s^2) a sensor can give: beyond, a damaged file."""
DEAD_RMS = 1e-5
"""Smallest vibration rms of a working accelerometer on a running train, m/s^2."""
ACCELERATION_LIMITS: dict[str | None, tuple[float, float, float]] = {
    "carbody": (0.003, 2.0, 20.0),
    "bogie": (0.02, 20.0, 200.0),
    "axlebox": (0.3, 500.0, 2000.0),
    None: (DEAD_RMS, 50.0, 2000.0),
}
"""Channel kind -> (usual lowest, usual highest, impossible above) vibration rms, m/s^2 (module docstring)."""
TRACK_D1_BAND_M = (3.0, 25.0)
"""The EN 13848 D1 wavelength band, m, in which track irregularities are judged."""
TRACK_D1_RMS_USUAL = 0.015
"""Largest usual rms of a track irregularity channel in the D1 band, m."""
TRACK_D1_RMS_LIMIT = 0.05
"""Rms of a track irregularity channel in the D1 band above which no track is in service, m."""
SPEED_USUAL = 100.0
"""Largest usual train speed, m/s (360 km/h)."""
SPEED_LIMIT = 160.0
"""Train speed above which no train has run, m/s (576 km/h)."""


KIND_WORDS = {"axlebox": ("axlebox", "axle", "wheelset", "ws"), "bogie": ("bogie", "frame"),
              "carbody": ("carbody", "car", "body")}
"""Words of a channel's name that give its kind, the most specific kind first (an axlebox of a bogie is an
axlebox: it sits below the primary suspension)."""


def kind_of(channel: str, kinds: Collection[str] = ("axlebox", "bogie", "carbody")) -> str | None:
    """The kind of a channel (``carbody``, ``bogie``, ``axlebox``): a word of its name, else None.

    The most specific kind wins: ``bogie_front_axlebox_vertical`` is an axlebox channel.
    """
    words = set(re.sub(r"\d+", "", channel.replace("-", "_").lower()).split("_"))   # car1 -> car
    specific = sorted(kinds, key=lambda k: list(KIND_WORDS).index(k) if k in KIND_WORDS else len(KIND_WORDS))
    return next((k for k in specific if words & set(KIND_WORDS.get(k, (k,)))), None)


@dataclass(frozen=True)
class Doubt:
    """One finding: ``check`` names what makes it impossible (None: merely unusual, a warning)."""

    message: str
    check: str | None = None


def vibration_rms(values: np.ndarray) -> float:
    """The rms about the mean of ``values`` (NaN left out), in their unit."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return float(np.std(v)) if v.size else float("nan")


def acceleration_doubts(channel: str, rms: float, constant: bool, unit_hint: str = "") -> list[Doubt]:
    """Doubts about one acceleration channel from its vibration rms (m/s^2).

    :param constant: every sample equal (a disconnected sensor reads one value).
    :param unit_hint: appended to an amplitude finding (e.g. what unit the file states).
    """
    kind = kind_of(channel)
    low, high, limit = ACCELERATION_LIMITS[kind]
    place = f"a {kind} of a train in service" if kind else "any place on a train in service"
    if constant:
        return [Doubt(f"channel '{channel}' is constant: a dead or disconnected sensor", "dead_channel")]
    if rms < DEAD_RMS:
        return [Doubt(f"channel '{channel}' vibrates with {rms:.3g} m/s^2 rms, below the noise of any working "
                      f"accelerometer ({DEAD_RMS:g} m/s^2): a dead sensor?", "dead_channel")]
    if rms > limit:
        return [Doubt(f"channel '{channel}' vibrates with {rms:.3g} m/s^2 rms, beyond {place} (at most "
                      f"{limit:g} m/s^2): values in mm/s^2 instead of m/s^2?{unit_hint}", "implausible_amplitude")]
    if rms > high:
        return [Doubt(f"channel '{channel}' vibrates with {rms:.3g} m/s^2 rms, more than {place} usually does "
                      f"(up to {high:g} m/s^2): is its unit right?{unit_hint}")]
    return []


def d1_rms(values: np.ndarray, step_m: float) -> float:
    """Rms of a track channel (m) sampled every ``step_m`` m, in the D1 wavelength band :data:`TRACK_D1_BAND_M`.

    NaN samples are bridged linearly; a record too short or too coarse for the band is judged whole
    (about its mean).
    """
    x = np.asarray(values, dtype=float)
    good = np.isfinite(x)
    if not good.any():
        return float("nan")
    if not good.all():
        x = np.interp(np.arange(x.size), np.flatnonzero(good), x[good])
    i = np.arange(x.size, dtype=float)
    x = x - np.polyval(np.polyfit(i, x, 1), i)    # the line's gradient or a drift is no irregularity
    x = x * signal.windows.tukey(x.size, 0.1)       # no jump where the FFT wraps the record around
    k = np.fft.rfftfreq(x.size, step_m)
    band = (k >= 1.0 / TRACK_D1_BAND_M[1]) & (k <= 1.0 / TRACK_D1_BAND_M[0])
    if not band.any():
        return float(np.sqrt(np.mean(x ** 2)))
    spectrum = np.fft.rfft(x)
    spectrum[~band] = 0.0
    return float(np.sqrt(np.mean(np.fft.irfft(spectrum, x.size) ** 2)))


def speed_statistic(speed: np.ndarray) -> float:
    """The speed judged against the limits, m/s: the 99th percentile of the finite samples (one glitch of the
    odometry is no speed), the same in ingest and in the readers of validate and run."""
    v = np.asarray(speed, dtype=float).ravel()
    v = v[np.isfinite(v)]
    return float(np.percentile(v, 99)) if v.size else float("nan")


def track_doubts(channel: str, rms_d1: float, unit_hint: str = "") -> list[Doubt]:
    """Doubts about one track irregularity channel from its D1-band rms (m)."""
    if rms_d1 > TRACK_D1_RMS_LIMIT:
        return [Doubt(f"channel '{channel}' has irregularities of {rms_d1:.3g} m rms in the 3-25 m wavelength band "
                      f"(EN 13848 D1), beyond any track open to traffic (at most {TRACK_D1_RMS_LIMIT:g} m): "
                      f"values in mm instead of m?{unit_hint}", "implausible_amplitude")]
    if rms_d1 > TRACK_D1_RMS_USUAL:
        return [Doubt(f"channel '{channel}' has irregularities of {rms_d1:.3g} m rms in the 3-25 m wavelength band "
                      f"(EN 13848 D1), more than a track in service usually has (up to {TRACK_D1_RMS_USUAL:g} m): "
                      f"is its unit right?{unit_hint}")]
    return []


def speed_doubts(speed: float, what: str = "speed") -> list[Doubt]:
    """Doubts about a train speed (m/s)."""
    if speed > SPEED_LIMIT:
        return [Doubt(f"{what} {speed:g} m/s ({speed * 3.6:g} km/h) is above any train's ({SPEED_LIMIT:g} m/s, the "
                      f"rail speed record being 574.8 km/h): km/h instead of m/s?", "implausible_speed")]
    if speed > SPEED_USUAL:
        return [Doubt(f"{what} {speed:g} m/s ({speed * 3.6:g} km/h) is above every commercial service "
                      f"({SPEED_USUAL:g} m/s): is its unit right?")]
    return []


def refused(doubts: Sequence[Doubt], *, accept: Collection[str] = (), accept_key: str = "data.accept") -> str | None:
    """The first finding :func:`judge` refuses, worded as it words it (without the file), or None.

    For a value that is no file's (a config's speed, a command-line option): the caller puts its own prefix
    (a config's file, line and key) before the same words.
    """
    accepted = set(accept)
    for d in doubts:
        if d.check is not None and d.check not in accepted:
            return f"{d.message} (if these values are right, add {d.check} to {accept_key})"
    return None


def judge(doubts: Sequence[Doubt], where: Path | str, *, accept: Collection[str] = (), strict: bool = False,
          accept_key: str = "data.accept", emit: bool = True, stacklevel: int = 2) -> list[str]:
    """Refuse the impossible, warn about the unusual: the policy of the module docstring.

    :param doubts: the findings, each message without the file.
    :param where: the file (or label) each message starts with.
    :param accept: the checks the user accepts (their findings become warnings).
    :param strict: unusual findings are errors too.
    :param accept_key: the key that takes ``accept`` (``data.accept``, ``quality.accept``), for the message.
    :param emit: send the warnings as one :class:`~suspid.errors.DataWarning` (the first, with how many more;
        False: the caller reports them, as ``suspid ingest`` does in its quality report).
    :returns: the warnings, one line each.
    :raises DataError: the first finding that is refused, one line naming ``where``.
    """
    refusal = refused(doubts, accept=accept, accept_key=accept_key)
    if refusal is not None:
        raise DataError(f"{where}: {refusal}")
    messages = [f"{where}: {d.message}" + (f" (accepted: {d.check} in {accept_key})" if d.check else "")
                for d in doubts]
    if strict and any(d.check is None for d in doubts):
        first = next(m for m, d in zip(messages, doubts) if d.check is None)
        raise DataError(first + " (refused in strict mode)")
    if emit and messages:   # one line per record: ten channels of one file in mm/s^2 are one finding
        more = f" (and {len(messages) - 1} more like it here)" if len(messages) > 1 else ""
        warnings.warn(messages[0] + more, DataWarning, stacklevel=stacklevel + 1)
    return messages
