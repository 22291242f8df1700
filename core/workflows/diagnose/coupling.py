"""The coupling test: vertical acceleration leaking into a lateral channel at the same point (a tilted sensor).

Method: ``docs/diagnose.md``, "Sensor tilt from the coupling".

A lateral accelerometer tilted by α reads x = cos α a_lat + sin α a_vert. The
vertical channel at the same point reads v = a_vert. If a_lat and a_vert were
uncorrelated, the regression of x on v would be H(f) = S_vx / S_vv = sin α at
every frequency: a real constant. The power spectrum of x changes by
sin²α V / L only, invisible where the lateral motion dominates (0.1-0.4 dB for
6-10° on a bogie); the cross-spectrum shows sin α directly.

Per segment i: β_i = Σ_f Re S_vx,i / S̄_xx ÷ Σ_f S_vv,i / S̄_xx over the band
(a weighted least-squares estimate of the constant H, weights 1 / S̄_xx, S̄_xx the
mean over the segments: a segment's own S_xx would correlate with its cross-spectrum).

A real vehicle has a lateral-vertical coupling of its own (asymmetric contact
geometry, gauge, creep): on the independent train β of an untilted bogie
sensor is ±0.02 from one set of track segments to another, a sixth of a 6°
tilt, and the same set moves both bogies' β together (their per-segment β
correlate by 0.9: the same track, the same dynamics). So a lateral channel with
a *twin* (the same sensor on the other bogie or carbody end: ``front`` and
``rear`` swapped in its name) is tested on the paired difference
d_i = β_i - β_twin,i: the coupling the twin does not have. Of a pair whose
difference is significant, the channel with the larger |mean β| is the
tilted one and its estimate is ±mean d (a tilt shared by both twins is taken
for the vehicle's own coupling). A channel without a twin is tested on its own
β. The estimate's standard error comes from the spread over segments, t with
v - 1 degrees of freedom, Bonferroni over the tests at ``alpha``. The angle is
asin β (the calibration gains of both channels enter as their ratio).
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np
from scipy.signal import csd, welch
from scipy.stats import t as student_t

from suspid.data.corrections import vertical_partner


def twin(channel: str, channels: Sequence[str]) -> str | None:
    """The same sensor at the other end (``front`` and ``rear`` swapped in the name), or None."""
    for a, b in (("front", "rear"), ("rear", "front")):
        if a in channel:
            other = channel.replace(a, b)
            return other if other in channels else None
    return None


def coupling_test(records: Sequence, channels: Sequence[str], f_band: tuple[float, float], alpha: float = 0.05,
                  segment_seconds: float = 2.56, reference: Sequence | None = None) -> list[dict[str, Any]]:
    """The coupling of each lateral channel with the vertical channel at its point.

    :param records: responses with ``accelerations`` ``(n_channels, n_t)`` m/s² and ``fs`` Hz, channels in the
        order of ``channels``.
    :param f_band: ``(f_min, f_max)`` Hz, the band the estimate uses (clipped to the records' Nyquist frequency).
    :param reference: records of the reference date: their coupling, by the same estimator, is subtracted with
        its standard error.
    :returns: per lateral channel with a vertical partner: ``{channel, vertical, twin, beta, se, t, p,
        angle_deg, significant, n_segments, beta_raw, beta_reference}``; ``beta`` is the estimate tested
        (against the twin when there is one, ``beta_raw`` the channel's own).
    """
    names = list(channels)
    lateral = [c for c in names if vertical_partner(c, names) is not None]
    betas = {c: _betas(records, names.index(c), names.index(vertical_partner(c, names)), f_band, segment_seconds)
             for c in lateral}
    ref = ({c: _betas(reference, names.index(c), names.index(vertical_partner(c, names)), f_band, segment_seconds)
            for c in lateral} if reference is not None else {})
    out = []
    for c in lateral:
        b = betas[c]
        if b.size < 3:
            continue
        t_name = twin(c, lateral)
        paired = t_name is not None and betas[t_name].size == b.size
        has_ref = ref.get(c) is not None and ref[c].size >= 3
        if paired and has_ref and ref[t_name].size != ref[c].size:
            paired = False                       # pair both dates or neither
        d = b - betas[t_name] if paired else b
        beta, se, n = float(d.mean()), float(d.std(ddof=1) / math.sqrt(d.size)), d.size
        b0 = None
        if has_ref:
            d0 = ref[c] - ref[t_name] if paired else ref[c]
            b0 = float(d0.mean())
            beta, se = beta - b0, math.hypot(se, float(d0.std(ddof=1) / math.sqrt(d0.size)))
            n = min(n, d0.size)
        t = beta / se if se > 0 else 0.0
        p = float(2 * student_t.sf(abs(t), n - 1))
        # of a pair, the tilted one is the channel whose own coupling (beyond the reference date's) is further
        # from zero; the vehicle's coupling of opposite sign and about half the tilt's can mislead this for
        # small tilts (docs/diagnose.md, Limits)
        own = abs(b.mean() - (ref[c].mean() if has_ref else 0.0))
        own_twin = abs(betas[t_name].mean() - (ref[t_name].mean() if has_ref else 0.0)) if paired else 0.0
        candidate = not paired or own >= own_twin
        out.append({"channel": c, "vertical": vertical_partner(c, names), "twin": t_name if paired else None,
                    "beta": beta, "se": se, "t": t, "p": p if candidate else 1.0,
                    "angle_deg": math.degrees(math.asin(max(-1.0, min(1.0, beta)))), "n_segments": int(b.size),
                    "beta_raw": float(b.mean()), "beta_reference": b0,
                    "note": None if candidate else f"its twin {t_name} is the further from zero: the pair's "
                                                   f"difference is tested there"})
    tests = len(out) - sum(1 for r in out if r["twin"] is not None) // 2
    for row in out:
        row["significant"] = bool(row["p"] < alpha / max(1, tests))
    return out


def _betas(records: Sequence, k: int, kv: int, f_band: tuple[float, float], segment_seconds: float) -> np.ndarray:
    """β_i of every record (see the module docstring). The weights 1 / S_xx come from the mean of S_xx over all
    records: a record's own S_xx correlates with its cross-spectrum and would bias β_i towards 0."""
    spectra = []
    for r in records:
        x, y = np.asarray(r.accelerations[k], float), np.asarray(r.accelerations[kv], float)
        n = min(x.size, int(round(segment_seconds * r.fs)))
        if n < 16:
            continue
        f, s_xx = welch(x, fs=r.fs, nperseg=n)
        _, s_vv = welch(y, fs=r.fs, nperseg=n)
        _, s_vx = csd(y, x, fs=r.fs, nperseg=n)
        spectra.append((f, s_xx, s_vv, np.real(s_vx)))
    if not spectra:
        return np.array([])
    f0 = spectra[0][0]
    spectra = [s for s in spectra if s[0].shape == f0.shape and np.allclose(s[0], f0)]
    use = (f0 >= f_band[0]) & (f0 <= f_band[1]) & (f0 > 0)
    mean_xx = np.mean([s[1] for s in spectra], axis=0)
    use &= mean_xx > 0
    if use.sum() < 3:
        return np.array([])
    w = 1.0 / mean_xx[use]
    return np.array([float(np.sum(c[use] * w) / np.sum(v[use] * w)) for _, _, v, c in spectra])
