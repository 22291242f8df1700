"""A stand-in for Vampire that honours the ``vampire`` adapter's command contract.

Run as ``python vampire_double.py RUN_FILE`` in a working directory prepared by
the adapter. It

1. reads the run file and the vehicle file it names (a made-up, line-based
   syntax; *not* Vampire's) and refuses any unrendered ``{{``/``}}``;
2. reads the 6-field track file (distance m, cross level mm, curvature 1/km,
   lateral mm, vertical mm, gauge mm; leading non-numeric lines are a header);
3. simulates a linear vehicle: half a carbody on one bogie, vertical and
   lateral motions decoupled, each a 2-DOF chain (track - primary - bogie -
   secondary - carbody) excited through the primary spring and damper by the
   vertical (resp. lateral) irregularity at constant speed. The state
   recursion is exact for an input linear between track samples;
4. writes the ASCII export (``FORMAT table`` or ``blocks``, ``UNITS g`` or
   ``m/s2``) at the run file's sample rate.

Faults, switched by the environment variable ``VAMPIRE_DOUBLE_FAULT``: one
mode for every run, or ``segment=mode`` pairs separated by commas. Modes:
``exit`` (exit code 5), ``hang`` (starts a child,
ignores SIGTERM, sleeps), ``missing`` (exit 0, no export), ``empty`` (empty
export), ``truncated`` (export cut in the middle of a line), ``malformed``
(a Fortran overflow field ``*********``), ``nonfinite`` (a NaN), ``licence``
(a licence error on stderr, exit 0), ``orphan`` (a correct run that leaves a
child process behind).

``VAMPIRE_DOUBLE_DELAY_S`` sleeps before working; ``VAMPIRE_DOUBLE_LOG`` names
a file that gets ``<time> start|end <segment> <pid>`` lines.

Imported (not run), the module gives :func:`double_options`, the adapter
options that drive this program, and :data:`PARAMETERS`.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
TEMPLATE_DIR = HERE / "template"
G = 9.80665  # m/s² per g

PARAMETERS: list[dict[str, Any]] = [
    {"name": "k_sec_z", "unit": "N/m", "nominal": 0.86e6, "lower": 0.43e6, "upper": 1.29e6, "scale": 1e-3,
     "description": "secondary vertical stiffness, both sides of one bogie (2 x 430 kN/m, Manchester coach)"},
    {"name": "c_sec_z", "unit": "N s/m", "nominal": 40e3, "lower": 20e3, "upper": 60e3, "scale": 1e-3,
     "description": "secondary vertical damping, both sides (2 x 20 kN s/m, Manchester coach)"},
    {"name": "k_sec_y", "unit": "N/m", "nominal": 0.32e6, "lower": 0.16e6, "upper": 0.48e6, "scale": 1e-3,
     "description": "secondary lateral stiffness, both sides (2 x 160 kN/m, Manchester coach)"},
    {"name": "c_sec_y", "unit": "N s/m", "nominal": 40e3, "lower": 20e3, "upper": 60e3, "scale": 1e-3,
     "description": "secondary lateral damping, both sides (made up for the double)"},
]
"""The double's identifiable parameters (SI); the vehicle file takes kN/m and kN s/m (scale 1e-3)."""

CHANNELS = [("carbody_z", "BodyVertical"), ("carbody_y", "BodyLateral"),
            ("bogie_z", "BogieVertical"), ("bogie_y", "BogieLateral")]
"""(suspid channel, export column) pairs, in the export's column order."""


