"""Standard indicators straight from the recordings: EN 14363 instability and EN 12299 comfort."""

from suspid.indicators.standard import (COMFORT, INSTABILITY, IndicatorValue, compute_indicators, instability,
                                        instability_limit, sliding_rms)
from suspid.indicators.weighting import WB, WD, Weighting, weight

__all__ = ["COMFORT", "INSTABILITY", "IndicatorValue", "compute_indicators", "instability", "instability_limit",
           "sliding_rms", "WB", "WD", "Weighting", "weight"]
