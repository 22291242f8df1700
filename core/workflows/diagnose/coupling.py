"""The coupling test: vertical acceleration leaking into a lateral channel at the same point (a tilted sensor).

Method: ``docs/diagnose.md``, "Sensor tilt from the coupling".

A lateral accelerometer tilted by α reads x = cos α a_lat + sin α a_vert. The
vertical channel at the same point reads v = a_vert. On a vehicle symmetric
about its centre plane, with sensors on it, a_lat and a_vert are uncorrelated
(the vertical and the lateral/roll motions decouple), so the regression of x
on v is H(f) = S_vx / S_vv = sin α at every frequency: a real constant. The
power spectrum of x changes by sin²α V / L only, invisible where the lateral
motion dominates (0.1-0.4 dB for 6-10° on a bogie); the cross-spectrum shows
sin α directly.

Per segment i: β_i = Σ_f Re S_vx,i / S̄_xx ÷ Σ_f S_vv,i / S̄_xx over the spectra band
(a weighted least-squares estimate of the constant H, weights 1 / S̄_xx, S̄_xx the
mean over the segments: a segment's own S_xx would correlate with its cross-spectrum);
β = mean β_i, its standard error from the spread over segments, t = β / se
with v - 1 degrees of freedom; a channel's coupling is significant when its
p-value is below alpha / (number of tested channels) (Bonferroni). The angle
is asin β (the calibration gains of both channels enter as their ratio).
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np
from scipy.signal import csd, welch
from scipy.stats import t as student_t


def partner(channel: str, channels: Sequence[str]) -> str | None:
    """The vertical channel at the same point as lateral ``channel`` (the same name with ``vertical``)."""
    if "lateral" not in channel:
        return None
    other = channel.replace("lateral", "vertical")
    return other if other in channels else None


def coupling_test(records: Sequence, channels: Sequence[str], f_band: tuple[float, float], alpha: float = 0.05,
                  segment_seconds: float = 2.56, reference: Sequence | None = None) -> list[dict[str, Any]]:
    """The coupling of each lateral channel with the vertical channel at its point.

    :param records: responses with ``accelerations`` ``(n_channels, n_t)`` m/s² and ``fs`` Hz, channels in the
        order of ``channels``.
    :param f_band: ``(f_min, f_max)`` Hz, the band the estimate uses.
    :param reference: records of the reference date: their coupling (the train's own, which suspid's symmetric
        model lacks) is subtracted, with its standard error.
    :returns: per lateral channel with a partner: ``{channel, vertical, beta, se, t, p, angle_deg,
        significant, n_segments, beta_reference}``.
    """
    names = list(channels)
    pairs = [(c, partner(c, names)) for c in names]
    pairs = [(c, v) for c, v in pairs if v is not None]
    out = []
    for c, v in pairs:
        k, kv = names.index(c), names.index(v)
        b, b0 = _betas(records, k, kv, f_band, segment_seconds), None
        if b.size < 3:
            continue
        beta, se = float(b.mean()), float(b.std(ddof=1) / math.sqrt(b.size))
        dof = b.size - 1
        if reference is not None:
            b0 = _betas(reference, k, kv, f_band, segment_seconds)
            if b0.size >= 3:
                se0 = float(b0.std(ddof=1) / math.sqrt(b0.size))
                beta, se = beta - float(b0.mean()), math.hypot(se, se0)
                dof = min(b.size, b0.size) - 1
        t = beta / se if se > 0 else 0.0
        p = float(2 * student_t.sf(abs(t), dof))
        out.append({"channel": c, "vertical": v, "beta": beta, "se": se, "t": t, "p": p,
                    "angle_deg": math.degrees(math.asin(max(-1.0, min(1.0, beta)))), "n_segments": int(b.size),
                    "beta_reference": None if b0 is None or b0.size < 3 else float(b0.mean())})
    for row in out:
        row["significant"] = bool(row["p"] < alpha / max(1, len(out)))
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
    use = (f0 >= f_band[0]) & (f0 <= f_band[1])
    mean_xx = np.mean([s[1] for s in spectra], axis=0)
    use &= mean_xx > 0
    if use.sum() < 3:
        return np.array([])
    w = 1.0 / mean_xx[use]
    return np.array([float(np.sum(c[use] * w) / np.sum(v[use] * w)) for _, _, v, c in spectra])
