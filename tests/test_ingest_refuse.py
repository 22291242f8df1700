"""Ingest refuses to guess: an alignment peak at the search window's edge, a static 1 g on a vertical channel,
a channel sampled too slowly for the spectra's top frequency.

Each test fails on the ingest that preceded these checks: it reported the edge peak (offset 490.41 m for a true
512.3 m) as the offset, passed the 1 g silently, and interpolated a 20 Hz channel onto the 200 Hz grid.
The recording is ``examples/recordings/make_recordings.py``'s (CSV), edited as a user's messy one would be.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

import suspid
from suspid.data.files import read_accelerations
from suspid.errors import DataError

from conftest import run_cli
from test_ingest import GEN

G = 9.80665
pytestmark = pytest.mark.slow   # the recording is simulated once (shared with test_ingest.py in one session)


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    out = tmp_path_factory.mktemp("refuse")
    truth = GEN.make(out, ["csv"])
    return out, truth


def _columns(folder: Path) -> tuple[list[str], list[str], np.ndarray]:
    lines = (folder / "recording.csv").read_text().splitlines()
    comments = [line for line in lines if line.startswith("#")]
    body = [line for line in lines if line and not line.startswith("#")]
    return comments, body[0].split(","), np.loadtxt(body[1:], delimiter=",")


def _write_csv(path: Path, comments, header, data) -> None:
    with open(path, "w", encoding="utf-8") as fh:
        fh.write("\n".join(comments + [",".join(header)]) + "\n")
        np.savetxt(fh, data, delimiter=",", fmt="%.9g")


def _ingest(folder: Path, name: str, **changes) -> Path:
    data = yaml.safe_load((folder / "ingest-csv.yaml").read_text())
    for key, value in changes.items():
        node = data
        *parents, last = key.split(".")
        for p in parents:
            node = node[p]
        node[last] = value
    data["output"]["dir"] = f"ingested/{name}"
    path = folder / f"ingest-{name}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_offset_beyond_the_search_window_is_found_by_widening_and_said(recording):
    folder, truth = recording
    shift = 512.3 - truth["offset_m"]                 # the track record starts further on: offset 512.3 m
    lines = (folder / "track-record.csv").read_text().splitlines()
    data = np.loadtxt(lines[2:], delimiter=",")
    data[:, 0] += shift
    _write_csv(folder / "track-far.csv", lines[:1], lines[1].split(","), data)
    path = _ingest(folder, "far", **{"track.path": "track-far.csv"})
    r = suspid.ingest(path)
    assert abs(r.offset_m - 512.3) < 1.0, r.offset_m           # was 490.41 m, the window's edge
    widened = [w for w in r.warnings if "widened" in w]
    assert len(widened) == 1 and "+- 500 m" in widened[0], r.warnings
    assert not [w for w in r.warnings if "sign" in w]


@pytest.mark.parametrize("sign", [1, -1])
def test_static_1g_on_verticals_is_removed_with_a_warning_or_refused_strictly(recording, tmp_path, sign):
    folder, _ = recording
    comments, header, data = _columns(folder)
    # ACC_Z_K1 is in mm/s^2, ACC_Z_B1 in g (make_recordings.CHANNELS)
    data[:, header.index("ACC_Z_K1 [mm/s^2]")] += sign * G * 1e3
    data[:, header.index("ACC_Z_B1 [g]")] += sign * 1.0
    _write_csv(folder / f"recording-1g{sign:+d}.csv", comments, header, data)
    path = _ingest(folder, f"1g{sign:+d}", **{"recording.path": f"recording-1g{sign:+d}.csv"})
    r = suspid.ingest(path, out_dir=tmp_path / "out")
    removed = [w for w in r.warnings if "static" in w]
    assert len(removed) == 2 and all(f"{sign:+d} g" in w for w in removed), r.warnings
    assert {w.split(" ")[1] for w in removed} == {"carbody_front_vertical", "bogie_front_vertical"}
    for rec in read_accelerations(r.measurements_path):
        assert np.all(np.abs(rec.accelerations.mean(axis=1)) < 0.05)   # the dynamic part only
    assert abs(r.offset_m - 137.37) < 1.0
    p = run_cli("ingest", str(path), "--strict", "--quiet", "--out", str(tmp_path / "strict"))
    assert p.returncode == 2 and p.stderr.strip().count("\n") == 0, p.stderr
    assert "static" in p.stderr and "carbody_front_vertical" in p.stderr
    assert not (tmp_path / "strict" / "accelerations").exists()


def test_a_channel_sampled_below_the_spectra_nyquist_rate_is_refused(recording, tmp_path):
    from asammdf import MDF, Signal

    folder, _ = recording
    _, header, data = _columns(folder)
    t = data[:, 0]
    mdf = MDF(version="4.10")
    sigs = []
    for name, unit, _ in GEN.CHANNELS.values():
        col = data[:, header.index(f"{name} [{unit}]")]
        if name == "ACC_Y_K2":                                  # a 20 Hz channel beside 200 Hz ones
            sigs.append(Signal(col[::10], t[::10], name=name, unit=unit))
        else:
            sigs.append(Signal(col, t, name=name, unit=unit))
    for s in sigs:
        mdf.append([s])
    mdf.append([Signal(data[:, header.index("V_TRAIN [km/h]")], t, name="V_TRAIN", unit="km/h")])
    mdf.save(folder / "slow.mf4", overwrite=True)
    mdf.close()
    path = _ingest(folder, "slow", **{"recording.path": "slow.mf4", "recording.options": {}})
    with pytest.raises(DataError, match=r"carbody_middle_lateral \('ACC_Y_K2'\) is sampled at 20 Hz, below "
                                        r"2 x spectra.f_max_hz = 60 Hz"):
        suspid.ingest(path, out_dir=tmp_path / "out")
    assert not (tmp_path / "out").exists()
    # the spectra's band within the slow channel's: ingested
    cfg = yaml.safe_load((folder / "suspid.yaml").read_text())
    cfg["spectra"] = {"f_min_hz": 0.5, "f_max_hz": 10.0, "n_freqs": 50}
    (folder / "suspid-10hz.yaml").write_text(yaml.safe_dump(cfg))
    path = _ingest(folder, "slow-10hz", **{"recording.path": "slow.mf4", "recording.options": {},
                                           "config": "suspid-10hz.yaml"})
    r = suspid.ingest(path, out_dir=tmp_path / "ok")
    assert len(r.segments) >= 3


def _curve(x: np.ndarray, start: float, transition: float, body: float, value: float) -> np.ndarray:
    """A design quantity along a curve: 0, a linear ramp over ``transition`` m, ``value`` over ``body`` m, ramp."""
    return value * np.interp(x, [start, start + transition, start + transition + body,
                                 start + 2 * transition + body], [0, 1, 1, 0], left=0, right=0)


def test_curvature_radius_and_cant_are_mapped_and_select_the_segments(recording, tmp_path):
    from suspid.data.files import read_track

    folder, truth = recording
    lines = (folder / "track-record.csv").read_text().splitlines()
    data = np.loadtxt(lines[2:], delimiter=",")
    x = data[:, 0]
    kappa = _curve(x, 3000.0, 300.0, 600.0, -1 / 7000.0)        # a right-hand curve, R = 7000 m
    with np.errstate(divide="ignore"):
        radius = np.where(kappa == 0, 0.0, 1 / np.where(kappa == 0, 1, kappa))   # 0: straight, as cars write
    cant = _curve(x, 3000.0, 300.0, 600.0, -150.0)               # mm, left rail above the right (outer rail)
    _write_csv(folder / "track-curve.csv", lines[:1], lines[1].split(",") + ["RADIUS", "CANT"],
               np.column_stack([data, radius, cant]))
    track = {"track.path": "track-curve.csv", "track.curvature": {"name": "RADIUS", "quantity": "radius", "unit": "m"},
             "track.cant": {"name": "CANT", "unit": "mm"}}
    r = suspid.ingest(_ingest(folder, "curve", **track), out_dir=tmp_path / "all")
    segs = read_track(r.track_path)
    inside = [s for s in segs if np.abs(s.curvature).max() > 0]
    assert inside and len(inside) < len(segs)
    for s in inside:
        assert np.all(s.curvature <= 0) and np.abs(s.curvature).max() == pytest.approx(1 / 7000.0, rel=1e-6)
        assert np.all(s.cant <= 0) and np.abs(s.cant).max() <= 0.150 + 1e-12
        assert s.curvature.shape == s.distance.shape == s.cant.shape
    # straight track only: no segment meets the curve, and the report says why the curve is left out
    r2 = suspid.ingest(_ingest(folder, "straight", **track, **{"segments.max_curvature_per_m": 1e-5}),
                       out_dir=tmp_path / "straight")
    segs2 = read_track(r2.track_path)
    assert segs2 and all(np.abs(s.curvature).max() <= 1e-5 for s in segs2)
    assert len(segs2) < len(segs)
    assert any("|curvature| above segments.max_curvature_per_m" in e["reason"] for e in r2.report["excluded"])
    # the curve only, by its cant
    r3 = suspid.ingest(_ingest(folder, "canted", **track, **{"segments.min_cant_m": 0.1,
                                                             "segments.length_m": 300.0}),
                       out_dir=tmp_path / "canted")
    assert all(np.abs(s.cant).min() >= 0.1 for s in read_track(r3.track_path))
    # a limit without the channel it needs: a config error naming the key
    with pytest.raises(suspid.errors.ConfigError, match=r"segments.min_curvature_per_m / max_curvature_per_m "
                                                        r"need the track record's curvature channel"):
        suspid.ingest(_ingest(folder, "nochannel", **{"segments.max_curvature_per_m": 1e-5}))
