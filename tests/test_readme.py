"""The README's two commands and CI stay in step; the README stays short, with a glossary true to the code."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _commands() -> list[str]:
    lines = (ROOT / "README.md").read_text().splitlines()
    return [ln.strip() for ln in lines[:15] if ln.startswith("    ") and "python3 -m venv" in ln]


def test_readme_starts_with_two_commands():
    main_job, tests = _commands()[:2]
    assert "suspid run configs/quickstart.yaml" in main_job
    assert (ROOT / "configs" / "quickstart.yaml").exists()
    assert "pytest" in tests


def test_ci_runs_exactly_the_readme_test_command():
    tests = _commands()[1]
    ci = (ROOT / ".ci" / "run").read_text().splitlines()
    assert tests in [ln.strip() for ln in ci]


GLOSSARY_TERMS = ("w0", "w_ref", "w_opt", "B (noise model)", "J (objective)", "identifiable", "trustworthy",
                  "borderline", "reference date", "element group")


def _glossary() -> dict[str, str]:
    """The README's glossary: ``term -> definition`` from its ``- **term**: definition`` items."""
    text = (ROOT / "README.md").read_text()
    section = text.split("## Glossary", 1)[1].split("\n## ", 1)[0]
    items = re.findall(r"^- \*\*(.+?)\*\*:? (.*?)(?=^- \*\*|\Z)", section, flags=re.M | re.S)
    return {term: " ".join(body.split()) for term, body in items}


def test_readme_is_short_and_defines_its_terms():
    """An engineer reads it in ten minutes: at most 250 lines, with a glossary of the words a run prints."""
    assert len((ROOT / "README.md").read_text().splitlines()) <= 250
    glossary = _glossary()
    missing = [t for t in GLOSSARY_TERMS if t not in glossary]
    assert not missing, f"README glossary lacks {missing}"


def test_the_glossary_numbers_are_the_code_defaults():
    """The thresholds the glossary quotes are the defaults a config without `identifiability:` gets."""
    import suspid

    cfg = suspid.load_config({"simulator": {"plugin": "exudyn-train", "options": {"solver": "frequency"}}})
    ident = cfg.identifiability
    g = _glossary()
    assert f"total Sobol index on the metamodel below {ident.min_total_index:g}" in g["identifiable"]
    assert ident.max_width == 0.5 and "more than half the admissible interval" in g["identifiable"]
    assert f"within {ident.bound_margin:.0%}".replace("%", " %") in g["identifiable"]
    assert f"± {ident.n_sigmas:g} standard deviations" in g["interval"]
    assert f"± {ident.model_error.max_half_width:.0%}".replace("%", " %") in g["trustworthy"]
    assert ident.model_error.run == "measured"   # why the quickstart's trust is "not assessed"