def double_options(work_root: str | Path | None = None, *, fs: float = 200.0, export_form: str = "table",
                   export_units: str = "g", fault: str | dict[str, str] | None = None,
                   **overrides: Any) -> dict[str, Any]:
    """Options of the ``vampire`` simulator that run this double.

    :param work_root: where the working directories go (default: a temp dir).
    :param fs: output sampling rate in Hz.
    :param export_form: ``"table"`` or ``"blocks"``.
    :param export_units: ``"g"`` or ``"m/s2"``.
    :param fault: a fault mode for every run, or segment name -> mode (module
        docstring), passed through ``env``.
    :param overrides: any other option, replacing the default.
    :returns: a plain dict, as it would appear under ``simulator.options`` in YAML.
    """
    env = {}
    if isinstance(fault, dict):
        env["VAMPIRE_DOUBLE_FAULT"] = ",".join(f"{seg}={mode}" for seg, mode in fault.items())
    elif fault:
        env["VAMPIRE_DOUBLE_FAULT"] = fault
    options: dict[str, Any] = {
        "template_dir": str(TEMPLATE_DIR),
        "run_file": "double.run",
        "parameters": [dict(p) for p in PARAMETERS],
        "channels": [{"name": name, "column": column, "unit": export_units} for name, column in CHANNELS],
        "command": ["{python}", str(HERE / "vampire_double.py"), "{run_file}"],
        "env": env,
        "values": {"export_form": export_form, "export_units": export_units},
        "fs": fs,
        "timeout_s": 60.0,
        "kill_grace_s": 1.0,
        "max_concurrent": 2,
        "copy_only": ["*.whe"],
        "track": {"file": "track.trk",
                  "header": ["! suspid track irregularities for segment {{ segment }}",
                             "! distance_m cross_level_mm curvature_1/km lateral_mm vertical_mm gauge_mm"]},
        "export": {"file": "out/accelerations.txt", "form": export_form, "x_column": "Time"},
        "expected_outputs": ["double.log"],
        "log_files": ["double.log"],
    }
    if work_root is not None:
        options["work_root"] = str(work_root)
    options.update(overrides)
    return options


# -- the program --------------------------------------------------------------------------------
def _fail(message: str, code: int) -> None:
    print(f"double: error: {message}", file=sys.stderr)
    sys.exit(code)


def _read_keyed(path: Path) -> dict[str, str]:
    """``KEY value`` lines; ``!`` starts a comment; unrendered placeholders are fatal."""
    out = {}
    for lineno, line in enumerate(path.read_text().splitlines(), 1):
        if "{{" in line or "}}" in line:
            _fail(f"{path}:{lineno}: unrendered placeholder: {line.strip()}", 2)
        text = line.split("!", 1)[0].strip()
        if text:
            key, _, value = text.partition(" ")
            out[key.upper()] = value.strip()
    return out


def _numbers(text: str, n: int, where: str) -> list[float]:
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        values = []
    if len(values) != n:
        _fail(f"{where}: expected {n} numbers, got {text!r}", 2)
    return values


def _read_track(path: Path):
    import numpy as np

    rows = []
    for lineno, line in enumerate(path.read_text().splitlines(), 1):
        parts = line.replace(",", " ").split()
        if not parts:
            continue
        try:
            values = [float(p) for p in parts]
        except ValueError:
            values = None
        if values is None or len(values) != 6:
            if rows:
                _fail(f"{path}:{lineno}: malformed track row {line!r}", 3)
            continue  # header
        rows.append(values)
    if len(rows) < 10:
        _fail(f"{path}: fewer than 10 track rows", 3)
    data = np.asarray(rows)
    steps = np.diff(data[:, 0])
    if np.any(steps <= 0) or np.ptp(steps) > 1e-3 * steps.mean():
        _fail(f"{path}: distance must increase in uniform steps", 3)
    return data


def _expm(m):
    """Matrix exponential by scaling and squaring of a Taylor series (numpy only)."""
    import numpy as np

    norm = float(np.abs(m).sum(axis=1).max())
    s = max(0, int(np.ceil(np.log2(norm / 0.25)))) if norm > 0.25 else 0
    x = m / 2.0 ** s
    term = np.eye(len(m))
    out = term.copy()
    for k in range(1, 20):
        term = term @ x / k
        out = out + term
    for _ in range(s):
        out = out @ out
    return out


