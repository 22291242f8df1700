"""benchmarks/RESULTS.md holds current figures only, and every benchmark has its place there.

History lives in git (``git log -p benchmarks/RESULTS.md``); the page stays short enough to read, every
``run_all.py`` benchmark finds its block (so a re-run replaces it rather than appending at the end), and every
script in ``benchmarks/`` is named where its figure is.
"""

from __future__ import annotations

from pathlib import Path

from test_run_all import _run_all   # loads benchmarks/run_all.py as a module

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "RESULTS.md"


def test_results_is_current_figures_only():
    assert len(RESULTS.read_text().splitlines()) <= 700


def test_every_run_all_benchmark_has_exactly_one_block():
    ra = _run_all()
    text = RESULTS.read_text()
    bad = [b.name for b in ra.BENCHMARKS
           if any(text.count(marker) != 1 for marker in ra.markers(b.name))
           or text.index(ra.markers(b.name)[0]) > text.index(ra.markers(b.name)[1])]
    assert not bad, f"benchmarks without one begin/end marker pair in RESULTS.md: {bad}"


def test_every_benchmark_script_is_named():
    text = RESULTS.read_text()
    scripts = sorted(p.name for p in (ROOT / "benchmarks").glob("*.py")) + ["loop_identity_before.json"]
    missing = [s for s in scripts if s not in text]
    assert not missing, f"benchmarks/ files RESULTS.md does not name: {missing}"


def test_an_empty_block_is_filled_in_place():
    """A block with no printed table yet is its two markers on one line; run_all replaces it where it stands."""
    ra = _run_all()
    text = RESULTS.read_text()
    begin, end = ra.markers("coverage")
    assert begin + end in text
    filled = ra.replace_block(text, "coverage", f"{begin}\nFILLED-BY-RUN-ALL\n{end}")
    assert filled.count("FILLED-BY-RUN-ALL") == 1 and len(filled) - len(text) == len("\nFILLED-BY-RUN-ALL\n")
    assert filled.index("FILLED-BY-RUN-ALL") < filled.index("## Sensor-noise floor")
