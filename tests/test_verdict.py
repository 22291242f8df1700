"""The maintenance verdict (limits, nominal values, rules), its terminal table, report.md, result.json, the
notebook display, and the figures an engineer reads (checked through their matplotlib objects)."""

from __future__ import annotations

import contextlib
import io
import json
import re
import sys

import numpy as np
import pytest
import yaml

import suspid
from suspid import cli
from suspid.errors import ConfigError
from suspid.infra import files
from suspid.interfaces import Parameter
from suspid.sections import Limits
from suspid.workflows import identify, report
from suspid.workflows.phases import ProgressPhases
from suspid.workflows.verdict import judge, rows_of, summary_line, table, verdict_rows, zone

DAMPER = Limits(warning=-25, alarm=-40)


def _judge(change, interval, trust="yes", identifiable=True, limits=DAMPER, decision="precautionary"):
    return judge(identifiable=identifiable, trust=trust, change=change, interval=interval,
                 warning=limits.warning, alarm=limits.alarm, decision=decision)


def test_a_damper_at_minus_30_percent_with_limits_minus_25_and_minus_40_warns():
    verdict, rule = _judge(-30.0, (-33.0, -27.0))
    assert verdict == "warning" and rule == "the whole interval -33.0 to -27.0 % is warning (warning -25 %; alarm -40 %)"
    assert _judge(-10.0, (-15.0, -5.0))[0] == "ok"
    assert _judge(-45.0, (-50.0, -41.0))[0] == "alarm"
    assert _judge(-40.0, (-40.0, -40.0))[0] == "alarm"     # at a level: that level's state
    assert _judge(+30.0, (25.0, 35.0))[0] == "ok"          # a one-sided (lower) limit leaves increases ok


def test_an_interval_across_one_level_gives_the_more_severe_state_marked_borderline():
    """Precautionary decision (the default): acceptance is shown by the whole interval, not presumed; the value
    lying on the milder side does not make it milder."""
    verdict, rule = _judge(-38.0, (-44.0, -32.0))          # value a warning, interval reaching the alarm level
    assert verdict == "alarm" and rule.startswith("borderline") and "alarm level -40 %" in rule
    assert "warning level" not in rule
    verdict, rule = _judge(-24.0, (-28.0, -21.0))          # value ok, interval reaching the warning level
    assert verdict == "warning" and "warning level -25 %" in rule


def test_an_interval_across_one_level_is_not_assessable_with_the_strict_decision():
    verdict, rule = _judge(-38.0, (-44.0, -32.0), decision="strict")
    assert verdict == "not assessable" and "alarm level -40 %" in rule and "warning" not in rule
    verdict, rule = _judge(-26.0, (-30.0, -22.0), decision="strict")
    assert verdict == "not assessable" and "warning level -25 %" in rule


def test_an_interval_across_two_levels_is_not_assessable_under_either_decision():
    for decision in ("precautionary", "strict"):
        verdict, rule = _judge(-30.0, (-45.0, -15.0), decision=decision)
        assert verdict == "not assessable"
        assert "warning level -25 %" in rule and "alarm level -40 %" in rule


def test_not_trustworthy_or_not_identifiable_is_not_assessable_whatever_the_value():
    verdict, rule = _judge(-45.0, (-47.0, -43.0), trust="no")
    assert verdict == "not assessable" and rule.startswith("not trustworthy")
    verdict, rule = _judge(-45.0, (-47.0, -43.0), identifiable=False)
    assert verdict == "not assessable" and rule.startswith("not identifiable")
    verdict, rule = _judge(-45.0, (-47.0, -43.0), trust="not assessed")   # stands, but says so
    assert verdict == "alarm" and "not assessed" in rule
    assert judge(identifiable=True, trust="yes", change=-45.0, interval=(-47.0, -43.0), warning=None,
                 alarm=None)[0] == "not assessable"


def test_both_directions_and_their_zones():
    both = Limits(warning=[-15, 15], alarm=[-30, 30])
    assert [zone(c, both.warning, both.alarm) for c in (-31, -20, 0, 14.9, 15, 29, 30)] == \
        ["alarm", "warning", "ok", "ok", "warning", "warning", "alarm"]
    assert Limits(warning=20).warning == (None, 20.0) and Limits(alarm=-40).alarm == (-40.0, None)


