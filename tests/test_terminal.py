"""The terminal after ``suspid run``: the quickstart's verdict table fits 100 columns with every verdict whole
(verdict first), a narrower terminal gets a few lines per parameter, the checks that did not run are one line
saying what to do, and a re-run says what it reuses from the ledger."""

from __future__ import annotations

import io
from pathlib import Path

import pytest
from rich.console import Console

import suspid
from suspid import cli
from suspid.workflows.verdict import rows_of

from conftest import ROOT

pytestmark = pytest.mark.slow   # the quickstart twice: 26 s of computing, up to a minute on a shared machine


@pytest.fixture(scope="module")
def quickstart(tmp_path_factory):
    """The quickstart, run as it is (about 15 s), then run again: its result and the second run's log."""
    out = tmp_path_factory.mktemp("quickstart")
    overrides = {"output.dir": str(out / "run")}
    first = suspid.identify(ROOT / "configs" / "quickstart.yaml", overrides)
    log: list[str] = []
    again = suspid.identify(ROOT / "configs" / "quickstart.yaml", overrides, log=log.append)
    return first.to_dict(), again.to_dict(), log


def _render(result: dict, width: int, monkeypatch) -> list[str]:
    """What ``suspid run`` prints after the run on a terminal ``width`` columns wide."""
    buf = io.StringIO()
    monkeypatch.setattr(cli, "console", Console(width=width, file=buf, force_terminal=True, color_system=None,
                                                soft_wrap=True))
    cli._print_result(result, Path("/runs/quickstart"))
    return buf.getvalue().splitlines()


def test_the_quickstart_table_fits_100_columns_with_every_verdict_whole(quickstart, monkeypatch):
    result = quickstart[0]
    lines = _render(result, 100, monkeypatch)
    rows = rows_of(result)
    header = next(i for i, line in enumerate(lines) if line.startswith("verdict "))
    table = lines[header:header + 2 + len(rows)]
    assert all(len(line) <= 100 for line in table), max(map(len, table))
    assert "…" not in "\n".join(lines)
    assert table[0].split()[:4] == ["verdict", "parameter", "identified", "change"]
    for row, line in zip(rows, table[2:]):
        verdict = row.verdict + (" (borderline)" if row.borderline else "")
        assert line.startswith(verdict + " ") and f" {row.name} " in line, line
        lo, hi = row.interval_percent
        assert f"{row.change_percent:+.1f} % [{lo:+.1f}, {hi:+.1f}]" in line and row.trust in line, line
    assert {r.verdict for r in rows} >= {"warning", "ok"} and any(r.borderline for r in rows)


def test_a_narrow_terminal_gets_a_few_lines_per_parameter(quickstart, monkeypatch):
    lines = _render(quickstart[0], 80, monkeypatch)
    assert not any(line.startswith("verdict ") for line in lines) and "…" not in "\n".join(lines)
    for row in rows_of(quickstart[0]):
        at = lines.index(f"{row.name}: {row.verdict}" + (" (borderline)" if row.borderline else ""))
        assert lines[at + 1].startswith("  identified ") and lines[at + 2].startswith(f"  trust {row.trust}")


def test_the_checks_that_did_not_run_are_one_line_saying_what_to_do(quickstart, monkeypatch):
    lines = _render(quickstart[0], 100, monkeypatch)
    checks = [line for line in lines if "check" in line.lower() and "(" in line and "trust" in line]
    assert checks == ["Model-error checks not run (identifiability.model_error.run: measured, data.source: "
                      "experiment; 'always' runs them): trust is not assessed (report.md lists the checks)"]
    assert not any(line.startswith("- ") for line in lines)


def test_a_rerun_says_what_it_reuses(quickstart, monkeypatch):
    first, again, log = quickstart
    reuse = [line for line in log if line.startswith("reusing ")]
    assert len(reuse) == 1 and reuse[0].startswith("reusing ") and "finished simulations from the ledger" in reuse[0]
    assert int(reuse[0].split()[1]) >= first["n_simulator_calls"]
    assert again["n_simulator_calls_this_session"] == 0 and again["w_opt"] == first["w_opt"]
    title = _render(again, 100, monkeypatch)[0]
    assert f"{again['n_simulator_calls']} simulations, none new: all reused from the ledger" in title
    assert "none new" not in _render(first, 100, monkeypatch)[0]
