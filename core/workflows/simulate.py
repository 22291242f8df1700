"""The work behind ``suspid simulate`` and ``suspid modes`` (the CLI only parses and prints).

``write_simulation`` runs a simulator with one parameter vector over track
segments and writes ``simulation.h5`` and ``spectra.png`` into a folder;
``modes_report`` asks a simulator that can (a ``modes(speed, w)`` method,
e.g. ``exudyn-train``) for its modes and writes ``modes.json``.

``simulation.h5`` is an accelerations file in the layout of
:mod:`suspid.data.files` (``/segments/<name>/accelerations`` (n_channels, n_t)
m/s^2 with attribute ``fs_hz``; root attribute ``channels``), plus

- ``/y`` ``(n_segments, n_channels, n_freqs)``: spectra in dB (paper eq. 1-2),
  segments in the order of ``/segments`` attribute ``order``;
- ``/freqs`` ``(n_freqs,)`` Hz;
- root attributes ``simulator`` (plugin name), ``parameters`` (JSON of the
  parameter values used, SI units) and ``identity`` (JSON of the simulator's
  identity).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import h5py
import numpy as np

from suspid.errors import SimulatorError
from suspid.infra.arrays import check_fits
from suspid.infra.files import canonical, pyplot, save_figure, write_text
from suspid.method.spectra import compute_spectra
from suspid.interfaces import Response, Simulator, TrackSegment
from suspid.data.files import read_accelerations_h5, write_accelerations_h5

SpectraFn = Callable[[Sequence[Response]], tuple[np.ndarray, np.ndarray]]
"""responses -> (y (n_samples, n_channels, n_freqs) dB, freqs (n_freqs,) Hz)."""


def default_spectra(responses: Sequence[Response], options: Mapping[str, Any] | None = None
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Spectra of :func:`suspid.method.spectra.compute_spectra` with the given ``spectra:`` options."""
    return compute_spectra(responses, options)


def write_simulation(simulator: Simulator, segments: Sequence[TrackSegment], w: Mapping[str, float],
                     out_dir: str | Path, spectra_fn: SpectraFn | None = None) -> Path:
    """Simulate ``w`` on ``segments`` and write ``out_dir/simulation.h5`` and ``out_dir/spectra.png``.

    :param simulator: a built simulator (``cls(**options)``).
    :param segments: the track segments.
    :param w: parameter values (name -> SI value); parameters not named keep
        their nominal values; ``{}`` simulates the nominal vehicle.
    :param out_dir: the folder to write into (created).
    :param spectra_fn: responses -> (y, freqs); default
        :func:`suspid.method.spectra.compute_spectra` with default options (pass
        ``lambda r: compute_spectra(r, config.spectra)`` for the config's).
    :returns: the path of ``simulation.h5``.
    :raises SimulatorError: the simulator failed; DataError: records unfit for the spectra.
    """
    if not segments:
        raise SimulatorError("no track segments to simulate")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    responses = simulator.simulate(dict(w), list(segments))
    if len(responses) != len(segments):
        raise SimulatorError(f"simulator '{simulator.name}' returned {len(responses)} records "
                             f"for {len(segments)} segments")
    # records are keyed by segment name in the file: make them unique and non-empty
    named = []
    seen: set[str] = set()
    for i, (r, s) in enumerate(zip(responses, segments)):
        name = r.segment or s.name or f"segment-{i + 1}"
        while name in seen:
            name = f"{name}-{i + 1}"
        seen.add(name)
        named.append(Response(tuple(r.channels), float(r.fs), np.asarray(r.accelerations, dtype=float), name))
    y, freqs = (spectra_fn or default_spectra)(named)
    path = out / "simulation.h5"
    values = _parameter_values(simulator, w)

    def spectra_and_identity(f) -> None:   # written with the records, in one atomic write
        f.create_dataset("y", data=np.asarray(y, dtype=float))
        f.create_dataset("freqs", data=np.asarray(freqs, dtype=float))
        f["y"].attrs["units"] = "dB re 1 m s^-1.5 (10 log10 |A_hat|, paper eq. 1)"
        f["freqs"].attrs["units"] = "Hz"
        f.attrs["simulator"] = simulator.name
        f.attrs["parameters"] = json.dumps(values, sort_keys=True)
        f.attrs["identity"] = json.dumps(canonical(simulator.identity()), sort_keys=True)

    write_accelerations_h5(named, path, extra=spectra_and_identity)
    plot_spectra(y, freqs, list(named[0].channels), out / "spectra.png",
                 title=f"{simulator.name}: {len(named)} segment(s)")
    return path


def read_simulation(path: str | Path) -> tuple[list[Response], np.ndarray, np.ndarray]:
    """Records, spectra ``y`` and ``freqs`` of a ``simulation.h5``."""
    responses = read_accelerations_h5(path)
    with h5py.File(path, "r") as f:
        for key in ("y", "freqs"):   # their declared sizes, before they are read
            check_fits(str(path), f"dataset /{key}", f[key].shape, f[key].dtype)
        return responses, np.asarray(f["y"][()]), np.asarray(f["freqs"][()])