def _result(**extra):
    base = {"parameters": ["c_yaw", "c_sec_y", "k_sec_z"], "units": {"c_yaw": "N s/m", "c_sec_y": "N s/m",
                                                                      "k_sec_z": "N/m"},
            "w_opt": {"c_yaw": 210e3, "c_sec_y": 29e3, "k_sec_z": 200e3},
            "interval": {"c_yaw": [201e3, 219e3], "c_sec_y": [27e3, 31e3], "k_sec_z": [150e3, 250e3]},
            "identifiable": {"c_yaw": True, "c_sec_y": True, "k_sec_z": False},
            "non_identifiable_reasons": {"k_sec_z": ["flat J"]},
            "trustworthy": {"c_yaw": True, "c_sec_y": False, "k_sec_z": None},
            "untrustworthy_reasons": {"c_sec_y": ["model inadequate where it is read"]}}
    return base | extra


PARAMETERS = [Parameter("c_yaw", "N s/m", 300e3, 50e3, 600e3, "yaw damper rate per damper (one per side); src"),
              Parameter("c_sec_y", "N s/m", 30e3, 5e3, 60e3, "secondary lateral damping per side"),
              Parameter("k_sec_z", "N/m", 350e3, 1e5, 6e5, "secondary vertical stiffness per side")]


def test_rows_from_a_result_kind_level_and_a_localisation_with_group_names():
    """Kind-level rows, and a localisation's groups: the group takes its kind's nominal and limits unless the
    config names the group; the label puts the group's place before the kind's description."""
    loc = [{"group": "c_yaw[bogie2]", "value": 186e3, "interval": [168e3, 204e3], "evidence": "ΔJ 12",
            "alternatives": [{"group": "c_yaw[bogie1]"}]},
           {"group": "c_yaw[bogie1,left]", "value": 120e3, "interval": [115e3, 124e3]}]
    limits = {"c_yaw": DAMPER, "c_yaw[bogie1,left]": Limits(warning=-50, alarm=-70, nominal=250e3)}
    rows = verdict_rows(_result(localisation=loc), PARAMETERS, limits)
    by = {r.name: r for r in rows}
    assert by["c_yaw"].verdict == "warning" and by["c_yaw"].change_percent == pytest.approx(-30.0)
    assert by["c_sec_y"].verdict == "not assessable" and "model inadequate" in by["c_sec_y"].rule
    assert by["k_sec_z"].verdict == "not assessable" and "flat J" in by["k_sec_z"].rule
    g2 = by["c_yaw[bogie2]"]
    assert (g2.source, g2.nominal, g2.unit, g2.verdict) == ("localisation", 300e3, "N s/m", "alarm")
    assert g2.borderline and "alarm level -40 %" in g2.rule
    assert g2.change_percent == pytest.approx(-38.0) and g2.interval_percent == pytest.approx((-44.0, -32.0))
    assert g2.label == "bogie 2: yaw damper rate per damper" and g2.alternatives == ["c_yaw[bogie1]"]
    assert summary_line(g2).startswith("bogie 2: yaw damper rate per damper (`c_yaw[bogie2]`): -38 % "
                                       "(interval -44 to -32 %), alarm (borderline): replace (the interval "
                                       "-44.0 to -32.0 % reaches across the alarm level -40 %)")
    g1 = by["c_yaw[bogie1,left]"]
    assert g1.nominal == 250e3 and g1.change_percent == pytest.approx(-52.0) and g1.verdict == "warning"
    assert g1.label.startswith("bogie 1, left: ")
    assert verdict_rows(_result(), PARAMETERS, limits, localisation={"rows": loc}) == rows   # a mapping with rows
    assert "rests on the sampling interval" in g1.rule
    # a localisation row whose interval holds the fit's model-form misfit (suspid.workflows.elements) says so
    misfit = [{**loc[1], "interval_statistical": [118e3, 122e3]}]
    m, = verdict_rows(_result(), PARAMETERS, limits, localisation={"rows": misfit})[3:]
    assert m.verdict == "warning" and "misfit the localisation's fit leaves" in m.rule and "sampling" not in m.rule
    # typed serialisation: a row goes through result.json and back unchanged
    block = {"verdict": {"rows": [r.to_dict() for r in rows]}}
    assert rows_of(json.loads(json.dumps(block))) == rows


