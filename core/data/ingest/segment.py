"""Cutting a recording into segments of ``length_m`` at quasi-constant speed.

A sample is usable when the train runs at ``min_speed_kmh`` or faster, the
speed is known, no quality check excluded it (``quality.exclude``, grown by
``margin_s``) and the track record covers it. Within each run of usable
samples, windows of ``length_m`` are tried from the start: a window whose speed
stays within ``speed_tolerance`` of its mean is kept and the next one starts
where it ends; otherwise the start moves on by ``step_m``. Every stretch that
ends up in no segment is reported with its reason.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .options import SegmentsSection
from .quality import runs


@dataclass
class Window:
    i0: int                 # first sample
    i1: int                 # one past the last sample
    v_mean: float
    v_min: float
    v_max: float


@dataclass
class Excluded:
    reason: str
    i0: int
    i1: int


def cut(distance: np.ndarray, speed: np.ndarray, reasons: dict[str, np.ndarray], opts: SegmentsSection,
        fs: float) -> tuple[list[Window], list[Excluded]]:
    """Windows kept, and the excluded stretches with their reason.

    :param reasons: reason -> ``(n,)`` samples excluded for it, in order of precedence.
    """
    n = distance.size
    bad = np.zeros(n, dtype=bool)
    excluded: list[Excluded] = []
    for reason, mask in reasons.items():
        new = mask & ~bad
        for a, b in runs(new):
            excluded.append(Excluded(reason, int(a), int(b)))
        bad |= mask
    step = opts.step_m or opts.length_m / 20.0
    tol = opts.speed_tolerance
    kept: list[Window] = []
    covered = np.zeros(n, dtype=bool)
    for a, b in runs(~bad):
        i0 = int(a)
        while True:
            i1 = int(np.searchsorted(distance, distance[i0] + opts.length_m, side="left"))
            if i1 > b or i1 >= n:
                break
            v = speed[i0:i1]
            m = float(v.mean())
            if float(np.max(np.abs(v - m))) <= tol * m:
                kept.append(Window(i0, i1, m, float(v.min()), float(v.max())))
                covered[i0:i1] = True
                i0 = i1
            else:
                i0 = max(i0 + 1, int(np.searchsorted(distance, distance[i0] + step, side="left")))
            if opts.max_segments is not None and len(kept) >= opts.max_segments:
                break
        if opts.max_segments is not None and len(kept) >= opts.max_segments:
            break
    for a, b in runs(~bad & ~covered):
        length = distance[min(b, n - 1)] - distance[a]
        if opts.max_segments is not None and len(kept) >= opts.max_segments and a >= kept[-1].i1:
            reason = "beyond segments.max_segments"
        elif length < opts.length_m:
            reason = "usable stretch shorter than one segment"
        else:
            reason = f"speed not within +-{100 * tol:g} % over {opts.length_m:g} m"
        excluded.append(Excluded(reason, int(a), int(b)))
    excluded.sort(key=lambda e: e.i0)
    return kept, excluded
