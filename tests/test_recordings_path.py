"""The recordings path of docs/ingest.md ends in a verdict.

The commands of its "Try it" section are run as they are written (a fresh clone's ``.venv`` is this
interpreter; the ``pip install`` line is checked, not run): two dates of recordings, the measurement date's yaw
dampers worn (``--param c_yaw=150e3``), ingested together, then identified. The report's verdict names the worn
element and every model-error check runs. The generator fails in one line, before writing anything, when a
format's library is missing or a ``--param`` is not the model's.
"""

from __future__ import annotations

import importlib.util
import json
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import ROOT

GENERATOR = ROOT / "examples" / "recordings" / "make_recordings.py"


def try_it() -> list[str]:
    """The commands of docs/ingest.md's "Try it" section, in order (comments kept)."""
    section = (ROOT / "docs" / "ingest.md").read_text().split("\n## Try it\n", 1)[1].split("\n## ", 1)[0]
    return [line.strip() for line in section.splitlines() if line.startswith("    .venv/bin/")]


def _argv(command: str, rec: Path) -> list[str] | None:
    """A documented command as this interpreter runs it (None: the install line, checked instead)."""
    args = shlex.split(command.replace("/tmp/rec", str(rec)), comments=True)
    if args[0] == ".venv/bin/pip":
        assert args[1:] == ["install", "-q", "-e", ".[ingest]"], args
        return None
    return {".venv/bin/python": [sys.executable], ".venv/bin/suspid": [sys.executable, "-m", "suspid"]}[args[0]] \
        + args[1:]


def test_try_it_installs_the_ingest_extra_and_degrades_the_measurement_date():
    commands = try_it()
    assert commands[0] == ".venv/bin/pip install -q -e '.[ingest]'"
    assert any("--param c_yaw=150e3" in c and "--reference" in c for c in commands)
    assert commands[-1].startswith(".venv/bin/suspid run ")


@pytest.mark.slow
@pytest.mark.long    # two dates of 200 s recordings simulated with the time solver, then the run: minutes
def test_try_it_ends_in_a_report_whose_verdict_names_the_worn_yaw_dampers(tmp_path):
    assert importlib.util.find_spec("asammdf") is not None      # what the install line gives
    rec = tmp_path / "rec"
    outputs = []
    for command in try_it():
        argv = _argv(command, rec)
        if argv is None:
            continue
        p = subprocess.run(argv, cwd=ROOT, capture_output=True, text=True, timeout=3000)
        assert p.returncode == 0, (command, p.stderr)
        outputs.append((command, p.stdout, p.stderr))
    ingest_err = next(err for c, _, err in outputs if " ingest " in c)
    assert "self-check needs" not in ingest_err and "no limits" not in ingest_err, ingest_err
    run_dir = rec / "2026-11" / "ingested" / "runs" / "recordings-two-dates"
    result = json.loads((run_dir / "result.json").read_text())
    rows = {r["name"]: r for r in result["verdict"]["rows"]}
    assert rows["c_yaw"]["verdict"] == "alarm" and -55 < rows["c_yaw"]["change_percent"] < -40, rows["c_yaw"]
    assert {n: r["verdict"] for n, r in rows.items() if n != "c_yaw"} == dict.fromkeys(
        ("k_sec_z", "c_sec_z", "k_prim_z", "c_sec_y"), "ok")          # nothing else worn
    report = (run_dir / "report.md").read_text()
    verdict = report.split("## Maintenance verdict", 1)[1].split("\n## ", 1)[0]
    line = next(ln for ln in verdict.splitlines() if "(`c_yaw`)" in ln)
    assert line.startswith("- yaw damper rate per damper (`c_yaw`): -") and rows["c_yaw"]["verdict"] in line
    # every model-error check ran (9 reference segments: the self-check needs 8), or says in one line why not
    checks = result["model_error"]["checks"]
    assert checks["self_check"]["ran"] and checks["adequacy"]["ran"] and checks["groups"]["ran"], checks
    assert all(v["ran"] or "\n" not in v["status"] for v in checks.values())
    run_out = outputs[-1][1]
    assert "c_yaw" in run_out and "Model-error checks not run" not in run_out


def _generator(tmp_path: Path, *args: str, blocked: str | None = None) -> subprocess.CompletedProcess:
    """The generator as a script, with module ``blocked`` made unimportable (an install without the extra)."""
    block = f"sys.modules[{blocked!r}] = None; " if blocked else ""
    code = (f"import runpy, sys; {block}sys.argv = ['make_recordings.py', *{list(args)!r}]; "
            f"runpy.run_path({str(GENERATOR)!r}, run_name='__main__')")
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, timeout=300)


def test_the_generator_without_the_ingest_extra_fails_in_one_line_and_writes_nothing(tmp_path):
    out = tmp_path / "rec"
    p = _generator(tmp_path, str(out), "--formats", "mf4", "csv", blocked="asammdf")
    assert p.returncode == 2 and p.stderr.strip().splitlines() == [
        "make_recordings.py: error: writing 'asammdf' (for mf4) needs the ingest extra: pip install 'suspid[ingest]' "
        "(or choose other --formats: mat, mat73, csv need nothing more)"], p.stderr
    assert list(tmp_path.iterdir()) == []                 # no folder, no half-written file


def test_the_generator_refuses_a_parameter_the_model_does_not_have(tmp_path):
    p = _generator(tmp_path, str(tmp_path / "rec"), "--formats", "csv", "--param", "c_yawn=1")
    assert p.returncode == 2 and len(p.stderr.strip().splitlines()) == 1, p.stderr
    assert p.stderr.startswith("make_recordings.py: error: --param c_yawn: not a parameter of exudyn-train; known: ")
    p = _generator(tmp_path, str(tmp_path / "rec"), "--formats", "csv", "--param", "c_yaw=soft")
    assert (p.returncode, p.stderr.strip()) == (
        2, "make_recordings.py: error: --param c_yaw=soft: expected NAME=VALUE with a number (SI units)")
    assert list(tmp_path.iterdir()) == []