def test_the_identified_value_is_the_bias_corrected_one_when_the_checks_gave_it():
    """With the model-error checks' correction the interval is centred on w_corrected: the verdict judges that
    value, not w_opt (which would put -30 % beside an interval of -17 to -11 %)."""
    corrected = _result(w_corrected={"c_yaw": 258e3, "c_sec_y": 29e3, "k_sec_z": 200e3},
                        interval={"c_yaw": [249e3, 267e3], "c_sec_y": [27e3, 31e3], "k_sec_z": [150e3, 250e3]})
    row = verdict_rows(corrected, PARAMETERS, {"c_yaw": DAMPER})[0]
    assert row.value == 258e3 and row.change_percent == pytest.approx(-14.0) and row.verdict == "ok"
    assert verdict_rows(_result(), PARAMETERS, {"c_yaw": DAMPER})[0].value == 210e3


def test_measured_data_tables_have_no_w_ref_columns():
    """Without a known truth (measured data) the table has no w_ref or error columns; with it, both."""
    rows = verdict_rows(_result(), PARAMETERS, {"c_yaw": DAMPER})
    header, cells = table(rows)
    assert "w_ref" not in header and "error (% of interval)" not in header and len(cells[0]) == len(header)
    assert cells[0][:4] == ["c_yaw", "300 kN s/m", "210 kN s/m", "-30.0 %"] and cells[0][-3:] == ["yes", "yes",
                                                                                                 "warning"]
    header, _ = table(verdict_rows(_result(w_ref={"c_yaw": 2e5}), PARAMETERS, {}), with_reference=True)
    assert header[5:7] == ["w_ref", "error (% of interval)"]


def test_an_alarm_line_says_replace():
    row = verdict_rows(_result(w_opt={"c_yaw": 150e3, "c_sec_y": 29e3, "k_sec_z": 2e5},
                               interval={"c_yaw": [140e3, 160e3], "c_sec_y": [27e3, 31e3],
                                         "k_sec_z": [1.5e5, 2.5e5]}), PARAMETERS, {"c_yaw": DAMPER})[0]
    assert summary_line(row) == "yaw damper rate per damper (`c_yaw`): -50 % (interval -53 to -47 %), alarm: replace"


@pytest.mark.parametrize("limits, key, words", [
    ({"c_yow": {"warning": -25}}, "limits.c_yow", "unknown parameter 'c_yow'"),
    ({"c_yaw": {"warning": -25, "alarm": -20}}, "limits.c_yaw", "must lie below the lower warning level"),
    ({"c_yaw": {"warning": -120}}, "limits.c_yaw.warning", "between -100 and 0"),
    ({"c_yaw": {}}, "limits.c_yaw", "give warning and/or alarm levels"),
    ({"c_yaw": {"warning": -25, "nominal": -3.0}}, "limits.c_yaw.nominal", "opposite sign"),
    ({"c_yaw": {"warning": -25, "alarms": -40}}, "limits.c_yaw.alarms", "unknown key"),
    ({"c_yaw": {"warning": -25, "decision": "cautious"}}, "limits.c_yaw.decision", "precautionary"),
])
def test_bad_limits_are_one_line_errors_naming_the_key(tmp_path, capsys, limits, key, words):
    cfg = tmp_path / "bad.yaml"
    cfg.write_text(yaml.safe_dump({"name": "bad", "parameters": {"c_yaw": {}}, "limits": limits}))
    with pytest.raises(ConfigError) as err:
        suspid.validate(cfg)
    assert key in str(err.value) and words in str(err.value) and "\n" not in str(err.value)
    with pytest.raises(SystemExit) as exit_:
        cli.main(["validate", str(cfg)])
    out = capsys.readouterr()
    assert exit_.value.code == 2 and len(out.err.strip().splitlines()) == 1 and key in out.err


def test_a_group_limit_of_a_known_kind_validates():
    cfg = suspid.load_config({"parameters": {"c_yaw": {}}, "limits": {"c_yaw[bogie2]": {"alarm": [-40, 30]}}})
    assert cfg.limits["c_yaw[bogie2]"].alarm == (-40.0, 30.0)


SMALL = {"name": "verdict", "seed": 5,
         "simulator": {"plugin": "exudyn-train", "options": {"solver": "frequency", "fs_hz": 50.0}},
         "parameters": {"c_yaw": {}, "c_sec_y": {}},
         "limits": {"c_yaw": {"warning": -25, "alarm": -40}, "c_sec_y": {"warning": [-20, 20], "alarm": [-45, 45]}},
         "data": {"track": {"n_segments": 6, "length_m": 1000.0}, "w_ref": {"c_yaw": 180.0e3, "c_sec_y": 30.0e3}},
         "spectra": {"f_min_hz": 0.5, "f_max_hz": 10.0, "n_freqs": 40},
         "design": {"n_initial": 6}, "ego": {"max_iter": 2},
         "identifiability": {"n_redraws": 6, "model_error": {"run": "always"}}}


