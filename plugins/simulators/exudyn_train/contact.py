"""Wheel-rail contact quantities of the linear model on a track segment: coordinates, creepages, creep forces.

The frequency solver gives the sensor outputs only; these functions solve the
same linear system (:class:`.model.LinearSystem`) for every free coordinate,
so that wheel-rail quantities can be read: how far the linear creep forces
are from the friction limit mu N (:func:`creep_usage`), where the
Shen-Hedrick-Elkins saturation of the time solver acts first.
"""

from __future__ import annotations

import numpy as np

from suspid.interfaces import TrackSegment

from . import parameters as P
from .layout import layout_of
from .modes import acting_positions
from .solvers import InputSpectra, fft_length, output_samples


def coordinate_response(simulator, segment: TrackSegment, w=None, fs: float | None = None, settle_s: float = 2.0):
    """Time histories of every free coordinate of the linear model on a constant-speed segment.

    :param simulator: an :class:`ExudynTrain`; ``w`` its parameter values (default nominal); ``fs`` in Hz
        (default the simulator's).
    :returns: ``(lin, q, r)``: the linear system, ``q`` ``(n, n_t)`` coordinates (m, rad) and ``r``
        ``(n_wheelsets, 3, n_t)`` the track inputs under each wheelset (vertical level, alignment,
        cross-level; m, m, rad), both without ``settle_s`` seconds at each end.
    """
    fs = simulator.sampling_rate_hz() if fs is None else fs
    v = float(np.asarray(segment.speed, dtype=float).flat[0])
    lin = simulator.linear_system(w, v)
    n_t = output_samples(segment, fs)
    n_fft = fft_length(n_t, fs, float(np.max(np.abs(lin.wheelset_x))) / v, 8.0)
    U = InputSpectra().get(segment, fs, n_fft, 20.0)
    omega = 2 * np.pi * np.arange(n_fft // 2 + 1) * fs / n_fft
    delay = np.exp(1j * np.outer(lin.wheelset_x, omega) / v)            # (n_wheelsets, n_freqs)
    Q = np.zeros((lin.M.shape[0], omega.size), dtype=complex)
    acting = acting_positions(lin.K)     # static line: a rolling wheelset's spin angle is free (left at 0)
    for k, wk in enumerate(omega):
        rhs = np.einsum("jnc,cj->n", lin.G, U[:, k][:, None] * delay[:, k][None, :])
        if wk == 0.0:
            Q[acting, k] = np.linalg.solve(lin.K[np.ix_(acting, acting)], rhs[acting])
        else:
            Q[:, k] = np.linalg.solve(lin.K - wk ** 2 * lin.M + 1j * wk * lin.D, rhs)
    cut = slice(int(settle_s * fs), n_t - int(settle_s * fs))
    q = np.fft.irfft(Q, n=n_fft, axis=1)[:, :n_t][:, cut]
    r = np.fft.irfft(U[None, :, :] * delay[:, None, :], n=n_fft, axis=2)[:, :, :n_t][:, :, cut]
    return lin, q, r


def creep_usage(simulator, segment: TrackSegment, friction: float, w=None) -> list[dict[str, float]]:
    """Linear creep forces per wheelset against the friction limit mu N (static wheel load N).

    Per wheel: lateral creep force F_y = -f22 (y'/v - psi) (with ``contact.creep_at_contact_point``:
    -f22 ((y' + r0 roll')/v - psi)), longitudinal
    F_x = f11 (l0 psi'/v + lambda (y - Y) / r0) (left wheel; the right one
    the opposite) plus, with rolling wheelsets, -f11 (x' - r0 pitch') / v on
    both wheels (the larger of the two wheels counts), Kalker's f11, f22 for
    the wheelset's own static load;
    u = |F| / (mu N) is the argument of the Shen-Hedrick-Elkins saturation
    (eps = 1 - u/3 + u^2/27: the creep force falls below the linear one
    from the smallest u).

    :returns: one dict per wheelset (leading first): ``wheel_load_n``,
        ``fx_rms_n``, ``fy_rms_n``, ``u_rms`` and ``u_max``.
    """
    lin, q, r = coordinate_response(simulator, segment, w)
    p = simulator.values(w or {})
    layout = layout_of(simulator.opts.preset)
    fs = simulator.sampling_rate_hz()
    v = lin.speed
    out = []
    for j, name in enumerate(layout.wheelsets):
        y, psi = q[lin.labels.index((name, "lateral"))], q[lin.labels.index((name, "yaw"))]
        dy, dpsi = np.gradient(y, 1 / fs), np.gradient(psi, 1 / fs)
        load = layout.wheel_load(p, j)
        f11, f22 = P.creep_coefficients(p, load)
        if simulator.opts.contact.creep_at_contact_point:       # the contact points move with the roll rate too
            dy = dy + p["r0"] * np.gradient(q[lin.labels.index((name, "roll"))], 1 / fs)
        fy = -f22 * (dy / v - psi)
        fx = f11 * (p["l0"] * dpsi / v + p["conicity"] / p["r0"] * (y - r[j, 1]))
        if (name, "longitudinal") in lin.labels:      # rolling wheelsets: the common longitudinal creep
            x, spin = q[lin.labels.index((name, "longitudinal"))], q[lin.labels.index((name, "pitch"))]
            fx_common = -f11 * (np.gradient(x, 1 / fs) - p["r0"] * np.gradient(spin, 1 / fs)) / v
            fx = np.maximum(np.abs(fx_common + fx), np.abs(fx_common - fx))
        u = np.hypot(fx, fy) / (friction * load)
        out.append({"wheel_load_n": load, "fx_rms_n": float(np.sqrt(np.mean(fx ** 2))),
                    "fy_rms_n": float(np.std(fy)),
                    "u_rms": float(np.sqrt(np.mean(u ** 2))), "u_max": float(np.max(u))})
    return out
