"""The coupling test: vertical acceleration leaking into a lateral channel at the same point (a tilted sensor).

Overview: ``docs/diagnose.md``, "How it works", step 4.

A lateral accelerometer tilted by α reads x = cos α a_lat + sin α a_vert + n_x. The
vertical channel at the same point reads v = a_vert + n_v, n_x and n_v the sensors'
own noise. If a_lat and a_vert were uncorrelated, x = sin α v + ... would have the real
constant coupling H(f) = sin α at every frequency. The power spectrum of x changes by
sin²α V / L only, invisible where the lateral motion dominates; the cross-spectrum
shows sin α directly.

**Errors in variables.** The regression of x on v, S_vx / S_vv, is biased toward zero
by the sensor noise of the regressor: S_vv = S_aa + S_nn. Where the vertical signal is
near the noise floor (a carbody's vertical above 15 Hz), most of the weight goes to
bins where the estimate is noise: on the independent train with 0.005 m/s² of white
sensor noise the mid-car coefficient came out 0.003 for a true 0.070. The estimator
here is an *instrumental variable*: every other vertical channel z of the vehicle (the
twin sensor's, the other points of the same body, the bogies') sees the same track, so
it correlates with a_vert, and its own sensor noise is independent of n_v and n_x.
Per speed group g, frequency f and instrument z:

    β = Σ w_zf Re(S_xz conj S_vz)  ÷  Σ w_zf |S_vz|²,     w_zf = 1 / (S̄_xx S̄_zz)

with S_xz, S_vz the cross-spectra summed over the group's records and the products of
a record with *itself* left out (Σ_{i≠j} a_i conj b_j: a record's own cross-spectra
share their estimation noise, whose product would bring back a bias of order
S_nn S_zz / (records × windows)). The records of a group are independent stretches of
track at one speed, so each cross-spectrum has one expectation across them. β is the
coupling of x with the part of v the vehicle's other sensors share: sin α plus the
vehicle's own lateral-vertical coupling, whatever the sensor noise.

**Uncertainty.** The delete-one-record jackknife over all records (the instrument sums
recomputed without the record), t with n - 1 degrees of freedom.

**What it is tested against.**

- *The model's own coupling* β_model (``model_coupling``; 0 for a vehicle model whose
  vertical and lateral motions are uncoupled, a symmetric linear one): a tilt shared by
  both twins shows here, where it cancels in their difference.
- *The twin* (the same sensor at the other end: ``front`` and ``rear`` swapped): the
  paired difference d = β - β_twin over the same deletions, which removes the part of
  the vehicle's own coupling both ends share.
- *A reference date* (``reference``): its coupling, by the same estimator, subtracted.
- *Constancy over frequency*: a tilt is a constant; a bracket resonance or the
  vehicle's own coupling is not. β is estimated in ``n_bands`` frequency bands and their
  spread about the common value is tested (χ² on the jackknife covariance of the band
  deviations); a channel whose bands disagree is not taken for a tilt.

A channel is *tilted* when its coupling differs from the model's (Bonferroni over the
channels at ``alpha``), its bands agree, and, with a twin, either the pair's difference
is significant and this channel's own coupling is the further from the model's, or
the twin is tilted alike (a shared tilt: both differ from the model, their difference
does not). Its estimate (``estimate``) is the pair's difference when its twin is not
tilted (the difference removes what both ends share); else the estimate with controls
below, against the model's coupling; without untilted lateral channels, β - β_model. The
angle is asin of it (the calibration gains of both channels enter as their ratio: the
angle is in the units of the channels' calibrations).

**Controls.** The estimate's error is the lateral motion's chance correlation with the
instruments over a finite record (S_{a_lat z} / S_vz: zero in expectation, not in one
measurement), and the lateral channels of one vehicle share most of their motion: the
errors of a shared tilt's channels move together, and a test on the twin cannot remove
them. The lateral channels the test finds untilted carry that motion without the tilt:
per speed group and frequency the channel's part they predict, x̃ = x - Σ_j g_j c_j with
g = S_cc⁻¹ S_cx (least squares over the group's records), is removed before the estimate.
What remains is the tilt, the lateral motion the untilted channels do not see, and the
sensor noise. The vehicle's own coupling the controls share goes with them; the model's
coupling is corrected alike (β_model minus the controls' β_model through g). g is taken as
known in the jackknife (its estimation error is of order the number of controls over the
number of Welch windows, a bias toward zero of the same order).

**One angle from several channels** (:func:`pooled_tilt`): a random-effects mean under
the estimates' jackknife covariance.
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np
from scipy.signal import csd
from scipy.stats import chi2
from scipy.stats import t as student_t

from suspid.data.corrections import vertical_partner


def twin(channel: str, channels: Sequence[str]) -> str | None:
    """The same sensor at the other end (``front`` and ``rear`` swapped in the name), or None."""
    for a, b in (("front", "rear"), ("rear", "front")):
        if a in channel:
            other = channel.replace(a, b)
            return other if other in channels else None
    return None


def instruments(channel: str, channels: Sequence[str]) -> list[str]:
    """The vertical channels other than ``channel``'s own vertical: its instruments."""
    own = vertical_partner(channel, channels)
    return [c for c in channels if "vertical" in c and c != own]


