"""Compiled (numba) right-hand side and RK4 integrator of the second independent train.

One implementation of the equations of motion (:func:`rhs_one`), used both
by the time integration (:func:`rk4`) and by the linearisation
(:func:`.vehicle.state_matrix`). Arguments are the arrays of
:class:`.vehicle.Model` (:func:`.vehicle.kernel_args`); ``sc`` holds the
scalars in the order of :data:`SCALARS`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

SCALARS = ("half_prim", "damper_asym", "r_blow", "conicity", "r0", "l0", "v", "f_creep", "creep_limit",
           "wheel_load", "flange_gap", "k_flange")
"""Order of the scalar vector ``sc``; ``half_prim`` = b_prim / (2 l0), ``creep_limit`` = mu x wheel load."""

WS = (16, 18, 20, 22)


@njit(cache=True)
def damper_force(vel, c, asym, v_blow, r):
    """Force (N) of an asymmetric damper with blow-off at stroke velocity ``vel`` m/s: rebound rate
    (1 + asym) c, compression (1 - asym) c, each up to ``v_blow``, then r times that rate."""
    cs = c * (1.0 + asym) if vel > 0 else c * (1.0 - asym)
    av = abs(vel)
    f = cs * av if av <= v_blow else cs * (v_blow + r * (av - v_blow))
    return f if vel >= 0 else -f


@njit(cache=True)
def damper_velocity(force, c, asym, v_blow, r):
    """The inverse of :func:`damper_force`: stroke velocity (m/s) at ``force`` N."""
    cs = c * (1.0 + asym) if force > 0 else c * (1.0 - asym)
    af = abs(force)
    fb = cs * v_blow
    v = af / cs if af <= fb else v_blow + (af - fb) / (r * cs)
    return v if force >= 0 else -v


@njit(cache=True)
def she_factor(u):
    """Shen-Hedrick-Elkins: F / F_linear at u = |F_linear| / (mu N): 1 - u/3 + u^2/27 below 3, 1/u above."""
    if u < 3.0:
        return 1.0 - u / 3.0 + u * u / 27.0
    return 1.0 / u


@njit(cache=True)
def rhs_one(q, qd, zm, za, u, K, C, mass, J_m, k_m, c_m, asym_m, vbo_m, r_m, J_a, k_a, c_a,
            J_p, k_pz, c_p, vbo_p, ws_p, side_p, sc, linear_contact, acc, zmd, zad):
    """Accelerations ``acc`` ``(N_DOF,)``, damper stroke rates ``zmd`` ``(12,)`` and orifice rates ``zad`` ``(4,)``
    (written in place) at state q, qd ``(N_DOF,)``, zm ``(12,)``, za ``(4,)`` and track ``u`` ``(4, 6)``: per
    wheelset V, dV/dt, C, dC/dt (vertical, cross-level; m, m/s), Y, G (alignment, gauge; m)."""
    n = q.shape[0]
    Q = np.zeros(n)
    for i in range(n):
        s = 0.0
        for j in range(n):
            s += K[i, j] * q[j] + C[i, j] * qd[j]
        Q[i] = -s
    half, asym, rbl = sc[0], sc[1], sc[2]
    # primary vertical springs and dampers against the track under each axlebox
    for e in range(J_p.shape[0]):
        j = ws_p[e]
        g = u[j, 0] + side_p[e] * half * u[j, 2]
        gd = u[j, 1] + side_p[e] * half * u[j, 3]
        vel = 0.0
        for i in range(n):
            vel += J_p[e, i] * qd[i]
        f = k_pz[e] * g - damper_force(vel - gd, c_p[e], asym, vbo_p[e], rbl)
        for i in range(n):
            Q[i] += f * J_p[e, i]
    # dampers on bushes
    for e in range(J_m.shape[0]):
        d = 0.0
        for i in range(n):
            d += J_m[e, i] * q[i]
        f = k_m[e] * (d - zm[e])
        zmd[e] = damper_velocity(f, c_m[e], asym_m[e], vbo_m[e], r_m[e])
        for i in range(n):
            Q[i] -= f * J_m[e, i]
    # air-spring orifice branches
    for e in range(J_a.shape[0]):
        d = 0.0
        for i in range(n):
            d += J_a[e, i] * q[i]
        f = k_a[e] * (d - za[e])
        zad[e] = f / c_a[e]
        for i in range(n):
            Q[i] -= f * J_a[e, i]
    # wheel-rail
    lam, r0, l0, v, fc, lim, W = sc[3], sc[4], sc[5], sc[6], sc[7], sc[8], sc[9]
    for j in range(4):
        iy = WS[j]
        y, psi, yd, psid = q[iy], q[iy + 1], qd[iy], qd[iy + 1]
        Yt, Gt, Cl = u[j, 4], u[j, 5], u[j, 2]
        xi_l = -lam * (y - Yt - Gt / 2) / r0 - l0 * psid / v
        xi_r = lam * (y - Yt + Gt / 2) / r0 + l0 * psid / v
        xi_y = yd / v - psi
        fxl, fxr, fyl, fyr = -fc * xi_l, -fc * xi_r, -fc * xi_y, -fc * xi_y
        if not linear_contact:
            sl = she_factor(math.hypot(fxl, fyl) / lim)
            sr = she_factor(math.hypot(fxr, fyr) / lim)
            fxl, fyl, fxr, fyr = fxl * sl, fyl * sl, fxr * sr, fyr * sr
        fy = fyl + fyr - 2 * W * Cl / (2 * l0)
        if not linear_contact:
            d = y - Yt
            gap = sc[10] + Gt / 2
            if d > gap:
                fy -= sc[11] * (d - gap)
            elif d < -gap:
                fy -= sc[11] * (d + gap)
        Q[iy] += fy
        Q[iy + 1] += l0 * (fxr - fxl)
    for i in range(n):
        acc[i] = Q[i] / mass[i]


@njit(cache=True)
def rk4(q0, tracks, slopes, n_steps, dt, K, C, mass, J_m, k_m, c_m, asym_m, vbo_m, r_m, J_a, k_a, c_a,
        J_p, k_pz, c_p, vbo_p, ws_p, side_p, sc, S, S_g):
    """Classical RK4 from rest for every segment b: ``tracks``, ``slopes`` ``(B, 4, 4, 2 n_steps + 1)`` (per
    wheelset: vertical, lateral, cross_level, gauge in m and m/m on the half-step grid). Returns the channels
    ``(B, n_ch, n_steps)`` m/s^2 at the step starts (S @ acceleration + S_g @ displacement)."""
    B = tracks.shape[0]
    n = q0.shape[0]
    nm, na = J_m.shape[0], J_a.shape[0]
    n_ch = S.shape[0]
    v = sc[6]
    out = np.empty((B, n_ch, n_steps))
    u = np.zeros((3, 4, 6))
    k_acc = np.zeros((4, n))
    k_vel = np.zeros((4, n))
    k_zm = np.zeros((4, nm))
    k_za = np.zeros((4, na))
    qs, qds = np.empty(n), np.empty(n)
    zms, zas = np.empty(nm), np.empty(na)
    w = (1.0, 2.0, 2.0, 1.0)
    for b in range(B):
        q = q0.copy()
        qd = np.zeros(n)
        zm = np.zeros(nm)
        za = np.zeros(na)
        for i in range(n_steps):
            for h in range(3):
                for j in range(4):
                    u[h, j, 0] = tracks[b, j, 0, 2 * i + h]
                    u[h, j, 1] = v * slopes[b, j, 0, 2 * i + h]
                    u[h, j, 2] = tracks[b, j, 2, 2 * i + h]
                    u[h, j, 3] = v * slopes[b, j, 2, 2 * i + h]
                    u[h, j, 4] = tracks[b, j, 1, 2 * i + h]
                    u[h, j, 5] = tracks[b, j, 3, 2 * i + h]
            for st in range(4):
                c = 0.0 if st == 0 else (dt / 2 if st < 3 else dt)
                p = st - 1 if st > 0 else 0
                for k in range(n):
                    qs[k] = q[k] + c * k_vel[p, k]
                    qds[k] = qd[k] + c * k_acc[p, k]
                    k_vel[st, k] = qds[k]
                for k in range(nm):
                    zms[k] = zm[k] + c * k_zm[p, k]
                for k in range(na):
                    zas[k] = za[k] + c * k_za[p, k]
                hh = 0 if st == 0 else (1 if st < 3 else 2)
                rhs_one(qs, qds, zms, zas, u[hh], K, C, mass, J_m, k_m, c_m, asym_m, vbo_m, r_m, J_a, k_a, c_a,
                        J_p, k_pz, c_p, vbo_p, ws_p, side_p, sc, False, k_acc[st], k_zm[st], k_za[st])
                if st == 0:
                    for ch in range(n_ch):
                        s = 0.0
                        for k in range(n):
                            s += S[ch, k] * k_acc[0, k] + S_g[ch, k] * q[k]
                        out[b, ch, i] = s
            for st in range(4):
                f = dt / 6 * w[st]
                for k in range(n):
                    q[k] += f * k_vel[st, k]
                    qd[k] += f * k_acc[st, k]
                for k in range(nm):
                    zm[k] += f * k_zm[st, k]
                for k in range(na):
                    za[k] += f * k_za[st, k]
    return out
