"""benchmarks/run_all.py: a benchmark's printed table replaces its block in RESULTS.md; a failure keeps the old one."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _run_all():
    spec = importlib.util.spec_from_file_location("run_all", ROOT / "benchmarks" / "run_all.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["run_all"] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


def test_block_replaced_on_success_kept_on_failure_appended_when_new(tmp_path):
    ra = _run_all()
    good = tmp_path / "bench_good.py"
    good.write_text("print('| case | wall (s) |')\nprint('| a | 0.5 |')\n")
    bad = tmp_path / "bench_bad.py"
    bad.write_text("print('| partial |')\nraise SystemExit(3)\n")
    results = tmp_path / "RESULTS.md"
    old_good = "<!-- run_all:good begin -->\nold good table\n<!-- run_all:good end -->"
    old_bad = "<!-- run_all:bad begin -->\nold bad table\n<!-- run_all:bad end -->"
    results.write_text(f"# Results\n\n## Good\n\n{old_good}\n\nprose kept\n\n## Bad\n\n{old_bad}\n\ntail\n")
    benches = [ra.Benchmark("good", (str(good), "--x"), (str(good),), "a fake"),
               ra.Benchmark("bad", (str(bad),), (str(bad),), "a failing fake"),
               ra.Benchmark("new", (str(good),), None, "a fake with no block yet")]

    failed = ra.update_results(results, benches, quick=False, python=sys.executable)

    text = results.read_text()
    assert failed == ["bad"]
    assert "old good table" not in text
    begin, end = ra.markers("good")
    good_block = text[text.index(begin):text.index(end)]
    assert f"`python {good} --x`" in good_block and "| a | 0.5 |" in good_block and "commit " in good_block
    assert old_bad in text and "| partial |" not in text  # the failed benchmark's old block, unchanged
    assert text.count(ra.markers("new")[0]) == 1 and text.rstrip().endswith(ra.markers("new")[1])
    assert "prose kept" in text and "tail" in text and text.index("## Good") < text.index("## Bad")

    # quick: a benchmark without quick arguments is skipped and its block left as it is
    before = text
    assert ra.update_results(results, benches[2:], quick=True, python=sys.executable) == []
    assert results.read_text() == before


def test_every_benchmark_has_quick_sizes_and_the_summary_totals_the_wall_times(tmp_path):
    ra = _run_all()
    assert all(b.quick for b in ra.BENCHMARKS), [b.name for b in ra.BENCHMARKS if not b.quick]
    assert len({b.name for b in ra.BENCHMARKS}) == len(ra.BENCHMARKS)
    slow = tmp_path / "bench_slow.py"
    slow.write_text("import time\ntime.sleep(0.3)\nprint('| x |')\n")
    results = tmp_path / "RESULTS.md"
    results.write_text("# Results\n")
    timings = []
    ra.update_results(results, [ra.Benchmark("slow", (str(slow),), (str(slow),), "sleeps")], quick=True,
                      python=sys.executable, timings=timings)
    (t,) = timings
    assert (t.name, t.status) == ("slow", "ok") and 0.3 <= t.wall_s < 30 and 0 < t.cpu_s < t.wall_s
    other = ra.Timing("other", 60.0, 50.0, "failed")
    summary = ra.timing_summary(timings + [other], quick=True, load_before="1", load_after="2")
    assert "quick sizes" in summary and "failed" in summary
    assert summary.splitlines()[-1].split()[:3] == ["total", f"{t.wall_s + 60:.0f}", f"{t.cpu_s + 50:.0f}"]


def test_progress_bars_are_left_out_of_a_block_and_tables_kept():
    ra = _run_all()
    out = ("variant a-seed1\nexecutor serial, 1 task(s) at once\n"
           "ego ━━━━━━━━━━ 89/89 0:00:55 eta 0:00:00 J_max 0.87\n"
           "┏━━━━━━━━━━━┳━━━━━━┓\n| variant | a |\n")
    assert ra.strip_progress(out) == "┏━━━━━━━━━━━┳━━━━━━┓\n| variant | a |\n"
