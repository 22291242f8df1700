"""Maximising J: the initial maximin design and EGO on a Kriging metamodel (paper §3.2, eq. 9).

- :mod:`~suspid.optimize.design`: space-filling initial designs in [0, 1]^q;
- :mod:`~suspid.optimize.ego`: the EGO loop as an ask/tell object (:class:`~suspid.optimize.ego.EGO`)
  and the loops over it (:func:`~suspid.optimize.ego.run_ego`, :func:`~suspid.optimize.ego.maximize`);
- :mod:`~suspid.optimize.driver`: the one loop (ask trials, evaluate them, tell their values by id,
  record them), serial, batch or asynchronous, with the evaluation plugged in;
- :mod:`~suspid.optimize.trials`: trials (points with an id), the one ask/tell state machine every
  optimiser runs on (:class:`~suspid.optimize.trials.TrialLoop`) and the stopping conditions, which combine
  with ``|``;
- :mod:`~suspid.optimize.loop`: the EGO loop's pieces: loop state, records, EI proposer, and the state of
  any loop at its end that the analysis reads (:class:`~suspid.optimize.loop.LoopOutcome`);
- :mod:`~suspid.optimize.normalize`: the unit cube as a surrogate's input transform
  (:class:`~suspid.optimize.normalize.Normalized`);
- :mod:`~suspid.optimize.acquisition`: the expected improvement and its maximisation;
- :mod:`~suspid.optimize.refine`: the local trust-region refinement (proposer and radius rule);
- :mod:`~suspid.optimize.options`: the ``ego:`` options and the surrogate they name;
- :mod:`~suspid.optimize.testfunctions`: analytic functions with known optima, for tests and benchmarks.
"""
