"""Faulty track and acceleration files: one-line errors naming the file; impossible data refused, unusual warned.

Every case: the reader raises a :class:`suspid.errors.SuspidError` subclass
whose message is one line naming the file (and the segment, dataset or
attribute), and the file read is left byte for byte as it was.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import warnings
from pathlib import Path
from typing import Callable

import h5py
import numpy as np
import pytest

from suspid.data.files import (read_accelerations, read_accelerations_csv, read_accelerations_h5,
                               read_accelerations_records, read_track, read_track_csv, read_track_h5,
                               write_accelerations_csv, write_accelerations_h5, write_track, write_track_csv,
                               write_track_h5)
from suspid.data.track import synthetic_segments
from suspid.errors import DataError, DataWarning, SuspidError
from suspid.interfaces import Response

ROOT_USER = hasattr(os, "geteuid") and os.geteuid() == 0
CHANNELS = ("carbody_front_vertical", "bogie_front_lateral")


def segments(n: int = 2):
    return synthetic_segments({"n_segments": n, "length_m": 50.0, "dx_m": 0.25, "speed_kmh": 300.0, "seed": 4})


def record(name: str = "seg-001", fs: float = 100.0, scale: float = 0.5, n: int = 400, seed: int = 0) -> Response:
    return Response(CHANNELS, fs, scale * np.random.default_rng(seed).standard_normal((2, n)), name)


def snapshot(path: Path) -> dict[str, bytes]:
    """Contents of a file or of every file under a folder (what must survive a failed read)."""
    if path.is_dir():
        return {str(p): p.read_bytes() for p in sorted(path.rglob("*")) if p.is_file()}
    return {str(path): path.read_bytes()} if path.is_file() else {}


def assert_one_line(exc: BaseException, *fragments: str) -> None:
    msg = str(exc)
    assert isinstance(exc, SuspidError), type(exc)
    assert "\n" not in msg and "Traceback" not in msg, msg
    for f in fragments:
        assert f in msg, f"{f!r} not in {msg!r}"


# ------------------------------------------------------------------------------------------ the cases
# Each case builds its files under tmp and returns (read, path, fragments): read() must raise DataError
# with every fragment in its message; path is the file or folder read (unchanged afterwards).
Case = Callable[[Path], tuple[Callable[[], object], Path, list[str]]]
CASES: dict[str, Case] = {}


def case(fn: Case) -> Case:
    CASES[fn.__name__] = fn
    return fn


@case
def duplicate_track_names_in_folder(tmp):
    a, b = segments(2)
    write_track_csv(a, tmp / "t" / "a.csv")
    b.name = a.name
    write_track_csv(b, tmp / "t" / "b.csv")
    return lambda: read_track(tmp / "t"), tmp / "t", [str(tmp / "t" / "b.csv"), f"'{a.name}'", str(tmp / "t" / "a.csv")]


@case
def duplicate_acceleration_records_in_folder(tmp):
    write_accelerations_csv(record("seg-001"), tmp / "m" / "day1.csv")
    write_accelerations_csv(record("seg-001", seed=1), tmp / "m" / "day2.csv")
    return (lambda: read_accelerations(tmp / "m"), tmp / "m",
            [str(tmp / "m" / "day2.csv"), "'seg-001'", str(tmp / "m" / "day1.csv")])


@case
def duplicate_in_h5_order_accelerations(tmp):
    path = write_accelerations_h5([record("s0"), record("s1")], tmp / "a.h5")
    with h5py.File(path, "a") as f:
        f["segments"].attrs["order"] = ["s0", "s1", "s0"]
    return lambda: read_accelerations_h5(path), path, [str(path), "lists segment 's0' twice", "entries 1 and 3"]


@case
def duplicate_in_h5_order_track(tmp):
    segs = segments(2)
    path = write_track_h5(segs, tmp / "t.h5")
    with h5py.File(path, "a") as f:
        f["segments"].attrs["order"] = [segs[1].name, segs[1].name]
    return lambda: read_track_h5(path), path, [str(path), f"lists segment '{segs[1].name}' twice"]


@case
def h5_segment_not_in_order(tmp):
    path = write_accelerations_h5([record("s0"), record("s1")], tmp / "a.h5")
    with h5py.File(path, "a") as f:
        f["segments"].attrs["order"] = ["s0"]
    return lambda: read_accelerations_h5(path), path, [str(path), "does not list: s1"]


def _h5_acc(tmp, edit):
    path = write_accelerations_h5([record("s0"), record("s1")], tmp / "a.h5")
    with h5py.File(path, "a") as f:
        edit(f)
    return path


@case
def h5_fs_hz_is_text(tmp):
    path = _h5_acc(tmp, lambda f: f["segments/s1/accelerations"].attrs.__setitem__("fs_hz", "100 Hz"))
    return (lambda: read_accelerations_h5(path), path,
            [str(path), "/segments/s1/accelerations: attribute 'fs_hz' must be one real number", "'100 Hz'"])


@case
def h5_fs_hz_is_an_array(tmp):
    path = _h5_acc(tmp, lambda f: f["segments/s0/accelerations"].attrs.__setitem__("fs_hz", [100.0, 200.0]))
    return lambda: read_accelerations_h5(path), path, [str(path), "'fs_hz' must be one real number", "shape (2,)"]


@case
def h5_channels_are_numbers(tmp):
    path = _h5_acc(tmp, lambda f: f.attrs.__setitem__("channels", [1, 2]))
    return lambda: read_accelerations_h5(path), path, [str(path), "root attribute 'channels' must be a list of names"]


@case
def h5_order_is_numbers(tmp):
    path = _h5_acc(tmp, lambda f: f["segments"].attrs.__setitem__("order", np.arange(2)))
    return lambda: read_accelerations_h5(path), path, [str(path), "'order' must be a list of names"]


@case
def h5_format_is_a_number(tmp):
    path = _h5_acc(tmp, lambda f: f.attrs.__setitem__("format", 7))
    return (lambda: read_accelerations_h5(path), path,
            [str(path), "format attribute is", "expected 'suspid-accelerations'"])


@case
def h5_format_missing(tmp):
    path = _h5_acc(tmp, lambda f: f.attrs.__delitem__("format"))
    return lambda: read_accelerations_h5(path), path, [str(path), "no format attribute"]


def _replace(f, name, data):
    attrs = dict(f[name].attrs)
    del f[name]
    d = f.create_dataset(name, data=data)
    d.attrs.update(attrs)


@case
def h5_complex_accelerations(tmp):
    path = _h5_acc(tmp, lambda f: _replace(f, "segments/s0/accelerations",
                                           record("s0").accelerations * (1 + 0.5j)))
    return lambda: read_accelerations_h5(path), path, [str(path), "/segments/s0/accelerations: complex values"]


@case
def h5_text_irregularities(tmp):
    segs = segments(1)
    path = write_track_h5(segs, tmp / "t.h5")
    with h5py.File(path, "a") as f:
        _replace(f, f"segments/{segs[0].name}/irregularities",
                 np.array([["0.001"] * segs[0].distance.size] * 4, dtype="S8"))
    return lambda: read_track_h5(path), path, [str(path), "irregularities: values of type", "not numbers"]


@case
def h5_dataset_is_a_group(tmp):
    def edit(f):
        del f["segments/s1/accelerations"]
        f["segments/s1"].create_group("accelerations")
    path = _h5_acc(tmp, edit)
    return lambda: read_accelerations_h5(path), path, [str(path), "/segments/s1/accelerations is a group"]


@case
def h5_truncated(tmp):
    path = write_accelerations_h5([record("s0", n=4000), record("s1", n=4000)], tmp / "a.h5")
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    return lambda: read_accelerations_h5(path), path, [str(path), "HDF5 file"]


@case
def h5_flipped_bits_give_absurd_values(tmp):
    def edit(f):
        d = f["segments/s1/accelerations"]
        a = d[()]
        a[1, 17] = 1e300
        d[...] = a
    path = _h5_acc(tmp, edit)
    return (lambda: read_accelerations_h5(path), path,
            [str(path), "segment 's1'", "channel 'bogie_front_lateral' holds 1e+300 m/s^2 at sample 17", "damaged"])


@case
def h5_flipped_bit_caught_by_the_checksum(tmp):
    path = write_accelerations_h5([record("s0"), record("s1")], tmp / "a.h5")
    with h5py.File(path, "r") as f:
        offset = f["segments/s1/accelerations"].id.get_chunk_info(0).byte_offset
    data = bytearray(path.read_bytes())
    data[offset + 100] ^= 0x10        # one bit of one sample: a plausible value, found by Fletcher-32
    path.write_bytes(bytes(data))
    return lambda: read_accelerations_h5(path), path, [str(path), "damaged or unreadable HDF5 file"]


@case
def csv_absurd_acceleration(tmp):
    path = write_accelerations_csv(record(), tmp / "r.csv")
    lines = path.read_text().splitlines()
    lines[10] = lines[10].rsplit(",", 1)[0] + ",-3e12"
    path.write_text("\n".join(lines) + "\n")
    return lambda: read_accelerations_csv(path), path, [str(path), "holds -3e+12 m/s^2", "|value| > 1e+06"]


@case
def csv_absurd_track(tmp):
    path = write_track_csv(segments(1)[0], tmp / "t.csv")
    lines = path.read_text().splitlines()
    cells = lines[20].split(",")
    cells[2] = "5e9"
    lines[20] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")
    return lambda: read_track_csv(path), path, [str(path), "channel 'lateral' holds 5e+09 m"]


@case
def unreadable_csv(tmp):
    if ROOT_USER:   # root reads any file: a folder where the file should be is what it cannot read
        path = tmp / "r.csv"
        path.mkdir()
        return lambda: read_accelerations_csv(path), path, [str(path), "is a folder, not a file"]
    path = write_accelerations_csv(record(), tmp / "r.csv")
    path.chmod(0)
    return lambda: read_accelerations_csv(path), path, [str(path), "cannot read the file (permission denied)"]


@case
def unreadable_h5(tmp):
    if ROOT_USER:
        path = tmp / "folder.h5"
        path.mkdir()
        return lambda: read_accelerations_h5(path), path, [str(path), "is a folder, not a file"]
    path = write_accelerations_h5([record()], tmp / "a.h5")
    path.chmod(0)
    return lambda: read_accelerations_h5(path), path, [str(path), "permission denied"]


@case
def folder_entry_is_not_a_file(tmp):
    write_track_csv(segments(1)[0], tmp / "t" / "a.csv")
    (tmp / "t" / "b.csv").mkdir()
    return lambda: read_track(tmp / "t"), tmp / "t", [str(tmp / "t" / "b.csv"), "is a folder, not a file"]


@case
def not_utf8(tmp):
    path = tmp / "r.csv"
    path.write_bytes("# fs_hz: 100\n# sensor: 20 \u00b0C\na\n1\n2\n".encode("latin-1"))
    return lambda: read_accelerations_csv(path), path, [str(path), "not UTF-8 text (byte 0xb0", "save it as UTF-8"]


@case
def nul_bytes(tmp):
    path = tmp / "r.csv"
    path.write_bytes(b"# fs_hz: 100\na,b\n1,2\n\x00\x00,3\n")
    return lambda: read_accelerations_csv(path), path, [str(path), "line 4"]


@case
def sampling_rates_differ_between_files(tmp):
    write_accelerations_csv(record("seg-001", fs=100.0), tmp / "m" / "a.csv")
    write_accelerations_csv(record("seg-002", fs=101.5), tmp / "m" / "b.csv")
    return (lambda: read_accelerations(tmp / "m"), tmp / "m",
            [str(tmp / "m" / "b.csv"), "sampling rate 101.5 Hz differs by 1.5 %", str(tmp / "m" / "a.csv")])


@case
def sampling_rates_differ_in_h5(tmp):
    path = write_accelerations_h5([record("s0"), record("s1", fs=98.5)], tmp / "a.h5")
    return lambda: read_accelerations_records(path), path, [str(path), "98.5 Hz differs by 1.5 %", "segment 's0'"]


@case
def fs_hz_disagrees_with_time_column(tmp):
    path = write_accelerations_csv(record(fs=100.0), tmp / "r.csv")
    path.write_text(path.read_text().replace("# fs_hz: 100.0", "# fs_hz: 101.5"))
    return lambda: read_accelerations_csv(path), path, [str(path), "fs_hz = 101.5 disagrees with the time column"]


@pytest.mark.parametrize("name", sorted(CASES))
def test_faulty_file_gives_one_line_and_keeps_the_file(tmp_path, name):
    read, path, fragments = CASES[name](tmp_path)
    before = snapshot(path)
    with pytest.raises(DataError) as err:
        read()
    assert_one_line(err.value, *fragments)
    assert snapshot(path) == before


@pytest.mark.parametrize("kind", ["accelerations.h5", "track.h5", "track.csv"])
def test_damaged_bytes_anywhere_give_a_data_error_or_a_good_read(tmp_path, kind):
    """16 random bytes written over a file suspid wrote, every 211 bytes: never anything but DataError.

    (HDF5 files of the older format, without metadata checksums, can make the HDF5 library itself loop
    forever on some damaged bytes; suspid writes the 1.10 format, whose metadata carry checksums.)
    """
    path = tmp_path / kind
    if kind == "accelerations.h5":
        write_accelerations_h5([record("s0", n=300), record("s1", n=300)], path)
        read = read_accelerations_h5
    else:
        write_track(segments(2), path) if kind.endswith(".h5") else write_track_csv(segments(1)[0], path)
        read = read_track
    good = path.read_bytes()
    expected = [np.asarray(getattr(x, "accelerations", getattr(x, "irregularities", None))) for x in read(path)]
    rng = np.random.default_rng(0)
    outcomes = set()
    for offset in range(0, len(good), 211):
        data = bytearray(good)
        data[offset:offset + 16] = rng.integers(0, 256, 16, dtype=np.uint8).tobytes()
        path.write_bytes(bytes(data))
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", DataWarning)
                back = read(path)
            for x, e in zip(back, expected):   # read despite the damage: then the data are intact
                assert np.array_equal(getattr(x, "accelerations", getattr(x, "irregularities", None)), e)
            outcomes.add("read")
        except DataError as exc:
            assert_one_line(exc, str(path))
            outcomes.add("DataError")
    assert "DataError" in outcomes


# ------------------------------------------------------------------------------------------ plausibility
def _acc_file(tmp, edit_channel):
    r = record()
    a = r.accelerations.copy()
    a[0] = edit_channel(a[0])
    return write_accelerations_csv(Response(r.channels, r.fs, a, r.segment), tmp / "r.csv")


IMPOSSIBLE = {   # values no train in service gives: (file, reader, the check, words of the one-line error)
    "accelerations_in_mm_per_s2": (lambda tmp: _acc_file(tmp, lambda a: a * 1000.0), read_accelerations,
                                   "implausible_amplitude", "channel 'carbody_front_vertical' vibrates with 498 m/s^2 "
                                   "rms, beyond a carbody of a train in service (at most 20 m/s^2)"),
    "dead_channel_all_zero": (lambda tmp: _acc_file(tmp, lambda a: 0.0 * a), read_accelerations, "dead_channel",
                              "channel 'carbody_front_vertical' is constant: a dead or disconnected sensor"),
    "dead_channel_tiny_rms": (lambda tmp: _acc_file(tmp, lambda a: 1e-8 * a), read_accelerations, "dead_channel",
                              "below the noise of any working accelerometer"),
    "track_in_mm": (lambda tmp: write_track([_scaled(segments(1)[0], 1000.0)], tmp / "t.h5"), read_track,
                    "implausible_amplitude", "in the 3-25 m wavelength band (EN 13848 D1), beyond any track open to "
                                             "traffic (at most 0.05 m): values in mm instead of m?"),
    "speed_in_kmh": (lambda tmp: write_track_csv(_speed(segments(1)[0], 300.0), tmp / "t.csv"), read_track,
                     "implausible_speed", "speed 300 m/s (1080 km/h) is above any train's"),
}

UNUSUAL = {   # possible but unusual: a warning, an error in strict mode
    "carbody_vibrating_5_m_per_s2": (lambda tmp: _acc_file(tmp, lambda a: a * 10.0), read_accelerations,
                                     "more than a carbody of a train in service usually does (up to 2 m/s^2)"),
    "track_d1_rms_25_mm": (lambda tmp: write_track([_d1(segments(1)[0], 0.025)], tmp / "t.h5"), read_track,
                           "more than a track in service usually has (up to 0.015 m)"),
    "speed_400_kmh": (lambda tmp: write_track_csv(_speed(segments(1)[0], 400 / 3.6), tmp / "t.csv"), read_track,
                      "is above every commercial service (100 m/s)"),
}


def _scaled(seg, k):
    seg.irregularities = seg.irregularities * k
    return seg


def _d1(seg, rms):
    """The segment scaled so that its vertical channel has ``rms`` (m) in the D1 band."""
    from suspid.data.plausibility import d1_rms

    return _scaled(seg, rms / d1_rms(seg.irregularities[0], float(seg.distance[1] - seg.distance[0])))


def _speed(seg, v):
    seg.speed = v
    return seg


@pytest.mark.parametrize("name", sorted(IMPOSSIBLE))
def test_impossible_data_are_refused_unless_the_check_is_accepted(tmp_path, name):
    """Each read with a warning before; now one line naming the file, the channel, the limit and the key that
    accepts it; with the check in ``accept`` the data are read, with one warning."""
    make, read, check, fragment = IMPOSSIBLE[name]
    path = make(tmp_path)
    with pytest.raises(DataError) as err:
        read(path)
    assert_one_line(err.value, str(path), fragment, f"(if these values are right, add {check} to data.accept)")
    others = [c for c in ("implausible_amplitude", "dead_channel", "implausible_speed") if c != check]
    with pytest.raises(DataError):
        read(path, accept=others)            # another check accepted: still refused
    with pytest.warns(DataWarning) as caught:
        read(path, accept=[check])
    msgs = [str(w.message) for w in caught if issubclass(w.category, DataWarning)]
    assert len(msgs) == 1 and fragment in msgs[0] and msgs[0].startswith(str(path)) and "\n" not in msgs[0]
    assert f"accepted: {check} in data.accept" in msgs[0]


@pytest.mark.parametrize("name", sorted(UNUSUAL))
def test_unusual_data_warn_and_strict_refuses(tmp_path, name):
    make, read, fragment = UNUSUAL[name]
    path = make(tmp_path)
    with pytest.warns(DataWarning) as caught:
        read(path)
    msgs = [str(w.message) for w in caught if issubclass(w.category, DataWarning)]
    assert len(msgs) == 1 and fragment in msgs[0] and msgs[0].startswith(str(path)) and "\n" not in msgs[0]
    with pytest.raises(DataError) as err:
        read(path, strict=True)
    assert_one_line(err.value, str(path), fragment, "strict")


def test_plausible_data_give_no_warning(tmp_path, recwarn):
    read_track(write_track(segments(2), tmp_path / "t.h5"))
    read_accelerations(write_accelerations_h5([record("a"), record("b")], tmp_path / "a.h5"), strict=True)
    assert not [w for w in recwarn if issubclass(w.category, DataWarning)]


@pytest.mark.parametrize("spectrum", ["german-low", "german-high", "fra-1", "fra-6"])
def test_every_published_track_spectrum_is_plausible(tmp_path, spectrum, recwarn):
    """The worst US class (FRA 1) included: its long wavelengths make the raw rms 0.15 m, the D1 band's 8 mm."""
    segs = synthetic_segments({"n_segments": 2, "length_m": 2000.0, "spectrum": spectrum, "seed": 1})
    read_track(write_track(segs, tmp_path / "t.h5"), strict=True)
    assert not [w for w in recwarn if issubclass(w.category, DataWarning)]


