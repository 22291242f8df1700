"""The discrepancy workflow (``suspid diagnose``): locate where model and measurements disagree, name the
missing effect, add it and identify again.

The method is described in ``docs/diagnose.md``. The modules follow its steps:

- the ``diagnose:`` section of a config is :class:`suspid.sections.DiagnoseOptions`;
- :mod:`.cells`: the cells (speed group × channel × band) and averages over them;
- :mod:`.null`: the null distributions of the cell statistics (analytic, bootstrap-calibrated);
- :mod:`.locate`: the discrepancy map and the gap measures;
- :mod:`.fit`: fitting one candidate effect, or the generic bump;
- :mod:`.joint`: the suspension and the named effects fitted together by least squares on D;
- :mod:`.coupling`: the vertical-into-lateral coupling of a tilted sensor, against its twin;
- :mod:`.name`: ranking the candidates and the naming rule;
- :mod:`.reidentify`: the base and augmented models, ``augmented.yaml``;
- :mod:`.report`: ``diagnosis.md`` and its figures;
- :mod:`.workflow`: :func:`run_diagnose`, the whole workflow.
"""

from .cells import CellGrid, make_cells
from .fit import Candidate, Discrepancy, EffectFitter, LocalFit, fit_bump, fit_local
from .joint import JointFit, fit_jointly
from .locate import DiscrepancyMap, locate
from .name import Ranking, check_after_joint_fit, decide, rank_effects, unexplained_regions
from .null import NullCalibration, analytic_null, calibrate_null, shape_statistic
from .reidentify import Stage, make_stage, write_augmented
from .report import figure_map, figure_spectra_gap, write_diagnosis_report
from .workflow import DiagnosisResult, run_diagnose

__all__ = ["CellGrid", "Candidate", "DiagnosisResult", "Discrepancy", "DiscrepancyMap", "EffectFitter", "LocalFit", "check_after_joint_fit", "Ranking", "fit_local", "unexplained_regions",
           "JointFit", "NullCalibration", "Stage", "fit_jointly", "analytic_null", "calibrate_null", "decide",
           "figure_map", "figure_spectra_gap", "fit_bump", "locate", "make_cells", "make_stage", "rank_effects",
           "run_diagnose", "shape_statistic", "write_augmented", "write_diagnosis_report"]
