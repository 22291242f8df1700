"""Cells of the discrepancy map: speed group × channel × band, and the averages over them.

Overview: ``docs/diagnose.md``, "How it works", step 2.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np


@dataclass
class CellGrid:
    """Cells: speed group × channel × band, flattened in that order.

    :ivar speeds: ``(G,)`` m/s of the speed groups; :ivar group_of: ``(v,)`` group of each segment.
    :ivar band_edges: ``(B, 2)`` Hz; :ivar average: ``(F, B)`` band-average matrix over the grid Ω.
    """

    channels: list[str]
    freqs: np.ndarray
    speeds: np.ndarray
    group_of: np.ndarray
    band_edges: np.ndarray
    average: np.ndarray

    @property
    def n_cells(self) -> int:
        return len(self.speeds) * len(self.channels) * self.band_edges.shape[0]

    def index(self, c: int) -> tuple[int, int, int]:
        """(group, channel, band) of cell ``c``."""
        K, B = len(self.channels), self.band_edges.shape[0]
        return c // (K * B), (c // B) % K, c % B

    def group_means(self, r: np.ndarray) -> np.ndarray:
        """``(G, K, F)``: mean of ``r`` ``(v, K, F)`` over each group's segments."""
        return np.array([r[self.group_of == g].mean(axis=0) for g in range(len(self.speeds))])

    def cell_means(self, r: np.ndarray) -> np.ndarray:
        """``(n_cells,)``: mean of ``r`` ``(v, K, F)`` over each group's segments and each band."""
        return (self.group_means(r) @ self.average).ravel()

    def cell_to_bins(self, values: np.ndarray) -> np.ndarray:
        """``(G, K, F)``: each bin takes the value of its cell (``values`` ``(n_cells,)``)."""
        G, K, B = len(self.speeds), len(self.channels), self.band_edges.shape[0]
        band_of_bin = np.argmax(self.average > 0, axis=1)
        return values.reshape(G, K, B)[:, :, band_of_bin]


def make_cells(channels: Sequence[str], freqs: np.ndarray, segment_speeds: Sequence[float],
               bands_per_octave: float = 3.0, min_bins: int = 3) -> CellGrid:
    """Bands of constant relative width over the grid ``freqs`` (Hz), each with at least ``min_bins`` bins."""
    f = np.asarray(freqs, dtype=float)
    half = np.diff(f) / 2
    lower = np.concatenate([[f[0] - half[0]], f[:-1] + half])
    upper = np.concatenate([f[:-1] + half, [f[-1] + half[-1]]])
    lower = np.maximum(lower, 0.0)
    ratio = 2.0 ** (1.0 / bands_per_octave)
    band_of = np.floor(np.log(f / f[0]) / np.log(ratio) + 1e-9).astype(int)
    groups: list[list[int]] = []
    for b in np.unique(band_of):
        idx = list(np.nonzero(band_of == b)[0])
        if groups and len(groups[-1]) < min_bins:
            groups[-1] += idx
        else:
            groups.append(idx)
    if len(groups) > 1 and len(groups[-1]) < min_bins:
        groups[-2] += groups.pop()
    average = np.zeros((f.size, len(groups)))
    edges = np.zeros((len(groups), 2))
    for b, idx in enumerate(groups):
        average[idx, b] = 1.0 / len(idx)
        edges[b] = lower[idx[0]], upper[idx[-1]]
    speeds_all = np.round(np.asarray(segment_speeds, dtype=float), 3)
    speeds = np.unique(speeds_all)
    group_of = np.searchsorted(speeds, speeds_all)
    return CellGrid(list(channels), f, speeds, group_of, edges, average)