class _Estimate:
    """β of one channel in bands, with every delete-one-record value (jackknife).

    :ivar num, den: ``(n_bands,)`` the estimator's sums; :ivar num_jk, den_jk: ``(n_records, n_bands)`` the
        same sums without each record; :ivar rho: ``(n_controls,)`` how much of each control's coupling the
        removal of its part takes from β (the model's coupling is corrected by it).
    """

    def __init__(self, num: np.ndarray, den: np.ndarray, num_jk: np.ndarray, den_jk: np.ndarray,
                 rho: np.ndarray | None = None) -> None:
        self.num, self.den, self.num_jk, self.den_jk = num, den, num_jk, den_jk
        self.rho = np.zeros(0) if rho is None else rho

    @property
    def n(self) -> int:
        return int(self.num_jk.shape[0])

    def beta(self) -> float:
        return float(self.num.sum() / self.den.sum()) if self.den.sum() > 0 else 0.0

    def beta_jk(self) -> np.ndarray:
        """``(n_records,)`` β without each record."""
        return self.num_jk.sum(axis=1) / np.where(self.den_jk.sum(axis=1) > 0, self.den_jk.sum(axis=1), np.nan)

    def bands(self) -> np.ndarray:
        return self.num / np.where(self.den > 0, self.den, np.nan)

    def bands_jk(self) -> np.ndarray:
        return self.num_jk / np.where(self.den_jk > 0, self.den_jk, np.nan)


def _jackknife_se(values_jk: np.ndarray) -> float:
    """Jackknife standard error of a statistic from its delete-one values ``(n,)``."""
    v = values_jk[np.isfinite(values_jk)]
    n = v.size
    return float(math.sqrt((n - 1) / n * np.sum((v - v.mean()) ** 2))) if n >= 3 else math.inf


def _jackknife_cov(values_jk: np.ndarray) -> np.ndarray:
    """Jackknife covariance ``(p, p)`` of a vector statistic from its delete-one values ``(n, p)``."""
    n = values_jk.shape[0]
    d = values_jk - values_jk.mean(axis=0)
    return (n - 1) / n * d.T @ d


