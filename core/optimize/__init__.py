"""Maximising J: the initial maximin design and EGO on a Kriging metamodel (paper §3.2, eq. 9).

- :mod:`~suspid.optimize.design`: space-filling initial designs in [0, 1]^q;
- :mod:`~suspid.optimize.ego`: the EGO loop, as composable ask/tell pieces;
- :mod:`~suspid.optimize.testfunctions`: analytic functions with known optima, for tests and benchmarks.
"""