def plot_spectra(y: np.ndarray, freqs: np.ndarray, channels: Sequence[str], path: str | Path,
                 title: str = "") -> Path:
    """PNG of the spectra: per channel, every segment (thin) and the mean over segments (thick)."""
    plt = pyplot()
    y = np.asarray(y, dtype=float)
    n = len(channels)
    cols = 2 if n > 1 else 1
    rows = int(math.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(6.0 * cols, 2.4 * rows), squeeze=False, sharex=True)
    for k, ch in enumerate(channels):
        ax = axes[k // cols][k % cols]
        for i in range(y.shape[0]):
            ax.plot(freqs, y[i, k], color="0.75", lw=0.6)
        ax.plot(freqs, y[:, k].mean(axis=0), color="C0", lw=1.5)
        ax.set_title(ch, fontsize=9)
        ax.set_ylabel("Y (dB)", fontsize=8)
        ax.grid(alpha=0.3)
    for k in range(n, rows * cols):
        axes[k // cols][k % cols].axis("off")
    for ax in axes[-1]:
        ax.set_xlabel("frequency (Hz)", fontsize=8)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path = Path(path)
    return save_figure(fig, path, dpi=100)


def modes_report(simulator: Simulator, speed: float | None = None, out_dir: str | Path | None = None,
                 w: Mapping[str, float] | None = None) -> dict:
    """The simulator's modes at ``speed`` (m/s; ``None``: the simulator's configured speed).

    Needs a simulator with a ``modes(speed, w)`` method returning
    ``{"stable": bool, "modes": [...], ...}`` (``exudyn-train`` has one).
    Writes ``out_dir/modes.json`` when ``out_dir`` is given.

    :returns: the report: ``stable``, ``speed_mps``, ``speed_kmh``,
        ``least_damped`` and ``modes`` (each with ``frequency_hz``,
        ``damping_ratio``, ``body``, ``motion``, ...).
    :raises SimulatorError: the simulator has no modes.
    """
    modes = getattr(simulator, "modes", None)
    if not callable(modes):
        raise SimulatorError(f"simulator '{simulator.name}' does not provide modes (no linear model)")
    report = dict(modes(speed=speed, w=dict(w or {})))
    report = {"simulator": simulator.name, **report}
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        write_text(out / "modes.json", json.dumps(canonical(report), indent=2) + "\n")
    return report


def format_modes(report: Mapping[str, Any], max_hz: float | None = None) -> str:
    """A text table of a modes report (frequency, damping, dominant body and motion)."""
    lines = [f"modes of {report.get('simulator', 'the model')} at {report['speed_kmh']:.1f} km/h "
             f"({report['speed_mps']:.2f} m/s): {'stable' if report['stable'] else 'UNSTABLE'}",
             f"{'f (Hz)':>9}  {'damping':>8}  {'body':<12} {'motion':<12} share"]
    shown = [m for m in report["modes"] if max_hz is None or m["frequency_hz"] <= max_hz]
    group = None
    for m in shown:
        if m.get("group") is not None and m["group"] != group:   # simulators that group their modes
            group = m["group"]
            lines.append(f"-- {group} modes")
        lines.append(f"{m['frequency_hz']:9.3f}  {m['damping_ratio']:8.3f}  {m['body']:<12} {m['motion']:<12} "
                     f"{m['share']:.2f}")
    for label, pool in (("least damped of these", shown), ("least damped of all", report["modes"])):
        if pool:
            least = min(pool, key=lambda m: m["damping_ratio"])
            lines.append(f"{label}: {least['frequency_hz']:.3f} Hz, damping ratio {least['damping_ratio']:.3f} "
                         f"({least['body']} {least['motion']})")
        if len(shown) == len(report["modes"]):
            break
    return "\n".join(lines)


def stability_report(simulator: Simulator, out_dir: str | Path | None = None, **kwargs: Any) -> dict:
    """The simulator's linear critical speed and its sweep over conicity and parameters.

    Needs a simulator with a ``stability(**kwargs)`` method (``exudyn-train`` has one: keyword
    arguments ``parameters``, ``conicities``, ``n_points``). Writes ``out_dir/stability.json`` when
    ``out_dir`` is given.

    :returns: ``{"simulator", "nominal_kmh", "conicity": [(lambda, km/h)], "parameters": {name: [(value,
        km/h)]}}`` (``inf``: stable over the whole speed range searched).
    :raises SimulatorError: the simulator has no stability analysis.
    """
    stability = getattr(simulator, "stability", None)
    if not callable(stability):
        raise SimulatorError(f"simulator '{simulator.name}' does not provide a stability analysis")
    report = {"simulator": simulator.name, **stability(**kwargs)}
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        write_text(out / "stability.json", json.dumps(canonical(report), indent=2, allow_nan=True) + "\n")
    return report


def format_stability(report: Mapping[str, Any]) -> str:
    """A text table of a stability report: critical speed against conicity and against each parameter."""
    kmh = lambda v: "stable" if math.isinf(v) else f"{v:.0f}"  # noqa: E731
    lines = [f"linear critical speed of {report.get('simulator', 'the model')}: {kmh(report['nominal_kmh'])} km/h "
             f"at the nominal parameters",
             "conicity   " + "  ".join(f"{c:g}: {kmh(v)}" for c, v in report["conicity"])]
    for name, row in report["parameters"].items():
        lines.append(f"{name:<10} " + "  ".join(f"{x:.4g}: {kmh(v)}" for x, v in row))
    return "\n".join(lines)


def _parameter_values(simulator: Simulator, w: Mapping[str, float]) -> dict[str, float]:
    try:
        values = {p.name: float(p.nominal) for p in simulator.parameters()}
    except Exception:  # a simulator that cannot list parameters still simulates
        values = {}
    values.update({k: float(v) for k, v in w.items()})
    return values