# ------------------------------------------------------------------------------------------ accepted
@pytest.mark.parametrize("kind", ["track", "accelerations"])
def test_utf8_bom_is_accepted(tmp_path, kind):
    if kind == "track":
        seg = segments(1)[0]
        path = write_track_csv(seg, tmp_path / "t.csv")
        path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())
        back = read_track_csv(path)
        assert back.name == seg.name and np.array_equal(back.irregularities, seg.irregularities)
    else:
        path = tmp_path / "r.csv"
        path.write_bytes("\ufefftime_s,a\r\n0,0.1\r\n0.01,-0.2\r\n0.02,0.3\r\n".encode("utf-8"))
        r = read_accelerations_csv(path)
        assert r.channels == ("a",) and r.fs == pytest.approx(100.0)


def test_hidden_files_in_a_folder_are_left_out(tmp_path):
    write_accelerations_csv(record("seg-001"), tmp_path / "m" / "a.csv")
    (tmp_path / "m" / "._a.csv").write_bytes(b"\x00\x05\x16\x07 resource fork")   # what macOS leaves
    assert [r.segment for r in read_accelerations(tmp_path / "m")] == ["seg-001"]


# ------------------------------------------------------------------------------------------ writers
WRITE_BIG = textwrap.dedent("""
    import resource, signal, sys
    import numpy as np
    from suspid.data.files import write_accelerations_csv, write_accelerations_h5
    from suspid.errors import SuspidError
    from suspid.interfaces import Response
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)      # a full disk: writes fail with EFBIG
    resource.setrlimit(resource.RLIMIT_FSIZE, (200_000, 200_000))
    r = Response(("a", "b"), 100.0, np.random.default_rng(1).standard_normal((2, 50_000)), "seg-001")
    write = write_accelerations_h5 if sys.argv[1].endswith(".h5") else write_accelerations_csv
    try:
        write([r] if sys.argv[1].endswith(".h5") else r, sys.argv[1])
    except SuspidError as exc:
        print(type(exc).__name__, exc)
""")


