"""An independent vehicle model ("real train") that writes measured-data files for suspid.

Written apart from suspid's own train model (numpy/scipy only) so that suspid
can be validated on data its own code did not make. See :mod:`.train`.
"""

from .train import (CHANNELS, Instrument, build_model, eigenvalues, generate_date, generate_two_dates,
                    parameters, simulate_segments)

__all__ = ["CHANNELS", "Instrument", "build_model", "eigenvalues", "generate_date", "generate_two_dates",
           "parameters", "simulate_segments"]
