"""The two solvers of the one exudyn model: time integration and frequency response.

Common conventions (both solvers give the same record for a linear case):

- **Record time.** t = 0 when the car centre is at the segment's first
  distance sample; the record lasts the segment's duration (T = length / v
  at constant speed), sampled at ``fs`` (sample j at t = j / fs).
- **Wheel inputs.** Wheelset j at distance a_j ahead of the car centre sees
  the track at s(t) + a_j: at constant speed its input is the car centre's
  input advanced by a_j / v. Outside the segment the track is flat (zero),
  and the segment is faded in and out over ``taper_m`` metres with a raised
  cosine, so that neither solver sees a step. The car starts at rest in
  static equilibrium before the leading wheelset reaches the segment.
- **Outputs.** Kinematic accelerations in m/s^2 at the sensors.

Time solver (:func:`simulate_time`): exudyn's generalised-alpha integrator
with a fixed step dt = 1 / (k fs) (k the smallest integer with dt <= the
requested step). The track enters through the symbolic tables of the model
(no Python call during the integration); sensors are recorded every step and
decimated to fs with a polyphase anti-aliasing filter
(``scipy.signal.resample_poly``). Linear contact: one linear solve per step
(``newton.active = False``; the system is linear up to second-order terms in
the small rotations); creep saturation, bump stops, yaw-damper blow-off or a
variable speed: modified Newton. Variable speed: the odometer's velocity
follows the speed record, and the creep forces (creep damping f/v) are
computed with it in the contact function; a single linear solve would keep
the step matrix of the starting speed (at 3 m/s the creep damping is 28 times
the one at 300 km/h), which left the lateral response of a run that starts
slow wrong by a factor of 2.5.

Frequency solver (:class:`FrequencyResponse`, :func:`simulate_frequency`):
exudyn's linearisation M, K, D at the segment speed, once per parameter
vector and speed; state-space eigen-decomposition; the frequency response
H(f) from the three track channels (vertical, lateral, cross-level at the
car centre) to the sensor accelerations, including the wheelset delays
exp(i 2 pi f a_j / v), evaluated for all frequencies in batched numpy
products. Each segment's response is irfft(H U) with U the spectrum of its
(tapered) track, zero padded so that the circular convolution is the linear
one (to 5 % of the slowest mode's tail); the input spectra do not depend on
the parameters and are cached. Small matrix products run on one BLAS thread
(:mod:`.threads`). Sensors read C q'' + C_disp q (C_disp from effects such as a
sensor tilt); periodic wheel inputs of effects (polygons) add their
steady-state sinusoidal response, H_j(f) A e^{i(2π s_j / wavelength + φ)} with
s_j = a_j + v t the distance of wheelset j from the segment start.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
from scipy import fft as sfft
from scipy.signal import resample_poly

from suspid.errors import SimulatorError
from suspid.interfaces import IRREGULARITY_CHANNELS, Response, TrackSegment

from suspid.infra.threads import single_blas_thread
from .model import TABLE_PAD, TRACK_INPUTS, LinearSystem, TrainModel, quiet
from .modes import acting_positions, state_matrix

_ROWS = [IRREGULARITY_CHANNELS.index(c) for c in TRACK_INPUTS]


def taper_window(distance: np.ndarray, taper_m: float) -> np.ndarray:
    """Raised-cosine fade-in and fade-out over ``taper_m`` metres at each end (1 in between)."""
    d = np.asarray(distance, dtype=float)
    if taper_m <= 0:
        return np.ones_like(d)
    from_start = d - d[0]
    to_end = d[-1] - d
    u = np.clip(np.minimum(from_start, to_end) / taper_m, 0.0, 1.0)
    return 0.5 * (1.0 - np.cos(math.pi * u))


def track_table(segment: TrackSegment, taper_m: float) -> np.ndarray:
    """``(3, n_x)`` tapered track inputs (rows :data:`TRACK_INPUTS`), m."""
    irr = np.asarray(segment.irregularities, dtype=float)[_ROWS]
    return irr * taper_window(segment.distance, taper_m)


def output_samples(segment: TrackSegment, fs: float) -> int:
    """Number of output samples of a segment's record (its duration times fs, rounded)."""
    return max(1, int(round(segment.duration() * fs)))


def is_constant_speed(segment: TrackSegment) -> bool:
    """True for a scalar speed or a record that does not vary (to 1e-9 relative)."""
    v = np.asarray(segment.speed, dtype=float)
    return v.ndim == 0 or bool(np.ptp(v) <= 1e-9 * np.max(np.abs(v)))