def coupling_test(records: Sequence, channels: Sequence[str], f_band: tuple[float, float], alpha: float = 0.05,
                  segment_seconds: float = 2.56, reference: Sequence | None = None,
                  groups: Sequence | None = None, reference_groups: Sequence | None = None,
                  model_coupling: dict[str, float] | None = None, n_bands: int = 4) -> list[dict[str, Any]]:
    """The coupling of each lateral channel with the vertical channel at its point (module docstring).

    :param records: responses with ``accelerations`` ``(n_channels, n_t)`` m/s² and ``fs`` Hz, channels in the
        order of ``channels``.
    :param f_band: ``(f_min, f_max)`` Hz, the band the estimate uses (clipped to the records' Nyquist frequency).
    :param reference: records of the reference date: their coupling is subtracted with its standard error.
    :param groups: ``(n_records,)`` the speed group of each record (records of one group have one
        cross-spectrum in expectation); default: one group.
    :param model_coupling: the model's own coupling per lateral channel (default 0).
    :param n_bands: bands (equal in log frequency) of the constancy test.
    :returns: per lateral channel with a vertical partner and instruments: ``{channel, vertical, twin,
        instruments, beta, se, t, p, angle_deg, significant, n_segments, beta_raw, se_raw, beta_model,
        beta_reference, t_own, beta_pair, se_pair, t_pair, bands, constancy_p, constant, estimate, controls,
        covariance, note}``; ``beta`` is the estimate of sin α (the coupling beyond the model's and the reference
        date's), ``beta_raw`` the channel's own coupling, ``covariance`` the jackknife covariance of ``beta``
        with the other tilted channels' (:func:`pooled_tilt`).
    """
    names = list(channels)
    lateral = [c for c in names if vertical_partner(c, names) is not None and instruments(c, names)]
    model_coupling = dict(model_coupling or {})
    spec = _spectra(records, segment_seconds, groups)
    ref_spec = _spectra(reference, segment_seconds, reference_groups) if reference is not None else None
    if spec is None:
        return []
    est = {c: _estimate(spec, names, c, f_band, n_bands) for c in lateral}
    ref = ({c: _estimate(ref_spec, names, c, f_band, n_bands) for c in lateral} if ref_spec is not None else {})
    rows: dict[str, dict[str, Any]] = {}
    jk: dict[str, np.ndarray] = {}          # the delete-one-record values of each row's beta
    for c in lateral:
        e = est[c]
        if e is None or e.n < 3:
            continue
        b_raw, se_raw = e.beta(), _jackknife_se(e.beta_jk())
        r = ref.get(c)
        beta, se = _beyond(b_raw, se_raw, model_coupling.get(c, 0.0), r)
        jk[c] = e.beta_jk()
        n = e.n if r is None else min(e.n, r.n)
        t_own = beta / se if se > 0 else 0.0
        # constancy: the band estimates about their common value
        bands, bands_jk = e.bands(), e.bands_jk()
        ok = np.isfinite(bands) & np.all(np.isfinite(bands_jk), axis=0)
        constancy_p = 1.0
        if ok.sum() >= 2:
            dev = bands[ok] - b_raw
            dev_jk = bands_jk[:, ok] - e.beta_jk()[:, None]
            cov = _jackknife_cov(dev_jk)
            stat = float(dev @ np.linalg.pinv(cov, rcond=1e-10) @ dev)
            constancy_p = float(chi2.sf(stat, int(ok.sum()) - 1))
        rows[c] = {"channel": c, "vertical": vertical_partner(c, names), "twin": None,
                   "instruments": instruments(c, names), "beta": beta, "se": se, "t": t_own,
                   "p_own": float(2 * student_t.sf(abs(t_own), max(n - 1, 1))), "n_segments": e.n,
                   "beta_raw": b_raw, "se_raw": se_raw, "beta_model": model_coupling.get(c, 0.0),
                   "beta_reference": None if r is None else r.beta(), "t_own": t_own,
                   "bands": [None if not math.isfinite(v) else float(v) for v in bands],
                   "constancy_p": constancy_p, "beta_pair": None, "se_pair": None, "t_pair": None,
                   "p_pair": None, "controls": [], "covariance": {}, "note": None}
    for c, row in rows.items():
        t_name = twin(c, list(rows))
        if t_name is None or est[t_name].n != est[c].n:
            continue
        d = est[c].beta() - est[t_name].beta()
        d_jk = est[c].beta_jk() - est[t_name].beta_jk()
        se_d = _jackknife_se(d_jk)
        if ref.get(c) is not None and ref.get(t_name) is not None and ref[c].n == ref[t_name].n:
            d -= ref[c].beta() - ref[t_name].beta()
            se_d = math.hypot(se_d, _jackknife_se(ref[c].beta_jk() - ref[t_name].beta_jk()))
        t_pair = d / se_d if se_d > 0 else 0.0
        row.update(twin=t_name, beta_pair=d, se_pair=se_d, t_pair=t_pair,
                   p_pair=float(2 * student_t.sf(abs(t_pair), max(row["n_segments"] - 1, 1))))
        row["_pair_jk"] = d_jk
    tests = max(1, len(rows))
    level = alpha / tests
    for c, row in rows.items():
        row["constant"] = bool(row["constancy_p"] >= alpha)
        own_sig = row["p_own"] < level
        why = None
        if row["twin"] is not None:
            other = rows[row["twin"]]
            pair_sig = row["p_pair"] < level
            other_sig = other["p_own"] < level
            if pair_sig and abs(row["beta"]) < abs(other["beta"]):
                why = (f"the pair differs, and its twin {row['twin']} is the further from the model's coupling: "
                       f"the twin is the candidate")
            elif not pair_sig and not other_sig and own_sig:
                why = f"its twin {row['twin']} differs from the model's coupling neither alone nor in the pair"
        if not row["constant"]:
            why = (f"its coupling is not constant over frequency (p {row['constancy_p']:.2g}): not a tilt (a "
                   f"resonance of the sensor or the vehicle's own coupling)") + (f"; {why}" if why else "")
        row["p"] = row["p_own"] if why is None else 1.0
        row["significant"] = bool(own_sig and why is None)
        row["note"] = why
        row["estimate"] = "against the model's coupling"
    untilted = [c for c, row in rows.items() if not row["significant"]]
    for c, row in rows.items():
        pair_jk = row.pop("_pair_jk", None)
        if not row["significant"]:
            pass
        elif row["twin"] is not None and not rows[row["twin"]]["significant"]:
            # a tilted channel whose twin is not tilted: the pair's difference is the better estimate (it removes
            # the vehicle's own coupling and the estimation error both ends share: the same track under both)
            row.update(beta=row["beta_pair"], se=row["se_pair"], t=row["t_pair"],
                       estimate=f"against its twin {row['twin']}")
            jk[c] = pair_jk
        elif untilted:
            # the lateral motion the untilted lateral channels also see, removed before the estimate (module
            # docstring, "Controls"): most of the estimate's error, and what the vehicle's own coupling they share
            e = _estimate(spec, names, c, f_band, n_bands, controls=untilted)
            r = (_estimate(ref_spec, names, c, f_band, n_bands, controls=untilted)
                 if ref_spec is not None else None)
            if e is not None and e.n == rows[c]["n_segments"]:
                b_model = row["beta_model"] - sum(e.rho[j] * rows[u]["beta_model"] for j, u in enumerate(untilted))
                beta, se = _beyond(e.beta(), _jackknife_se(e.beta_jk()), b_model, r)
                row.update(beta=beta, se=se, t=beta / se if se > 0 else 0.0, controls=list(untilted),
                           estimate="against the model's coupling, the lateral motion of "
                                    f"{', '.join(untilted)} removed")
                jk[c] = e.beta_jk()
        row["angle_deg"] = math.degrees(math.asin(max(-1.0, min(1.0, row["beta"]))))
    tilted = [c for c, row in rows.items() if row["significant"]]
    for c in tilted:
        for o in tilted:
            if jk[c].shape == jk[o].shape:
                rows[c]["covariance"][o] = float(_jackknife_cov(np.column_stack([jk[c], jk[o]]))[0, 1])
    return [rows[c] for c in lateral if c in rows]


