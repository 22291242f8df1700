"""The paper's chain, from accelerations to J(w) and what J says about w.

- :mod:`~suspid.method.spectra`: Y(ω) = 10 log10 |Â(ω)| per channel (eq. 1-2);
- :mod:`~suspid.method.noise`: the noise model B(ω) identified at the reference date (eq. 3);
- :mod:`~suspid.method.kde`: kernel density estimates per (channel, ω) shared by the objectives (eq. 6-8);
- :mod:`~suspid.method.objective`: J(w) = Σ α_k Ψ_k(w) with common random numbers (eq. 5);
- :mod:`~suspid.method.sensitivity` and :mod:`~suspid.method.identifiability`: which components
  of w_opt the data pin down, and their intervals.
"""
