"""diagnosis.md's first lines in plain words (:func:`suspid.workflows.diagnose.report.plain_summary`): what was
found, how sure, and what changed in the identification, without the statistics (q values, scores), on the
three outcomes: an effect named at an identified suspension, a discrepancy nothing explains, and none."""

from __future__ import annotations

from suspid.workflows.diagnose.report import plain_summary

UNITS = {"c_yaw": "N s/m", "k_sec_z": "N/m"}
STATS = {"alpha": 0.05}


def _named_at_identified() -> dict:
    gap = {"n_flagged": 12, "n_cells": 150, "share_flagged": 0.08, "w": {"c_yaw": 2.2e5, "k_sec_z": 3.3e5},
           "identified": {"w": {"c_yaw": 2.0e5, "k_sec_z": 3.5e5}}}
    params = {"frequency_hz": 9.5, "damping": 0.02, "modal_mass_kg": None}
    return {"gap_before": gap, "gap_after": {"n_flagged": 1, "n_cells": 150, "share_flagged": 1 / 150},
            "statistics": STATS, "named": "carbody-bending", "named_parameters": params, "base_model": "identified",
            "steps": [{"named": "carbody-bending", "named_parameters": params}],
            "ranking": [{"effect": "carbody-bending", "status": "fitted", "evidence": {"explained_own": 0.91},
                         "score": 2.0e4},
                        {"effect": "wheel-polygon", "status": "fitted", "score": 12.0}],
            "suspension": {"source": "re-identification", "w": {"c_yaw": 3.0e5, "k_sec_z": 3.51e5}}}


def test_a_named_effect_says_what_how_sure_and_how_the_suspension_moved():
    text = plain_summary(_named_at_identified(), UNITS)
    found, sure, ident, tail = text.split("\n\n")
    assert found == ("**Found:** the measurements show what the model lacks: a carbody first vertical bending mode "
                     "(`carbody-bending`; natural frequency of the first vertical bending mode 9.5 Hz).")
    assert sure == ("**How sure:** it explains 91 % of the disagreement where it acts, clearly ahead of the next "
                    "explanation (`wheel-polygon`) and of a generic bump; with it in the model the part of the "
                    "spectra that disagrees falls from 8.0 % of the spectra (12 of 150 cells) to 0.7 %.")
    assert ident == ("**Identification:** the suspension reported with the effect added (the re-identification) "
                     "against the identification before: c_yaw 200 kN s/m → 300 kN s/m (+50 %); k_sec_z within 0.5 %.")
    assert "None" not in text and "score" not in text and "q (BY)" not in text


def test_an_unexplained_discrepancy_and_none_at_all():
    d = _named_at_identified() | {"named": None, "named_parameters": {}, "steps": [], "suspension": None,
                                  "flagged": [{"channel": "bogie_front_lateral", "f_low_hz": 6.47, "f_high_hz": 8.06}]}
    found, sure, ident, _ = plain_summary(d, UNITS).split("\n\n")
    assert found == ("**Found:** the model and the measurements disagree in 8.0 % of the spectra (12 of 150 cells), "
                     "most on bogie_front_lateral at 6.47-8.06 Hz, and no effect of the catalogue explains it "
                     "(section 3 lists what is left unexplained).")
    assert sure.startswith("**How sure:** the disagreement lies beyond the noise model at a false discovery rate of "
                           "5 %") and ident == "**Identification:** unchanged (nothing was added to the model)."
    d["gap_before"] = {"n_flagged": 0, "n_cells": 150, "share_flagged": 0.0, "w": {}}
    d["base_model"] = "nominal"
    found, ident, _ = plain_summary(d, UNITS).split("\n\n")
    assert found.startswith("**Found:** nothing: the model reproduces the measurements within the noise model")
    assert ident.startswith("**Identification:** not re-run: the diagnosis compared the model at its nominal")
