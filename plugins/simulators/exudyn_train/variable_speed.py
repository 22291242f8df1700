"""Frequency solver for a slowly varying speed: short-time constant speed with overlap-add.

Why this method. With a speed record the track input as a function of time,
u_j(t) = r(s(t) + a_j) under wheelset j (s(t) the car centre's distance from
the speed record), is known exactly; what changes with the speed is the
vehicle: the creep damping f/v of the wheel-rail contact (its stiffness and
mass do not depend on v). The record of the inputs is cut into overlapping
blocks with raised-cosine (Hann) windows w_k(t) that sum to one (50 %
overlap), and each windowed piece w_k u_j is run through the linear model
frozen at the block's speed v_k:

    y(t) = sum_k  irfft( sum_j H_j(f; v_k) FFT(w_k u_j) )

with H_j the response to the track under wheelset j alone (no delay: each
wheelset's input is built at its own position, so the wheelset delays a_j / v
are exact at every instant, which a delay exp(i 2 pi f a_j / v) with a frozen
v would not be: 10 m at 300 km/h and 1 % speed error is 1.2 ms, 0.15 rad at
20 Hz). For one speed the sum is exactly the constant-speed response (the
windows add up to one and the model is linear); the error comes from the
speed change within a block (the creep damping at v_k instead of v(t)) and
from the block's response tail, computed with v_k. Resampling the record to
distance would be exact for the delays but not for the creep damping (the
vehicle's modes do not scale with the speed), and a chirped input needs the
same frozen model: the blocks are the simplest construction that is exact in
the limit.

Cost. Only the creep damping depends on the speed, D(v) = D_inf + D_creep / v
with D_creep of rank 3 per wheelset: H_j(f; v_k) comes from the model
linearised once per parameter vector at v0 by a low-rank update
(:class:`SpeedFamily`), one r x r solve per frequency line and block, no
linearisation per block.

Validity. Block length :data:`BLOCK_S` (4 s, 50 % overlap); v0 is the mean
speed rounded to a relative step :data:`SPEED_STEP` (shared between runs).
Measured against the time solver for +-10 % over a segment (benchmarks/
bench_variable_speed.py); the error grows with the speed change inside a
block. Periodic wheel inputs of effects (polygons) have a speed-dependent
frequency and are refused here (the time solver runs them).
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np
from scipy import fft as sfft

from suspid.errors import SimulatorError
from suspid.infra.threads import single_blas_thread
from suspid.interfaces import Response, TrackSegment

from .solvers import FrequencyResponse, _speed_profile, output_samples, track_table

BLOCK_S = 4.0
"""Length (s) of one block of constant speed; consecutive blocks overlap by half."""

SPEED_STEP = 0.005
"""Relative step (0.5 %) of the grid of reference speeds v0 about which the model is linearised."""


def quantised_speed(v: float, step: float = SPEED_STEP) -> float:
    """``v`` (m/s) rounded to the logarithmic grid (1 + step)^k: the reference speed v0 of a segment."""
    k = round(math.log(v) / math.log1p(step))
    return float(math.exp(k * math.log1p(step)))


def wheelset_responses(response: FrequencyResponse, freqs: np.ndarray) -> np.ndarray:
    """``(n_wheelsets, 3, n_sensors, n_freqs)``: sensor accelerations per m of each track channel under
    wheelset j alone (no delay), (m/s^2)/m."""
    f = np.asarray(freqs, dtype=float)
    w = 2 * math.pi * f
    n_w = response.B.shape[0]
    out = []
    with single_blas_thread():
        for j in range(n_w):
            if response.modal:
                S = response.R[j][:, :, None] / (1j * w[None, None, :] - response.eigenvalues[:, None, None])
                m2, nin, nf = S.shape
                X = (response.L @ S.reshape(m2, nin * nf)).reshape(-1, nin, nf).transpose(1, 0, 2) * -(w ** 2)
                if response.Ld is not None:
                    X = X + (response.Ld @ S.reshape(m2, nin * nf)).reshape(-1, nin, nf).transpose(1, 0, 2)
            else:
                lhs = 1j * w[:, None, None] * np.eye(response.n_state)[None] - response.A[None]
                state = np.linalg.solve(lhs, np.broadcast_to(response.B[j], (len(f),) + response.B[j].shape))
                X = np.einsum("om,fmc->cof", response.Cq, state) * -(w ** 2)
                if response.Cd is not None:
                    X = X + np.einsum("om,fmc->cof", response.Cd, state)
            out.append(X)
    return np.array(out)


class SpeedFamily:
    """Per-wheelset frequency responses at any speed from one eigen-decomposition (see the module docstring).

    Only the creep damping depends on the speed: D(v) = D_inf + D_creep / v, with D_creep of low rank
    (3 per wheelset: lateral, yaw, and the common longitudinal-spin creepage). About the model at v0,
    the change (1/v - 1/v0) D_creep q' is a feedback through r = rank(D_creep) channels, D_creep = U Vc^T:

        H(f; v) = T_yg - T_yu (I + d T_zu)^-1 d T_zg,    d = 1/v - 1/v0,

    with the transfers of the model at v0 (modal form): T_yg from the track under each wheelset to the
    sensors, T_yu from the forces U to the sensors, T_zg and T_zu from the track and from U to the
    velocities Vc^T q'. Per speed: one r x r solve per frequency line, no linearisation.

    :param response: the model's frequency response at ``v0`` (modal form required).
    :param d_creep: ``(n, n)`` the speed-dependent damping times the speed, N s/m * m/s.
    :param freqs: ``(n_f,)`` Hz.
    """

    def __init__(self, response: FrequencyResponse, d_creep: np.ndarray, freqs: np.ndarray) -> None:
        lin = response.linear
        self.v0 = float(lin.speed)
        self.wheelset_x = np.asarray(lin.wheelset_x, dtype=float)
        self.periodic = bool(lin.periodic)
        self.settling_time = response.settling_time
        if not response.modal:
            raise SimulatorError(f"the eigenvectors of the linear model are ill-conditioned at "
                                 f"{self.v0 * 3.6:.1f} km/h: the variable-speed frequency solver needs the "
                                 f"modal form; use solver: time")
        n = lin.M.shape[0]
        p = response.n_state - n
        u, sv, vt = np.linalg.svd(d_creep)
        keep = sv > 1e-10 * max(float(sv[0]), 1e-300)
        U = u[:, keep] * sv[keep]                                    # (n, r)
        Vc = vt[keep].T                                              # (n, r)
        w = 2 * math.pi * np.asarray(freqs, dtype=float)
        with single_blas_thread():
            z = 1.0 / (1j * w[None, :] - response.eigenvalues[:, None])            # (m2, n_f)
            n_w = lin.G.shape[0]
            Rg = response.R.transpose(1, 0, 2).reshape(response.n_state, 3 * n_w)  # (m2, 12): wheelset-major
            Ru = response.Vinv[:, p:] @ (response.Minv @ U)                          # (m2, r)
            Lz = Vc.T @ response.V[p:, :]                                           # (r, m2)
            right = np.hstack([Rg, Ru])                                             # (m2, 12 + r)
            k = Rg.shape[1]

            def transfer(left: np.ndarray) -> np.ndarray:
                """(n_f, rows, 12 + r): left diag(z(f)) right."""
                return np.einsum("am,mf,mb->fab", left, z, right, optimize=True)

            acc = transfer(response.L) * -(w ** 2)[:, None, None]
            if response.Ld is not None:
                acc = acc + transfer(response.Ld)
            vel = transfer(Lz)
        self.T_yg, self.T_yu = np.ascontiguousarray(acc[:, :, :k]), np.ascontiguousarray(acc[:, :, k:])
        self.T_zg, self.T_zu = np.ascontiguousarray(vel[:, :, :k]), np.ascontiguousarray(vel[:, :, k:])
        self.rank = U.shape[1]

    def apply(self, speed: float, U: np.ndarray) -> np.ndarray:
        """``(n_sensors, n_f)``: the sensor spectra at ``speed`` (m/s) for the track spectra ``U``
        ``(n_wheelsets * 3, n_f)`` (wheelset-major: the three channels under wheelset 1, then 2, ...)."""
        Ut = np.ascontiguousarray(U.T)[:, :, None]                               # (n_f, k, 1)
        Y = np.matmul(self.T_yg, Ut)[:, :, 0]                                    # (n_f, n_sensors)
        d = 1.0 / float(speed) - 1.0 / self.v0
        if d != 0.0 and self.rank:
            g = np.matmul(self.T_zg, Ut)                                          # (n_f, r, 1)
            wv = np.linalg.solve(np.eye(self.rank)[None] + d * self.T_zu, d * g)
            Y = Y - np.matmul(self.T_yu, wv)[:, :, 0]
        return Y.T


def car_distance(segment: TrackSegment, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Car-centre distance s(t) (m) and speed v(t) (m/s) at times ``t`` (s, 0 at the segment's first
    sample); before the start and after the end the first and last speeds hold."""
    t_x, v_x = _speed_profile(segment)
    x = np.asarray(segment.distance, dtype=float)
    s = np.interp(t, t_x, x)
    s = np.where(t < 0, x[0] + v_x[0] * t, s)
    s = np.where(t > t_x[-1], x[-1] + v_x[-1] * (t - t_x[-1]), s)
    v = np.interp(t, t_x, v_x)
    return s, v