def check_segment(segment: TrackSegment) -> None:
    """Raise SimulatorError for a segment the solvers cannot run."""
    x = np.asarray(segment.distance, dtype=float)
    irr = np.asarray(segment.irregularities, dtype=float)
    v = np.asarray(segment.speed, dtype=float)
    name = segment.name
    if x.ndim != 1 or x.size < 2:
        raise SimulatorError(f"segment '{name}': distance must have at least 2 samples")
    if irr.shape != (len(IRREGULARITY_CHANNELS), x.size):
        raise SimulatorError(f"segment '{name}': irregularities of shape {irr.shape}, expected "
                             f"({len(IRREGULARITY_CHANNELS)}, {x.size})")
    dx = np.diff(x)
    if not np.all(dx > 0) or np.ptp(dx) > 1e-6 * dx.mean() + 1e-9:
        raise SimulatorError(f"segment '{name}': distance must increase with a uniform step")
    if not np.all(np.isfinite(irr)):
        raise SimulatorError(f"segment '{name}': irregularities contain NaN or inf")
    if v.ndim not in (0, 1) or (v.ndim == 1 and v.size != x.size):
        raise SimulatorError(f"segment '{name}': speed must be a number or one value per distance sample")
    if not np.all(np.isfinite(v)) or np.any(v <= 0):
        raise SimulatorError(f"segment '{name}': speed must be positive and finite")


# ====================================================================== time solver
@dataclass
class TimeSettings:
    """Settings of the time solver (see the module docstring)."""

    fs: float
    step: float
    spectral_radius: float = 0.8
    taper_m: float = 20.0
    newton: bool = False


def time_step(fs: float, step: float) -> tuple[float, int]:
    """The integration step dt = 1/(k fs) <= ``step`` and the decimation factor k."""
    k = max(1, int(math.ceil(1.0 / (fs * step) - 1e-9)))
    return 1.0 / (k * fs), k


def _speed_profile(segment: TrackSegment) -> tuple[np.ndarray, np.ndarray]:
    """Car-centre time t(x) at each distance sample (t = 0 at the first) and the speeds."""
    x = np.asarray(segment.distance, dtype=float)
    v = np.broadcast_to(np.asarray(segment.speed, dtype=float), x.shape)
    inv = 1.0 / v
    t = np.concatenate([[0.0], np.cumsum(0.5 * (inv[1:] + inv[:-1]) * np.diff(x))])
    return t, v


