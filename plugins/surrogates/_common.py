"""What the surrogate plugins share: checks of the training data and the scaling of inputs and outputs."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from suspid.errors import ConfigError


def check_data(name: str, X: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``X (n_points, q)`` and ``y (n_points,)`` as float arrays (a ``(n, 1)`` y is flattened).

    :param name: the plugin's name, for the messages.
    :raises ValueError: wrong shapes, fewer than 2 points, or non-finite values.
    """
    X = np.asarray(X, dtype=float)
    y = np.asarray(y, dtype=float)
    if X.ndim != 2:
        raise ValueError(f"{name}: X must have shape (n_points, q), got {X.shape}")
    y = y.reshape(-1) if y.ndim == 2 and y.shape[1] == 1 else y
    if y.ndim != 1 or y.shape[0] != X.shape[0]:
        raise ValueError(f"{name}: y must have shape ({X.shape[0]},), got {y.shape}")
    if X.shape[0] < 2:
        raise ValueError(f"{name}: at least 2 points are needed to fit")
    if not (np.all(np.isfinite(X)) and np.all(np.isfinite(y))):
        raise ValueError(f"{name}: X and y must be finite")
    return X, y


def scaling(name: str, X: np.ndarray, y: np.ndarray, bounds: Sequence[tuple[float, float]] | None
            ) -> tuple[np.ndarray, np.ndarray, float, float]:
    """``(x_lower (q,), x_range (q,), y_mean, y_std)``: inputs to ``[0, 1]^q`` by ``bounds``
    (else by the data's min and max per column), outputs standardised (a constant y gets std 1).

    :raises ConfigError: ``bounds`` has not one row per input.
    """
    q = X.shape[1]
    if bounds is not None:
        if len(bounds) != q:
            raise ConfigError(f"{name}: bounds has {len(bounds)} rows for q={q} inputs",
                              key="surrogate.options.bounds")
        b = np.asarray(bounds, dtype=float)
        x_lower, x_range = b[:, 0], b[:, 1] - b[:, 0]
    else:
        lo, hi = X.min(axis=0), X.max(axis=0)
        x_lower, x_range = lo, np.where(hi - lo > 0, hi - lo, 1.0)
    std = float(y.std())
    return x_lower, x_range, float(y.mean()), std if std > 0 else 1.0
