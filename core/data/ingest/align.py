"""Alignment of the track record to the vehicle's odometry distance.

At speed v a body that follows the track vertically has the acceleration
a = v^2 z''(x) (plus a_x z'(x), negligible here), so a / v^2, integrated twice
over distance in a band of wavelengths where the body follows the track (a
bogie or axlebox below its bounce frequency), is the band-limited vertical
profile z under it. Both are put on one distance grid (step: the short
wavelength / 16), band-limited by FFT (cosine edges), and cross-correlated
over the offsets ``guess_m +- search_m`` (by FFT over blocks of the
vehicle's profile, at those offsets only: the memory does not grow with the
run); the offset of the highest normalised correlation, refined by a parabola
through its neighbours, is where the sensor meets the track; minus
``lever_m`` it is the offset of the odometry reference point: track distance
= odometry distance + offset.

The lever is where the channel's response meets the track. A body's response
also lags its input (a bogie on its primary suspension: about 20 ms, 1.8 m at
300 km/h on exudyn-train), so the geometric lever is not enough for a 1 m
result: ``lever_m: model`` (the default) runs the same correlation on the
configured simulator's response to a synthetic track at the recording's
dominant speed, which gives the effective lever of that channel.

Confidence: the peak ratio, the highest correlation divided by the highest
one further than the long wavelength from it (1: ambiguous).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal as sps

from suspid.errors import DataError

from suspid.data.track import realise
from suspid.interfaces import Simulator, TrackSegment

from .load import CHUNK, TrackRecord
from .options import AlignmentSection

MAX_WIDENING = 8.0
"""A peak at the edge of ``guess_m +- search_m`` doubles the half-width, up to this many times search_m."""


@dataclass
class Alignment:
    offset_m: float              # track distance = odometry distance + offset_m
    peak_ratio: float            # confidence (inf: fixed offset)
    rho: float                   # normalised correlation at the peak
    lags_m: np.ndarray           # odometry offsets searched (sensor lags minus the lever)
    correlation: np.ndarray      # normalised correlation at each lag
    channel: str | None
    lever_m: float
    method: str
    calibration_speed_mps: float | None = None
    searched_m: float | None = None    # the half-width finally searched (wider than search_m: widened)

    def to_dict(self) -> dict:
        return {"offset_m": self.offset_m, "peak_ratio": self.peak_ratio, "rho": self.rho,
                "channel": self.channel, "lever_m": self.lever_m, "method": self.method,
                "calibration_speed_mps": self.calibration_speed_mps, "searched_m": self.searched_m}


def _band(n: int, dx: float, band: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """rfft wavenumbers (1/m) and a band window with cosine edges (a quarter octave)."""
    k = np.fft.rfftfreq(n, dx)
    lo, hi = 1.0 / band[1], 1.0 / band[0]
    w = np.zeros_like(k)
    w[(k >= lo) & (k <= hi)] = 1.0
    for edge, inside in ((lo, 1), (hi, -1)):
        ramp = (k >= edge / 2 ** 0.25) & (k <= edge * 2 ** 0.25)
        x = np.log2(np.maximum(k[ramp], 1e-12) / edge) / 0.25   # -1 .. 1 across the edge
        w[ramp] = 0.5 * (1 + inside * np.sin(0.5 * np.pi * x))
    return k, w


def _profile_from_acceleration(c: np.ndarray, dx: float, band) -> np.ndarray:
    """Band-limited double integral over distance of the curvature-like c = a / v^2."""
    n = c.size
    k, w = _band(n, dx, band)
    spec = np.fft.rfft(c)
    with np.errstate(divide="ignore", invalid="ignore"):
        spec = np.where(k > 0, -spec * w / (2 * np.pi * k) ** 2, 0.0)
    return np.fft.irfft(spec, n)


def _bandpass(z: np.ndarray, dx: float, band) -> np.ndarray:
    k, w = _band(z.size, dx, band)
    return np.fft.irfft(np.fft.rfft(z) * w, z.size)


def _at_speed(distance: np.ndarray, speed: np.ndarray, acc: np.ndarray, usable: np.ndarray, v_min: float
              ) -> tuple[np.ndarray, np.ndarray, float, float]:
    """The usable samples at speed: their distance and a / v^2, and the sums of v^2 and v^3.

    Built a chunk of samples at a time into arrays of the selected size (no whole-record temporaries).
    """
    sel = usable & np.isfinite(acc) & np.isfinite(speed) & (speed > v_min)
    m = int(sel.sum())
    if m < 16:
        raise DataError("alignment: too few samples at speed to correlate the track record")
    d, c = np.empty(m), np.empty(m)
    v2 = v3 = 0.0
    k = 0
    for a in range(0, sel.size, CHUNK):
        part = sel[a:a + CHUNK]
        v = speed[a:a + CHUNK][part]
        j = k + v.size
        d[k:j] = distance[a:a + CHUNK][part]
        c[k:j] = acc[a:a + CHUNK][part] / v ** 2
        v2, v3 = v2 + float(np.sum(v ** 2)), v3 + float(np.sum(v ** 3))
        k = j
    return d, c, v2, v3


def _correlation(u_v: np.ndarray, u_t: np.ndarray, s0: int, n_lags: int, block: int = 1 << 18) -> np.ndarray:
    """``r[i] = sum_j u_v[j] u_t[j + s0 + i]`` for ``i < n_lags`` (``u_t`` zero outside its record).

    By FFT over blocks of ``block`` samples of ``u_v``: the working memory grows with the block and the
    number of lags, not with the length of the run.
    """
    r = np.zeros(n_lags)
    for j0 in range(0, u_v.size, block):
        v = u_v[j0:j0 + block]
        lo, m = j0 + s0, v.size + n_lags - 1        # the stretch of u_t this block meets at all lags
        a, b = max(lo, 0), min(lo + m, u_t.size)
        if a >= b:
            continue
        t = np.zeros(m)
        t[a - lo:b - lo] = u_t[a:b]
        r += sps.correlate(t, v, mode="valid", method="fft")
    return r


def calibrate_lever(simulator: Simulator, channel: str, speed: float, opts: AlignmentSection,
                    length_m: float = 3000.0) -> float:
    """The effective lever of ``channel`` at ``speed`` (m/s): the same correlation, run on the simulator's
    response (nominal parameters) to a synthetic track whose position is known (German low spectra, fixed seed).

    :raises DataError: when the simulator cannot run (give ``alignment.lever_m`` then).
    """
    dx = 0.25
    x = np.arange(0.0, length_m, dx)
    irr = realise("german-low", x.size, dx, np.random.default_rng(20261123), (2.0, 250.0))
    try:
        r = simulator.simulate({}, [TrackSegment("lever-calibration", x, irr, float(speed))])[0]
    except Exception as exc:
        raise DataError(f"alignment: the simulator could not run the lever calibration ({exc}); "
                        f"give alignment.lever_m") from None
    a = r.accelerations[list(r.channels).index(channel)]
    t = np.arange(a.size) / r.fs
    track = TrackRecord("<calibration track>", 0.0, dx, irr, ("vertical",))
    sub = opts.model_copy(update={"lever_m": 0.0, "guess_m": 0.0, "search_m": 60.0, "offset_m": None})
    found = align(speed * t, np.full(a.size, float(speed)), a, np.ones(a.size, bool), track, sub, channel, 0.0)
    return found.offset_m


def align(distance: np.ndarray, speed: np.ndarray, acc: np.ndarray, usable: np.ndarray, track: TrackRecord,
          opts: AlignmentSection, channel: str | None, min_speed: float,
          simulator: Simulator | None = None) -> Alignment:
    """The odometry offset of the track record (module docstring).

    :param distance: ``(n,)`` odometry distance, m, non-decreasing.
    :param speed: ``(n,)`` m/s.
    :param acc: ``(n,)`` vertical acceleration of the alignment channel, m/s^2 (NaN: dropout).
    :param usable: ``(n,)`` samples the correlation may use.
    :raises DataError: too little usable data, or an ambiguous correlation.
    """
    if opts.offset_m is not None:
        return Alignment(float(opts.offset_m), float("inf"), float("nan"), np.empty(0), np.empty(0), channel,
                         float("nan") if opts.lever_m == "model" else opts.lever_m, "given")
    if channel is None:
        raise DataError("alignment: no vertical bogie or axlebox channel is mapped; set alignment.channel "
                        "or give alignment.offset_m")
    band = opts.wavelength_m
    dx = band[0] / 16.0
    d, c_d, v2, v3 = _at_speed(distance, speed, acc, usable, max(min_speed, 5.0))
    v_cal = None
    if opts.lever_m == "model":
        if simulator is None:
            raise DataError("alignment: lever_m 'model' needs the simulator; give alignment.lever_m")
        v_cal = v3 / v2      # the speeds whose responses dominate
        opts = opts.model_copy(update={"lever_m": calibrate_lever(simulator, channel, v_cal, opts)})
    xv = np.arange(d[0], d[-1], dx)
    if xv.size * dx < 4 * band[1]:
        raise DataError(f"alignment: {xv.size * dx:.0f} m at speed is too short for wavelengths up to "
                        f"{band[1]:g} m")
    c = np.interp(xv, d, c_d)
    del c_d
    # stretches the vehicle did not cover at speed (excluded, stations) carry no information: zero them
    near = np.searchsorted(d, xv)
    near = np.clip(near, 1, d.size - 1)
    hole = (d[near] - d[near - 1]) > 4 * dx
    del d, near
    c[hole] = 0.0
    u_v = _profile_from_acceleration(c - c.mean(), dx, band)
    u_v[hole] = 0.0
    n_t = int(np.floor((track.irregularities.shape[1] - 1) * track.dx / dx)) + 1
    xt = track.x0 + np.arange(n_t) * dx
    z_src = track.irregularities[0]
    ok = np.isfinite(z_src)
    x_src = track.x0 + np.arange(z_src.size) * track.dx
    z = np.interp(xt, x_src, z_src) if ok.all() else np.interp(xt, x_src[ok], z_src[ok])
    u_t = _bandpass(z - z.mean(), dx, band)
    del x_src, z, ok
    search = opts.search_m
    widest = max(opts.search_m, MAX_WIDENING * opts.search_m)
    while True:
        lags, rho, i, lag, ratio, peak = _search(u_v, u_t, xv, xt, dx, opts.guess_m + opts.lever_m, search, band,
                                                 track.path)
        at_edge = (lags[i] - (opts.guess_m + opts.lever_m - search) < band[1]
                   or (opts.guess_m + opts.lever_m + search) - lags[i] < band[1])
        if not at_edge:
            break
        if search >= widest:
            raise DataError(f"{track.path}: alignment: the correlation peak (offset {lag - opts.lever_m:.2f} m) "
                            f"stays at the edge of the offsets searched even at alignment.guess_m +- "
                            f"{search:g} m: the true offset lies further out; give alignment.guess_m near it "
                            f"(or alignment.offset_m)")
        search = min(2.0 * search, widest)
    return Alignment(lag - opts.lever_m, ratio, peak, lags - opts.lever_m, rho, channel, opts.lever_m,
                     "correlation", v_cal, searched_m=search)


def _search(u_v: np.ndarray, u_t: np.ndarray, xv: np.ndarray, xt: np.ndarray, dx: float, centre: float,
            search: float, band: tuple[float, float], path) -> tuple[np.ndarray, np.ndarray, int, float, float, float]:
    """The normalised correlation of the band-limited profiles at sensor offsets ``centre +- search`` (m).

    :returns: ``(lags, rho, i_peak, refined peak lag, peak ratio, rho at the peak)``.
    """
    # r(s) = sum_j u_v[j] u_t[j + s]; sensor offset L: xv[0] + L = xt[0] + s dx
    lags = centre + np.arange(-search, search + dx / 2, dx)
    s = np.round((xv[0] + lags - xt[0]) / dx).astype(np.int64)
    valid = (s > -u_v.size) & (s < u_t.size)
    if not valid.any():
        raise DataError(f"{path}: the track record ({xt[0]:.0f} to {xt[-1]:.0f} m) does not overlap the "
                        f"vehicle's distances ({xv[0]:.0f} to {xv[-1]:.0f} m) for any offset within "
                        f"alignment.guess_m +- {search:g} m")
    lags, s = lags[valid], s[valid]
    cs = np.concatenate(([0.0], np.cumsum(u_t ** 2)))
    lo, hi = np.clip(s, 0, u_t.size), np.clip(s + u_v.size, 0, u_t.size)
    energy_t = cs[hi] - cs[lo]
    # only the part of the vehicle record that overlaps the track counts
    cv = np.concatenate(([0.0], np.cumsum(u_v ** 2)))
    energy_v = cv[np.clip(hi - s, 0, u_v.size)] - cv[np.clip(lo - s, 0, u_v.size)]
    del cs, cv
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = _correlation(u_v, u_t, int(s[0]), int(s[-1] - s[0]) + 1)[s - s[0]] / np.sqrt(energy_t * energy_v)
    overlap = (hi - lo) * dx
    rho[~np.isfinite(rho) | (overlap < 0.5 * min(u_v.size * dx, xt[-1] - xt[0]))] = 0.0
    i = int(np.argmax(np.abs(rho)))
    peak = float(rho[i])
    sign = 1.0 if peak >= 0 else -1.0
    frac = 0.0
    if 0 < i < rho.size - 1:
        y0, y1, y2 = sign * rho[i - 1], sign * rho[i], sign * rho[i + 1]
        den = y0 - 2 * y1 + y2
        frac = 0.5 * (y0 - y2) / den if den < 0 else 0.0
    lag = float(lags[i] + frac * dx)
    far = np.abs(lags - lags[i]) > band[1]
    other = float(np.max(np.abs(rho[far]))) if far.any() else 0.0
    ratio = abs(peak) / other if other > 0 else float("inf")
    return lags, rho, i, lag, ratio, peak