def simulate_time(model: TrainModel, segment: TrackSegment, settings: TimeSettings) -> Response:
    """Integrate the model over one segment with exudyn (see the module docstring)."""
    exu = model.exu
    mbs = model.mbs
    fs = settings.fs
    dt, k = time_step(fs, settings.step)
    x = np.asarray(segment.distance, dtype=float)
    dx = float(x[1] - x[0])
    table = track_table(segment, settings.taper_m)
    n_t = output_samples(segment, fs)
    T = n_t / fs
    a = model.layout.wheelset_x(model.values)
    a_max = float(np.max(a))
    t_post = 0.05 + 12.0 / fs          # margin for the decimation filter (half length 10 k fine samples = 10 / fs)

    constant = is_constant_speed(segment)
    if constant:
        v0 = float(np.asarray(segment.speed, dtype=float).flat[0])
        n_pre = int(math.ceil(a_max / v0 * fs)) + 1
        t_pre = n_pre / fs
        odo0 = -v0 * t_pre / dx
        odo_v = v0 / dx
    else:
        t_x, v_x = _speed_profile(segment)
        v_start, v_end = float(v_x[0]), float(v_x[-1])
        n_pre = int(math.ceil(a_max / v_start * fs)) + 1
        t_pre = n_pre / fs
        odo0 = -v_start * t_pre / dx
        odo_v = v_start / dx
        # speed of the car centre on a time grid from the start of the integration
        t_end = t_pre + T + t_post
        dt_v = 0.02                                    # speed records vary slowly
        tg = np.arange(0.0, t_end + 2 * dt_v, dt_v)
        tc = tg - t_pre                                  # record time of each grid point
        speeds = np.interp(tc, t_x, v_x, left=v_start, right=v_end)
        model.set_speed_table(speeds / dx, dt_v)

    model.set_track(table, dx)
    odo = odo0 + a / dx + TABLE_PAD         # each wheelset's position in the track table (leaf units)
    for node, o in zip(model.odometers, odo):
        mbs.SetNodeParameter(node, "initialCoordinates", [float(o)])
        mbs.SetNodeParameter(node, "initialCoordinates_t", [odo_v])
    if model.features.variable_speed:
        for link, off in zip(model.odometer_links, odo[1:] - odo[0]):
            mbs.SetObjectParameter(link, "offset", float(off))
    mbs.AssembleInitializeSystemCoordinates()

    t_end = t_pre + T + t_post
    n_steps = int(math.ceil(t_end / dt - 1e-9))
    ss = exu.SimulationSettings()
    ti = ss.timeIntegration
    ti.numberOfSteps = n_steps
    ti.endTime = n_steps * dt
    ti.automaticStepSize = False
    ti.adaptiveStep = False
    ti.verboseMode = 0
    ti.generalizedAlpha.spectralRadius = settings.spectral_radius
    ti.generalizedAlpha.computeInitialAccelerations = True
    ti.newton.active = bool(settings.newton)
    ti.newton.useModifiedNewton = True
    ti.newton.relativeTolerance = 1e-7
    ti.newton.absoluteTolerance = 1e-4      # residual norm / n, in N: far below the forces (1e4-1e5 N)
    ti.newton.maxIterations = 50
    ss.solution.file.write = False
    ss.solution.sensors.writePeriod = dt
    ss.solution.sensors.active = True
    try:
        with quiet(exu):
            ok = mbs.SolveDynamic(ss, showHints=False, showCausingItems=False)
    except Exception as exc:  # exudyn raises its own SolverError family
        raise SimulatorError(f"segment '{segment.name}': exudyn time integration failed: "
                             f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") from exc
    if ok is False:
        raise SimulatorError(f"segment '{segment.name}': exudyn time integration failed")

    fine = model.sensor_accelerations()
    coarse = resample_poly(fine, 1, k, axis=1) if k > 1 else fine
    if coarse.shape[1] < n_pre + n_t:
        raise SimulatorError(f"segment '{segment.name}': the integration stopped early")
    acc = coarse[:, n_pre:n_pre + n_t]
    if not np.all(np.isfinite(acc)) or np.max(np.abs(acc)) > 1e4:
        raise SimulatorError(f"segment '{segment.name}': the time integration diverged "
                             f"(unstable vehicle at this speed, or a too large step)")
    return Response(tuple(s.name for s in model.sensors), float(fs), acc, segment.name)


# ====================================================================== frequency solver
class FrequencyResponse:
    """H(f): track channels at the car centre -> sensor accelerations, for one linear system.

    :param linear: the linearised model at its speed.
    :raises SimulatorError: when the model is unstable at that speed.
    """

    def __init__(self, linear: LinearSystem) -> None:
        self.linear = linear
        M = linear.M
        n = M.shape[0]
        # state x = (q_acting, q'): the positions of cyclic coordinates (a rolling wheelset's spin angle)
        # move nothing and are left out (:func:`.modes.acting_positions`)
        acting = acting_positions(linear.K, linear.C, linear.C_disp)
        p = acting.size
        with single_blas_thread():
            Minv = np.linalg.inv(M)
            A = state_matrix(linear, positions=acting)
            lam, V = np.linalg.eig(A)
            # condition number of the eigenvectors in the 1-norm (an inverse instead of an SVD: cheaper,
            # and the inverse serves the modal form)
            try:
                Vinv = np.linalg.inv(V)
                cond = float(np.linalg.norm(V, 1) * np.linalg.norm(Vinv, 1))
            except np.linalg.LinAlgError:
                cond = math.inf
        self.eigenvalues = lam
        self.acting, self.Minv = acting, Minv     # kept for the derivatives (:mod:`.sensitivity`)
        unstable = lam[lam.real > 1e-9 * np.maximum(1.0, np.abs(lam))]
        if unstable.size:
            worst = unstable[np.argmax(unstable.real)]
            raise SimulatorError(
                f"the linear model is unstable at {linear.speed * 3.6:.1f} km/h: a mode at "
                f"{abs(worst) / (2 * math.pi):.2f} Hz grows (damping ratio {-worst.real / abs(worst):.3f}); "
                f"check conicity, yaw dampers and creep parameters")
        self.modal = bool(cond < 1e8)
        self.A = A
        self.n_state = p + n
        # inputs: B_j = [0; M^-1 G_j]; outputs: accelerations C q''
        B = np.zeros((linear.G.shape[0], p + n, linear.G.shape[2]))
        B[:, p:, :] = np.einsum("ab,jbc->jac", Minv, linear.G)
        self.B = B
        self.Cq = np.hstack([linear.C[:, acting], np.zeros_like(linear.C)])
        self.Cd = (None if linear.C_disp is None
                   else np.hstack([linear.C_disp[:, acting], np.zeros_like(linear.C_disp)]))
        if self.modal:
            self.V, self.Vinv = V, Vinv
            self.L = self.Cq @ V                               # (n_out, p + n)
            self.Ld = None if self.Cd is None else self.Cd @ V
            R = np.einsum("ab,jbc->jac", Vinv, B)              # (n_w, p + n, n_in)
            self.R = R
            self.Rt = np.ascontiguousarray(R.transpose(1, 2, 0).reshape((p + n) * R.shape[2], R.shape[0]))

    def __call__(self, freqs: np.ndarray) -> np.ndarray:
        """H ``(n_freqs, n_sensors, 3)`` in (m/s^2) per m of track input at the car centre."""
        return self.by_input(freqs).transpose(2, 1, 0)

    def by_input(self, freqs: np.ndarray) -> np.ndarray:
        """H in the layout of the per-segment products: ``(3, n_sensors, n_freqs)``."""
        f = np.asarray(freqs, dtype=float)
        w = 2 * math.pi * f
        delays = self.linear.wheelset_x / self.linear.speed                  # (n_w,)
        E = np.exp(1j * np.outer(delays, w))                                 # (n_w, n_f)
        m2, nin = self.n_state, self.B.shape[2]
        nf = len(f)
        with single_blas_thread():
            if self.modal:
                # S[m, c, f] = z_m(w) sum_j R_j[m, c] e^{i w t_j}, z_m = 1 / (i w - lambda_m)
                S = (self.Rt @ E).reshape(m2, nin, nf)
                S *= (1.0 / (1j * w[None, :] - self.eigenvalues[:, None]))[:, None, :]
                X = (self.L @ S.reshape(m2, nin * nf)).reshape(-1, nin, nf)    # (n_out, 3, n_f)
                X = X.transpose(1, 0, 2) * -(w ** 2)
                if self.Ld is not None:
                    X += (self.Ld @ S.reshape(m2, nin * nf)).reshape(-1, nin, nf).transpose(1, 0, 2)
            else:
                Bw = np.einsum("jf,jac->fac", E, self.B)
                lhs = 1j * w[:, None, None] * np.eye(m2)[None] - self.A[None]
                state = np.linalg.solve(lhs, Bw)
                X = np.einsum("om,fmc->cof", self.Cq, state) * -(w ** 2)
                if self.Cd is not None:
                    X += np.einsum("om,fmc->cof", self.Cd, state)
        return np.ascontiguousarray(X)

    def wheelset_response(self, f: float, j: int) -> np.ndarray:
        """``(n_sensors, 3)``: response at ``f`` Hz to the track channels under wheelset ``j`` alone (no delay)."""
        w = 2 * math.pi * float(f)
        with single_blas_thread():
            if self.modal:
                S = self.R[j] / (1j * w - self.eigenvalues)[:, None]          # (p + n, 3)
                X = -(w ** 2) * (self.L @ S)
                if self.Ld is not None:
                    X = X + self.Ld @ S
            else:
                state = np.linalg.solve(1j * w * np.eye(self.n_state) - self.A, self.B[j])
                X = -(w ** 2) * (self.Cq @ state)
                if self.Cd is not None:
                    X = X + self.Cd @ state
        return X

    def periodic_response(self, n_t: int, fs: float) -> np.ndarray | None:
        """``(n_sensors, n_t)`` steady-state response to the periodic wheel inputs, or ``None`` without any.

        Inputs above fs / 2 are left out (the time solver's decimation filter removes them too).
        """
        lin = self.linear
        if not lin.periodic:
            return None
        t = np.arange(n_t) / fs
        out = np.zeros((lin.C.shape[0], n_t))
        for pi in lin.periodic:
            f = lin.speed / pi.wavelength
            if f >= fs / 2:
                continue
            h = self.wheelset_response(f, pi.wheelset)[:, 0]                    # vertical input
            a = pi.amplitude * np.exp(1j * (2 * math.pi * lin.wheelset_x[pi.wheelset] / pi.wavelength + pi.phase))
            out += np.real(np.outer(h * a, np.exp(2j * math.pi * f * t)))
        return out

    @property
    def settling_time(self) -> float:
        """Time (s) for the slowest mode to decay to 5 % (e^-3): 3 / min |Re lambda|."""
        return 3.0 / float(np.min(-self.eigenvalues.real))


def fft_length(n_t: int, fs: float, delay_s: float, settle_s: float) -> int:
    """FFT length so that the circular convolution equals the linear one (see the module docstring).

    A power of two: the length then rarely changes from one parameter vector
    to the next, and the cached input spectra stay valid.
    """
    need = n_t + 2 * int(math.ceil(delay_s * fs)) + int(math.ceil(settle_s * fs)) + 2
    return 1 << int(math.ceil(math.log2(need)))


class InputSpectra:
    """Spectra of the tapered track under the car centre, cached per segment.

    A segment is recognised by its arrays (identity, shape and a sample of
    values): the cache keeps the arrays alive, so that an id cannot be reused.
    """

    def __init__(self, maxsize: int = 512) -> None:
        self._cache: OrderedDict = OrderedDict()
        self.maxsize = maxsize

    @staticmethod
    def _fingerprint(segment: TrackSegment) -> tuple:
        irr = segment.irregularities
        x = segment.distance
        sample = np.asarray(irr)[:, :: max(1, np.shape(irr)[1] // 64)]
        return (id(irr), id(x), np.shape(irr), float(np.sum(sample)), float(x[0]), float(x[-1]))

    def get(self, segment: TrackSegment, fs: float, n_fft: int, taper_m: float) -> np.ndarray:
        """U ``(3, n_fft // 2 + 1)``: spectrum of the track inputs on the time grid j / fs.

        The track is sampled on a grid q times finer than fs (q so that the
        train moves at most half a track sample per point) and the first
        n_fft // 2 + 1 lines are kept: the lines above fs / 2 do not fold
        back into the band.
        """
        v = float(np.asarray(segment.speed, dtype=float).flat[0])
        key = (self._fingerprint(segment), fs, n_fft, taper_m, v)
        hit = self._cache.get(key)
        if hit is not None:
            self._cache.move_to_end(key)
            return hit[0]
        x = np.asarray(segment.distance, dtype=float)
        dx = float(x[1] - x[0])
        q = max(1, int(math.ceil(2.0 * v / (fs * dx))))
        n_hi = q * n_fft
        table = track_table(segment, taper_m)
        t = np.arange(n_hi) / (q * fs)
        xs = x[0] + v * t
        u = np.zeros((3, n_hi))
        inside = xs <= x[-1]
        for c in range(3):
            u[c, inside] = np.interp(xs[inside], x, table[c])
        U = sfft.rfft(u, axis=1)[:, : n_fft // 2 + 1] / q
        if n_fft % 2 == 0:
            U[:, -1] = 0.0   # the Nyquist line of an even-length record must be real: drop it
        U = np.ascontiguousarray(U)
        self._cache[key] = (U, segment.irregularities, segment.distance)
        if len(self._cache) > self.maxsize:
            self._cache.popitem(last=False)
        return U


def fft_plan(response: FrequencyResponse, segments: list[TrackSegment], fs: float, settle_s: float
             ) -> tuple[list[int], int]:
    """The records' lengths ``n_t`` and the FFT length the frequency solver uses for ``segments``
    (see :func:`simulate_frequency`)."""
    lin = response.linear
    delay = float(np.max(np.abs(lin.wheelset_x))) / lin.speed
    pad = min(max(settle_s, response.settling_time), 120.0)
    n_ts = [output_samples(seg, fs) for seg in segments]
    return n_ts, fft_length(max(n_ts), fs, delay, pad)


def simulate_frequency(response: FrequencyResponse, segments: list[TrackSegment], fs: float, taper_m: float,
                       settle_s: float, spectra: InputSpectra, channels: tuple[str, ...],
                       frf_cache: dict) -> list[Response]:
    """Responses of constant-speed segments at the speed of ``response`` (see the module docstring).

    All segments share one FFT length (the longest need); the zero padding
    covers ``settle_s`` or three time constants of the slowest mode, whichever
    is longer (at most 120 s): what leaks from the end of a record into its
    start is below 5 % of the slowest mode's amplitude.
    """
    n_ts, n_fft = fft_plan(response, segments, fs, settle_s)
    H = frf_cache.get(n_fft)
    if H is None:
        H = response.by_input(np.arange(n_fft // 2 + 1) * fs / n_fft)         # (3, n_out, n_f)
        frf_cache[n_fft] = H
    out = []
    for seg, n in zip(segments, n_ts):   # one segment at a time: its arrays stay in cache
        U = spectra.get(seg, fs, n_fft, taper_m)                               # (3, n_f)
        Y = H[0] * U[0]
        Y += H[1] * U[1]
        Y += H[2] * U[2]
        y = sfft.irfft(Y, n=n_fft, axis=-1)[:, :n]
        periodic = response.periodic_response(n, fs)
        if periodic is not None:
            y = y + periodic
        out.append(Response(channels, float(fs), np.ascontiguousarray(y), seg.name))
    return out