def _chain(m_c, m_b, k_p, c_p, k_s, c_s):
    """State matrices of one direction: states (z_b, z_c, v_b, v_c), inputs u and du/dt."""
    import numpy as np

    a = np.array([[0, 0, 1, 0], [0, 0, 0, 1],
                  [-(k_p + k_s) / m_b, k_s / m_b, -(c_p + c_s) / m_b, c_s / m_b],
                  [k_s / m_c, -k_s / m_c, c_s / m_c, -c_s / m_c]], dtype=float)
    b_u = np.array([0, 0, k_p / m_b, 0], dtype=float)
    b_v = np.array([0, 0, c_p / m_b, 0], dtype=float)
    return a, b_u, b_v


def simulate(vehicle: dict[str, str], track, speed: float, fs: float):
    """Accelerations (m/s²) of carbody and bogie, vertical and lateral, sampled at ``fs``.

    :param vehicle: the vehicle file's entries (kg, kN/m, kN s/m).
    :param track: ``(n_x, 6)`` rows of the track file.
    :param speed: m/s. :param fs: Hz.
    :returns: ``(t, acc)`` with ``t (n_t,)`` s and ``acc (4, n_t)`` in the order of :data:`CHANNELS`.
    """
    import numpy as np

    m_c = _numbers(vehicle["CARBODY_MASS"], 1, "CARBODY_MASS")[0]
    m_b = _numbers(vehicle["BOGIE_MASS"], 1, "BOGIE_MASS")[0]
    t_in = (track[:, 0] - track[0, 0]) / speed
    h = t_in[1] - t_in[0]
    accs = {}
    for direction, column in (("VERTICAL", 4), ("LATERAL", 3)):
        k_p, c_p = (1e3 * v for v in _numbers(vehicle[f"PRIMARY_{direction}"], 2, f"PRIMARY_{direction}"))
        k_s, c_s = (1e3 * v for v in _numbers(vehicle[f"SECONDARY_{direction}"], 2, f"SECONDARY_{direction}"))
        a, b_u, b_v = _chain(m_c, m_b, k_p, c_p, k_s, c_s)
        f = np.zeros((6, 6))
        f[:4, :4], f[:4, 4], f[:4, 5], f[4, 5] = a, b_u, b_v, 1.0
        e = _expm(f * h)
        phi, g_u, g_s = e[:4, :4], e[:4, 4], e[:4, 5]
        u = track[:, column] * 1e-3
        slope = np.diff(u) / h
        drive = np.outer(u[:-1], g_u) + np.outer(slope, g_s)
        x = np.zeros((len(u), 4))
        x[0, :2] = u[0]
        for k in range(len(u) - 1):
            x[k + 1] = phi @ x[k] + drive[k]
        udot = np.empty_like(u)
        udot[1:-1] = 0.5 * (slope[1:] + slope[:-1])
        udot[0], udot[-1] = slope[0], slope[-1]
        acc = x @ a.T + np.outer(u, b_u) + np.outer(udot, b_v)
        accs[direction] = acc[:, 2:4]  # bogie, carbody
    n_out = int(np.floor(t_in[-1] * fs + 1e-9)) + 1
    t = np.arange(n_out) / fs
    out = np.array([np.interp(t, t_in, accs["VERTICAL"][:, 1]), np.interp(t, t_in, accs["LATERAL"][:, 1]),
                    np.interp(t, t_in, accs["VERTICAL"][:, 0]), np.interp(t, t_in, accs["LATERAL"][:, 0])])
    return t, out


