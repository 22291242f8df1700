"""Quality checks of each channel of a recording (on the common grid, in m/s^2).

- **dropouts**: NaN samples (NaN in the file, or gaps in its time stamps);
- **clipping**: ``clip_min_run`` or more consecutive identical samples within
  2 % of the channel's largest magnitude (a saturated sensor holds its
  extreme), or ``|a| >= 0.999 full_scale`` when the sensor range is declared;
- **flat lines**: ``flat_s`` or more of identical consecutive values while moving;
- **spikes**: samples further than ``spike_sigma`` robust standard deviations
  (1.4826 x median absolute deviation, over the moving samples) from the median;
- **RMS** while moving against the plausible range of the channel's kind
  (``quality.rms_range``): outside it usually means a wrong declared unit;
- **sampling jitter**: the spread of the file's time steps.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from suspid.data.plausibility import (acceleration_doubts, d1_rms, judge, speed_doubts, speed_statistic,
                                      track_doubts)
from suspid.interfaces import IRREGULARITY_CHANNELS

from .load import Recording, TrackRecord
from .options import IngestOptions, kind_of


@dataclass
class ChannelQuality:
    """One channel's checks; ``masks`` holds, per check, the ``(n_runs, 2)`` start and stop (exclusive)
    sample indices of the flagged runs (a few numbers, not a boolean per sample)."""

    dropouts: int = 0
    clipped: int = 0
    flat: int = 0
    spikes: int = 0
    rms_moving: float = float("nan")
    rms_range: tuple[float, float] | None = None
    masks: dict[str, np.ndarray] = field(default_factory=dict, repr=False)

    def to_dict(self) -> dict:
        return {"dropouts": self.dropouts, "clipped": self.clipped, "flat": self.flat, "spikes": self.spikes,
                "rms_moving": self.rms_moving,
                "rms_range": list(self.rms_range) if self.rms_range else None}


def runs(mask: np.ndarray) -> np.ndarray:
    """``(n_runs, 2)`` start and stop (exclusive) of the runs of True in ``mask``."""
    edges = np.flatnonzero(np.diff(mask.view(np.int8), prepend=0, append=0))
    return edges.reshape(-1, 2)


def from_runs(r: np.ndarray, n: int, out: np.ndarray | None = None) -> np.ndarray:
    """The ``(n,)`` boolean mask of the runs ``r`` (added to ``out`` when given)."""
    out = np.zeros(n, dtype=bool) if out is None else out
    for a, b in r:
        out[a:b] = True
    return out


def long_runs(mask: np.ndarray, min_len: int) -> np.ndarray:
    """The runs of ``mask`` that last at least ``min_len`` samples, ``(n_runs, 2)``."""
    r = runs(mask)
    return r[r[:, 1] - r[:, 0] >= min_len]


def dilate(mask: np.ndarray, k: int) -> np.ndarray:
    """``mask`` grown by ``k`` samples on each side."""
    if k <= 0 or not mask.any():
        return mask
    out = mask.copy()
    for a, b in runs(mask):
        out[max(0, a - k):b + k] = True
    return out


def _count(r: np.ndarray) -> int:
    return int(np.sum(r[:, 1] - r[:, 0]))


def check_channel(a: np.ndarray, moving: np.ndarray, fs: float, opts: IngestOptions,
                  full_scale: float | None, kind: str | None) -> ChannelQuality:
    """The checks of the module docstring on one channel ``a`` (m/s^2), ``(n,)``.

    Working memory: a few boolean ``(n,)`` arrays and the moving samples; no float temporary of the
    whole channel besides those.
    """
    q = opts.quality
    out = ChannelQuality()
    finite = np.isfinite(a)
    drop = runs(~finite)
    out.dropouts = _count(drop)
    good = a[finite & moving]
    if good.size == 0:
        out.masks = {"dropouts": drop}
        return out
    held = np.zeros(a.size, dtype=bool)        # sample equal to the one before
    np.equal(a[1:], a[:-1], out=held[1:])
    if full_scale is not None:
        clip_mask = np.abs(a) >= 0.999 * full_scale
    else:   # a saturated sensor holds its extreme value: runs of identical samples near max |a|
        top = 0.98 * max(float(good.max()), -float(good.min()))
        with np.errstate(invalid="ignore"):
            clip_mask = (a >= top) | (a <= -top)
        clip_mask &= held | np.append(held[1:], False)
    clip = long_runs(clip_mask, q.clip_min_run) if full_scale is None else runs(clip_mask)
    out.clipped = _count(clip)
    held &= moving
    flat = long_runs(held, max(2, int(round(q.flat_s * fs))))
    out.flat = _count(flat)
    sample = good[:: max(1, good.size // 200_000)]
    med = float(np.median(sample))
    sigma = 1.4826 * float(np.median(np.abs(sample - med)))
    spikes = np.empty((0, 2), dtype=np.int64)
    if sigma > 0:
        with np.errstate(invalid="ignore"):
            far = (a > med + q.spike_sigma * sigma) | (a < med - q.spike_sigma * sigma)
        spikes = runs(far & ~from_runs(clip, a.size))
    out.spikes = _count(spikes)
    mean = float(good.mean())
    out.rms_moving = float(np.sqrt(max(float(good @ good) / good.size - mean ** 2, 0.0)))
    if kind is not None:
        out.rms_range = tuple(q.rms_range[kind])
    out.masks = {"dropouts": drop, "clipping": clip, "flat": flat, "spikes": spikes}
    return out


def check_recording(rec: Recording, opts: IngestOptions, moving: np.ndarray
                    ) -> tuple[dict[str, ChannelQuality], list[str]]:
    """Every channel's checks, and one warning line per problem found.

    :raises DataError: a channel or the speed beyond physics (:mod:`suspid.data.plausibility`), unless
        ``quality.accept`` names the check.
    """
    out, warnings = {}, []
    kinds = list(opts.quality.rms_range)
    for row, c in enumerate(rec.channels):
        m = opts.recording.channels[c]
        fs_si = None if m.full_scale is None else m.full_scale * abs(m.factor)
        cq = check_channel(rec.accelerations[row], moving, rec.grid.fs, opts, fs_si, kind_of(c, kinds))
        out[c] = cq
        name = f"channel {c} ('{m.name}')"
        dur = 1.0 / rec.grid.fs
        if cq.dropouts:
            warnings.append(f"{name}: {cq.dropouts} dropped samples ({cq.dropouts * dur:.2f} s: NaN or gaps in time)")
        if cq.clipped:
            warnings.append(f"{name}: clipped (saturated) on {cq.clipped} samples ({cq.clipped * dur:.2f} s)")
        if cq.flat:
            warnings.append(f"{name}: flat line (identical values while moving) on {cq.flat * dur:.2f} s")
        if cq.spikes:
            warnings.append(f"{name}: {cq.spikes} spike samples (> {opts.quality.spike_sigma:g} robust sigma)")
        if cq.rms_range is not None and np.isfinite(cq.rms_moving):
            lo, hi = cq.rms_range
            if not lo <= cq.rms_moving <= hi:
                warnings.append(f"{name}: RMS {cq.rms_moving:.4g} m/s^2 while moving is outside the plausible "
                                f"range [{lo:g}, {hi:g}] m/s^2 of a {kind_of(c, kinds)} channel: is the declared "
                                f"unit '{m.unit}' right?")
        info = rec.info[c]
        if np.isfinite(cq.rms_moving):   # beyond physics: an error unless quality.accept names the check
            stated = f", the file gives '{info.file_unit}'" if info.file_unit else ""
            found = acceleration_doubts(c, cq.rms_moving, cq.rms_moving == 0.0,
                                        f" (recorded channel '{m.name}', declared unit '{m.unit}'{stated})")
            warnings += judge([d for d in found if d.check], rec.path, accept=opts.quality.accept,
                              accept_key="quality.accept", emit=False)
        if info.jitter > 1e-3:
            warnings.append(f"{name}: sampling jitter {100 * info.jitter:.2g} % of the time step")
        if info.n_gaps:
            warnings.append(f"{name}: {info.n_gaps} gaps in the time stamps")
    warnings += check_speed(rec, moving, opts)
    return out, warnings


def excluded_mask(quality: dict[str, ChannelQuality], opts: IngestOptions, fs: float, n: int
                  ) -> dict[str, np.ndarray]:
    """Reason -> ``(n,)`` samples excluded for it (any channel), grown by ``segments.margin_s``."""
    k = int(round(opts.segments.margin_s * fs))
    out = {}
    for reason in opts.quality.exclude:
        flagged = [cq.masks[reason] for cq in quality.values() if reason in cq.masks and len(cq.masks[reason])]
        if flagged:
            m = np.zeros(n, dtype=bool)
            for r in flagged:
                from_runs(r, n, out=m)
            out[reason] = dilate(m, k)
    return out


def check_track_record(track: TrackRecord, opts: IngestOptions) -> list[str]:
    """The track record's channels against the limits of :mod:`suspid.data.plausibility` (D1-band rms, m).

    :returns: warnings for the unusual (and the accepted impossible) channels.
    :raises DataError: a channel beyond any track open to traffic, unless ``quality.accept`` names the check.
    """
    doubts = []
    for q, row in zip(IRREGULARITY_CHANNELS, track.irregularities):
        if q in track.present:
            unit = opts.track.channels[q]
            doubts += track_doubts(q, d1_rms(row, track.dx), f" (recorded channel '{unit.name}', declared unit "
                                                             f"'{unit.unit}')")
    return judge(doubts, track.path, accept=opts.quality.accept, accept_key="quality.accept", emit=False)


def check_speed(rec: Recording, moving: np.ndarray, opts: IngestOptions) -> list[str]:
    """The train's speed while moving (its 99th percentile: one glitch is no speed) against the limits."""
    v = rec.speed[moving & np.isfinite(rec.speed)]
    if v.size == 0:
        return []
    unit = (opts.recording.speed or opts.recording.distance).unit
    doubts = speed_doubts(speed_statistic(v), f"speed (declared unit '{unit}'), 99th percentile")
    return judge(doubts, rec.path, accept=opts.quality.accept, accept_key="quality.accept", emit=False)
