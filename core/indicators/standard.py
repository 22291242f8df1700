"""The standard ride and stability indicators of a recording, no identification needed.

**EN 14363 bogie-frame lateral instability** (EN 14363:2016 §7.6.3.2.2 and
UIC 518 (2009) §10.1.2.2; the public summary of the UIC 518 / EN 14363 test
quantities at gensys.se, "Acceptance test according to UIC 518", lists the
band f0 ± 2 Hz and the sliding rms): the bogie frame's lateral acceleration
is band-passed around the instability (hunting) frequency f0, then its rms is
taken over a window of 100 m of track sliding by 10 m. The limit for the
sliding rms is ``(12 - m_b / 5) / 2`` m/s^2 with m_b the bogie mass in tonnes
(UIC 515-1 / UIC 518's simplified criterion, kept as the limit of the sliding
rms in EN 14363). The indicator of a segment is the largest sliding rms; the
run's is the largest over its segments. f0 is the configured hunting
frequency or, by default, the peak of the lateral bogie-frame spectrum
between 2 and 12 Hz (Welch).

**EN 12299 mean comfort, standard method** (N_MV; EN 12299:2009 §6.2.1):
``N_MV = 6 sqrt((a_XP95^Wd)^2 + (a_YP95^Wd)^2 + (a_ZP95^Wb)^2)`` where a^W is the
rms of the weighted carbody-floor acceleration over consecutive 5 s blocks and
P95 the 95th percentile of the blocks (of a 5 min zone in the standard; here
of a segment, and of all the run's segments for the run's value). The
carbody's longitudinal acceleration is not among the simulators' channels:
its term is left out, so N_MV here is a lower bound of the standard's (said in
the ``detail``). Scale (EN 12299 Table 3): < 1 very comfortable, 1-2
comfortable, 2-4 medium, 4-5 uncomfortable, > 5 very uncomfortable.

Verdicts: instability ``alarm`` above the limit, ``warning`` above 80 % of it,
else ``ok``; ``not assessable`` without a bogie mass. Comfort: ``alarm`` from
4 (uncomfortable), ``warning`` from 2 (medium), else ``ok``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any, Sequence

import numpy as np
from scipy import signal

from suspid.indicators.weighting import WB, WD, weight
from suspid.interfaces import Response, TrackSegment

INSTABILITY = "en14363-instability"
COMFORT = "en12299-comfort"
WINDOW_M = 100.0
"""EN 14363 sliding window of the instability rms, m."""
STEP_M = 10.0
"""Step of the sliding window, m."""
HALF_BAND_HZ = 2.0
"""Half-width of the band around the hunting frequency, Hz."""
BLOCK_S = 5.0
"""EN 12299 block of the weighted rms, s."""
HUNTING_SEARCH_HZ = (2.0, 12.0)
COMFORT_WARNING, COMFORT_ALARM = 2.0, 4.0
INSTABILITY_WARNING_FRACTION = 0.8


@dataclass
class IndicatorValue:
    """One indicator value: per segment (``segment`` set) or per run (``segment`` None)."""

    name: str
    value: float
    unit: str
    verdict: str
    segment: str | None = None
    channel: str = ""
    limit: float | None = None
    detail: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def instability_limit(bogie_mass_kg: float) -> float:
    """EN 14363 / UIC 518 limit of the sliding rms of the bogie-frame lateral acceleration, m/s^2.

    ``(12 - m_b / 5) / 2`` with m_b in tonnes (3.5 t: 5.65 m/s^2).
    """
    return 0.5 * (12.0 - bogie_mass_kg / 1000.0 / 5.0)


def sliding_rms(x: np.ndarray, fs: float, speed_mps: float, window_m: float = WINDOW_M,
                step_m: float = STEP_M) -> np.ndarray:
    """rms of ``x`` (n_t,) over windows of ``window_m`` of track sliding by ``step_m`` at ``speed_mps``.

    A record shorter than one window gives one rms over the whole record.
    """
    n_win = int(round(window_m / speed_mps * fs))
    n_step = max(1, int(round(step_m / speed_mps * fs)))
    if n_win >= x.size:
        return np.array([np.sqrt(np.mean(x**2))])
    sq = np.concatenate([[0.0], np.cumsum(x**2)])
    starts = np.arange(0, x.size - n_win + 1, n_step)
    return np.sqrt((sq[starts + n_win] - sq[starts]) / n_win)


def band_pass(x: np.ndarray, fs: float, f0: float, half_band: float = HALF_BAND_HZ) -> np.ndarray:
    """``x`` band-passed to [f0 - half_band, f0 + half_band] Hz (4th-order Butterworth, zero phase)."""
    lo, hi = max(f0 - half_band, 0.05), min(f0 + half_band, 0.49 * fs)
    sos = signal.butter(4, [lo, hi], btype="bandpass", fs=fs, output="sos")
    return signal.sosfiltfilt(sos, x)


def hunting_frequency(x: np.ndarray, fs: float, search: tuple[float, float] = HUNTING_SEARCH_HZ) -> float:
    """Peak of the Welch spectrum of ``x`` between ``search`` (Hz): the frequency the bogie frame hunts at."""
    f, p = signal.welch(x - np.mean(x), fs=fs, nperseg=min(x.size, int(8 * fs)))
    band = (f >= search[0]) & (f <= search[1])
    return float(f[band][np.argmax(p[band])])


def instability(x: np.ndarray, fs: float, speed_mps: float, *, bogie_mass_kg: float | None,
                hunting_hz: float | None = None) -> tuple[float, float, np.ndarray]:
    """EN 14363 instability indicator of one record of bogie-frame lateral acceleration ``x`` (n_t,), m/s^2.

    :returns: (the largest sliding rms, f0 used, the sliding rms series).
    """
    f0 = hunting_hz if hunting_hz is not None else hunting_frequency(x, fs)
    s = sliding_rms(band_pass(np.asarray(x, float), fs, f0), fs, speed_mps)
    return float(s.max()), f0, s


def block_rms(x: np.ndarray, fs: float, block_s: float = BLOCK_S) -> np.ndarray:
    """rms over consecutive blocks of ``block_s`` (a shorter record: one block over all of it)."""
    n = int(round(block_s * fs))
    if x.size < n:
        return np.array([np.sqrt(np.mean(x**2))])
    k = x.size // n
    return np.sqrt(np.mean(x[: k * n].reshape(k, n) ** 2, axis=1))


def comfort_nmv(a_y95: float, a_z95: float, a_x95: float = 0.0) -> float:
    """EN 12299 mean comfort N_MV from the 95th percentiles of the weighted 5 s rms (m/s^2)."""
    return 6.0 * float(np.sqrt(a_x95**2 + a_y95**2 + a_z95**2))


def _verdict(value: float, warning: float | None, alarm: float | None) -> str:
    if alarm is None:
        return "not assessable"
    return "alarm" if value > alarm else "warning" if value > warning else "ok"


def _first(channels: Sequence[str], *words: str) -> str | None:
    return next((c for c in channels if all(w in c for w in words)), None)


def compute_indicators(segments: Sequence[TrackSegment], responses: Sequence[Response], *,
                       bogie_mass_kg: float | None, hunting_hz: float | None = None,
                       lateral_bogie: str | None = None, lateral_carbody: str | None = None,
                       vertical_carbody: str | None = None) -> list[IndicatorValue]:
    """Both indicators per segment and per run (the run's values last).

    Channels default to the first whose name has ``bogie`` and ``lateral`` (instability) and ``carbody``
    with ``lateral`` / ``vertical`` (comfort); an indicator whose channel is missing is left out.

    :param segments: the track segments, for the speeds (same order as ``responses``).
    :param responses: accelerations (n_channels, n_t) in m/s^2.
    :param bogie_mass_kg: the bogie's mass for the instability limit; None: verdict ``not assessable``.
    """
    if not responses:
        return []
    channels = list(responses[0].channels)
    bogie = lateral_bogie or _first(channels, "bogie", "lateral")
    car_y = lateral_carbody or _first(channels, "carbody", "lateral")
    car_z = vertical_carbody or _first(channels, "carbody", "vertical")
    limit = instability_limit(bogie_mass_kg) if bogie_mass_kg is not None else None
    # what the verdicts were judged against, in every value's detail (an output file must say it)
    inputs = {"bogie_mass_kg": bogie_mass_kg, "alarm_level": limit,
              "warning_level": None if limit is None else round(INSTABILITY_WARNING_FRACTION * limit, 9),
              "hunting_hz_source": "given" if hunting_hz is not None else "spectral peak of the segment"}
    levels = {"warning_level": COMFORT_WARNING, "alarm_level": COMFORT_ALARM}
    out: list[IndicatorValue] = []
    worst: tuple[float, str, float] | None = None
    all_y, all_z = [], []
    for seg, resp in zip(segments, responses):
        index = {c: i for i, c in enumerate(resp.channels)}
        if bogie in index:
            peak, f0, _ = instability(resp.accelerations[index[bogie]], resp.fs, seg.mean_speed,
                                      bogie_mass_kg=bogie_mass_kg, hunting_hz=hunting_hz)
            out.append(IndicatorValue(INSTABILITY, peak, "m/s^2",
                                      _verdict(peak, None if limit is None else INSTABILITY_WARNING_FRACTION * limit,
                                               limit), resp.segment or seg.name, bogie, limit,
                                      {"f0_hz": f0, "window_m": WINDOW_M, "step_m": STEP_M} | inputs))
            if worst is None or peak > worst[0]:
                worst = (peak, resp.segment or seg.name, f0)
        if car_y in index and car_z in index:
            ay = block_rms(weight(resp.accelerations[index[car_y]], resp.fs, WD), resp.fs)
            az = block_rms(weight(resp.accelerations[index[car_z]], resp.fs, WB), resp.fs)
            all_y.append(ay)
            all_z.append(az)
            n = comfort_nmv(float(np.percentile(ay, 95)), float(np.percentile(az, 95)))
            out.append(IndicatorValue(COMFORT, n, "-", _verdict(n, COMFORT_WARNING, COMFORT_ALARM),
                                      resp.segment or seg.name, f"{car_y}, {car_z}", None,
                                      {"n_blocks": int(ay.size), "longitudinal": "not measured (left out)"} | levels))
    if worst is not None:
        out.append(IndicatorValue(INSTABILITY, worst[0], "m/s^2",
                                  _verdict(worst[0], None if limit is None else INSTABILITY_WARNING_FRACTION * limit,
                                           limit), None, bogie, limit,
                                  {"worst_segment": worst[1], "f0_hz": worst[2]} | inputs))
    if all_y:
        ay, az = np.concatenate(all_y), np.concatenate(all_z)
        n = comfort_nmv(float(np.percentile(ay, 95)), float(np.percentile(az, 95)))
        out.append(IndicatorValue(COMFORT, n, "-", _verdict(n, COMFORT_WARNING, COMFORT_ALARM), None,
                                  f"{car_y}, {car_z}", None,
                                  {"n_blocks": int(ay.size), "longitudinal": "not measured (left out)"} | levels))
    return out