def simulate_variable_speed(family: Callable[[float, int], SpeedFamily], segment: TrackSegment, fs: float,
                            taper_m: float, settle_s: float, channels: tuple[str, ...],
                            block_s: float = BLOCK_S) -> Response:
    """The response of one segment with a speed record (see the module docstring).

    :param family: ``family(v0, n_fft)``: the :class:`SpeedFamily` of the model about ``v0`` (m/s) on the
        frequency lines k fs / n_fft; the caller caches it per parameter vector.
    :returns: accelerations ``(n_sensors, n_t)`` on the record's time grid j / fs.
    """
    n_t = output_samples(segment, fs)
    x = np.asarray(segment.distance, dtype=float)
    dx = float(x[1] - x[0])
    table = track_table(segment, taper_m)
    v_all = np.broadcast_to(np.asarray(segment.speed, dtype=float), x.shape)
    v_min, v_max = float(np.min(v_all)), float(np.max(v_all))
    v0 = quantised_speed(segment.duration() and segment.length / segment.duration())
    hop = 0.5 * block_s
    n_hop = max(2, int(round(hop * fs)))
    n_block = 2 * n_hop
    probe = family(v0, 0)                    # the model at v0 without transfers: its wheelsets and settling
    if probe.periodic:
        raise SimulatorError(f"segment '{segment.name}': periodic wheel inputs of effects (polygons) with a "
                             f"variable speed need the time solver (solver: time)")
    a = probe.wheelset_x
    pad = min(max(settle_s, probe.settling_time), 120.0)
    n_fft = 1 << int(math.ceil(math.log2(n_block + int(math.ceil(pad * fs)) + 2)))
    fam = family(v0, n_fft)
    # the inputs are non-zero from when the leading wheelset enters to when the trailing one leaves
    t0 = -float(np.max(a)) / v_min - 1.0 / fs
    t1 = n_t / fs + max(0.0, -float(np.min(a))) / v_min
    q = max(1, int(math.ceil(2.0 * v_max / (fs * dx))))       # fine grid: at most half a track sample a step
    first_start = int(math.floor(t0 * fs)) - n_hop
    starts = range(first_start, int(math.ceil(t1 * fs)) + 1, n_hop)
    window = 0.5 * (1.0 - np.cos(2 * math.pi * np.arange(n_block * q) / (n_block * q)))   # periodic Hann
    out = np.zeros((len(channels), n_t))
    n_f = n_fft // 2 + 1
    for start in starts:
        t = (start * q + np.arange(n_block * q)) / (q * fs)                # block times on the fine grid
        s, v = car_distance(segment, t)
        U = np.zeros((3 * len(a), n_f), dtype=complex)
        for j, aj in enumerate(a):
            where = s + aj
            inside = (where >= x[0]) & (where <= x[-1])
            if not np.any(inside):
                continue
            u = np.zeros((3, t.size))
            for c in range(3):
                u[c, inside] = np.interp(where[inside], x, table[c]) * window[inside]
            U[3 * j:3 * j + 3] = sfft.rfft(u, n=n_fft * q, axis=1)[:, :n_f] / q
        if not np.any(U):
            continue
        if n_fft % 2 == 0:
            U[:, -1] = 0.0
        # the block's speed: the mean over its window (the window's weights)
        y = sfft.irfft(fam.apply(float(np.sum(window * v) / np.sum(window)), U), n=n_fft, axis=-1)
        lo, hi = max(0, start), min(n_t, start + n_fft)
        if hi > lo:
            out[:, lo:hi] += y[:, lo - start:hi - start]
    return Response(channels, float(fs), out, segment.name)
