"""Sizes checked before allocating: an array a file declares is checked against the shape expected, the bytes
the file holds and the memory available before anything is allocated.

The two cases of the acceptance run in a subprocess under an address-space limit (``RLIMIT_AS``) far below
what the file declares: a ``noise_model.npz`` whose ``mean`` declares (200000, 200000) float64 (320 GB) in a
file of 1 MB, given to ``suspid validate`` by a config's ``noise.path``, and a 2 GB CSV recording of NUL bytes
(a sparse file) given to ``suspid ingest``. Each is one line naming the file, exit code 2, within a second.
The others are table-driven: the ledger's arrays, HDF5 datasets, a CSV without newlines, a MAT variable.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import numpy as np
import pytest
import yaml
from numpy.lib import format as npy

from suspid.errors import DataError, LedgerError
from suspid.infra.arrays import CheckedNpz, available_memory, check_fits, load_npy_bytes
from suspid.method.noise import NoiseModel

LIMIT = 1_500_000_000
"""RLIMIT_AS of the subprocess, bytes: suspid with numpy, scipy, GPy and exudyn imported maps about 0.7 GB."""


def _npy(shape, dtype="<f8", data: bytes = b"") -> bytes:
    """An ``.npy`` image whose header declares ``shape``, followed by ``data`` (whatever it holds)."""
    import io

    buf = io.BytesIO()
    npy.write_array_header_1_0(buf, {"descr": dtype, "fortran_order": False, "shape": tuple(shape)})
    return buf.getvalue() + data


def _noise_model(tmp_path: Path, n_channels: int = 4, n_freqs: int = 200) -> Path:
    rng = np.random.default_rng(0)
    model = NoiseModel().fit(rng.normal(0.0, 1.0, (20, n_channels, n_freqs)), freqs=np.linspace(0.5, 20, n_freqs),
                             channels=[f"c{i}" for i in range(n_channels)])
    return model.save(tmp_path / "good_model.npz")


def _altered(source: Path, out: Path, member: str, image: bytes) -> Path:
    """``source`` with ``member`` replaced by ``image`` (the other members as they were)."""
    with zipfile.ZipFile(source) as zin, zipfile.ZipFile(out, "w") as zout:
        for info in zin.infolist():
            zout.writestr(info.filename, image if info.filename == f"{member}.npy" else zin.read(info))
    return out


def _absurd_noise_model(tmp_path: Path) -> Path:
    """A noise model whose ``mean`` declares (200000, 200000) float64 in a file of about 1 MB."""
    return _altered(_noise_model(tmp_path), tmp_path / "noise_model.npz", "mean",
                    _npy((200_000, 200_000), data=bytes(860_000)))


def _limited(argv: list[str], cwd: Path) -> tuple[subprocess.CompletedProcess, float]:
    """``suspid argv`` in a subprocess whose address space is limited to :data:`LIMIT`: the libraries are imported
    first, then only the command is timed (seconds, printed by the child)."""
    driver = textwrap.dedent(f"""
        import resource, sys, time
        resource.setrlimit(resource.RLIMIT_AS, ({LIMIT}, {LIMIT}))
        import suspid.api, suspid.cli, suspid.registry
        suspid.registry.registry()
        t0 = time.perf_counter()
        try:
            suspid.cli.main({argv!r})
        except SystemExit as exc:
            code = exc.code
        sys.stdout.write(f"\\nelapsed {{time.perf_counter() - t0:.3f}} code {{code}}\\n")
    """)
    p = subprocess.run([sys.executable, "-c", driver], capture_output=True, text=True, cwd=cwd, timeout=120)
    elapsed = float(p.stdout.rsplit("elapsed ", 1)[1].split()[0]) if "elapsed " in p.stdout else float("inf")
    return p, elapsed


def test_a_noise_model_declaring_320_gb_in_1_mb_is_one_line_within_a_second_under_a_memory_limit(tmp_path):
    model = _absurd_noise_model(tmp_path)
    assert 0.9e6 < model.stat().st_size < 1.0e6
    config = tmp_path / "run.yaml"
    config.write_text(yaml.safe_dump({
        "name": "absurd", "simulator": {"plugin": "exudyn-train", "options": {"solver": "frequency"}},
        "parameters": {"c_yaw": {}}, "data": {"track": {"n_segments": 4}},
        "spectra": {"f_min_hz": 0.5, "f_max_hz": 20.0, "n_freqs": 200}, "noise": {"path": str(model)}}))
    p, elapsed = _limited(["validate", str(config)], tmp_path)
    lines = p.stderr.strip().splitlines()
    assert "code 2" in p.stdout and len(lines) == 1, p.stderr
    at = next(i for i, t in enumerate(config.read_text().splitlines(), 1) if t.strip().startswith("path:"))
    line = (f"error: {config}:{at}, key 'noise.path': noise model file {model}: array 'mean' declares shape "
            f"(200000, 200000) float64 (320 GB), expected shape (4, 200) (channels x frequencies of the model's "
            f"grid); the file holds 860 kB for it")
    assert lines[0] == line
    assert elapsed < 1.0, elapsed


def test_a_2_gb_csv_of_nul_bytes_is_one_line_within_a_second_under_a_memory_limit(tmp_path):
    from test_ingest import GEN as gen    # the example generator's ingest file and sensors (nothing simulated)

    (tmp_path / "suspid.yaml").write_text(yaml.safe_dump({
        "name": "recordings", "simulator": {"plugin": "exudyn-train",
                                            "options": {"fs_hz": 200.0, "sensors": gen.sensors_options()}}}))
    (tmp_path / "ingest.yaml").write_text(yaml.safe_dump(gen.ingest_file("csv", "recording.csv", "csv")))
    recording = tmp_path / "recording.csv"
    with open(recording, "wb") as fh:     # sparse: 2 GB of NUL bytes that take no room on the disk
        fh.truncate(2_000_000_000)
    p, elapsed = _limited(["ingest", str(tmp_path / "ingest.yaml"), "--quiet"], tmp_path)
    lines = p.stderr.strip().splitlines()
    assert "code 2" in p.stdout and len(lines) == 1, p.stderr
    assert lines[0] == (f"error: {recording}: not text: a NUL byte on line 1 (byte 0 of its 2.0 GB; a binary or "
                        f"damaged file, expected delimited text: a header line of channel names, one row per sample)")
    assert elapsed < 1.0, elapsed
    assert not (tmp_path / "ingested").exists()


# -- the other places an array is read from a file ------------------------------------------------------------
def _ledger_blob(tmp_path):
    from suspid.infra.ledger import Ledger

    led = Ledger(tmp_path / "ledger.sqlite")
    led.put_array("y", np.zeros(3))
    led._write("UPDATE artifacts SET value = ? WHERE key = ?", (_npy((200_000, 200_000), data=bytes(24)), "y"))
    return lambda: led.get_array("y"), LedgerError, (
        f"{tmp_path / 'ledger.sqlite'}: the run ledger is damaged (array y: declares shape (200000, 200000) float64 "
        f"(320 GB) but holds 24 B)")


def _npz_member_short(tmp_path):
    path = _altered(_noise_model(tmp_path), tmp_path / "short.npz", "variance", _npy((4, 200), data=bytes(800)))
    return lambda: NoiseModel.load(path), DataError, (
        f"noise model file {path}: array 'variance' declares shape (4, 200) float64 (6.4 kB) but the file holds "
        f"800 B for it (a damaged or altered file)")


def _npz_pickled(tmp_path):
    path = _altered(_noise_model(tmp_path), tmp_path / "pickled.npz", "mean", _npy((4, 200), dtype="|O"))
    return lambda: NoiseModel.load(path), DataError, (
        f"noise model file {path}: array 'mean' holds Python objects (object), expected numbers")


def _hdf5_track(tmp_path):
    import h5py

    from suspid.data.files import read_track_h5, write_track_h5
    from suspid.interfaces import TrackSegment

    x = np.arange(0.0, 100.0, 0.25)
    path = write_track_h5([TrackSegment("s1", x, np.zeros((4, x.size)), 80.0)], tmp_path / "track.h5")
    with h5py.File(path, "r+") as f:
        del f["segments/s1/irregularities"]
        f["segments/s1"].create_dataset("irregularities", shape=(4, 10**11), dtype="f8", chunks=(4, 1024))
    return lambda: read_track_h5(path), DataError, (
        f"{path}: /segments/s1/irregularities declares shape (4, 100000000000) float64 (3.2 TB), expected shape "
        f"(4, 400) (irregularity channels x points of distance)")


def _hdf5_recording(tmp_path):
    import h5py

    from suspid.plugins.readers.hdf5 import Hdf5Reader

    path = tmp_path / "rec.h5"
    with h5py.File(path, "w") as f:
        f.create_dataset("acc", shape=(10**12,), dtype="f4", chunks=(1024,))
    reader = Hdf5Reader(path, step=0.005)
    return lambda: reader.read("acc"), DataError, (
        f"{path}: channel 'acc' declares shape (1000000000000,) float32 (4.0 TB) (held 3 times: 12 TB), more than "
        f"the {{free}} of memory available (a damaged file, or one too large for this machine)")


def _csv_one_long_line(tmp_path):
    from suspid.plugins.readers.delimited import CsvReader

    path = tmp_path / "long.csv"
    path.write_text("time_s,a\n" + "1," * 600_000 + "\n")
    reader = CsvReader(path, index="time_s")
    return lambda: reader.read("a"), DataError, (
        f"{path}: line 2 is longer than 1.0 MB: not a delimited text recording (expected "
        f"delimited text: a header line of channel names, one row per sample)")


def _suspid_csv_nul(tmp_path):
    from suspid.data.files import read_track

    path = tmp_path / "seg.csv"
    path.write_bytes(b"# suspid track segment\n" + bytes(1000))
    return lambda: read_track(path), DataError, (
        f"{path}: not text: a NUL byte on line 2 (byte 23 of its 1.0 kB; a binary or damaged file, expected a "
        f"suspid CSV file: # metadata lines, a header, rows of numbers)")


CASES = [_ledger_blob, _npz_member_short, _npz_pickled, _hdf5_track, _hdf5_recording, _csv_one_long_line,
         _suspid_csv_nul]


@pytest.mark.parametrize("case", CASES, ids=[c.__name__.strip("_") for c in CASES])
def test_each_declared_size_is_checked_before_it_is_read(tmp_path, case):
    call, error, expected = case(tmp_path)
    with pytest.raises(error) as exc:
        call()
    message = str(exc.value)
    if "{free}" in expected:
        head, tail = expected.split("{free}")
        assert message.startswith(head) and message.endswith(tail), message
    else:
        assert message.startswith(expected), message


def test_a_sound_noise_model_and_ledger_array_read_back_unchanged(tmp_path):
    from suspid.infra.ledger import Ledger

    path = _noise_model(tmp_path)
    with np.load(path) as raw, CheckedNpz(path, "noise model file") as npz:
        assert sorted(npz.files) == sorted(raw.files)
        for name in raw.files:
            assert np.array_equal(npz.load(name), raw[name])
    loaded = NoiseModel.load(path)
    assert loaded.mean_.shape == (4, 200) and json.loads(str(np.load(path)["meta"]))["channels"] == list(loaded.channels_)
    led = Ledger(tmp_path / "ledger.sqlite")
    led.put_array("k", np.arange(12.0).reshape(3, 4))
    assert np.array_equal(led.get_array("k"), np.arange(12.0).reshape(3, 4))
    assert np.array_equal(load_npy_bytes(_npy((2,), data=np.array([1.0, 2.0]).tobytes()), "x"), [1.0, 2.0])


def test_check_fits_compares_with_what_this_process_can_still_have():
    free = available_memory()
    assert free is not None and free > 0
    check_fits("f", "a", (1000,), np.float64)                       # 8 kB: fits
    with pytest.raises(DataError, match=r"^f: a declares shape \(\d+,\) uint8 \(.*\), more than the"):
        check_fits("f", "a", (free + 1,), np.uint8)
