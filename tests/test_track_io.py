"""Track and acceleration files: CSV and HDF5 round trips, and one-line errors for bad files."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from suspid.errors import DataError
from suspid.interfaces import Response, TrackSegment
from suspid.data.files import (read_accelerations, read_accelerations_csv, read_accelerations_h5, read_track,
                               read_track_csv, read_track_h5, write_accelerations_csv, write_accelerations_h5,
                               write_track, write_track_csv, write_track_h5)
from suspid.data.track import synthetic_segments


@pytest.fixture
def segments():
    return synthetic_segments({"n_segments": 3, "length_m": 50.0, "dx_m": 0.25, "speed_kmh": 300.0, "seed": 4})


@pytest.fixture
def responses():
    rng = np.random.default_rng(0)
    chans = ("carbody_front_vertical", "bogie_front_lateral")
    return [Response(chans, 100.0, rng.standard_normal((2, 500)), f"seg-{i}") for i in range(3)]


def same_segment(a: TrackSegment, b: TrackSegment):
    assert a.name == b.name
    assert np.array_equal(a.distance, b.distance)
    assert np.array_equal(a.irregularities, b.irregularities)
    assert np.array_equal(np.asarray(a.speed), np.asarray(b.speed))


# ------------------------------------------------------------------------------------------ round trips
def test_track_csv_round_trip_constant_and_variable_speed(tmp_path, segments):
    seg = segments[0]
    same_segment(read_track_csv(write_track_csv(seg, tmp_path / "a.csv")), seg)
    varying = TrackSegment("ramp", seg.distance, seg.irregularities, np.linspace(50.0, 70.0, seg.distance.size))
    back = read_track_csv(write_track_csv(varying, tmp_path / "b.csv"))
    same_segment(back, varying)
    assert (tmp_path / "b.csv").read_text().splitlines()[2].endswith(",speed_mps")


def test_track_csv_columns_in_any_order_and_name_from_file(tmp_path):
    (tmp_path / "my-seg.csv").write_text(
        "# a comment\n# speed_mps: 50\ngauge_m,distance_m,vertical_m,cross_level_m,lateral_m\n"
        "0.0,0.0,0.001,0.0,0.002\n0.001,0.5,0.002,0.0,0.003\n0.002,1.0,0.003,0.0,0.004\n")   # gauge: mm, as tracks have
    seg = read_track_csv(tmp_path / "my-seg.csv")
    assert seg.name == "my-seg" and seg.speed == 50.0
    assert np.allclose(seg.irregularities[0], [0.001, 0.002, 0.003])   # vertical
    assert np.allclose(seg.irregularities[1], [0.002, 0.003, 0.004])   # lateral
    assert np.allclose(seg.irregularities[3], [0.0, 0.001, 0.002])     # gauge


def test_track_h5_round_trip_keeps_order(tmp_path, segments):
    segs = [segments[2], segments[0], segments[1]]
    back = read_track_h5(write_track_h5(segs, tmp_path / "t.h5"))
    assert [s.name for s in back] == [s.name for s in segs]
    for a, b in zip(back, segs):
        same_segment(a, b)


def test_track_folder_and_any_path(tmp_path, segments):
    write_track(segments, tmp_path / "csvs")
    assert [s.name for s in read_track(tmp_path / "csvs")] == [s.name for s in segments]
    write_track(segments, tmp_path / "t.hdf5")
    assert len(read_track(tmp_path / "t.hdf5")) == 3
    assert read_track(tmp_path / "csvs" / f"{segments[1].name}.csv")[0].name == segments[1].name


def test_accelerations_csv_round_trip_with_and_without_time(tmp_path, responses):
    r = responses[0]
    for with_time in (True, False):
        back = read_accelerations_csv(write_accelerations_csv(r, tmp_path / f"r{with_time}.csv", with_time))
        assert back.channels == r.channels and back.fs == pytest.approx(100.0) and back.segment == "seg-0"
        assert np.array_equal(back.accelerations, r.accelerations)


def test_accelerations_h5_round_trip_and_channel_order(tmp_path, responses):
    path = write_accelerations_h5(responses, tmp_path / "a.h5")
    back = read_accelerations_h5(path)
    assert [b.segment for b in back] == ["seg-0", "seg-1", "seg-2"]
    assert np.array_equal(back[1].accelerations, responses[1].accelerations)
    swapped = read_accelerations(path, channels=["bogie_front_lateral", "carbody_front_vertical"])
    assert np.array_equal(swapped[0].accelerations, responses[0].accelerations[::-1])
    write_accelerations_csv(responses[0], tmp_path / "csv" / "x.csv")
    assert read_accelerations(tmp_path / "csv")[0].segment == "seg-0"


# ------------------------------------------------------------------------------------------ bad files
GOOD_HEADER = "distance_m,vertical_m,lateral_m,cross_level_m,gauge_m"


@pytest.mark.parametrize("text, message", [
    (f"# speed_mps: 50\n{GOOD_HEADER}\n0,0,0,0,0\n0.25,0,0,0\n", "line 4: 4 values, but the header has 5"),
    (f"# speed_mps: 50\n{GOOD_HEADER}\n0,0,0,0,0\n0.25,nan,0,0,0\n", "NaN or inf in column 'vertical_m'"),
    (f"# speed_mps: 50\n{GOOD_HEADER}\n0,0,0,0,0\n0.25,inf,0,0,0\n", "NaN or inf"),
    (f"# speed_mps: 50\n{GOOD_HEADER}\n0.5,0,0,0,0\n0.25,0,0,0,0\n", "distance must increase"),
    (f"# speed_mps: 50\n{GOOD_HEADER}\n0,0,0,0,0\n0.25,0,0,0,0\n0.75,0,0,0,0\n", "distance step must be uniform"),
    ("# speed_mps: 50\ndistance_m,vertical_m,lateral_m,cross_level_m\n0,0,0,0\n1,0,0,0\n",
     "missing column(s) gauge_m"),
    (f"{GOOD_HEADER}\n0,0,0,0,0\n0.25,0,0,0,0\n", "no speed"),
    (f"# speed_mps: 50\n{GOOD_HEADER},speed_mps\n0,0,0,0,0,50\n0.25,0,0,0,0,50\n", "speed given twice"),
    (f"# speed_mps: fast\n{GOOD_HEADER}\n0,0,0,0,0\n0.25,0,0,0,0\n", "speed_mps 'fast' is not a number"),
    (f"# speed_mps: -5\n{GOOD_HEADER}\n0,0,0,0,0\n0.25,0,0,0,0\n", "speed must be positive"),
    (f"# speed_mps: 50\n{GOOD_HEADER}\n0,0,0,0,0\n0.25,0,x1,0,0\n", "line 4: 'x1' is not a number"),
    (f"# speed_mps: 50\n{GOOD_HEADER}\n0,0,0,0,0\n", "at least 2 distance samples"),
    ("# only comments\n", "no header line"),
    (f"# speed_mps: 50\n{GOOD_HEADER},vertical_m\n", "repeated column names"),
])
def test_bad_track_csv_raises_one_line_naming_the_file(tmp_path, text, message):
    assert_one_line_error(read_track_csv, tmp_path / "bad.csv", text, message)


def assert_one_line_error(reader, path, text, message):
    """``reader(path)`` on a file holding ``text`` raises one DataError line: file name, then ``message``."""
    path.write_text(text)
    with pytest.raises(DataError) as err:
        reader(path)
    msg = str(err.value)
    assert msg.startswith(str(path)) and message in msg and "\n" not in msg


@pytest.mark.parametrize("text, message", [
    ("# fs_hz: 100\na,b\n1,2\n3\n", "line 4: 1 values"),
    ("# fs_hz: 100\na,b\n1,2\nnan,3\n", "NaN or inf in channel 'a'"),
    ("a,b\n1,2\n3,4\n", "no sampling rate"),
    ("time_s,a\n0,1\n0.01,2\n0.005,3\n", "time must increase"),
    ("time_s,a\n0,1\n0.01,2\n0.03,3\n", "time step must be uniform"),
    ("# fs_hz: 50\ntime_s,a\n0,1\n0.01,2\n0.02,3\n", "disagrees with the time column"),
    ("# fs_hz: 0\na\n1\n2\n", "fs_hz must be positive"),
    ("# fs_hz: 100\ntime_s\n0\n0.01\n", "no channel columns"),
    ("# fs_hz: 100\na\n1\n", "at least 2 samples"),
])
def test_bad_acceleration_csv_raises_one_line_naming_the_file(tmp_path, text, message):
    assert_one_line_error(read_accelerations_csv, tmp_path / "acc.csv", text, message)


def test_missing_channel_is_named(tmp_path, responses):
    path = write_accelerations_csv(responses[0], tmp_path / "r.csv")
    with pytest.raises(DataError, match="missing channel\\(s\\) carbody_rear_vertical"):
        read_accelerations_csv(path, channels=["carbody_front_vertical", "carbody_rear_vertical"])
    h5 = write_accelerations_h5(responses, tmp_path / "r.h5")
    with pytest.raises(DataError, match=f"{h5}: segment 'seg-0': missing channel"):
        read_accelerations_h5(h5, channels=["nope"])


def test_bad_h5_files(tmp_path, segments, responses):
    with pytest.raises(DataError, match="file not found"):
        read_track_h5(tmp_path / "none.h5")
    (tmp_path / "text.h5").write_text("not hdf5")
    with pytest.raises(DataError, match="not a readable HDF5 file"):
        read_track_h5(tmp_path / "text.h5")
    acc = write_accelerations_h5(responses, tmp_path / "acc.h5")
    with pytest.raises(DataError, match="format attribute is 'suspid-accelerations', expected 'suspid-track'"):
        read_track_h5(acc)
    trk = write_track_h5(segments, tmp_path / "trk.h5")
    with h5py.File(trk, "a") as f:
        del f["segments"][segments[0].name]["speed"]
    with pytest.raises(DataError, match=f"segment '{segments[0].name}': missing dataset 'speed'"):
        read_track_h5(trk)
    trk2 = write_track_h5(segments, tmp_path / "trk2.h5")
    with h5py.File(trk2, "a") as f:
        d = f["segments"][segments[1].name]["irregularities"]
        data = d[()]
        data[0, 3] = np.nan
        d[...] = data
    with pytest.raises(DataError, match="NaN or inf"):
        read_track_h5(trk2)
    with h5py.File(acc, "a") as f:
        del f["segments"]["seg-1"]["accelerations"].attrs["fs_hz"]
    with pytest.raises(DataError, match="no 'fs_hz' attribute"):
        read_accelerations_h5(acc)


def test_writers_refuse_bad_data(tmp_path, segments):
    bad = TrackSegment("short", segments[0].distance, segments[0].irregularities[:, :-1], 50.0)
    with pytest.raises(DataError, match="do not match"):
        write_track_csv(bad, tmp_path / "x.csv")
    with pytest.raises(DataError, match="unique"):
        write_track_h5([segments[0], segments[0]], tmp_path / "x.h5")
    with pytest.raises(DataError, match="folder holds no .csv"):
        (tmp_path / "empty").mkdir()
        read_track(tmp_path / "empty")
