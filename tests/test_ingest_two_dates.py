"""From two recordings to a finished report: ``suspid ingest`` with a ``reference:`` recording writes both
segment sets and a two-date config that ``validate`` and ``run`` accept; ``validate`` and ``run`` agree on
measured data without a noise model."""

from __future__ import annotations

import shutil

import pytest
import yaml

import suspid
from suspid.errors import ConfigError

from conftest import run_cli
from test_ingest import GEN

pytestmark = pytest.mark.slow   # the recording is simulated once (shared with test_ingest.py in one session)


@pytest.fixture(scope="module")
def two_dates(tmp_path_factory):
    """The measurement date's and the reference date's recordings (the same vehicle), an ingest file of both."""
    root = tmp_path_factory.mktemp("two")
    meas, ref = root / "2026-11", root / "2026-05"
    GEN.make(meas, ["csv"])
    GEN.make(ref, ["mf4"])
    shutil.copy(meas / "suspid.yaml", root / "source.yaml")
    cfg = yaml.safe_load((root / "source.yaml").read_text())
    cfg["simulator"]["options"]["solver"] = "frequency"
    cfg |= {"name": "from-recordings", "parameters": {"c_sec_z": {}, "k_sec_z": {}},
            "spectra": {"f_min_hz": 0.5, "f_max_hz": 20.0, "n_freqs": 60},
            "design": {"n_initial": 6}, "ego": {"max_iter": 1}, "output": {"dir": "runs/from-recordings"}}
    (root / "source.yaml").write_text(yaml.safe_dump(cfg))
    ingest = yaml.safe_load((meas / "ingest-csv.yaml").read_text())
    ref_file = yaml.safe_load((ref / "ingest-mf4.yaml").read_text())
    for section in (ingest, ref_file):
        for key in ("recording", "track"):
            section[key]["path"] = str((meas if section is ingest else ref) / section[key]["path"])
    ingest["config"] = "source.yaml"
    ingest["track"]["band"] = {"filter": "en13848", "bands": ["D1", "D2"]}
    ingest["reference"] = {"recording": ref_file["recording"], "track": ref_file["track"] | {
        "band": {"filter": "en13848", "bands": ["D1", "D2"]}}}
    ingest["output"] = {"dir": "ingested"}
    (root / "ingest.yaml").write_text(yaml.safe_dump(ingest))
    return root


def test_two_recordings_give_both_segment_sets_and_a_config_validate_and_run_accept(two_dates):
    root = two_dates
    p = run_cli("ingest", str(root / "ingest.yaml"), "--quiet")
    assert p.returncode == 0, p.stderr
    out = root / "ingested"
    # what a run of the two-date config will not assess, said by ingest: 4 reference segments, no limits
    config_file = out / "two-dates.yaml"
    assert (f"warning: {config_file}: the reference date has 4 segments ({out / 'reference' / 'accelerations'}); "
            f"the reference-date self-check needs 8, so trust will be 'not assessed'") in p.stderr, p.stderr
    assert f"warning: {config_file}: no limits: for c_sec_z, k_sec_z: their maintenance verdict" in p.stderr
    assert "two-date config: " in p.stdout and str(out / "two-dates.yaml") in p.stdout
    for date in ("reference", "measurement"):
        assert (out / date / "track").is_dir() and (out / date / "accelerations").is_dir()
        assert "EN 13848 D1+D2" in (out / date / "ingest.md").read_text()
    config = yaml.safe_load((out / "two-dates.yaml").read_text())
    assert config["data"] == {"source": "measured", "measurements": "measurement/accelerations",
                              "track_file": "measurement/track",
                              "track_band": {"filter": "en13848"}}     # D1+D2 is the default band list
    assert config["noise"]["reference"] == {"measurements": "reference/accelerations", "track_file": "reference/track"}
    assert config["parameters"] == {"c_sec_z": {}, "k_sec_z": {}}
    p = run_cli("validate", str(out / "two-dates.yaml"))
    assert p.returncode == 0, p.stderr
    assert "valid" in p.stdout and "note: the track record (EN 13848 D1+D2" in p.stdout
    assert "spectra restricted from 0.5-20 Hz to" in p.stdout
    result = suspid.identify(out / "two-dates.yaml")
    report = (result.run_dir / "report.md").read_text()
    assert "Track band: the track record (EN 13848 D1+D2" in report
    assert result.run_dir.resolve() == (root / "runs" / "from-recordings").resolve()


def test_validate_and_run_agree_on_measured_data_without_a_noise_model(two_dates):
    root = two_dates
    out = root / "ingested"
    if not (out / "two-dates.yaml").exists():
        suspid.ingest(root / "ingest.yaml")
    config = yaml.safe_load((out / "two-dates.yaml").read_text())
    config.pop("noise")
    (out / "no-noise.yaml").write_text(yaml.safe_dump(config))
    with pytest.raises(ConfigError, match="measured data need the noise model of the reference date") as v:
        suspid.validate(out / "no-noise.yaml")
    with pytest.raises(ConfigError, match="measured data need the noise model of the reference date") as r:
        suspid.identify(out / "no-noise.yaml")
    assert str(v.value) == str(r.value)


def test_two_date_bands_must_agree(two_dates):
    root = two_dates
    ingest = yaml.safe_load((root / "ingest.yaml").read_text())
    ingest["reference"]["track"]["band"] = {"filter": "full"}
    (root / "ingest-bands.yaml").write_text(yaml.safe_dump(ingest))
    with pytest.raises(ConfigError, match=r"ingest-bands.yaml.*reference.track.band.*one data.track_band"):
        suspid.ingest(root / "ingest-bands.yaml")
