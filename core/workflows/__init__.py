"""What the commands do, built on :mod:`suspid.method` and :mod:`suspid.optimize`.

- :mod:`~suspid.workflows.pipeline`: one identification (``suspid run``);
- :mod:`~suspid.workflows.study`: variants of one config (``suspid study``);
- :mod:`~suspid.workflows.monitor`: one identification per measurement date (``suspid monitor``);
- :mod:`~suspid.workflows.diagnose`: the discrepancy workflow (``suspid diagnose``);
- :mod:`~suspid.workflows.simulate`: simulations and modes (``suspid simulate``, ``suspid modes``);
- :mod:`~suspid.workflows.report`: figures and markdown.
"""
