"""The ``vampire`` simulator plugin, driven through its test double.

Every run here starts ``tests/vampire_double/vampire_double.py`` as the
external program. The environment carries a token unique to this test
session; every process the double starts inherits it, so that
:func:`_processes_left` can find, in ``/proc/*/environ``, anything a test left
running, and every test checks that nothing is.
"""

from __future__ import annotations

import importlib.util
import json
import os
import pickle
import re
import shutil
import signal
import time
import uuid
from pathlib import Path

import numpy as np
import pytest
from pydantic import ValidationError

from suspid.errors import ConfigError, DataError, SimulatorError
from suspid.interfaces import TrackSegment
from suspid.plugins.simulators import vampire as vampire_pkg
from suspid.plugins.simulators.vampire import Options, VampireSimulator
from suspid.plugins.simulators.vampire.export import read_export, to_response
from suspid.plugins.simulators.vampire.options import (COMMAND_FIELDS, STANDARD_GRAVITY, ChannelSpec,
                                                       ExportOptions, TrackFileOptions)
from suspid.plugins.simulators.vampire.profiles import Profile, read_profile, write_profile
from suspid.plugins.simulators.vampire.templates import inside, render, safe_relpath
from suspid.plugins.simulators.vampire.trackfile import track_rows, write_track_file
from suspid.testing import check_simulator

ROOT = Path(__file__).resolve().parents[1]
DOUBLE_DIR = Path(__file__).resolve().parent / "vampire_double"
TOKEN_VAR = "VAMPIRE_DOUBLE_TEST_TOKEN"
TOKEN = uuid.uuid4().hex


