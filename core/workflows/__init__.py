"""What the commands do, built on :mod:`suspid.method` and :mod:`suspid.optimize`.

- :mod:`~suspid.workflows.identify`: one identification (``suspid run``), built from
  :mod:`~suspid.workflows.problem` (data, noise model, objective),
  :mod:`~suspid.workflows.evaluation` (J through the ledger and an executor),
  :mod:`~suspid.workflows.analysis` (errors, identifiability, intervals) and
  :mod:`~suspid.workflows.report` (figures, ``report.md``);
- :mod:`~suspid.workflows.study`: variants of one config (``suspid study``);
- :mod:`~suspid.workflows.monitor`: one identification per measurement date (``suspid monitor``);
- :mod:`~suspid.workflows.diagnose`: the discrepancy workflow (``suspid diagnose``);
- :mod:`~suspid.workflows.simulate`: simulations and modes (``suspid simulate``, ``suspid modes``);
- :mod:`~suspid.workflows.report`: figures and markdown;
- :mod:`~suspid.workflows.jacobian`: y_sim with its Jacobian (analytic where the simulator offers it,
  finite differences through the executor otherwise), which :mod:`~suspid.workflows.gradient` gives a
  gradient-based optimiser.
"""
