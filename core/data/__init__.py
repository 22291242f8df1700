"""Where the measurements come from: track segments and acceleration files, and the numerical experiment.

- :mod:`~suspid.data.track`: synthetic track from published spectra;
- :mod:`~suspid.data.files`: the file formats of measured track and accelerations (CSV, HDF5)
  with their checks;
- :mod:`~suspid.data.experiment`: the numerical experiment of the paper (§3.3) and its reference date.
"""