class RecordedPhases(ProgressPhases):
    """The run's phase display, recording what it was told."""

    seen: list[str] = []

    def start(self, name: str) -> None:
        RecordedPhases.seen.append(name)
        super().start(name)


@pytest.fixture(scope="module")
def small_run(tmp_path_factory):
    """A tiny identification through the command line: its terminal output and run directory."""
    folder = tmp_path_factory.mktemp("verdict")
    cfg = folder / "verdict.yaml"
    cfg.write_text(yaml.safe_dump(SMALL | {"output": {"dir": str(folder / "run")}}, sort_keys=False))
    out = io.StringIO()
    with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stdout(out), pytest.raises(SystemExit) as exit_:
        mp.setattr(identify, "ProgressPhases", RecordedPhases)
        cli.main(["run", str(cfg), "--quiet"])
    assert exit_.value.code == 0
    return out.getvalue(), folder / "run"


def test_terminal_table_and_report_show_units_nominal_change_trust_and_verdict(small_run):
    out, run = small_run
    result = json.loads((run / "result.json").read_text())
    rows = rows_of(result)
    assert result["verdict"]["version"] == 1 and [r.name for r in rows] == ["c_yaw", "c_sec_y"]
    assert result["nominal"] == {"c_yaw": 300e3, "c_sec_y": 30e3}
    header = next(line for line in out.splitlines() if line.startswith("verdict "))   # the verdict first
    for col in ("nominal", "identified", "change [interval]", "w_ref", "trust", "verdict"):
        assert col in header, col
    report = (run / "report.md").read_text()
    first = report.split("\n## ")[1]
    assert first.startswith("Maintenance verdict")        # the report's first section
    for r in rows:
        # the terminal's row: nominal and identified value with their units, change in %, trust, verdict
        line = next(ln for ln in out.splitlines() if f" {r.name} " in ln and "kN s/m" in ln)
        assert "300 kN s/m" in line or "30 kN s/m" in line
        trust = r.trust if r.identifiable else "not identifiable"    # the terminal folds identifiability in
        assert f"{r.change_percent:+.1f} %" in line and trust in line and r.verdict in line
        # 6 segments: the self-check (8 needed) does not run, so no component is trustworthy
        assert r.trust in ("not assessed", "no")
        # the same in report.md's verdict table, and a plain-language line each
        cells = [c.strip() for c in next(ln for ln in first.splitlines() if ln.startswith(f"| {r.name} |")).split("|")]
        assert f"{r.change_percent:+.1f} %" in cells and r.verdict in cells and r.trust in cells
        assert any(c.endswith("kN s/m") for c in cells)
        assert f"- {summary_line(r)}" in first and summary_line(r, markdown=False) in out
        expected = judge(identifiable=r.identifiable, trust=r.trust, change=r.change_percent,
                         interval=r.interval_percent, warning=r.warning, alarm=r.alarm)
        assert r.verdict == expected[0] and r.rule.startswith(expected[1])   # (the reasons are quoted after it)


def test_every_phase_after_the_optimiser_is_shown(small_run):
    """The analysis (intervals, identifiability, the model-error checks that run: the linearised ones by
    default) and the report each show a phase on the progress display (about 3.5 of 4.3 minutes of a
    measured two-date run used to show nothing)."""
    seen = [name.split(" (")[0] for name in RecordedPhases.seen]
    assert seen == ["intervals", "identifiability", "model error", "figures and report"]


def test_notebook_summary_html_rows_and_dataframe(small_run, monkeypatch):
    _, run = small_run
    r = suspid.IdentificationResult.load(run)
    text = r.summary()
    assert "nominal" in text and "300 kN s/m" in text and "verdict" in text and "\n" in text
    html = r._repr_html_()
    assert html.count("<tr>") == 1 + len(r.parameters) and "kN s/m" in html
    rows = r.verdict_table()
    assert [row["name"] for row in rows] == r.parameters and isinstance(rows[0]["change_percent"], float)
    assert len(repr(r)) < 300 and "verdict" in repr(r)
    try:
        import pandas  # noqa: F401
    except ImportError:
        with pytest.raises(ImportError, match="verdict_table"):
            r.to_dataframe()
    else:
        df = r.to_dataframe()
        assert list(df.index) == r.parameters and "verdict" in df.columns
    monkeypatch.setitem(sys.modules, "pandas", None)   # pandas absent: a clear error
    with pytest.raises(ImportError, match="needs pandas"):
        r.to_dataframe()


