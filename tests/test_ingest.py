"""suspid ingest: readers, units, alignment, segmentation, quality report, written layout.

The recordings come from ``examples/recordings/make_recordings.py`` (suspid's
exudyn-train model on a long synthetic track, written through each format's
own library), generated once per module in a temporary folder.
"""

from __future__ import annotations

import importlib.util
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.io
import yaml

import suspid
from suspid import registry
from suspid.data.files import read_accelerations, read_track
from suspid.errors import ConfigError, DataError

from conftest import ROOT, interruptible, run_cli

pytest.importorskip("asammdf")
pytest.importorskip("nptdms")


def _generator():
    spec = importlib.util.spec_from_file_location("make_recordings", ROOT / "examples/recordings/make_recordings.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules["make_recordings"] = mod
    spec.loader.exec_module(mod)
    return mod


GEN = _generator()


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    out = tmp_path_factory.mktemp("recordings")
    truth = GEN.make(out)
    return out, truth


def _ingest_file(folder: Path, fmt: str, **changes) -> dict:
    data = yaml.safe_load((folder / f"ingest-{fmt}.yaml").read_text())
    for key, value in changes.items():
        node = data
        *parents, last = key.split(".")
        for p in parents:
            node = node[p]
        if value is None:
            node.pop(last)
        else:
            node[last] = value
    return data


def _run(folder: Path, data: dict, out: Path):
    path = folder / f"ingest-{out.name}.yaml"
    path.write_text(yaml.safe_dump(data))
    return suspid.ingest(path, out_dir=out)


def test_every_builtin_reader_is_registered_with_extensions():
    names = registry.names("reader")
    assert {"mdf4", "mat", "tdms", "csv", "hdf5"} <= set(names)
    for n in ("mdf4", "mat", "tdms", "csv", "hdf5"):
        assert registry.get("reader", n).extensions


@pytest.mark.parametrize("fmt", ["mf4", "mat", "mat73", "tdms", "csv"])
def test_offset_found_within_1_m_and_segments_at_constant_speed(recordings, tmp_path, fmt):
    folder, truth = recordings
    r = suspid.ingest(folder / f"ingest-{fmt}.yaml", out_dir=tmp_path / fmt)
    assert abs(r.offset_m - truth["offset_m"]) < 1.0, r.offset_m
    assert r.peak_ratio > 3.0
    assert len(r.segments) >= 3
    assert r.warnings == []
    profile = GEN.Profile(**truth["profile"])
    tol = 0.02
    for seg in r.report["segments"]:
        t = np.linspace(seg["t_start_s"], seg["t_end_s"], 500)
        v_true = profile.speed(t)
        assert v_true.min() * 3.6 >= 100.0
        assert np.max(np.abs(v_true - v_true.mean())) <= tol * v_true.mean() * 1.01
        assert seg["speed_max_mps"] - seg["speed_min_mps"] <= 2 * tol * seg["speed_mps"]
    # the documented layout, read as `suspid validate` and `suspid run` read it
    segs = read_track(r.track_path)
    recs = read_accelerations(r.measurements_path, list(GEN.CHANNELS))
    assert [s.name for s in segs] == [x.segment for x in recs] == r.segments
    for s, x in zip(segs, recs):
        assert abs(s.duration() - x.duration) <= max(0.02 * x.duration, 2 / x.fs)
    first = (r.track_path / f"{r.segments[0]}.csv").read_text()
    assert f"# source: {folder / GEN.FILES[fmt]}" in first and "# offset_m: " in first
    report = json.loads((r.out_dir / "ingest.json").read_text())
    assert report == json.loads(json.dumps(r.to_dict(), default=str))
    for fig in ("speed.png", "alignment.png", "spectrogram_carbody.png", "spectrogram_bogie.png"):
        assert (r.out_dir / fig).stat().st_size > 1000


def test_units_are_converted_by_the_declared_unit(recordings, tmp_path):
    """mm/s^2 and g in the file come out in m/s^2: the same values through mf4 and csv."""
    folder, _ = recordings
    a = suspid.ingest(folder / "ingest-mf4.yaml", out_dir=tmp_path / "mf4")
    b = suspid.ingest(folder / "ingest-csv.yaml", out_dir=tmp_path / "csv")
    ra, rb = read_accelerations(a.measurements_path), read_accelerations(b.measurements_path)
    np.testing.assert_allclose(ra[0].accelerations, rb[0].accelerations, rtol=1e-6, atol=1e-6)
    rms = a.report["channels"]["bogie_front_vertical"]["rms_moving"]
    assert 0.3 < rms < 5.0      # g converted, not left as ~0.1


def test_hdf5_output_validates_with_a_measured_config(recordings, tmp_path):
    folder, _ = recordings
    r = suspid.ingest(folder / "ingest-tdms.yaml", {"output.format": "hdf5"}, out_dir=tmp_path / "h5")
    assert r.track_path.name == "track.h5" and r.measurements_path.name == "accelerations.h5"
    cfg = yaml.safe_load((folder / "suspid.yaml").read_text())
    cfg["data"] = {"source": "measured", "track_file": str(r.track_path), "measurements": str(r.measurements_path)}
    cfg["noise"] = {"reference": {"track_file": str(r.track_path), "measurements": str(r.measurements_path)}}
    assert suspid.validate(cfg).n_measured_segments == len(r.segments)


def _zeroed(folder: Path, column: int) -> str:
    lines = (folder / "recording.csv").read_text().splitlines()
    body = [line for line in lines if line and not line.startswith("#")]
    out = [line for line in lines if line.startswith("#")] + [body[0]]
    for line in body[1:]:
        cells = line.split(",")
        cells[column] = "0"
        out.append(",".join(cells))
    (folder / "dead.csv").write_text("\n".join(out) + "\n")
    return "dead.csv"


# impossible values through ingest: (format, changes, words of the one-line DataError)
INGEST_IMPOSSIBLE = {
    # a MAT file has no units: only the amplitude can tell
    "mat_data_in_mm_per_s2_declared_m_per_s2": (
        "mat", {"recording.channels.carbody_front_vertical.unit": "m/s^2"},
        ["recording.mat: channel 'carbody_front_vertical' vibrates with", "beyond a carbody of a train in service",
         "(recorded channel 'ACC_Z_K1', declared unit 'm/s^2')", "add implausible_amplitude to quality.accept"]),
    "declared_unit_contradicts_the_mdf_header": (
        "mf4", {"recording.channels.carbody_front_vertical.unit": "m/s^2"},
        ["recording.mf4: channel 'carbody_front_vertical' vibrates with",
         "declared unit 'm/s^2', the file gives 'mm/s^2'"]),
    "track_in_mm_declared_m": (
        "csv", {"track.channels.vertical.unit": "m"},
        ["track-record.csv: channel 'vertical' has irregularities of", "beyond any track open to traffic",
         "(recorded channel 'LL', declared unit 'm')", "add implausible_amplitude to quality.accept"]),
    "speed_in_kmh_declared_m_per_s": (
        "csv", {"recording.speed.unit": "m/s"},
        ["recording.csv: speed (declared unit 'm/s'), 99th percentile", "above any train's",
         "add implausible_speed to quality.accept"]),
    "all_zero_channel": (
        "csv", {"recording.path": "dead.csv"},
        ["dead.csv: channel 'bogie_front_lateral' is constant: a dead or disconnected sensor",
         "add dead_channel to quality.accept"]),
}


@pytest.mark.parametrize("name", sorted(INGEST_IMPOSSIBLE))
def test_impossible_values_stop_the_ingest_before_it_writes(recordings, tmp_path, name):
    """Each was a warning line in the quality report and segments written; now one error, nothing written."""
    folder, _ = recordings
    fmt, changes, words = INGEST_IMPOSSIBLE[name]
    if name == "all_zero_channel":
        _zeroed(folder, 4)     # ACC_Y_B1, mapped to bogie_front_lateral
    with pytest.raises(DataError) as err:
        _run(folder, _ingest_file(folder, fmt, **changes), tmp_path / name)
    msg = str(err.value)
    assert "\n" not in msg and all(w in msg for w in words), msg
    assert not (tmp_path / name).exists()


def test_impossible_values_accepted_by_name_are_ingested_with_a_warning(recordings, tmp_path):
    folder, _ = recordings
    data = _ingest_file(folder, "mat", **{"recording.channels.carbody_front_vertical.unit": "m/s^2"})
    data.setdefault("quality", {})["accept"] = ["implausible_amplitude"]
    r = _run(folder, data, tmp_path / "accepted")
    lines = [w for w in r.warnings if "vibrates with" in w]
    assert len(lines) == 1 and "accepted: implausible_amplitude in quality.accept" in lines[0]
    assert r.segments


def test_unknown_unit_is_a_config_error(recordings):
    folder, _ = recordings
    data = _ingest_file(folder, "csv", **{"recording.channels.carbody_front_vertical.unit": "gal"})
    with pytest.raises(ConfigError, match=r"recording.channels.carbody_front_vertical.unit.*unknown unit 'gal'"):
        suspid.ingest(data)


def test_missing_channel_mapping_is_a_config_error(recordings, tmp_path):
    folder, _ = recordings
    data = _ingest_file(folder, "csv", **{"recording.channels.bogie_front_lateral": None})
    with pytest.raises(ConfigError, match=r"recording.channels.*no mapping for simulator channel\(s\) "
                                          r"bogie_front_lateral") as err:
        _run(folder, data, tmp_path / "missing")
    assert "\n" not in str(err.value)
    assert not (tmp_path / "missing").exists()       # nothing written before the inputs are valid


def test_channel_absent_from_the_file_is_a_data_error(recordings, tmp_path):
    folder, _ = recordings
    data = _ingest_file(folder, "mf4", **{"recording.channels.bogie_front_lateral.name": "ACC_Y_B9"})
    with pytest.raises(DataError, match=r"recording.mf4: no channel 'ACC_Y_B9' \(mapped to bogie_front_lateral, "
                                        r"key recording.channels.bogie_front_lateral.name\)"):
        _run(folder, data, tmp_path / "absent")


def test_unknown_key_is_rejected(recordings):
    folder, _ = recordings
    data = _ingest_file(folder, "csv")
    data["segments"]["lenght_m"] = 500
    with pytest.raises(ConfigError, match=r"segments.lenght_m.*unknown key; expected one of: .*length_m"):
        suspid.ingest(data)


def test_recording_shorter_than_one_segment_is_a_data_error(recordings, tmp_path):
    folder, truth = recordings
    data = _ingest_file(folder, "csv", **{"segments.length_m": 50_000.0})
    with pytest.raises(DataError, match=r"shorter than one segment \(segments.length_m = 50000 m\)"):
        _run(folder, data, tmp_path / "short")


def test_saturated_channel_is_reported_and_excluded(tmp_path):
    truth = GEN.make(tmp_path, ["csv"], artefacts=GEN.Artefacts(saturate={"bogie_front_vertical": (4.2, 0, 1e9)}))
    r = suspid.ingest(tmp_path / "ingest-csv.yaml", out_dir=tmp_path / "out")
    lines = [w for w in r.warnings if "clipped" in w]
    assert len(lines) == 1 and "bogie_front_vertical" in lines[0]
    clipped = [e for e in r.report["excluded"] if e["reason"].startswith("clipping (saturated sensor) in "
                                                                          "bogie_front_vertical")]
    assert clipped
    for seg in r.report["segments"]:
        for e in clipped:
            assert seg["t_end_s"] <= e["t_start_s"] + 1e-9 or seg["t_start_s"] >= e["t_end_s"] - 1e-9
    assert abs(r.offset_m - truth["offset_m"]) < 1.0


def test_dropout_is_reported_and_excluded(tmp_path):
    GEN.make(tmp_path, ["mf4"], artefacts=GEN.Artefacts(dropout={"carbody_front_vertical": (70.0, 70.5)}))
    r = suspid.ingest(tmp_path / "ingest-mf4.yaml", out_dir=tmp_path / "out")
    lines = [w for w in r.warnings if "dropped samples" in w]
    assert len(lines) == 1 and "carbody_front_vertical" in lines[0]
    drop = [e for e in r.report["excluded"] if e["reason"] == "dropout in carbody_front_vertical"]
    assert len(drop) == 1 and drop[0]["t_start_s"] <= 70.0 and drop[0]["t_end_s"] >= 70.5
    for seg in r.report["segments"]:
        assert seg["t_end_s"] <= drop[0]["t_start_s"] + 1e-9 or seg["t_start_s"] >= drop[0]["t_end_s"] - 1e-9


def test_cli_ingest_and_its_one_line_error(recordings, tmp_path):
    folder, _ = recordings
    p = run_cli("ingest", str(folder / "ingest-mat.yaml"), "--out", str(tmp_path / "cli"), "--quiet")
    assert p.returncode == 0, p.stderr
    assert "segments, offset 137." in p.stdout and "ingest.md" in p.stdout
    p = run_cli("ingest", str(folder / "ingest-mat.yaml"), "--set", "recording.channels.bogie_front_lateral=null")
    assert p.returncode == 2
    assert p.stderr.strip().count("\n") == 0 and p.stderr.startswith("error: ")



def _truncated(folder: Path, name: str) -> str:
    data = (folder / name).read_bytes()
    (folder / f"truncated-{name}").write_bytes(data[: len(data) * 6 // 10])
    return f"truncated-{name}"


def _sparse_time(folder: Path, name: str) -> str:
    lines = (folder / name).read_text().splitlines()
    cells = lines[-1].split(",")
    cells[0] = "3.0e7"          # the last time stamp a year later: a grid of billions of samples
    lines[-1] = ",".join(cells)
    (folder / f"sparse-{name}").write_text("\n".join(lines) + "\n")
    return f"sparse-{name}"


# damaged recordings and mapping typos through `suspid ingest`: (format, damage -> changes, words of the line)
INGEST_FAULTS = {
    "tdms_truncated": ("tdms", lambda f: {"recording.path": _truncated(f, "recording.tdms")},
                       "recording.tdms: damaged or truncated TDMS file ("),
    "mf4_truncated": ("mf4", lambda f: {"recording.path": _truncated(f, "recording.mf4")},
                      "recording.mf4: damaged or unreadable MDF file (struct.error"),
    "mat5_truncated": ("mat", lambda f: {"recording.path": _truncated(f, "recording.mat")},
                       "recording.mat: damaged or truncated MATLAB file (the variable at byte"),
    "mat73_truncated": ("mat73", lambda f: {"recording.path": _truncated(f, "recording-v73.mat")},
                        "recording-v73.mat: damaged or unreadable MATLAB 7.3 (HDF5) file (OSError"),
    "sparse_time_stamps": ("csv", lambda f: {"recording.path": _sparse_time(f, "recording.csv")},
                           "recording.csv: channel 'ACC_Z_K1' spans 3e+07 s at 200 Hz"),
    "channel_key_typo": ("csv", lambda f: {"recording.channels.carbody_front_verticle":
                                           {"name": "ACC_Z_K1", "unit": "mm/s^2"},
                                           "recording.channels.carbody_front_vertical": None},
                         "key 'recording.channels.carbody_front_verticle': 'carbody_front_verticle' is not a "
                         "channel of simulator 'exudyn-train' (did you mean carbody_front_vertical?)"),
}

INGEST_MANY = """
import sys
from suspid.cli import main
for path in sys.argv[1:]:
    print("@@", path, file=sys.stderr, flush=True)
    try:
        main(["ingest", path, "--quiet"])
    except SystemExit as exc:
        print("@@ exit", exc.code, file=sys.stderr, flush=True)
import gc
gc.collect()
"""


def test_damaged_recordings_and_typos_are_one_line_naming_the_file_or_key(recordings, tmp_path):
    """Each was exit 1 ("a bug": a truncated TDMS), a line and then asammdf's "Exception ignored" traceback
    (a truncated MDF4), h5py's words without the file (MAT 7.3), "out of memory" without the file (time
    stamps far apart) or the missing channel instead of the misspelt key. One process runs them all, so
    that a finalizer's traceback at its end shows too."""
    folder, _ = recordings
    paths = []
    for name, (fmt, damage, _) in sorted(INGEST_FAULTS.items()):
        data = _ingest_file(folder, fmt, **damage(folder))
        data["output"]["dir"] = str(tmp_path / name)
        paths.append(folder / f"ingest-fault-{name}.yaml")
        paths[-1].write_text(yaml.safe_dump(data))
    script = tmp_path / "many.py"
    script.write_text(INGEST_MANY)
    p = subprocess.run([sys.executable, str(script), *map(str, paths)], capture_output=True, text=True, timeout=600,
                       env=dict(os.environ, SUSPID_DISABLE_PLUGIN_AUTOLOAD="1"))
    assert p.returncode == 0 and "Traceback" not in p.stderr and "Exception ignored" not in p.stderr, p.stderr
    blocks = p.stderr.split("@@ ")[1:]
    for (name, (_, _, words)), path in zip(sorted(INGEST_FAULTS.items()), paths):
        head, *lines = blocks.pop(0).strip().splitlines()
        assert head == str(path) and blocks.pop(0).strip() == "exit 2", (name, lines)
        assert len(lines) == 1 and lines[0].startswith("error: ") and words in lines[0], (name, lines)
        assert not (tmp_path / name).exists()


@pytest.mark.parametrize("compress", [False, True])
def test_a_whole_matlab_5_file_is_not_taken_for_a_cut_one(tmp_path, compress):
    """(scipy lists the variables of a cut file up to the cut: the mapped channel after it was "absent")"""
    from suspid.plugins.readers.mat import v5_cut

    path = tmp_path / "r.mat"
    scipy.io.savemat(path, {"a": np.arange(1001.0), "b": np.ones(7), "s": "text"}, do_compression=compress)
    assert v5_cut(path) is None
    path.write_bytes(path.read_bytes()[:-3])
    assert "needs" in v5_cut(path)


def test_a_matlab_4_file_is_read_not_taken_for_a_cut_version_5_one(tmp_path):
    """(a version 4 file has no 128-byte header: read as version 5 it was "damaged or truncated")"""
    from suspid.plugins.readers.mat import v5_cut

    path = tmp_path / "r4.mat"
    scipy.io.savemat(path, {"a": np.arange(1001.0)}, format="4")
    assert v5_cut(path) is None
    assert np.array_equal(scipy.io.loadmat(path)["a"].ravel(), np.arange(1001.0))


def _limit_file_size(limit: int):
    """``preexec_fn``: files limited to ``limit`` bytes (a write beyond fails with EFBIG, as on a full disk)."""
    def preexec():
        import resource

        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return preexec


def _snapshot(out: Path) -> dict[str, bytes]:
    """Every file under ``out`` (relative path -> content)."""
    return {str(p.relative_to(out)): p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()}


def _consistent(out: Path) -> list[str]:
    """The segments ingest.json lists, checked to be exactly those the written files hold."""
    rep = json.loads((out / "ingest.json").read_text())
    names = [s["name"] for s in rep["segments"]]
    track, acc = Path(rep["output"]["track_file"]), Path(rep["output"]["measurements"])
    assert track.parent == out and acc.parent == out
    assert [s.name for s in read_track(track)] == names
    assert sorted(r.segment for r in read_accelerations(acc)) == sorted(names)
    assert all(f"| {n} |" in (out / "ingest.md").read_text() for n in names)
    assert not [p for p in out.iterdir() if p.name.startswith(".ingest-")]   # no staging folder left
    return names


def test_a_failing_or_interrupted_re_ingest_keeps_the_previous_segments_and_reports(recordings, tmp_path):
    """Re-ingest into a folder that holds an ingest, with files limited to 100 kB (a segment file is larger):
    one line, exit 2, and every file of the previous ingest (CSV, then HDF5) is still there, byte for byte,
    with ingest.json listing what the files hold. A re-ingest that succeeds replaces the whole set. Ctrl-C
    during a re-ingest says what is kept, and keeps it."""
    folder, _ = recordings
    data, out = _ingest_file(folder, "mat"), tmp_path / "out"
    path = folder / "ingest-reingest.yaml"
    path.write_text(yaml.safe_dump(data))
    suspid.ingest(path, out_dir=out)
    for fmt, prefix in (("csv", "first"), ("hdf5", "second")):
        before = _snapshot(out)
        names = _consistent(out)
        p = subprocess.run([sys.executable, "-m", "suspid", "ingest", str(path), "--out", str(out), "--quiet",
                            "--set", f"segments.prefix=again-{fmt}"], capture_output=True, text=True,
                           preexec_fn=_limit_file_size(100_000), timeout=300)
        assert p.returncode == 2, (p.stdout, p.stderr)
        lines = p.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0] == (f"error: {out}: cannot write the ingest: file too large (disk full or a "
                                                f"file-size limit?); the previous segments and reports in it, if any, "
                                                f"are kept"), p.stderr
        assert _snapshot(out) == before and _consistent(out) == names
        # a re-ingest that succeeds (in the other format): the new set only, the previous one gone
        suspid.ingest(path, [f"output.format={'hdf5' if fmt == 'csv' else 'csv'}", f"segments.prefix={prefix}",
                             "quality.figures=false"], out_dir=out)
        assert all(n.startswith(f"{prefix}-") for n in _consistent(out))
        assert {"track", "accelerations"}.isdisjoint(p.name for p in out.iterdir()) == (fmt == "csv")
        assert {"track.h5", "accelerations.h5"}.isdisjoint(p.name for p in out.iterdir()) == (fmt == "hdf5")
        assert not list(out.glob("*.png"))   # the first ingest's figures went with its set
    # Ctrl-C while re-ingesting: exit 130, a line that says what is kept (no "run ledger": ingest has none)
    before, names = _snapshot(out), _consistent(out)
    proc = subprocess.Popen([sys.executable, "-m", "suspid", "ingest", str(path), "--out", str(out),
                             "--set", "segments.prefix=interrupted"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, preexec_fn=interruptible)
    first = proc.stdout.readline()   # "reading <recording>": the ingest has started its work
    proc.send_signal(signal.SIGINT)
    rest, err = proc.communicate(timeout=120)
    assert first.startswith("reading ") and proc.returncode == 130, (first, rest, err)
    assert err.strip() == (f"interrupted: ingest keeps no partial work (it has no ledger): {out} still holds the "
                           f"segments and reports of the previous ingest, if any; run the same command to ingest "
                           f"again"), err
    assert _snapshot(out) == before and _consistent(out) == names


def test_a_lab_can_add_its_own_reader(recordings, tmp_path):
    from suspid import hookimpl
    from suspid.interfaces import Reader, Signal

    folder, truth = recordings
    table = np.loadtxt(folder / "recording.csv", delimiter=",", skiprows=2)
    names = ["time_s"] + [n for n, _, _ in GEN.CHANNELS.values()] + ["V_TRAIN"]
    with open(tmp_path / "run.labz", "wb") as fh:
        np.savez(fh, **{n: table[:, i] for i, n in enumerate(names)})

    class LabReader(Reader):
        name = "labz"
        extensions = (".labz",)

        def _data(self):
            return np.load(self.path)

        def channels(self):
            return [n for n in self._data().files if n != "time_s"]

        def read(self, channel):
            d = self._data()
            return Signal(channel, d[channel], "", index=d["time_s"])

    plugin = type("plugin", (), {"suspid_register_readers": staticmethod(hookimpl(lambda register: register(LabReader)))})
    registry.add_plugin(plugin, "lab-readers")
    data = _ingest_file(folder, "csv", **{"recording.path": str(tmp_path / "run.labz"), "recording.options": {}})
    r = _run(folder, data, tmp_path / "labz")               # chosen by the extension .labz
    assert abs(r.offset_m - truth["offset_m"]) < 1.0 and r.report["format"] == "labz"
    data["recording"]["path"] = str(folder / "recording.unknown")
    with pytest.raises(ConfigError, match=r"key 'recording.format': no reader for extension '.unknown'.*labz \(.labz\)"):
        _run(folder, data, tmp_path / "unknown")


@pytest.mark.parametrize("fmt", ["csv", "mat"])
def test_odometry_distance_instead_of_speed(recordings, tmp_path, fmt):
    folder, truth = recordings
    data = _ingest_file(folder, fmt, **{"recording.speed": None})
    data["recording"]["distance"] = {"name": "ODO", "unit": "m"}
    r = _run(folder, data, tmp_path / f"odo-{fmt}")
    assert abs(r.offset_m - truth["offset_m"]) < 1.0
    assert len(r.segments) >= 3 and r.report["motion"]["kind"] == "distance"


def test_speed_and_distance_together_is_a_config_error(recordings):
    folder, _ = recordings
    data = _ingest_file(folder, "csv")
    data["recording"]["distance"] = {"name": "ODO", "unit": "m"}
    with pytest.raises(ConfigError, match="give the train's motion once: recording.speed or recording.distance"):
        suspid.ingest(data)


def test_track_quantity_that_does_not_follow_is_an_ambiguous_alignment(recordings, tmp_path):
    """Aligning on the gauge instead of the longitudinal level finds no clear peak: an error, not an offset."""
    folder, _ = recordings
    data = _ingest_file(folder, "csv", **{"track.channels.vertical.name": "GA", "alignment.min_peak_ratio": 2.0})
    with pytest.raises(DataError, match=r"alignment is ambiguous: the correlation peak at offset .* is only "
                                        r".* times the next one"):
        _run(folder, data, tmp_path / "ambiguous")
    assert not (tmp_path / "ambiguous").exists()


def test_flat_line_spike_and_jitter_are_reported(tmp_path):
    art = GEN.Artefacts(flat={"carbody_middle_lateral": (50.0, 52.0)}, spike={"bogie_front_lateral": (65.0, 80.0)},
                        jitter_s=1e-4)
    truth = GEN.make(tmp_path, ["mf4"], artefacts=art)
    r = suspid.ingest(tmp_path / "ingest-mf4.yaml", out_dir=tmp_path / "out")
    flat = [w for w in r.warnings if "flat line" in w]
    spikes = [w for w in r.warnings if "spike" in w]
    jitter = [w for w in r.warnings if "sampling jitter" in w]
    assert len(flat) == 1 and "carbody_middle_lateral" in flat[0]
    assert len(spikes) == 1 and "bogie_front_lateral" in spikes[0]
    assert len(jitter) == len(GEN.CHANNELS)                       # every acceleration channel's time stamps
    assert r.report["channels"]["bogie_front_vertical"]["jitter"] == pytest.approx(1e-4 / 5e-3 * 2 ** 0.5, rel=0.2)   # std(dt) / dt
    reasons = {e["reason"] for e in r.report["excluded"]}
    assert "flat line in carbody_middle_lateral" in reasons and "spikes in bogie_front_lateral" in reasons
    for seg in r.report["segments"]:
        assert seg["t_end_s"] <= 50.0 or seg["t_start_s"] >= 52.0
        assert not seg["t_start_s"] <= 65.0 <= seg["t_end_s"]
    assert abs(r.offset_m - truth["offset_m"]) < 1.0


def _bench():
    spec = importlib.util.spec_from_file_location("bench_ingest", ROOT / "benchmarks/bench_ingest.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_memory_grows_by_less_than_2_5_copies_of_the_data(tmp_path):
    """The Python (numpy included) memory an ingest needs grows with the recording by less than 2.5 times
    the float64 accelerations it holds (measured: 2.1, once a first ingest has done its imports and
    caches; one more whole copy of the data at any step would add 1.0). Two recordings of 10 channels
    at 500 Hz, 7.2 and 14.4 minutes of one cruise at 300 km/h (MDF4, asammdf); the difference of the
    tracemalloc peaks cancels what does not grow with the data (imports, the simulator)."""
    import tracemalloc

    importlib.import_module("matplotlib.pyplot")     # imports are not data: before tracemalloc starts
    bench = _bench()
    peaks, sizes = [], []
    for hours in (0.12, 0.24):
        work = tmp_path / f"{hours:g}h"
        rec, trk, cfg = bench.make_recording(work, hours, 500.0, legs=1)
        path = bench.ingest_file(work, rec, trk, cfg)
        if not peaks:  # a first ingest, not measured: what it imports and caches is not data either
            suspid.ingest(path, out_dir=tmp_path / "warm-up")
        tracemalloc.start()
        try:
            r = suspid.ingest(path)
            peaks.append(tracemalloc.get_traced_memory()[1])
        finally:
            tracemalloc.stop()
        assert abs(r.offset_m - bench.OFFSET_M) < 1.0 and len(r.segments) >= 8
        sizes.append(len(bench.CHANNELS) * int(3600 * hours * 500.0) * 8)
    growth = (peaks[1] - peaks[0]) / (sizes[1] - sizes[0])
    print(f"tracemalloc peaks {peaks[0] / 2 ** 20:.1f} and {peaks[1] / 2 ** 20:.1f} MiB for {sizes[0] / 2 ** 20:.1f} "
          f"and {sizes[1] / 2 ** 20:.1f} MiB of samples: growth {growth:.2f}")
    assert growth < 2.5, (growth, [p / 2 ** 20 for p in peaks])


def test_hdf5_accelerations_written_straight_to_disk_read_back_and_need_room(tmp_path, monkeypatch):
    """``write_accelerations_h5(..., in_memory=False)`` (the ingest's large output) writes the layout that
    ``read_accelerations`` reads; when the disk has no room for it, one DataError line and no file."""
    from suspid.data import files
    from suspid.interfaces import Response

    rng = np.random.default_rng(0)
    recs = [Response(("a", "b"), 100.0, rng.normal(size=(2, 500)), f"seg-{i}") for i in range(3)]
    path = files.write_accelerations_h5(recs, tmp_path / "acc.h5", in_memory=False)
    back = read_accelerations(path, ["a", "b"])
    assert [r.segment for r in back] == ["seg-0", "seg-1", "seg-2"]
    assert all(np.array_equal(r.accelerations, s.accelerations) for r, s in zip(back, recs))
    monkeypatch.setattr(files.shutil, "disk_usage", lambda p: type("usage", (), {"free": 1000})())
    with pytest.raises(DataError, match=r"full\.h5: cannot write the file \(only 0 megabytes free on the disk, "
                                        r"about 16 needed\)"):
        files.write_accelerations_h5(recs, tmp_path / "full.h5", in_memory=False)
    assert not (tmp_path / "full.h5").exists() and sorted(p.name for p in tmp_path.iterdir()) == ["acc.h5"]


def test_every_ingested_recording_gets_its_indicators(recordings, tmp_path):
    """ingest writes indicators.json: EN 14363 instability and EN 12299 comfort per segment cut, and the run's."""
    folder, _ = recordings
    r = suspid.ingest(folder / "ingest-csv.yaml", out_dir=tmp_path / "out")
    values = json.loads((r.out_dir / "indicators.json").read_text())["indicators"]
    for name in ("en14363-instability", "en12299-comfort"):
        assert {v["segment"] for v in values if v["name"] == name and v["segment"] is not None} == set(r.segments)
        (run,) = [v for v in values if v["name"] == name and v["segment"] is None]
        assert run["value"] > 0 and run["verdict"] in ("ok", "warning", "alarm")
    assert all(v["limit"] == pytest.approx(5.65) for v in values if v["name"] == "en14363-instability")
