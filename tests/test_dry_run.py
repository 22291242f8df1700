"""What run would reject from the config and its files alone, validate rejects first, and run starts nothing.

Each case is a config that used to pass ``suspid validate`` and fail later in ``suspid run`` (sometimes
after every simulation): now both give exit 2 and one line naming the file and the key, and ``run``
creates no run directory.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from suspid.cli import main
from suspid.method.noise import fit_noise_model

BASE = {"name": "dry", "seed": 1,
        "simulator": {"plugin": "exudyn-train", "options": {"solver": "frequency", "fs_hz": 50.0}},
        "parameters": {"k_sec_z": {}, "c_sec_z": {}},
        "data": {"track": {"n_segments": 4, "length_m": 1000.0}},
        "spectra": {"f_min_hz": 0.5, "f_max_hz": 10.0, "n_freqs": 40},
        "design": {"n_initial": 6}, "ego": {"max_iter": 2}}


def _noise_model(tmp_path: Path, n_freqs: int, channels: list[str]) -> Path:
    rng = np.random.default_rng(0)
    b = rng.normal(size=(8, len(channels), n_freqs))
    model = fit_noise_model(b, np.zeros_like(b), {}, freqs=np.linspace(0.5, 10.0, n_freqs), channels=channels)
    return model.save(tmp_path / f"nm-{n_freqs}-{len(channels)}.npz")


def _channels() -> list[str]:
    from suspid.plugins.simulators.exudyn_train import ExudynTrain

    return ExudynTrain(solver="frequency").channels()


CASES = [
    # (id, change of the config (a function of tmp_path and the dict), key named, words of the message)
    ("figure channel", lambda t, c: c.update(output={"figure_channel": "roof"}), "output.figure_channel",
     "unknown channel"),
    ("noise path is a folder", lambda t, c: c.update(noise={"path": str(t)}), "noise.path", "is a directory"),
    ("noise path missing", lambda t, c: c.update(noise={"path": str(t / "none.npz")}), None, "not found"),
    ("noise model of another grid", lambda t, c: c.update(noise={"path": str(_noise_model(t, 30, _channels()))}),
     None, "other frequencies"),
    ("noise model of other channels", lambda t, c: c.update(noise={"path": str(_noise_model(t, 40, ["a", "b"]))}),
     None, "channels"),
    ("noise file not a model", lambda t, c: (t.joinpath("junk.npz").write_bytes(b"junk"),
                                             c.update(noise={"path": str(t / "junk.npz")})), None, "not a readable"),
    ("above Nyquist", lambda t, c: c["spectra"].update(f_max_hz=30.0), "spectra", "Nyquist"),
    ("records too short", lambda t, c: c["data"]["track"].update(length_m=150.0), "spectra", "too short"),
    ("negative weights", lambda t, c: c.update(objective={"plugin": "overlap", "weights": [-1.0] + [1.0] * 9}),
     "objective.weights", "weight"),
    ("all-zero weights", lambda t, c: c.update(objective={"plugin": "overlap", "weights": [0.0] * 10}),
     "objective.weights", "weight"),
    ("design seed -1", lambda t, c: c["design"].update(seed=-1), "design.seed", "greater than or equal to 0"),
    ("run seed too large", lambda t, c: c.update(seed=2**40), "seed", "less than"),
    ("output dir is a file", lambda t, c: (t.joinpath("f").write_text("x"), c.update(output={"dir": str(t / "f")})),
     "output.dir", "not a directory"),
    ("negative stiffness", lambda t, c: c["parameters"].update(k_sec_z={"lower": -1e5, "upper": 5e5}),
     "parameters.k_sec_z", "physical domain"),
    ("zero damping", lambda t, c: c["parameters"].update(c_sec_z={"lower": 0.0, "upper": 3e4}),
     "parameters.c_sec_z", "physical domain"),
    ("infinite bound", lambda t, c: c["parameters"].update(c_sec_z={"lower": 1e3, "upper": float("inf")}),
     "parameters.c_sec_z", "finite"),
    ("w_ref outside", lambda t, c: c["data"].update(w_ref={"k_sec_z": 1e9}), "data.w_ref.k_sec_z", "outside"),
    ("unknown effect", lambda t, c: c.update(diagnose={"effects": ["hunting"]}), "diagnose.effects.0",
     "unknown effect"),
    ("huge design", lambda t, c: c["design"].update(n_initial=10**12), "design.n_initial", "less than"),
]


@pytest.mark.parametrize("change, key, words", [pytest.param(c, k, w, id=i) for i, c, k, w in CASES])
def test_validate_rejects_what_run_would(tmp_path, capsys, change, key, words):
    cfg = json.loads(json.dumps(BASE))
    change(tmp_path, cfg)
    path = tmp_path / "dry.yaml"
    path.write_text(yaml.safe_dump(cfg, sort_keys=False))
    for command in ("validate", "run"):
        with pytest.raises(SystemExit) as exit_:
            main([command, str(path), "--quiet"] if command == "run" else [command, str(path)])
        out, err = capsys.readouterr()
        lines = err.strip().splitlines()
        assert exit_.value.code == 2 and len(lines) == 1 and "Traceback" not in err, (command, err)
        assert words in lines[0] and (key is None or f"key '{key}'" in lines[0]), lines[0]
        assert not (tmp_path / "runs").exists() and not (tmp_path / "f").is_dir(), f"{command} started a run"