def test_figures_draw_every_channel_and_the_limits(tmp_path, monkeypatch):
    """Figure 1: one axes per channel, the dB label naming its reference, Hz ticks; Figure 2: % of nominal,
    the nominal line, the limits, the intervals and one marker style per trust state, with a legend."""
    figures = {}
    monkeypatch.setattr(report, "save_figure", lambda fig, path: figures.setdefault(path.name, fig) and path)
    freqs = np.geomspace(0.4, 20.0, 60)
    channels = [f"ch{i}" for i in range(7)]
    rng = np.random.default_rng(0)
    y = rng.normal(-20, 3, (12, 7, 60))
    report.figure_spectra(tmp_path / "f1.png", freqs, y, y + 1.0, channels, title="t", first=2)
    fig = figures["f1.png"]
    shown = [ax for ax in fig.axes if ax.get_visible()]
    assert sorted(ax.get_title() for ax in shown) == channels and shown[0].get_title() == "ch2"
    assert shown[0].get_ylabel() == "Y (dB re 1 m s⁻¹·⁵)" and shown[-1].get_xlabel() == "frequency (Hz)"
    assert [t.get_text() for t in shown[0].get_xticklabels()] == ["0.5", "1", "2", "5", "10", "20"]
    assert all(len(ax.lines) == 4 and len(ax.collections) == 1 for ax in shown)   # 2 means, 2 quantiles; a band
    files.pyplot().close(fig)

    rows = verdict_rows(_result(w_ref={"c_yaw": 2e5, "c_sec_y": 3e4, "k_sec_z": 3e5},   # c_yaw -29 to -23 %: borderline
                                interval={"c_yaw": [213e3, 231e3], "c_sec_y": [27e3, 31e3], "k_sec_z": [150e3, 250e3]}),
                        PARAMETERS,
                        {"c_yaw": DAMPER, "c_sec_y": DAMPER, "k_sec_z": Limits(warning=[-15, 15], alarm=[-30, 30])})
    report.figure_verdict(tmp_path / "f2.png", rows)
    ax = figures["f2.png"].axes[0]
    assert ax.get_ylabel() == "change from nominal (% of nominal)"
    assert [t.get_text() for t in ax.get_xticklabels()] == ["c_yaw\n300 kN s/m", "c_sec_y\n30 kN s/m",
                                                            "k_sec_z\n350 kN/m"]
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    for words in ("nominal value (0 %)", "warning level", "alarm level", "trustworthy (filled)",
                  "not trustworthy (grey cross)", "not identifiable (grey square)", "w_ref (the experiment's truth)"):
        assert words in legend, words
    levels = sorted(round(float(seg[0][1]), 6) for coll in ax.collections if hasattr(coll, "get_segments")
                    for seg in coll.get_segments() if len(seg) == 2 and seg[0][1] == seg[1][1]
                    and abs(seg[1][0] - seg[0][0]) > 0.7)
    assert {-40.0, -30.0, -25.0, -15.0, 15.0, 30.0} <= set(levels)
    bars = [seg for coll in ax.collections if hasattr(coll, "get_segments") for seg in coll.get_segments()
            if len(seg) == 2 and seg[0][0] == seg[1][0]]
    assert len(bars) == 3 and sorted(tuple(sorted((b[0][1], b[1][1]))) for b in bars)[0] == \
        pytest.approx((-57.142857, -28.571429))   # k_sec_z's interval in % of 350 kN/m
    markers = [coll for coll in ax.collections if coll.get_offsets().shape[0] == 1 and not hasattr(coll, "get_segments")]
    assert len(markers) == 6   # a value and a w_ref per parameter
    assert [t.get_text() for t in ax.texts] == [r.verdict + ("\n(borderline)" if r.borderline else "")
                                                for r in rows]
    assert any(r.borderline for r in rows) and "(borderline)" in " ".join(t.get_text() for t in ax.texts)
    files.pyplot().close(figures["f2.png"])


def test_run_figures_are_written_and_linked(small_run):
    _, run = small_run
    report = (run / "report.md").read_text()
    for name in ("figure1_spectra.png", "figure1_reference.png", "figure2_parameters.png"):
        assert (run / name).stat().st_size > 10_000 and f"]({name})" in report
    assert re.search(r"every channel", report)
