"""The README's two commands and CI stay in step."""

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
