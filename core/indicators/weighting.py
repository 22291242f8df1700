"""Frequency weightings of whole-body vibration for ride comfort (EN 12299, ISO 2631-1, ISO 2631-4, ISO 8041).

Each weighting is the product of four analogue filters in s = j 2 pi f
(ISO 2631-1 Annex A; the parameters as ISO 8041 tabulates them, reproduced
in the public Larson Davis HVM200 reference manual, Table 3.1):

- band limiting: a 2nd-order high pass at f1 and low pass at f2 (Q = 1/sqrt 2),
- acceleration-velocity transition: ``(1 + s/w3) / (1 + s/(Q4 w4) + s^2/w4^2)``,
- upward step: ``(s^2 + s w5/Q5 + w5^2) / (s^2 + s w6/Q6 + w6^2)`` (1 at high frequency),
- a gain K.

EN 12299 weights the carbody floor's vertical acceleration with Wb and the
horizontal ones with Wd. The weighting is applied in the frequency domain
(:func:`weight`), the exact analogue response at each FFT bin, which no
bilinear transform distorts near the Nyquist frequency of a 100 Hz record.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Weighting:
    """Parameters of an ISO 2631 / ISO 8041 weighting (Hz; ``inf`` for an absent stage)."""

    name: str
    f1: float
    f2: float
    f3: float
    f4: float
    q4: float
    f5: float
    q5: float
    f6: float
    q6: float
    k: float = 1.0

    def response(self, f_hz: np.ndarray) -> np.ndarray:
        """Complex response H(j 2 pi f), ``f_hz`` of any shape (Hz); 0 at f = 0."""
        f = np.asarray(f_hz, dtype=float)
        s = 2j * np.pi * f
        w1, w2 = 2 * np.pi * self.f1, 2 * np.pi * self.f2
        q = 1.0 / np.sqrt(2.0)
        h = s**2 / (s**2 + s * w1 / q + w1**2) * w2**2 / (s**2 + s * w2 / q + w2**2)
        if np.isfinite(self.f3):
            w3, w4 = 2 * np.pi * self.f3, 2 * np.pi * self.f4
            h = h * (1 + s / w3) / (1 + s / (self.q4 * w4) + s**2 / w4**2)
        if np.isfinite(self.f5):
            w5, w6 = 2 * np.pi * self.f5, 2 * np.pi * self.f6
            h = h * (s**2 + s * w5 / self.q5 + w5**2) / (s**2 + s * w6 / self.q6 + w6**2)
        return self.k * h

    def gain(self, f_hz: np.ndarray | float) -> np.ndarray:
        """|H| at ``f_hz``."""
        return np.abs(self.response(np.asarray(f_hz, dtype=float)))


WB = Weighting("Wb", 0.4, 100.0, 16.0, 16.0, 0.55, 2.5, 0.9, 4.0, 0.95, 1.024)
"""Vertical comfort weighting (ISO 2631-4; EN 12299)."""
WD = Weighting("Wd", 0.4, 100.0, 2.0, 2.0, 0.63, np.inf, 1.0, np.inf, 1.0)
"""Horizontal comfort weighting (ISO 2631-1; EN 12299)."""


def weight(x: np.ndarray, fs: float, weighting: Weighting) -> np.ndarray:
    """The weighted signal: ``x`` ``(..., n_t)`` (m/s^2, sampled at ``fs`` Hz) through ``weighting``.

    Zero-phase in effect only for the magnitude used here: the rms of the result is what EN 12299 needs.
    The record's mean is removed first (the band limiting at 0.4 Hz removes it anyway).
    """
    x = np.asarray(x, dtype=float)
    n = x.shape[-1]
    spectrum = np.fft.rfft(x - x.mean(axis=-1, keepdims=True), axis=-1)
    f = np.fft.rfftfreq(n, 1.0 / fs)
    return np.fft.irfft(spectrum * weighting.response(f), n=n, axis=-1)
