"""Derivatives of the frequency solver's records with respect to the model's parameters.

The frequency solver (:mod:`.solvers`) computes the records from the receptance
of the linearised model, M q'' + D q' + K q = Σ_j G_j r_j, outputs a = C q'' + C_disp q:

    H(ω) = (-ω² C + C_disp) Z(ω)^-1 F(ω),   Z(ω) = -ω² M + iω D + K,   F(ω) = Σ_j G_j e^{iω a_j / v}.

For a parameter p that does not move the geometry (C, C_disp and the wheelset
positions stay), differentiating Z Z^-1 = I gives

    ∂H/∂p = (-ω² C + C_disp) Z^-1 (∂F/∂p - ∂Z/∂p Z^-1 F) = O(ω) (∂F/∂p - ∂Z/∂p Q(ω)),

with O = (-ω² C + C_disp) Z^-1 the sensors' response to a unit force on each
coordinate and Q = Z^-1 F the coordinates' response to the track. Both come
from the eigen-decomposition the plain solve has already made (the modal form
of :class:`.solvers.FrequencyResponse`: nothing is factorised again); O is
needed only on the coordinates where some ∂Z/∂p acts, Q only where ∂Z/∂p
reads, and ∂Z/∂p of a spring, a damper or a mass is sparse: a few rows and
columns per parameter. ∂Z/∂p q is written ∂K/∂p q + (∂D/∂p + iω ∂M/∂p) q'
on the state (q_acting, q'), so that the cyclic coordinates (a wheelset's spin
angle, left out of the state) need no position. Each record's derivative is
then irfft(∂H/∂p U)[:n_t] with the track spectrum U of the plain solve.

Semi-analytic: ∂M/∂p, ∂K/∂p, ∂D/∂p and ∂G/∂p are differences of exudyn's
linearisation (:meth:`.model.TrainModel.linear_system`) at p and at p + h.
For the parameters in :data:`LINEAR` the matrices are affine in p (a spring's
or a damper's rate, a Maxwell element's mass c / (2π f_fast), the creep
coefficients times ``kalker_scale``, the conicity), so a one-sided difference
is exact but for rounding; the others (masses and inertias: the wheel loads
set the Hertzian stiffness and Kalker's coefficients; ``r_rail``) take a
central difference. What is *not* differentiated here, and is left to finite
differences of the whole simulation by the caller
(:meth:`.simulator.ExudynTrain.differentiable`): the geometry
(:data:`.model.GEOMETRY`: it moves attachment points and sensors and rebuilds
the system), the parameters of effects, and any parameter of the time solver
(its nonlinear options: creep saturation, bump stops, blow-off).
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass

import numpy as np
from scipy import fft as sfft
from scipy import sparse

from suspid.elements import kind_of
from suspid.infra.threads import single_blas_thread

try:  # numba is a dependency; without it the products fall back to numpy
    from numba import njit
except ImportError:  # pragma: no cover - exercised only without numba
    njit = None
HAVE_NUMBA = njit is not None

from .model import GEOMETRY, LinearSystem, TrainModel
from .solvers import FrequencyResponse, InputSpectra, fft_plan

LINEAR = frozenset({
    "k_prim_x", "c_prim_x", "k_prim_y", "k_prim_z", "c_prim_z", "k_sec_x", "k_sec_y", "k_sec_z", "c_sec_z",
    "k_sec_z_s", "c_sec_y", "c_yaw", "k_yaw_s", "k_trac", "k_arb", "conicity", "kalker_scale", "m_track",
    "k_track", "c_track", "k_art", "c_art", "c_ic"})
"""Parameters on which M, K, D and G depend affinely (one linearisation per derivative suffices); an element
group (``c_yaw[bogie1]``) is as linear as its kind (:func:`suspid.elements.kind_of`)."""

LINEAR_STEP = 1e-2
"""Relative step of the one-sided difference of the matrices for :data:`LINEAR` parameters (exact: affine)."""

CENTRAL_STEP = 1e-4
"""Relative step of the central difference of the matrices for the other parameters (error O(h²))."""

RECORD_PRECISION = np.complex64
"""The products ∂H/∂p U and their inverse FFTs, one per parameter, channel and segment, run in single
precision (the receptance's derivatives themselves, with their modal sums, in double): a relative error
near 1e-6 of each record, far below the 1e-4 the derivatives are checked to, for half the memory
traffic of the step that dominates the cost."""

FREQUENCY_BLOCK = 512
"""Frequencies processed together (bounds the memory of the (n_f, n_sensors, n_coordinates) products)."""


def analytic_parameters(names, table_names) -> list[str]:
    """The names among ``names`` this module differentiates: parameters of the table that keep the geometry."""
    return [n for n in names if n in table_names and n not in GEOMETRY]


@dataclass
class MatrixDerivative:
    """∂M/∂p, ∂K/∂p, ∂D/∂p ``(n, n)`` and ∂G/∂p ``(n_wheelsets, n, 3)`` on the free coordinates (SI per SI of p)."""

    dM: np.ndarray
    dK: np.ndarray
    dD: np.ndarray
    dG: np.ndarray


def _difference(a: LinearSystem, b: LinearSystem, h: float) -> MatrixDerivative:
    return MatrixDerivative((a.M - b.M) / h, (a.K - b.K) / h, (a.D - b.D) / h, (a.G - b.G) / h)


def _step(name: str, x: float) -> float:
    rel = LINEAR_STEP if kind_of(name) in LINEAR else CENTRAL_STEP
    return rel * abs(x) if x != 0 else rel


def _linearised(model: TrainModel, values: dict[str, float], speed: float, base: LinearSystem,
                shifts: dict[str, float], what: str) -> LinearSystem:
    """The linear system with ``values`` moved by ``shifts``; refuses a move of the sensors or wheelsets."""
    model.update({**values, **{n: float(values[n]) + h for n, h in shifts.items()}}, speed)
    out = model.linear_system()
    if not (np.array_equal(out.C, base.C) and np.array_equal(out.wheelset_x, base.wheelset_x)
            and (out.C_disp is None) == (base.C_disp is None)
            and (out.C_disp is None or np.array_equal(out.C_disp, base.C_disp))):
        raise ValueError(f"parameter {what} moves the sensors or the wheelsets")
    return out


def _single(model: TrainModel, values: dict[str, float], speed: float, name: str,
            base: LinearSystem) -> MatrixDerivative:
    """One parameter's derivative: one-sided for :data:`LINEAR`, central otherwise."""
    h = _step(name, float(values[name]))
    plus = _linearised(model, values, speed, base, {name: h}, repr(name))
    if kind_of(name) in LINEAR:
        return _difference(plus, base, h)
    minus = _linearised(model, values, speed, base, {name: -h}, repr(name))
    return _difference(plus, minus, 2 * h)


Pattern = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
"""Where a parameter's derivative is not zero: boolean masks of ∂M, ∂K, ∂D, ∂G."""

_PATTERNS: "weakref.WeakKeyDictionary[TrainModel, dict[tuple[str, ...], list[Pattern]]]" = weakref.WeakKeyDictionary()

POINT_INDEPENDENT = (LINEAR - {"conicity", "kalker_scale"}) | {
    "I_car_x", "I_car_y", "I_car_z", "I_bogie_x", "I_bogie_y", "I_bogie_z", "I_ws_x", "I_ws_y", "I_ws_z"}
"""Kinds whose matrix derivatives do not depend on where they are taken (for a given model, speed and
geometry): a spring's or a damper's rate multiplies a deformation set by the geometry alone (∂K/∂k, ∂D/∂c
constant), an inertia multiplies an angular acceleration, and its gyroscopic term the spin the speed sets.
Not so the masses (the wheel loads set the Hertzian stiffness and Kalker's coefficients), the wheelbase
``l0``, the rail radius, the conicity and the creep scale (their terms are products among themselves), whose
derivatives depend on these parameters only. ``tests/test_jacobian.py`` checks both claims on both presets."""

_KEPT: "weakref.WeakKeyDictionary[TrainModel, dict]" = weakref.WeakKeyDictionary()
"""Per model: the matrix derivatives kept between calls (:func:`matrix_derivatives`): the rates' and inertias'
per speed and element groups, the others' at the latest values of the parameters they depend on."""


def _pattern(d: MatrixDerivative) -> Pattern:
    return d.dM != 0, d.dK != 0, d.dD != 0, d.dG != 0


def _groups(names: list[str], patterns: list[Pattern]) -> list[list[int]]:
    """Parameters whose derivatives touch disjoint entries (greedy colouring, largest pattern first), the
    one-sided (:data:`LINEAR`) and the central ones apart."""
    sizes = [sum(int(m.sum()) for m in pat) for pat in patterns]
    groups: list[list[int]] = []
    used: list[list[np.ndarray]] = []
    for i in sorted(range(len(names)), key=lambda i: (kind_of(names[i]) not in LINEAR, -sizes[i])):
        for g, union in zip(groups, used):
            if (kind_of(names[g[0]]) in LINEAR) == (kind_of(names[i]) in LINEAR) and \
                    not any(np.any(u & m) for u, m in zip(union, patterns[i])):
                g.append(i)
                for u, m in zip(union, patterns[i]):
                    u |= m
                break
        else:
            groups.append([i])
            used.append([m.copy() for m in patterns[i]])
    return groups


def matrix_derivatives(model: TrainModel, values: dict[str, float], speed: float, names: list[str],
                       base: LinearSystem) -> list[MatrixDerivative]:
    """The matrices' derivatives for each of ``names`` (see the module docstring); ``model`` is left at ``values``.

    The first call on a model differentiates every parameter on its own and keeps where each derivative
    is not exactly zero (its pattern: a spring, a damper or a mass touches a few entries of M, K, D and G).
    Later calls move together the parameters whose patterns are disjoint (a greedy colouring: the
    conventional car's 34 parameters in 11 groups, 16 linearisations instead of 48) and read each one's
    derivative on its own entries: exact, because an entry outside a parameter's pattern does not depend
    on it. A group whose difference changes an entry outside all its patterns (a parameter that reaches
    further at this point) is differentiated again one by one, and its patterns renewed.

    The matrices are A(θ) + Σ_r w_r B_r: the rates and inertias w_r (:data:`POINT_INDEPENDENT`) enter
    linearly with matrices B_r of the geometry and the speed, the other parameters θ (masses, wheelbase,
    conicity, creep scale, rail radius) through A. So ∂/∂w_r = B_r is the same at every point and ∂/∂θ
    depends on θ alone: each derivative is kept (per model, speed and set of element groups given their own
    values; the θ-dependent ones for the latest θ only) and read again wherever θ has not moved: an
    identification of rates linearises the model for the first Jacobian only.

    :raises ValueError: a parameter moves the sensors' matrices or the wheelsets (geometry): not differentiable here.
    """
    kept = _KEPT.setdefault(model, {})
    context = (float(speed), tuple(sorted(k for k in values if "[" in k)))
    others = context + tuple(sorted((k, float(v)) for k, v in values.items()
                                    if kind_of(k) not in POINT_INDEPENDENT))
    if kept.get("others") != others:       # θ moved: only the latest θ's derivatives are kept (bounded memory)
        kept["others"], kept["at_others"] = others, {}
    rates, at_others = kept.setdefault("rates", {}), kept["at_others"]

    def store(n: str) -> dict:
        return rates if kind_of(n) in POINT_INDEPENDENT else at_others

    def key(n: str) -> tuple:
        return (n,) + context if kind_of(n) in POINT_INDEPENDENT else n

    found = {n: store(n).get(key(n)) for n in names}
    todo = [n for n in names if found[n] is None]
    if todo:
        for n, d in zip(todo, _point_derivatives(model, values, speed, todo, base)):
            found[n] = store(n)[key(n)] = d
    return [found[n] for n in names]  # type: ignore[misc]


def _point_derivatives(model: TrainModel, values: dict[str, float], speed: float, names: list[str],
                       base: LinearSystem) -> list[MatrixDerivative]:
    """:func:`matrix_derivatives` at ``values`` (every one computed), sharing linearisations after a first call."""
    key = tuple(names)
    known = _PATTERNS.setdefault(model, {})
    try:
        patterns = known.get(key)
        if patterns is None:
            out = [_single(model, values, speed, n, base) for n in names]
            known[key] = [_pattern(d) for d in out]
            return out
        out: list[MatrixDerivative | None] = [None] * len(names)
        for group in _groups(names, patterns):
            if len(group) == 1:
                out[group[0]] = _single(model, values, speed, names[group[0]], base)
                continue
            steps = {names[i]: _step(names[i], float(values[names[i]])) for i in group}
            what = ", ".join(map(repr, steps))
            plus = _linearised(model, values, speed, base, steps, what)
            if kind_of(names[group[0]]) in LINEAR:
                low, scale = base, 1.0
            else:
                low, scale = _linearised(model, values, speed, base, {n: -h for n, h in steps.items()}, what), 2.0
            delta = _difference(plus, low, 1.0)
            fields = (delta.dM, delta.dK, delta.dD, delta.dG)
            union = [np.zeros_like(f, dtype=bool) for f in fields]
            for i in group:
                for u, m in zip(union, patterns[i]):
                    u |= m
            if any(np.any(f[~u] != 0) for f, u in zip(fields, union)):
                for i in group:
                    out[i] = _single(model, values, speed, names[i], base)
                    patterns[i] = _pattern(out[i])
                continue
            for i in group:
                h = scale * steps[names[i]]
                out[i] = MatrixDerivative(*(np.where(m, f, 0.0) / h for f, m in zip(fields, patterns[i])))
        return out  # type: ignore[return-value]
    finally:
        model.update(values, speed)


def _support(*matrices: np.ndarray, axis: int) -> np.ndarray:
    """Indices where any of ``matrices`` has a nonzero entry along ``axis`` (0: rows, 1: columns)."""
    hit = None
    for m in matrices:
        a = np.abs(m) > 0
        h = np.any(a, axis=1 - axis) if m.ndim == 2 else np.any(a, axis=(0, 2))
        hit = h if hit is None else hit | h
    return np.flatnonzero(hit)


def _conjugate_pairs(response: FrequencyResponse) -> tuple[np.ndarray, np.ndarray] | None:
    """``(first, real)``: the modes m with m + 1 their exact conjugate (eigenvalue and eigenvector, as LAPACK
    returns a real matrix's complex pairs) and the real modes; ``None`` when they do not cover every mode."""
    lam, V = response.eigenvalues, response.V
    first = np.flatnonzero(lam.imag > 0)
    real = np.flatnonzero(lam.imag == 0)
    if first.size and first[-1] + 1 >= lam.size:
        return None
    if 2 * first.size + real.size != lam.size or np.intersect1d(first + 1, np.concatenate([first, real])).size:
        return None
    if not (np.array_equal(lam[first + 1], np.conj(lam[first]))
            and np.array_equal(V[:, first + 1], np.conj(V[:, first]))):
        return None
    return first, real


def receptance_derivatives(response: FrequencyResponse, derivatives: list[MatrixDerivative],
                           freqs: np.ndarray) -> np.ndarray:
    """∂H/∂p ``(n_p, 3, n_sensors, n_freqs)`` in the layout of :meth:`.solvers.FrequencyResponse.by_input`.

    :param freqs: ``(n_freqs,)`` Hz (0 included: the modal form holds at ω = 0).
    """
    lin = response.linear
    acting = response.acting
    p = acting.size
    n = lin.M.shape[0]
    m2 = p + n
    position_of = np.full(n, -1)
    position_of[acting] = np.arange(p)
    # per parameter: force rows, and the state columns read (positions through ∂K, velocities through ∂D, ∂M)
    plans = []
    for d in derivatives:
        rows = _support(d.dK, d.dD, d.dM, d.dG, axis=0)
        k_cols = _support(d.dK, axis=1)
        if np.any(position_of[k_cols] < 0):
            raise ValueError("a stiffness derivative acts on a cyclic coordinate")
        v_cols = _support(d.dD, d.dM, axis=1)
        state_cols = np.concatenate([position_of[k_cols], p + v_cols])
        plans.append((rows, k_cols, v_cols, state_cols))
    all_rows = np.unique(np.concatenate([r for r, *_ in plans] + [np.zeros(0, int)]))
    all_cols = np.unique(np.concatenate([c for *_, c in plans] + [np.zeros(0, int)]))
    row_at = {r: i for i, r in enumerate(all_rows)}
    col_at = {c: i for i, c in enumerate(all_cols)}
    # every parameter's force rows stacked: W = ∂F U - ∂Z Q for all of them from three sparse products
    # (∂K on the positions read, ∂D and ∂M on the velocities) and one with the wheelsets' delays (∂G)
    offsets = np.cumsum([0] + [pl[0].size for pl in plans])
    n_stack = int(offsets[-1])
    entries: dict[str, tuple[list, list, list]] = {"K": ([], [], []), "D": ([], [], []), "M": ([], [], [])}
    dG_stack = np.zeros((lin.G.shape[0], n_stack, 3))
    for d, (rows, k_cols, v_cols, _), lo in zip(derivatives, plans, offsets):
        for key, mat, cols, state in (("K", d.dK, k_cols, position_of[k_cols]), ("D", d.dD, v_cols, p + v_cols),
                                      ("M", d.dM, v_cols, p + v_cols)):
            block = mat[np.ix_(rows, cols)]
            i, j = np.nonzero(block)
            entries[key][0].append(lo + i)
            entries[key][1].append(np.array([col_at[c] for c in state], dtype=int)[j] if j.size else j)
            entries[key][2].append(block[i, j])
        dG_stack[:, lo:lo + rows.size, :] = d.dG[:, rows, :]
    stacked = {key: sparse.csr_matrix((np.concatenate(v) if v else np.zeros(0), (np.concatenate(i).astype(int),
                                                                                 np.concatenate(j).astype(int))),
                                      shape=(n_stack, len(all_cols)))
               for key, (i, j, v) in entries.items()}
    dG_flat = dG_stack.reshape(dG_stack.shape[0], -1).T                                # (n_stack 3, n_w)
    stack_rows = np.array([row_at[r] for pl in plans for r in pl[0]], dtype=np.int64)  # O's column of each
    f = np.asarray(freqs, dtype=float)
    nf = f.size
    n_out = lin.C.shape[0]
    out = np.zeros((len(derivatives), 3, n_out, nf), dtype=complex)
    if not derivatives:
        return out
    lam = response.eigenvalues
    delays = lin.wheelset_x / lin.speed
    with single_blas_thread():
        # sensors per unit force on the touched coordinates: (-ω² C + C_disp) V diag(z) V^-1 [0; M^-1]
        Psi = response.Vinv[:, p:] @ response.Minv[:, all_rows]                      # (m2, n_rows)
        V_cols = response.V[all_cols]                                                  # (n_cols, m2)
        # O(ω) = Σ_m z_m(ω) (-ω² L[:, m] + Ld[:, m]) Psi[m, :]. With -ω² z_m = (iω)² / (iω - λ_m)
        # = iω + λ_m + λ_m² z_m it is iω A0 + A1 + Σ_m z_m (λ_m² L[:, m] + Ld[:, m]) Psi[m, :] (A0, A1 the
        # modal sums of L Psi and λ L Psi, constant in ω): one product of (n_f, m2) by the modes' outer
        # products (m2, n_out n_rows) instead of two (L and Ld), one large matrix product instead of n_f
        # small ones
        n_rows = all_rows.size
        n_ld = 1 if response.Ld is None else 2           # the right-first order applies L and Ld apart
        # which order is cheaper per frequency: O for every touched row once, then a small product per
        # parameter; or per parameter Psi[:, rows] W, then z, then the sensors (right to left)
        pairs = _conjugate_pairs(response)
        # O's product: complex by complex, or (conjugate pairs) complex by real, half the work
        by_rows = m2 * n_out * n_rows // (2 if pairs is not None else 1) + sum(n_out * p_[0].size * 3 for p_ in plans)
        by_parameter = sum(m2 * p_[0].size * 3 + n_ld * n_out * m2 * 3 for p_ in plans)
        right_first = by_parameter < by_rows
        if not right_first:
            T_L = (response.L[:, :, None] * Psi[None]).transpose(1, 0, 2).reshape(m2, n_out * n_rows)
            A0, A1 = T_L.sum(axis=0), lam @ T_L
            T_z = (lam ** 2)[:, None] * T_L
            if response.Ld is not None:
                T_z += (response.Ld[:, :, None] * Psi[None]).transpose(1, 0, 2).reshape(m2, n_out * n_rows)
            del T_L
            if pairs is not None:
                # a real system's modes come in conjugate pairs (m, m+1) whose outer products are conjugate:
                # z_m T_m + z_m+1 conj(T_m) = (z_m + z_m+1) Re T_m + i (z_m - z_m+1) Im T_m, a product of a
                # complex (n_f, m2) by a real (m2, n_out n_rows) matrix: half the work of a complex one
                first, real = pairs
                T_z = np.ascontiguousarray(np.concatenate([T_z[first].real, T_z[first].imag, T_z[real].real]))
        for lo in range(0, nf, FREQUENCY_BLOCK):
            sl = slice(lo, min(nf, lo + FREQUENCY_BLOCK))
            w = 2 * math.pi * f[sl]
            s = 1j * w
            z = 1.0 / (s[:, None] - lam[None, :])                                     # (b, m2)
            E = np.exp(1j * np.outer(delays, w))                                       # (n_w, b)
            # the state's response to the track, on the columns read: V diag(z) V^-1 B(ω)
            S = (response.Rt @ E).reshape(m2, 3, -1) * z.T[:, None, :]                 # (m2, 3, b)
            X = (V_cols @ S.reshape(m2, -1)).reshape(len(all_cols), 3, -1)             # (n_cols, 3, b)
            if not right_first:
                if pairs is None:
                    O = z @ T_z                                                        # (b, n_out n_rows)
                else:
                    zc = np.concatenate([z[:, first] + z[:, first + 1], 1j * (z[:, first] - z[:, first + 1]),
                                         z[:, real]], axis=1)
                    O = np.concatenate([zc.real, zc.imag]) @ T_z                       # rows: real parts, imag parts
                    b_ = zc.shape[0]
                    O = O[:b_] + 1j * O[b_:]
                O += s[:, None] * A0[None] + A1[None]
                O = O.reshape(-1, n_out, n_rows)                                       # (b, n_out, n_rows)
            nb = X.shape[2]
            Xf = X.reshape(len(all_cols), 3 * nb)
            dZq = (stacked["K"] @ Xf + stacked["D"] @ Xf).reshape(n_stack, 3, nb)
            dZq += (stacked["M"] @ Xf).reshape(n_stack, 3, nb) * s[None, None, :]
            W = (dG_flat @ E).reshape(n_stack, 3, nb) - dZq                            # (n_stack, 3, b)
            if not right_first:
                _contract(np.ascontiguousarray(O.transpose(2, 1, 0)), W, stack_rows, offsets, out, lo)
                continue
            for k, (rows, *_) in enumerate(plans):
                if rows.size == 0:
                    continue
                # (-ω² L + Ld) diag(z) Psi[:, rows] W, right to left
                r = rows.size
                Wk = W[offsets[k]:offsets[k + 1]].reshape(r, 3 * nb)
                u = (Psi[:, stack_rows[offsets[k]:offsets[k + 1]]] @ Wk).reshape(m2, 3, nb)
                u *= z.T[:, None, :]
                u = u.reshape(m2, 3 * nb)
                res = (response.L @ u).reshape(n_out, 3, nb) * (-(w ** 2))[None, None, :]
                if response.Ld is not None:
                    res += (response.Ld @ u).reshape(n_out, 3, nb)
                out[k, :, :, sl] = res.transpose(1, 0, 2)
    return out


def _contract_numpy(O_t: np.ndarray, W: np.ndarray, stack_rows: np.ndarray, offsets: np.ndarray, out: np.ndarray,
                    lo: int) -> None:
    """out[k, in, c, lo + f] += Σ_r O_t[stack_rows[r], c, f] W[r, in, f] over parameter k's stacked rows r
    (the reference of the compiled :func:`_contract`)."""
    nb = W.shape[2]
    for k in range(len(offsets) - 1):
        sl = slice(offsets[k], offsets[k + 1])
        out[k, :, :, lo:lo + nb] += np.einsum("rcf,rif->icf", O_t[stack_rows[sl]], W[sl])


if HAVE_NUMBA:
    @njit(cache=True, nogil=True)
    def _contract(O_t, W, stack_rows, offsets, out, lo):  # pragma: no cover - compiled
        n_out, nb = O_t.shape[1], W.shape[2]
        for k in range(offsets.size - 1):
            for r in range(offsets[k], offsets[k + 1]):
                col = stack_rows[r]
                for i in range(3):
                    for c in range(n_out):
                        for f in range(nb):
                            out[k, i, c, lo + f] += O_t[col, c, f] * W[r, i, f]
else:  # pragma: no cover - without numba
    _contract = _contract_numpy


def _combine_numpy(dH: np.ndarray, U: np.ndarray, out: np.ndarray) -> None:
    """out[p, c, f] = Σ_in dH[p, in, c, f] U[in, f] (the reference of the compiled :func:`_combine`)."""
    np.multiply(dH[:, 0], U[0], out=out)
    out += dH[:, 1] * U[1]
    out += dH[:, 2] * U[2]


if HAVE_NUMBA:
    @njit(cache=True, nogil=True)
    def _combine(dH, U, out):  # pragma: no cover - compiled
        n_p, _, n_out, nf = dH.shape
        for k in range(n_p):
            for c in range(n_out):
                for f in range(nf):
                    out[k, c, f] = dH[k, 0, c, f] * U[0, f] + dH[k, 1, c, f] * U[1, f] + dH[k, 2, c, f] * U[2, f]
else:  # pragma: no cover - without numba
    _combine = _combine_numpy


def record_derivatives(response: FrequencyResponse, derivatives: list[MatrixDerivative], segments: list,
                       fs: float, taper_m: float, settle_s: float, spectra: InputSpectra) -> list[np.ndarray]:
    """Per segment ``(n_p, n_sensors, n_t)`` float32: the derivatives of the records
    :func:`.solvers.simulate_frequency` makes (same FFT length, same track spectra), (m/s²) per SI unit.

    The products ∂H/∂p U (a compiled loop) and their inverse FFTs run in single precision
    (:data:`RECORD_PRECISION`), one segment at a time (its arrays stay in cache); the records stay single
    precision: the spectra's derivatives (:func:`suspid.method.jacobian.spectra_derivatives`) take them as
    they are.
    """
    n_ts, n_fft = fft_plan(response, segments, fs, settle_s)
    dH = receptance_derivatives(response, derivatives, np.arange(n_fft // 2 + 1) * fs / n_fft)
    dH = np.ascontiguousarray(dH, dtype=RECORD_PRECISION)
    n_p, _, n_out, nf = dH.shape
    out: list[np.ndarray] = []
    dY = np.empty((n_p, n_out, nf), dtype=RECORD_PRECISION)
    with single_blas_thread():
        for seg, n in zip(segments, n_ts):   # one segment at a time: its products and records stay in cache
            U = spectra.get(seg, fs, n_fft, taper_m).astype(RECORD_PRECISION)           # (3, n_f)
            _combine(dH, U, dY)
            out.append(np.ascontiguousarray(sfft.irfft(dY, n=n_fft, axis=-1)[..., :n]))      # float32
    return out