@pytest.mark.parametrize("name", ["r.csv", "a.h5"])
def test_a_failed_write_keeps_the_previous_file(tmp_path, name):
    path = tmp_path / name
    if name.endswith(".h5"):
        write_accelerations_h5([record("seg-001", n=200)], path)
    else:
        write_accelerations_csv(record("seg-001", n=200), path)
    before = path.read_bytes()
    script = tmp_path / "big.py"
    script.write_text(WRITE_BIG)
    out = subprocess.run([sys.executable, str(script), str(path)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    line = out.stdout.strip()
    assert line.startswith(f"DataError {path}: cannot write the file (") and "\n" not in line, line
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([name, "big.py"])   # no temporary file left


def test_the_most_specific_channel_kind_sets_the_limit():
    """An axlebox of a bogie is judged as an axlebox (it was 'bogie': 250 m/s^2 rms refused as mm/s^2);
    numbered and short names find their kind too."""
    from suspid.data.plausibility import acceleration_doubts, kind_of

    assert kind_of("bogie_front_axlebox_vertical") == "axlebox"
    assert kind_of("car1_z") == "carbody" and kind_of("bogie_rear_lateral") == "bogie" and kind_of("x_y") is None
    assert not [d for d in acceleration_doubts("bogie_front_axlebox_vertical", 250.0, False) if d.check]
    assert [d.check for d in acceleration_doubts("car1_z", 200.0, False)] == ["implausible_amplitude"]


def test_a_line_gradient_is_no_d1_irregularity():
    """A 0.5 % gradient over 1 km under 2 mm of irregularity: the D1 rms is that of the irregularity (the
    untreated gradient's wrap-around put it at 0.17 m, refused as track in mm)."""
    from suspid.data.plausibility import d1_rms

    rng = np.random.default_rng(0)
    step, n = 0.25, 4000
    x = 0.002 * rng.standard_normal(n)
    flat, sloped = d1_rms(x, step), d1_rms(x + 0.005 * step * np.arange(n), step)
    assert 0.0005 < flat < 0.002 and abs(sloped - flat) < 1e-3 * flat
