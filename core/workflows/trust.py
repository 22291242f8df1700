"""Trust per component under model error: yes, no or not assessed, and which checks ran.

Shared by the full checks (:func:`suspid.workflows.analysis.model_error`) and the linearised ones
(:func:`suspid.workflows.linearised.linearised_model_error`), so that both call a component
trustworthy on the same rule.
"""

from __future__ import annotations

from typing import Any

__all__ = ["REQUIRED_CHECKS", "CHECK_LABELS", "LINEARISED_LABELS", "check_labels", "checks_report", "trust_states",
           "trust_word"]

REQUIRED_CHECKS = ("self_check", "adequacy", "groups")
"""The checks that must all have run for a component to be called trustworthy: the reference-date self-check
(model-form error at w0), the adequacy test at w_opt and the data groups (a sensitivity that differs from the
vehicle's). The nuisance sweep is opt-in: it runs where the user declares uncertain model parameters."""

CHECK_LABELS = {"self_check": "reference-date self-check", "adequacy": "adequacy at w_opt",
                "groups": "data groups", "nuisance": "nuisance parameters", "no_change": "no-change test at w0"}

LINEARISED_LABELS = CHECK_LABELS | {
    "self_check": "reference-date self-check on the spectra linearised at w0",
    "groups": "data groups on the spectra linearised at w_opt",
    "nuisance": "model parameters calibrated at the reference date and propagated by linearisation"}
"""The checks' names when ``identifiability.model_error.method`` is ``linearised`` (the default): no
re-identification by simulation, the same checks on the spectra linearised once per date."""


def check_labels(method: str | None) -> dict[str, str]:
    """The checks' names for report.md and the terminal, by the model-error method of a result."""
    return LINEARISED_LABELS if method == "linearised" else CHECK_LABELS


def trust_word(trustworthy: bool | None) -> str:
    """A component's trust under model error in words: True "yes", False "no", None (or absent) "not assessed"."""
    return "yes" if trustworthy is True else "no" if trustworthy is False else "not assessed"


def checks_report(checks: dict[str, str]) -> dict[str, dict[str, Any]]:
    """``{check: {"ran": bool, "status": str, "required": bool}}`` for result.json (every check, in order)."""
    out = {}
    for c in CHECK_LABELS:
        status = checks.get(c, "not run")
        out[c] = {"ran": status == "done", "status": status, "required": c in REQUIRED_CHECKS}
    return out


def trust_states(names: list[str], flags: list[list[str]], checks: dict[str, str]) -> dict[str, Any]:
    """Trust per component: yes (True), no (False) or not assessed (None), with the reasons.

    A component is **not trustworthy** when a check that ran flags it (``flags[k]`` not empty): one check
    is enough to say no. It is **trustworthy** only when no check flags it and every check of
    :data:`REQUIRED_CHECKS` ran (``checks[c] == "done"``); otherwise it is **not assessed**: no check that
    ran found a fault, but the checks that would judge it did not all run (their statuses are the reasons).

    :param flags: ``(q,)`` lists of the checks' reasons against each component.
    :param checks: check name -> ``"done"`` or why it did not run.
    :returns: ``{"trustworthy": name -> bool | None, "reasons": name -> [str] (the no's),
        "not_assessed": name -> [str]}``.
    """
    missing = [f"{CHECK_LABELS[c]} {checks.get(c, 'not run')}" for c in REQUIRED_CHECKS if checks.get(c) != "done"]
    trustworthy: dict[str, bool | None] = {}
    for n, f in zip(names, flags):
        trustworthy[n] = False if f else (None if missing else True)
    return {"trustworthy": trustworthy, "reasons": {n: f for n, f in zip(names, flags) if f},
            "not_assessed": {n: list(missing) for n in names if trustworthy[n] is None}}
