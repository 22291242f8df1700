"""The unit cube as a surrogate's input transform (as BoTorch's ``Normalize``).

A :class:`~suspid.interfaces.Surrogate` plugin models J on the unit cube ``[0, 1]^q``: its
length-scales, the EI search and the Sobol indices of the identifiability verdict are all
read there. :class:`Normalized` puts the map from the parameter box to the cube inside the
surrogate, so that a caller holding SI points (an optimiser's result, the trials of a run)
fits and predicts in SI and never converts points itself::

    model = Normalized(make_surrogate("gpy-kriging"), bounds).fit(X_si, y)
    mean, var = model.predict(X_si)
    model.cube        # the plugin's model on [0, 1]^q (for the analysis, which works in the cube)

The map is :func:`suspid.optimize.design.to_unit`, ``u = (x - lo) / (hi - lo)``: the plugin
is fitted on exactly the floats a caller's own ``to_unit`` would have given it.

Public API: :class:`Normalized`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from suspid.interfaces import Surrogate
from suspid.optimize.design import check_bounds, to_unit

__all__ = ["Normalized"]


class Normalized:
    """A surrogate on the SI box ``bounds (q, 2)``: ``cube`` (a :class:`~suspid.interfaces.Surrogate` on
    ``[0, 1]^q``) behind the unit-cube input transform.

    :param cube: the surrogate plugin instance, fitted or not.
    :param bounds: ``(q, 2)`` lower and upper bounds, SI units.
    """

    def __init__(self, cube: Surrogate, bounds: Any) -> None:
        self.cube = cube
        self.bounds = check_bounds(bounds)

    def transform(self, X: np.ndarray) -> np.ndarray:
        """SI points ``X (n, q)`` (or ``(q,)``) in ``[0, 1]^q``."""
        return to_unit(X, self.bounds)

    def fit(self, X: np.ndarray, y: np.ndarray) -> "Normalized":
        """Fit to SI points ``X (n_points, q)`` and their J ``y (n_points,)``; returns ``self``."""
        self.cube.fit(self.transform(X), y)
        return self

    def predict(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mean and variance of J at SI points ``X (n_points, q)``, each ``(n_points,)``."""
        return self.cube.predict(self.transform(np.atleast_2d(X)))

    @property
    def hyperparameters_(self) -> dict[str, Any] | None:
        """The plugin's fitted hyperparameters (length-scales in units of the cube)."""
        return self.cube.hyperparameters_