def _load_double():
    spec = importlib.util.spec_from_file_location("vampire_double", DOUBLE_DIR / "vampire_double.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


double = _load_double()


# -- leftover processes --------------------------------------------------------------------------
def _processes_left() -> list[str]:
    """Live processes whose environment carries this session's token: ``pid: cmdline``."""
    needle = f"{TOKEN_VAR}={TOKEN}".encode()
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            if needle in (entry / "environ").read_bytes().split(b"\0"):
                cmd = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
                found.append(f"{entry.name}: {cmd}")
        except OSError:
            continue
    return found


def _kill_left(found: list[str]) -> None:
    for line in found:
        try:
            os.kill(int(line.split(":")[0]), signal.SIGKILL)
        except OSError:
            pass


@pytest.fixture(autouse=True)
def _no_process_left(monkeypatch):
    """Every test: children get the token; afterwards nothing with it may be running."""
    if not Path("/proc/self/environ").exists():
        pytest.skip("needs /proc to check for leftover processes")
    monkeypatch.setenv(TOKEN_VAR, TOKEN)
    yield
    left = _processes_left()
    _kill_left(left)
    assert not left, f"processes left running: {left}"


# -- helpers ---------------------------------------------------------------------------------------
@pytest.fixture
def double_options(tmp_path):
    """``double_options(**kw)``: the double's plugin options with work_root in this test's tmp dir."""
    def make(**kw):
        kw.setdefault("work_root", tmp_path / "work")
        return double.double_options(**kw)
    return make


def _segment(name: str = "seg", length_m: float = 300.0, speed: float = 50.0, dx: float = 0.25,
             seed: int = 0, smooth: int = 9) -> TrackSegment:
    """A segment with broadband irregularities of about 1 mm rms, (4, n_x) in m."""
    rng = np.random.default_rng(seed)
    x = np.arange(0.0, length_m + dx / 2, dx)
    kernel = np.hanning(smooth + 2)[1:-1]
    kernel /= kernel.sum()
    irr = np.array([np.convolve(r, kernel, mode="same") for r in rng.standard_normal((4, x.size))])
    irr *= 1e-3 / irr.std(axis=1, keepdims=True)
    return TrackSegment(name, x, irr, speed)


def _copy_templates(tmp_path: Path) -> Path:
    target = tmp_path / "template"
    shutil.copytree(double.TEMPLATE_DIR, target)
    return target


def _workdirs(root: Path) -> list[Path]:
    return sorted(p for p in root.iterdir() if p.is_dir()) if root.exists() else []


# -- registration and conformance ---------------------------------------------------------------------
def test_registered_as_vampire_through_the_entry_point():
    from suspid import registry

    text = (ROOT / "pyproject.toml").read_text()
    assert re.search(r'^vampire = "suspid\.plugins\.simulators\.vampire"$', text, re.M)
    if "vampire" not in registry.names("simulator"):  # installed metadata older than pyproject.toml
        registry.add_plugin(vampire_pkg, "vampire")
    assert registry.get("simulator", "vampire") is VampireSimulator


def test_conformance_kit(double_options):
    check_simulator(VampireSimulator, double_options())


def test_command_fields_are_all_provided(double_options):
    sim = VampireSimulator(**double_options())
    job = sim._job(0, _segment(), sim._values({}, sim._opts()), sim._opts(), sim.identity())
    argv, _ = sim._command(job, sim._opts())
    fields = "".join("{" + f + "}" for f in COMMAND_FIELDS)
    sim2 = VampireSimulator(**double_options(command=[fields]))
    argv, _ = sim2._command(job, sim2._opts())
    assert "{" not in argv[0] and str(job.workdir) in argv[0]


# -- a correct run ---------------------------------------------------------------------------------------
def _frf(m_c, m_b, k_p, c_p, k_s, c_s, f):
    """Accelerations of (bogie, carbody) per metre of base displacement, (2, n_f) complex."""
    out = []
    for w in 2 * np.pi * np.asarray(f):
        d = np.array([[k_p + k_s + 1j * w * (c_p + c_s) - m_b * w**2, -(k_s + 1j * w * c_s)],
                      [-(k_s + 1j * w * c_s), k_s + 1j * w * c_s - m_c * w**2]])
        z = np.linalg.solve(d, np.array([k_p + 1j * w * c_p, 0.0]))
        out.append(-w**2 * z)
    return np.array(out).T


def _template_constants() -> dict[str, list[float]]:
    """Masses (kg) and primary rates (N/m, N s/m) as written in the double's vehicle template."""
    consts = {}
    for line in (double.TEMPLATE_DIR / "vehicle.veh").read_text().splitlines():
        parts = line.split("!")[0].split()
        if parts and "{{" not in line:
            consts[parts[0]] = [float(v) for v in parts[1:]]
    return consts


def test_accelerations_follow_the_linear_vehicle_frf(double_options):
    """The double's response, estimated from input and output (H1 = S_ua / S_uu), matches
    an independent frequency-domain solution of its 2-DOF chains, resonance included."""
    from scipy.signal import csd, welch

    speed, dx = 50.0, 0.25
    fs = speed / dx  # output samples fall on the track samples
    seg = _segment("frf", length_m=4000.0, speed=speed, dx=dx, seed=3, smooth=3)
    w = {"k_sec_z": 1.0e6, "c_sec_z": 45e3, "k_sec_y": 0.25e6, "c_sec_y": 50e3}
    (resp,) = VampireSimulator(**double_options(fs=fs)).simulate(w, [seg])
    assert resp.fs == pytest.approx(fs) and resp.channels == ("carbody_z", "carbody_y", "bogie_z", "bogie_y")
    n = resp.accelerations.shape[1]
    c = _template_constants()
    m_c, m_b = c["CARBODY_MASS"][0], c["BOGIE_MASS"][0]
    irr = dict(zip(("vertical", "lateral", "cross_level", "gauge"), seg.irregularities))
    for direction, (body, bogie), (k_s, c_s) in (
            ("VERTICAL", (0, 2), (w["k_sec_z"], w["c_sec_z"])),
            ("LATERAL", (1, 3), (w["k_sec_y"], w["c_sec_y"]))):
        k_p, c_p = (1e3 * v for v in c[f"PRIMARY_{direction}"])
        u = irr[direction.lower()][:n]
        for row, which in ((body, 1), (bogie, 0)):
            f, s_ua = csd(u, resp.accelerations[row], fs=fs, nperseg=4096)
            _, s_uu = welch(u, fs=fs, nperseg=4096)
            band = (f > 0.5) & (f < 20.0)
            estimated = np.abs(s_ua[band] / s_uu[band])
            exact = np.abs(_frf(m_c, m_b, k_p, c_p, k_s, c_s, f[band])[which])
            relative = np.abs(estimated / exact - 1)
            assert np.median(relative) < 0.025 and np.max(relative) < 0.10, (direction, row, relative.max())
            if which == 1:  # the carbody resonance on the secondary suspension sits where the model puts it
                assert abs(f[band][np.argmax(estimated)] - f[band][np.argmax(exact)]) < 0.1, direction


def test_g_and_m_s2_exports_and_both_forms_give_the_same_response(double_options):
    seg = _segment(length_m=200.0)
    base = VampireSimulator(**double_options()).simulate({}, [seg])[0]
    for kw in ({"export_units": "m/s2"}, {"export_form": "blocks"}):
        other = VampireSimulator(**double_options(**kw)).simulate({}, [seg])[0]
        assert other.channels == base.channels and other.fs == base.fs
        np.testing.assert_allclose(other.accelerations, base.accelerations, rtol=1e-7, atol=1e-9)


def test_unit_conversion():
    assert ChannelSpec(name="a", column="A", unit="g").to_si == STANDARD_GRAVITY == 9.80665
    assert ChannelSpec(name="a", column="A", unit="m/s^2").to_si == 1.0
    assert ChannelSpec(name="a", column="A", unit="g", scale=-1).to_si == -9.80665
    with pytest.raises(ValidationError):
        ChannelSpec(name="a", column="A", unit="km/h")


def test_keep_workdirs_and_hash_named_directories(double_options, tmp_path):
    seg = _segment(length_m=100.0)
    root = tmp_path / "work"
    VampireSimulator(**double_options(keep_workdirs="failed")).simulate({}, [seg])
    assert _workdirs(root) == []  # removed after success
    sim = VampireSimulator(**double_options(keep_workdirs="always"))
    sim.simulate({}, [seg])
    sim.simulate({"k_sec_z": 0.5e6}, [seg])
    dirs = _workdirs(root)
    assert len(dirs) == 2 and all(re.fullmatch(r"seg-[0-9a-f]{16}", d.name) for d in dirs)
    info = json.loads((dirs[0] / "_suspid_run.json").read_text())
    assert info["segment"] == "seg" and (dirs[0] / "_suspid_stdout.log").read_text().startswith("double:")
    sim.simulate({}, [seg])  # same inputs: same directory, made fresh
    assert len(_workdirs(root)) == 2


def test_identity_hashes_the_templates(double_options, tmp_path):
    template = _copy_templates(tmp_path)
    a = VampireSimulator(**double_options(template_dir=str(template)))
    b = VampireSimulator(**double_options(template_dir=str(template), work_root=str(tmp_path / "elsewhere"),
                                          max_concurrent=1, timeout_s=5))
    assert a.identity() == b.identity()  # where and how fast runs go does not change results
    json.dumps(a.identity())
    moved = tmp_path / "moved" / "project"
    shutil.copytree(template, moved)
    assert VampireSimulator(**double_options(template_dir=str(moved))).identity() == a.identity()
    veh = template / "vehicle.veh"
    veh.write_text(veh.read_text() + "! an edited comment is an edited template\n")
    c = VampireSimulator(**double_options(template_dir=str(template)))
    assert c.identity()["templates"] != a.identity()["templates"]


def test_pickles_after_use(double_options):
    sim = VampireSimulator(**double_options())
    seg = _segment(length_m=100.0)
    first = sim.simulate({}, [seg])[0]
    again = pickle.loads(pickle.dumps(sim)).simulate({}, [seg])[0]
    np.testing.assert_array_equal(first.accelerations, again.accelerations)


def test_the_documented_double_config_runs(tmp_path):
    """The YAML for the double in docs/vampire.md validates (paths relative to configs/) and runs."""
    import yaml

    from suspid.config import validate_options

    text = (ROOT / "docs" / "vampire.md").read_text()
    snippet = yaml.safe_load(re.findall(r"```yaml\n(.*?)```", text, re.S)[-1])["simulator"]["options"]
    snippet["work_root"] = str(tmp_path / "work")
    options = validate_options(VampireSimulator, snippet, file="vampire-double.yaml", key="simulator.options",
                               base_dir=ROOT / "configs")
    seg = _segment(length_m=100.0)
    documented = VampireSimulator(**options).simulate({}, [seg])[0]
    built = VampireSimulator(**double.double_options(tmp_path / "work2")).simulate({}, [seg])[0]
    np.testing.assert_array_equal(documented.accelerations, built.accelerations)


# -- faults ---------------------------------------------------------------------------------------------
FAULTS = [
    ("exit", "table", r"exit code 5; end of output: 'double: error: solver diverged"),
    ("hang", "table", r"timed out after 1 s; process tree killed"),
    ("missing", "table", r"expected output 'out/accelerations.txt' is missing"),
    ("empty", "table", r"accelerations.txt: expected output is empty"),
    ("truncated", "table", r"accelerations.txt:\d+: \d+ fields where the header has 5"),
    ("truncated", "blocks", r"accelerations.txt: block '\w+' \(line \d+\) declares \d+ pairs but the file "
                            r"ends after \d+ \(truncated output\?\)"),
    ("malformed", "table", r"accelerations.txt:\d+: cannot read column 'BogieLateral' from '\*{9}'"),
    ("malformed", "blocks", r"accelerations.txt:\d+: cannot read value of block '\w+' from '\*{9}'"),
    ("nonfinite", "table", r"accelerations.txt:\d+: non-finite value nan in 'BodyVertical'"),
    ("licence", "table", r"_suspid_stderr.log:1: error pattern .* matches 'ERROR: licence not available"),
]


@pytest.mark.parametrize("fault,form,message", FAULTS, ids=[f"{f}-{form}" for f, form, _ in FAULTS])
def test_fault_modes_end_in_a_clear_simulator_error(fault, form, message, double_options, tmp_path):
    opts = double_options(fault=fault, export_form=form, timeout_s=1.0, kill_grace_s=0.5)
    sim = VampireSimulator(**opts)
    seg = _segment("bad seg", length_m=100.0)
    start = time.monotonic()
    with pytest.raises(SimulatorError) as info:
        sim.simulate({}, [seg])
    text = str(info.value)
    assert re.search(message, text), text
    assert text.startswith("vampire run for segment 'bad seg' failed: ")
    (kept,) = _workdirs(tmp_path / "work")  # keep_workdirs: failed
    assert f"(workdir {kept})" in text
    assert time.monotonic() - start < 10
    assert not _processes_left()


def test_orphans_of_a_successful_run_are_ended(double_options):
    sim = VampireSimulator(**double_options(fault="orphan", kill_grace_s=0.5))
    (resp,) = sim.simulate({}, [_segment(length_m=100.0)])
    assert np.all(np.isfinite(resp.accelerations))
    assert not _processes_left()


def test_failed_workdir_removed_when_keep_is_never(double_options, tmp_path):
    sim = VampireSimulator(**double_options(fault="exit", keep_workdirs=False))
    with pytest.raises(SimulatorError, match=r"workdir .*, removed\)"):
        sim.simulate({}, [_segment(length_m=100.0)])
    assert _workdirs(tmp_path / "work") == []


def test_on_error_raise_stops_the_other_runs_at_once(double_options):
    segs = [_segment("fails", length_m=100.0), _segment("hangs", length_m=100.0, seed=1)]
    sim = VampireSimulator(**double_options(fault={"fails": "exit", "hangs": "hang"}, kill_grace_s=0.5,
                                            on_error="raise"))
    start = time.monotonic()
    with pytest.raises(SimulatorError) as info:
        sim.simulate({}, segs)
    assert time.monotonic() - start < 10  # not the 60 s timeout of the hanging run
    assert "segment 'fails'" in str(info.value) and "hangs" not in str(info.value)
    assert not _processes_left()


def test_on_error_finish_lets_the_other_runs_complete(double_options, tmp_path):
    segs = [_segment("a", length_m=100.0), _segment("b", length_m=100.0, seed=1),
            _segment("c", length_m=100.0, seed=2)]
    sim = VampireSimulator(**double_options(fault={"a": "exit", "c": "missing"}, on_error="finish",
                                            max_concurrent=1))
    with pytest.raises(SimulatorError) as info:
        sim.simulate({}, segs)
    text = str(info.value)
    assert text.startswith("vampire run for segment 'a' failed: exit code 5")
    assert "[+1 more failed: vampire run for segment 'c' failed: expected output" in text
    names = sorted(d.name.split("-")[0] for d in _workdirs(tmp_path / "work"))
    assert names == ["a", "c"]  # b ran to the end and was cleaned up


def test_a_failing_point_leaves_other_points_and_the_ledger_alone(double_options, tmp_path):
    """The run goes on with other points after a failure; evaluations already committed stay."""
    ledger_mod = pytest.importorskip("suspid.infra.ledger")
    good, bad = _segment("good", length_m=100.0), _segment("bad", length_m=100.0, seed=1)
    sim = VampireSimulator(**double_options(fault={"bad": "hang"}, timeout_s=1.0, kill_grace_s=0.5))
    ledger = ledger_mod.Ledger(tmp_path / "ledger.sqlite")
    points = [({"k_sec_z": 0.6e6}, [good]), ({"k_sec_z": 0.7e6}, [good, bad]), ({"k_sec_z": 0.8e6}, [good])]
    for w, segs in points:
        key = ledger_mod.evaluation_key(sim.identity(), w, "data")
        try:
            resp = sim.simulate(w, segs)
            ledger.put(ledger_mod.Evaluation(key, w, J=float(np.std(resp[0].accelerations)), psi=None))
        except SimulatorError as exc:
            ledger.put(ledger_mod.Evaluation(key, w, J=None, psi=None, status="failed", error=str(exc)))
    evaluations = list(ledger.evaluations())
    assert [e.status for e in evaluations] == ["ok", "failed", "ok"]
    assert "segment 'bad' failed: timed out" in evaluations[1].error
    assert ledger.count("ok") == 2
    ledger.close()


def test_licence_seats_limit_concurrent_runs(double_options, tmp_path):
    log = tmp_path / "runs.log"
    sim = VampireSimulator(**double_options(max_concurrent=2, env={"VAMPIRE_DOUBLE_LOG": str(log),
                                                                   "VAMPIRE_DOUBLE_DELAY_S": "0.6"}))
    segs = [_segment(f"s{i}", length_m=60.0, seed=i) for i in range(4)]
    out = sim.simulate({}, segs)
    assert [r.segment for r in out] == ["s0", "s1", "s2", "s3"]
    events = sorted((float(t), +1 if e == "start" else -1) for t, e, *_ in
                    (line.split() for line in log.read_text().splitlines()))
    running = np.cumsum([d for _, d in events])
    assert running.max() == 2


def test_command_is_an_argument_list_never_a_shell(double_options, tmp_path):
    script = "import sys, pathlib; pathlib.Path('argv.json').write_text(__import__('json').dumps(sys.argv[1:]))"
    args = ["a b; touch pwned", "$HOME", "`id`", "{{literal}}"]
    sim = VampireSimulator(**double_options(command=["{python}", "-c", script, *args], keep_workdirs="always"))
    with pytest.raises(SimulatorError, match="missing"):
        sim.simulate({}, [_segment(length_m=50.0)])
    (wd,) = _workdirs(tmp_path / "work")
    assert json.loads((wd / "argv.json").read_text()) == ["a b; touch pwned", "$HOME", "`id`", "{literal}"]
    assert not (wd / "pwned").exists()


def test_missing_program_is_a_simulator_error(double_options):
    sim = VampireSimulator(**double_options(command=["/nonexistent/vampire.exe", "{run_file}"]))
    with pytest.raises(SimulatorError, match=r"command not found: '/nonexistent/vampire.exe'"):
        sim.simulate({}, [_segment(length_m=50.0)])


# -- strict templates, paths, options ------------------------------------------------------------------------
def _edit(template: Path, name: str, old: str, new: str) -> int:
    path = template / name
    lines = path.read_text().splitlines()
    lineno = next(i for i, line in enumerate(lines, 1) if old in line)
    lines[lineno - 1] = lines[lineno - 1].replace(old, new)
    path.write_text("\n".join(lines) + "\n")
    return lineno


@pytest.mark.parametrize("old,new,message", [
    ("{{ c_sec_y }}", "{{ c_sec_y }} {{ c_sec_yy }}", r"unknown placeholder '\{\{ c_sec_yy \}\}'"),
    ("{{ c_sec_y }}", "{{ c_sec_y }} {{ c_sec_y", r"unmatched '\{\{'"),
    ("{{ c_sec_y }}", "{{ c_sec_y }} }}", r"unmatched '\}\}'"),
    ("{{ c_sec_y }}", "{{ c_sec_y }} {{ 2x }}", r"invalid placeholder '\{\{ 2x \}\}'"),
])
def test_strict_placeholders_name_file_and_line(old, new, message, double_options, tmp_path):
    template = _copy_templates(tmp_path)
    lineno = _edit(template, "vehicle.veh", old, new)
    sim = VampireSimulator(**double_options(template_dir=str(template)))
    with pytest.raises(ConfigError, match=message) as info:
        sim.simulate({}, [_segment(length_m=50.0)])
    assert str(info.value).startswith(f"{template / 'vehicle.veh'}:{lineno}: ")
    assert not (tmp_path / "work").exists() or _workdirs(tmp_path / "work") == []


def test_parameter_without_placeholder_and_fs_without_value(double_options, tmp_path):
    template = _copy_templates(tmp_path)
    _edit(template, "vehicle.veh", "{{ c_sec_y }}", "40")
    with pytest.raises(ConfigError, match=r"parameter 'c_sec_y' has no placeholder"):
        VampireSimulator(**double_options(template_dir=str(template))).identity()
    with pytest.raises(ConfigError, match=r"double.run:8: the templates use '\{\{ fs \}\}' but the option fs"):
        VampireSimulator(**double_options(fs=None)).identity()


def test_render_replaces_and_refuses_unknown_names():
    assert render("k = {{k}} / {{  c }}\n", {"k": "1", "c": "2"}, "f") == "k = 1 / 2\n"
    with pytest.raises(ConfigError, match=r"^f:2: unknown placeholder '\{\{ x \}\}'; known: k"):
        render("a\n{{ x }}\n", {"k": "1"}, "f")


@pytest.mark.parametrize("path", ["../x", "a/../../x", "/etc/passwd", "C:\\vampire\\run", "..\\x", "", "."])
def test_paths_outside_the_working_directory_are_refused(path):
    with pytest.raises(ValueError, match="export.file"):
        safe_relpath(path, "export.file")


@pytest.mark.parametrize("key,value", [
    ("export", {"file": "../results.txt"}), ("track", {"file": "/tmp/track.dat"}), ("run_file", "../double.run"),
    ("expected_outputs", ["..\\out"]), ("log_files", ["/var/log/*"]),
])
def test_options_refuse_paths_that_leave_the_working_directory(key, value, double_options):
    with pytest.raises(ValidationError, match=r"absolute|'\.\.'"):
        Options.model_validate(double_options(**{key: value}))


def test_links_cannot_lead_outside(tmp_path):
    wd = tmp_path / "wd"
    wd.mkdir()
    (wd / "out").symlink_to(tmp_path)
    with pytest.raises(ConfigError, match="outside the working directory"):
        inside(wd, "out/x")
    template = tmp_path / "template"
    shutil.copytree(double.TEMPLATE_DIR, template)
    (template / "linked").symlink_to(tmp_path, target_is_directory=True)
    sim = VampireSimulator(**double.double_options(tmp_path / "work", template_dir=str(template)))
    with pytest.raises(ConfigError, match="linked directory"):
        sim.identity()


@pytest.mark.parametrize("change,message", [
    ({"parameters": double.PARAMETERS + [double.PARAMETERS[0]]}, "duplicate parameter names"),
    ({"parameters": [dict(double.PARAMETERS[0], placeholder="speed")]}, "already a built-in value"),
    ({"parameters": [dict(double.PARAMETERS[0], nominal=1.0)]}, "outside"),
    ({"values": {"k_sec_z": 1}}, "already parameter 'k_sec_z'"),
    ({"error_patterns": ["(unclosed"]}, "not a regular expression"),
    ({"run_file": "nope.run"}, "not a file of the template directory"),
    ({"run_file": None}, r"set run_file"),
    ({"command": ["vampire", "{runfile}"]}, r"unknown placeholder '\{runfile\}'"),
    ({"template_dir": "/nonexistent/template"}, "template directory not found"),
    ({"track": {"value_format": "q"}}, "invalid number format"),
    ({"timeout": 5}, "Extra inputs are not permitted"),
    ({"values": {"title": "two\nlines"}}, "must be one line"),
])
def test_options_validation(change, message, double_options):
    with pytest.raises(ValidationError, match=message):
        Options.model_validate(double_options(**change))


def test_unknown_or_non_finite_parameter_values(double_options):
    sim = VampireSimulator(**double_options())
    with pytest.raises(ConfigError, match="unknown parameter.*k_primary"):
        sim.simulate({"k_primary": 1.0}, [_segment(length_m=50.0)])
    with pytest.raises(SimulatorError, match="not finite"):
        sim.simulate({"k_sec_z": float("nan")}, [_segment(length_m=50.0)])


def test_segments_the_adapter_cannot_run(double_options):
    sim = VampireSimulator(**double_options())
    seg = _segment(length_m=50.0)
    varying = TrackSegment("vary", seg.distance, seg.irregularities, np.linspace(40, 60, seg.distance.size))
    with pytest.raises(DataError, match="segment 'vary': speed varies"):
        sim.simulate({}, [varying])
    with pytest.raises(DataError, match=r"shape \(3, "):
        sim.simulate({}, [TrackSegment("bad", seg.distance, seg.irregularities[:3], 50.0)])
    with pytest.raises(DataError, match="must be one line"):
        sim.simulate({}, [TrackSegment("a\nSPEED_KMH 1", seg.distance, seg.irregularities, 50.0)])


# -- track file ------------------------------------------------------------------------------------------------
def test_track_file_layout_units_and_signs(tmp_path):
    x = np.arange(0.0, 10.0 + 1e-9, 0.25) + 100.0
    vertical, lateral = 1e-3 * np.sin(x), 2e-3 * ((x - 100.0) ** 2) / 100.0
    cross, gauge = np.full_like(x, 0.5e-3), np.full_like(x, -1e-3)
    seg = TrackSegment("t", x, np.array([vertical, lateral, cross, gauge]), 80.0)
    opts = TrackFileOptions(curvature="from_lateral", signs={"cross_level": -1}, delimiter=",", newline="crlf")
    rows = track_rows(seg, opts)
    np.testing.assert_allclose(rows[:, 0], x - 100.0)
    np.testing.assert_allclose(rows[:, 1], -0.5)  # mm, sign flipped
    np.testing.assert_allclose(rows[:, 3], lateral * 1e3)
    np.testing.assert_allclose(rows[:, 4], vertical * 1e3)
    np.testing.assert_allclose(rows[:, 5], -1.0)
    np.testing.assert_allclose(rows[2:-2, 2], 2 * 2e-3 / 100.0 * 1e3)  # d²y/dx² in 1/km
    path = tmp_path / "t.trk"
    write_track_file(path, rows, opts, ["HEADER t"])
    raw = path.read_bytes()
    assert raw.startswith(b"HEADER t\r\n0.000,-0.5000,") and raw.endswith(b"\r\n")
    np.testing.assert_allclose(np.loadtxt(path, delimiter=",", skiprows=1), rows, atol=1e-4)
    assert TrackFileOptions(distance_origin="segment").distance_origin == "segment"
    np.testing.assert_allclose(track_rows(seg, TrackFileOptions(distance_origin="segment"))[:, 0], x)


# -- export reader ------------------------------------------------------------------------------------------------
def _seg_for(duration: float, speed: float = 50.0) -> TrackSegment:
    x = np.linspace(0.0, duration * speed, 11)
    return TrackSegment("e", x, np.zeros((4, x.size)), speed)


CH = [ChannelSpec(name="z", column="Az", unit="g"), ChannelSpec(name="y", column="Ay")]


def test_export_table_with_comments_delimiter_and_fortran_exponents(tmp_path):
    path = tmp_path / "r.csv"
    rows = "\n".join(f"{k * 0.01:.2f}, {0.1 * k:.3E}, 9, {k}.0D-01" for k in range(101))
    path.write_text("Vampire output\n# comment\nTime, Az, Other, Ay\n" + rows + "\n")
    opts = ExportOptions(file="r.csv", skip_lines=1, delimiter=",")
    resp = to_response(read_export(path, opts, ["Az", "Ay"]), CH, opts, _seg_for(1.0), fs_expected=100.0)
    assert resp.fs == pytest.approx(100.0) and resp.accelerations.shape == (2, 101)
    np.testing.assert_allclose(resp.accelerations[0], 0.1 * np.arange(101) * 9.80665)
    np.testing.assert_allclose(resp.accelerations[1], 0.1 * np.arange(101))


def test_export_blocks_and_distance_abscissa(tmp_path):
    path = tmp_path / "r.txt"
    xs = np.arange(0, 51) * 1.0  # m, at 50 m/s: 50 Hz
    text = ""
    for title, scale in (("Az", 1.0), ("Ay", 2.0)):
        text += f"{title}\n{xs.size}\n" + "".join(f"{x:g} ; {scale * x:g}\n" for x in xs)
    path.write_text(text)
    opts = ExportOptions(form="blocks", x_kind="distance")
    resp = to_response(read_export(path, opts, ["Az", "Ay"]), CH, opts, _seg_for(1.0))
    assert resp.fs == pytest.approx(50.0)
    np.testing.assert_allclose(resp.accelerations[1], 2 * xs)


@pytest.mark.parametrize("body,form,message", [
    ("Time Az Ay\n0 1 1\n0.01 1 1\n0.005 1 1\n", "table", r"r.txt:4: time does not increase"),
    ("Time Az Ay\n0 1 1\n0.01 1 1\n0.03 1 1\n0.04 1 1\n", "table", r"r.txt:4: non-uniform sampling: a step of 0.02 s"),
    ("Time Az Ay\n0 1 1\n0.01 inf 1\n", "table", r"r.txt:3: non-finite value inf in 'Az'"),
    ("Time Ax Ay\n0 1 1\n", "table", r"r.txt:1: no column 'Az' in the header; columns are 'Time', 'Ax', 'Ay'"),
    ("Time Az Az Ay\n0 1 1 1\n", "table", r"column 'Az' appears 2 times"),
    ("Time Az Ay\n", "table", r"header but no data rows"),
    ("", "table", r"no header line found"),
    ("Az\n2\n0 ; 1\n1 ; 1\nAy\n2\n0 ; 1\n2 ; 1\n", "blocks", r"block 'Ay' .* has another abscissa"),
    ("Az\ntwo\n", "blocks", r"r.txt:2: block 'Az': expected the number of pairs, got 'two'"),
    ("Az\n1\n0 , 1\n", "blocks", r"r.txt:3: block 'Az': expected 'x ; y'"),
    ("Az\n1\n0 ; 1\n", "blocks", r"no block titled 'Ay'; blocks are 'Az'"),
])
def test_export_problems_name_the_file_and_line(body, form, message, tmp_path):
    path = tmp_path / "r.txt"
    path.write_text(body)
    opts = ExportOptions(form=form, check_duration=False)
    with pytest.raises(SimulatorError, match=message):
        to_response(read_export(path, opts, ["Az", "Ay"]), CH, opts, _seg_for(1.0))


def test_export_sampling_rate_and_duration_checks(tmp_path):
    path = tmp_path / "r.txt"
    path.write_text("Time Az Ay\n" + "".join(f"{k * 0.01:.2f} 0 0\n" for k in range(51)))
    opts = ExportOptions()
    data = read_export(path, opts, ["Az", "Ay"])
    with pytest.raises(SimulatorError, match=r"sampling rate 100 Hz, expected 200 Hz"):
        to_response(data, CH, opts, _seg_for(0.5), fs_expected=200.0)
    with pytest.raises(SimulatorError, match=r"r.txt: the record lasts 0.51 s \(51 samples at 100 Hz\), expected "
                                             r"2 s for segment 'e' \(truncated output\?\)"):
        to_response(data, CH, opts, _seg_for(2.0))
    assert to_response(data, CH, opts, _seg_for(0.5)).duration == pytest.approx(0.51)


# -- profiles ------------------------------------------------------------------------------------------------
def test_profiles_round_trip(tmp_path):
    y = np.linspace(-70, 60, 27)
    z = 0.05 * y + 1e-3 * y**2
    wheel = Profile("wheel", "test wheel", "CUSTOM", 70.0, 1360.0, np.column_stack([y, z, y, z + 0.5]))
    rail = Profile("rail", "test rail", "EUROPEAN", None, 1435.0, np.column_stack([y, -z, y, -z]))
    for prof, name in ((wheel, "w.whe"), (rail, "r.rai")):
        write_profile(tmp_path / name, prof)
        back = read_profile(tmp_path / name)
        assert (back.kind, back.title, back.datum, back.datum_value, back.spacing) == \
            (prof.kind, prof.title, prof.datum, prof.datum_value, prof.spacing)
        np.testing.assert_allclose(back.points, prof.points, atol=1e-4)
    np.testing.assert_allclose(read_profile(tmp_path / "w.whe").right[:, 1], z + 0.5, atol=1e-4)


def test_profile_reader_comments_commas_and_errors(tmp_path):
    path = tmp_path / "p.rai"
    path.write_text('RAILPROFILE\nmy rail\nGAUGEPOINT CUSTOM 14\nGAUGE 1435\n'
                    '-10, 1, 10, 1  " a comment\n! whole-line comment\n\n0 0 0 0 % another\n')
    prof = read_profile(path)
    assert prof.datum_value == 14.0 and prof.points.shape == (2, 4) and prof.left[0].tolist() == [-10, 1]
    assert read_profile(double.TEMPLATE_DIR / "profiles" / "wheel.whe").datum == "EUROPEAN"
    for text, message in [("WHEEL\nt\nTREADDATUM EUROPEAN\nFLANGEBACK 1360\n0 0 0 0\n1 1 1 1\n", r"p.rai:1: "),
                          ("RAILPROFILE\nt\nGAUGEPOINT US1\nGAUGE 1435\n", r"p.rai:3: unknown GAUGEPOINT"),
                          ("RAILPROFILE\nt\nGAUGEPOINT US\nGAUGE 1435\n0 0 0\n1 1 1 1\n", r"p.rai:5: expected 4")]:
        path.write_text(text)
        with pytest.raises(DataError, match=message):
            read_profile(path)
    with pytest.raises(DataError, match="at most 80 characters"):
        write_profile(tmp_path / "x.whe", Profile("wheel", "t" * 81, "EUROPEAN", None, 1360.0, np.zeros((2, 4))))


# -- last: nothing left running ---------------------------------------------------------------------------------
def test_no_double_process_left_running():
    """After every test above (timeouts, hangs, cancellations, orphans), nothing is left."""
    assert _processes_left() == []