def _export_text(t, acc, form: str) -> str:
    names = [column for _, column in CHANNELS]
    if form == "table":
        lines = ["# suspid Vampire test double export", " ".join(["Time", *names])]
        lines += [f"{ti:.6f} " + " ".join(f"{v:.9e}" for v in row) for ti, row in zip(t.tolist(), acc.T.tolist())]
    else:
        lines = []
        for name, row in zip(names, acc.tolist()):
            lines += [name, str(len(t))] + [f"{ti:.6f} ; {v:.9e}" for ti, v in zip(t.tolist(), row)]
    return "\n".join(lines) + "\n"


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        _fail("usage: vampire_double.py RUN_FILE", 2)
    run = _read_keyed(Path(argv[0]))
    segment = run.get("SEGMENT", "")
    fault = os.environ.get("VAMPIRE_DOUBLE_FAULT", "")
    if "=" in fault:
        pairs = dict(item.split("=", 1) for item in fault.split(",") if item)
        fault = pairs.get(segment, "")
    log_file = os.environ.get("VAMPIRE_DOUBLE_LOG")

    def log(event: str) -> None:
        if log_file:
            with open(log_file, "a") as fh:
                fh.write(f"{time.time():.6f} {event} {segment} {os.getpid()}\n")

    log("start")
    time.sleep(float(os.environ.get("VAMPIRE_DOUBLE_DELAY_S", "0") or 0))
    if fault == "hang":
        subprocess.Popen([sys.executable, "-c", "import time; time.sleep(3600)"])
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        time.sleep(3600)
    if fault == "exit":
        _fail("solver diverged (simulated failure)", 5)
    for key in ("VEHICLE", "WHEEL", "TRACK", "SPEED_KMH", "SAMPLE_HZ", "OUTPUT", "FORMAT", "UNITS"):
        if key not in run:
            _fail(f"{argv[0]}: no {key} line", 2)
    vehicle = _read_keyed(Path(run["VEHICLE"]))
    if not Path(run["WHEEL"]).read_text().startswith("WHEELPROFILE"):
        _fail(f"{run['WHEEL']}: not a wheel profile", 2)
    track = _read_track(Path(run["TRACK"]))
    speed = _numbers(run["SPEED_KMH"], 1, "SPEED_KMH")[0] / 3.6
    fs = _numbers(run["SAMPLE_HZ"], 1, "SAMPLE_HZ")[0]
    if run["FORMAT"] not in ("table", "blocks") or run["UNITS"] not in ("g", "m/s2"):
        _fail(f"FORMAT must be table|blocks and UNITS g|m/s2, got {run['FORMAT']!r}, {run['UNITS']!r}", 2)
    t, acc = simulate(vehicle, track, speed, fs)
    if run["UNITS"] == "g":
        acc = acc / G
    if fault == "nonfinite":
        acc[0, len(t) // 2] = float("nan")
    text = _export_text(t, acc, run["FORMAT"])
    if fault == "malformed":  # a Fortran overflow field in the last column of a data line
        lines = text.splitlines(keepends=True)
        k = next(k for k in range(len(lines) // 2, len(lines)) if len(lines[k].split()) >= 3)
        parts = lines[k].split()
        parts[-1] = "*********"
        lines[k] = " ".join(parts) + "\n"
        text = "".join(lines)
    if fault == "truncated":  # cut after 40 %: tables inside a row, blocks at the end of a line
        text = text[: int(len(text) * 0.4)]
        text = text[: text.rfind("\n") + 1] + ("0.12" if run["FORMAT"] == "table" else "")
    out = Path(run["OUTPUT"])
    out.parent.mkdir(parents=True, exist_ok=True)
    if fault != "missing":
        out.write_text("" if fault == "empty" else text)
    Path("double.log").write_text(f"double: segment {segment}: {len(t)} samples at {fs:g} Hz\n")
    if fault == "licence":
        print("ERROR: licence not available (all seats in use)", file=sys.stderr)
    if fault == "orphan":
        subprocess.Popen([sys.executable, "-c", "import time; time.sleep(3600)"])
    print(f"double: run complete for segment {segment}")
    log("end")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