def _beyond(b_raw: float, se_raw: float, b_model: float, r: _Estimate | None) -> tuple[float, float]:
    """``(beta, se)``: a channel's coupling ``b_raw`` ± ``se_raw`` less the model's ``b_model`` and, with 3 or more
    records, the reference date's ``r`` (its jackknife standard error added in quadrature)."""
    b0, se0 = b_model, 0.0
    if r is not None and r.n >= 3:
        b0, se0 = b0 + r.beta(), _jackknife_se(r.beta_jk())
    return b_raw - b0, math.hypot(se_raw, se0)


def pooled_tilt(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """One angle from several tilted channels' estimates (their magnitudes |β|), with its standard error.

    A random-effects mean: the channels measure one angle, each with its estimation error (the jackknife
    covariance C of :func:`coupling_test`'s ``covariance``: channels whose errors move together, such as twins
    on the same track, count about once) and a channel's own deviation of variance τ² that the covariance
    does not hold (the ratio of its lateral and vertical calibration gains, its mounting), τ² estimated from
    the scatter of the channels beyond C (the DerSimonian-Laird moment estimator, with C in place of the
    diagonal). The weights (C + τ² I)⁻¹ 1 are kept non-negative (a channel with a negative weight is left out
    and the rest solved again: a negative weight extrapolates from a difference of the channels). Without a
    usable covariance, C = diag(se²).

    :returns: ``{angle_deg, se_deg, tau, weights}``: the angle and its standard error in degrees, τ (in sin α)
        and the weight of each channel.
    """
    chans = [r["channel"] for r in rows]
    b = np.array([abs(r["beta"]) for r in rows])
    sign = np.array([1.0 if r["beta"] >= 0 else -1.0 for r in rows])
    try:
        C = np.array([[r["covariance"][o] for o in chans] for r in rows]) * np.outer(sign, sign)
        np.linalg.cholesky(C)
    except (KeyError, TypeError, np.linalg.LinAlgError):
        C = np.diag([r["se"] ** 2 for r in rows])
    n = len(chans)
    tau2 = 0.0
    if n >= 2:
        Ci = np.linalg.inv(C)
        one = np.ones(n)
        s1 = one @ Ci @ one
        mu = one @ Ci @ b / s1
        q = float((b - mu) @ Ci @ (b - mu))
        denom = float(np.trace(Ci) - one @ Ci @ Ci @ one / s1)
        tau2 = max(0.0, (q - (n - 1)) / denom) if denom > 0 else 0.0
    keep = list(range(n))
    while True:
        V = C[np.ix_(keep, keep)] + tau2 * np.eye(len(keep))
        w = np.linalg.solve(V, np.ones(len(keep)))
        if np.all(w >= 0) or len(keep) == 1:
            break
        keep.pop(int(np.argmin(w)))
    se = math.sqrt(1.0 / w.sum())
    w = w / w.sum()
    weights = {c: 0.0 for c in chans} | {chans[i]: float(x) for i, x in zip(keep, w)}
    beta = float(w @ b[keep])
    angle = math.degrees(math.asin(min(1.0, beta)))
    return {"angle_deg": angle, "se_deg": math.degrees(se / math.sqrt(max(1e-12, 1.0 - min(beta, 0.999) ** 2))),
            "tau": math.sqrt(tau2), "weights": weights}


class _Spectra:
    """The records' Welch cross-spectral matrices: ``f`` ``(F,)`` Hz, ``S`` ``(n_records, K, K, F)`` with
    S[i, a, b] = E[conj(A) B] of record i (scipy's convention), ``groups`` ``(n_records,)`` speed-group labels."""

    def __init__(self, f: np.ndarray, S: np.ndarray, groups: np.ndarray) -> None:
        self.f, self.S, self.groups = f, S, groups


def _spectra(records: Sequence, segment_seconds: float, groups: Sequence | None) -> _Spectra | None:
    """The cross-spectral matrix of every record (all channels at once, Welch), or None when fewer than 3 records
    of at least 16 samples at one sampling rate."""
    labels = list(groups) if groups is not None else [0] * len(records)
    usable = [(r, g) for r, g in zip(records, labels) if np.asarray(r.accelerations).shape[1] >= 16]
    if len(usable) < 3:
        return None
    fs = usable[0][0].fs
    usable = [(r, g) for r, g in usable if r.fs == fs]
    if len(usable) < 3:
        return None
    acc = [np.asarray(r.accelerations, float) for r, _ in usable]
    nper = min(min(a.shape[1] for a in acc), int(round(segment_seconds * fs)))
    out = [csd(a[:, None, :], a[None, :, :], fs=fs, nperseg=nper) for a in acc]
    return _Spectra(out[0][0], np.array([s for _, s in out]), np.array([str(g) for _, g in usable]))


def _estimate(spec: _Spectra | None, names: list[str], channel: str, f_band: tuple[float, float], n_bands: int,
              controls: Sequence[str] = ()) -> _Estimate | None:
    """The instrumental-variable sums of ``channel`` (module docstring), in ``n_bands`` bands, with their
    delete-one-record values; with ``controls`` (lateral channels), the channel's lateral motion they predict
    removed first. None when fewer than 3 records or 3 bins are usable."""
    if spec is None:
        return None
    k, kv = names.index(channel), names.index(vertical_partner(channel, names))
    kz = [names.index(z) for z in instruments(channel, names)]
    kc = [names.index(c) for c in controls]
    S, f, lab = spec.S, spec.f, spec.groups
    s_xx = np.real(S[:, k, k])
    use = (f >= f_band[0]) & (f <= f_band[1]) & (f > 0) & (s_xx.mean(axis=0) > 0)
    if use.sum() < 3:
        return None
    S = S[..., use]
    fu = f[use]
    edges = np.geomspace(fu[0], fu[-1] * (1 + 1e-9), n_bands + 1)
    band = np.clip(np.searchsorted(edges, fu, side="right") - 1, 0, n_bands - 1)
    n_rec = S.shape[0]
    # the controls' prediction of the channel, per speed group (the controls' transfer to the channel is the
    # vehicle's, one per speed): x~ = x - Σ_j g_j c_j, g = S_cc⁻¹ S_cx, and g without each record (jackknife)
    p = len(kc)
    gam = np.zeros((n_rec, fu.size, p), dtype=complex)          # g of each record's group
    gam_jk = np.zeros((n_rec, fu.size, p), dtype=complex)       # g of its group without it
    if kc:
        Scc_r = np.moveaxis(S[:, kc][:, :, kc], -1, 1)            # (n_rec, F, p, p)
        Scx_r = np.moveaxis(S[:, kc, k], -1, 1)                   # (n_rec, F, p)
        for g in np.unique(lab):
            sel = lab == g
            Scc, Scx = Scc_r[sel].sum(axis=0), Scx_r[sel].sum(axis=0)
            gam[sel] = np.einsum("fij,fj->fi", np.linalg.pinv(Scc, rcond=1e-12), Scx)[None]
            gam_jk[sel] = np.einsum("rfij,rfj->rfi", np.linalg.pinv(Scc[None] - Scc_r[sel], rcond=1e-12),
                                    Scx[None] - Scx_r[sel])
    # the residual's power, for the weights: E|X~|² = S_xx - 2 Re(g^H S_cx) + g^H S_cc g
    s_res = np.real(S[:, k, k]) - (np.real(np.einsum("rfj,rjf->rf", gam, np.conj(S[:, kc, k]))) if kc else 0.0)
    num, den = np.zeros(n_bands), np.zeros(n_bands)
    num_jk, den_jk = np.zeros((n_rec, n_bands)), np.zeros((n_rec, n_bands))
    rho_num = np.zeros(p)                            # the controls' share of the model's coupling (docstring)
    sxx_mean = np.maximum(s_res.mean(axis=0), 1e-300)
    kcv = [names.index(vertical_partner(names[j], names)) if vertical_partner(names[j], names) else None
           for j in kc]
    for kzi in kz:
        s_zz = np.real(S[:, kzi, kzi])
        ax, ac, b = S[:, k, kzi], np.moveaxis(S[:, kc, kzi], 1, -1), S[:, kv, kzi]   # ac: (n_rec, F, p)
        w = 1.0 / (sxx_mean * np.maximum(s_zz.mean(axis=0), 1e-300))
        for g in np.unique(lab):
            sel = lab == g
            Ax, Ac, B = ax[sel].sum(axis=0), ac[sel].sum(axis=0), b[sel].sum(axis=0)
            dx = ax[sel] * np.conj(b[sel])                           # (n_g, F) a record with itself
            dc = ac[sel] * np.conj(b[sel])[..., None]                # (n_g, F, p)
            dd = np.abs(b[sel]) ** 2
            G, Gj = gam[sel][0], gam_jk[sel]
            A = Ax - np.einsum("fj,fj->f", np.conj(G), Ac)
            N_f = np.real(A * np.conj(B) - (dx.sum(axis=0) - np.einsum("fj,fj->f", np.conj(G), dc.sum(axis=0))))
            D_f = np.abs(B) ** 2 - dd.sum(axis=0)
            # without record i of the group: sums without it, its own product removed, g without it
            A_j = (Ax - ax[sel]) - np.einsum("rfj,rfj->rf", np.conj(Gj), Ac[None] - ac[sel])
            diag_j = (dx.sum(axis=0) - dx) - np.einsum("rfj,rfj->rf", np.conj(Gj), dc.sum(axis=0)[None] - dc)
            Nj = np.real(A_j * np.conj(B - b[sel]) - diag_j)
            Dj = np.abs(B - b[sel]) ** 2 - (dd.sum(axis=0) - dd)
            for j, kv_j in enumerate(kcv):           # the control's vertical in place of the control
                if kv_j is not None:
                    Cj = np.conj(G[:, j]) * S[sel, kv_j, kzi].sum(axis=0)
                    rho_num[j] += float((w * np.real(Cj * np.conj(B))).sum())
            for bb in range(n_bands):
                on = band == bb
                nb, db = float((w * N_f)[on].sum()), float((w * D_f)[on].sum())
                num[bb] += nb
                den[bb] += db
                num_jk[~sel, bb] += nb                    # a record of another group: this group's sums whole
                den_jk[~sel, bb] += db
                num_jk[sel, bb] += (Nj[:, on] * w[on]).sum(axis=1)
                den_jk[sel, bb] += (Dj[:, on] * w[on]).sum(axis=1)
    rho = rho_num / den.sum() if den.sum() > 0 else np.zeros(len(kc))
    return _Estimate(num, den, num_jk, den_jk, rho)
