"""Figures and the markdown report of an identification run (paper Figures 1-2).

Inputs are plain arrays so that the report can be rebuilt from the files of a
run directory. Figures are PNG files written with matplotlib's Agg backend.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np


def pyplot():
    """matplotlib.pyplot on the Agg backend (files only, no display needed)."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def figure_spectra(path: Path, freqs: np.ndarray, y_mes: np.ndarray, y_sim: np.ndarray, y_mod: np.ndarray,
                   channel: int, channel_name: str, quantiles: tuple[float, float] = (0.05, 0.95)) -> Path:
    """Figure 1 analogue: mean and quantiles of Y_mes against Y_sim(w0) (top) and Y_mod(w0) (bottom).

    :param freqs: ``(n_freqs,)`` Hz.
    :param y_mes, y_sim, y_mod: ``(n_samples, n_channels, n_freqs)`` dB.
    """
    plt = pyplot()
    fig, axes = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    for ax, other, label, color in ((axes[0], y_sim, "Y_sim(w0)", "tab:red"),
                                    (axes[1], y_mod, "Y_mod(w0)", "tab:blue")):
        for y, lab, col in ((y_mes, "Y_mes", "black"), (other, label, color)):
            q_lo, q_hi = np.quantile(y[:, channel], quantiles, axis=0)
            ax.fill_between(freqs, q_lo, q_hi, color=col, alpha=0.18, lw=0)
            ax.plot(freqs, y[:, channel].mean(axis=0), color=col, lw=1.4,
                    label=f"{lab} mean, {int(quantiles[0] * 100)}-{int(quantiles[1] * 100)} % band")
        ax.set_ylabel("Y (dB)")
        ax.legend(loc="best", fontsize=8)
        ax.grid(alpha=0.3)
    axes[0].set_title(f"Channel {channel_name}: measured against simulated (top) and modelled (bottom)")
    axes[1].set_xlabel("frequency (Hz)")
    if freqs[-1] / max(freqs[0], 1e-9) > 20:
        axes[1].set_xscale("log")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def figure_parameters(path: Path, names: Sequence[str], variants: Mapping[str, np.ndarray],
                      w_ref: np.ndarray | None = None,
                      intervals: Mapping[str, np.ndarray] | None = None) -> Path:
    """Figure 2 analogue: w_ref and each variant's w_opt on the normalised scale [0, 1].

    :param variants: label -> ``(q,)`` normalised w_opt.
    :param w_ref: ``(q,)`` normalised reference, when known.
    :param intervals: label -> ``(q, 2)`` normalised intervals, drawn as bars.
    """
    plt = pyplot()
    q = len(names)
    fig, ax = plt.subplots(figsize=(max(6, 1.1 * q + 2), 4))
    x = np.arange(q)
    markers = ["^", "o", "s", "D", "v", "P", "X", "*"]
    offsets = np.linspace(-0.2, 0.2, max(len(variants), 1))
    if w_ref is not None:
        ax.scatter(x, w_ref, marker="s", s=70, color="black", label="w_ref", zorder=3)
    for (label, w), off, mk in zip(variants.items(), offsets, markers * 4):
        ax.scatter(x + off, w, marker=mk, s=40, label=f"w_opt ({label})", zorder=4)
        if intervals and label in intervals:
            iv = np.asarray(intervals[label])
            ax.vlines(x + off, iv[:, 0], iv[:, 1], alpha=0.5)
    ax.set_xticks(x, names, rotation=30, ha="right")
    ax.set_ylim(-0.05, 1.05)
    ax.set_ylabel("normalised value")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def figure_convergence(path: Path, J: np.ndarray, n_initial: int, ei: Sequence[float], n_refine: int = 0) -> Path:
    """Convergence: J of every evaluation, running J_max, and max EI per EGO iteration (log scale).

    :param J: ``(n,)`` J of every evaluation in order; :param ei: EI per iteration, the
        last ``n_refine`` of them at the points of the local refinement (``ego.refine``).
    """
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    n = np.arange(1, len(J) + 1)
    axes[0].plot(n, J, ".", color="0.6", label="J of each evaluation")
    axes[0].plot(n, np.maximum.accumulate(J), color="tab:blue", label="J_max")
    axes[0].axvline(n_initial + 0.5, color="k", ls=":", lw=1, label="end of initial design")
    if n_refine:
        axes[0].axvline(len(J) - n_refine + 0.5, color="tab:orange", ls="--", lw=1,
                        label="paper's stop, refinement after")
    axes[0].set_xlabel("evaluation")
    axes[0].set_ylabel("J")
    axes[0].legend(fontsize=8)
    ei = np.asarray(ei, dtype=float)
    n_loop = ei.size - n_refine
    it = np.arange(1, ei.size + 1)
    if n_loop > 0:
        axes[1].semilogy(it[:n_loop], np.maximum(ei[:n_loop], 1e-300), "o-", ms=3, label="max EI, paper's loop")
    if n_refine:
        axes[1].semilogy(it[n_loop:], np.maximum(ei[n_loop:], 1e-300), "s-", ms=3, color="tab:orange",
                         label="EI at the refinement points")
        axes[1].legend(fontsize=8)
    axes[1].set_xlabel("iteration")
    axes[1].set_ylabel("EI")
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """A GitHub-flavoured markdown table."""
    def fmt(v: Any) -> str:
        if isinstance(v, float):
            return f"{v:.4g}"
        return str(v)

    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(fmt(v) for v in row) + " |" for row in rows]
    return "\n".join(lines)
