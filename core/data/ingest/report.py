"""The quality report of an ingest: ``ingest.json`` (every figure), ``ingest.md`` (for people), PNGs.

Figures (:func:`suspid.infra.files.save_figure`): ``speed.png`` (speed over
time with the kept segments and the excluded stretches), ``alignment.png``
(normalised correlation against the offset), ``spectrogram_<kind>.png`` (one
per channel kind: carbody, bogie, axlebox, ...; the first channel of that kind).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import numpy as np
from scipy import signal as sps

from suspid.infra.files import pyplot, save_figure, write_json, write_text
from suspid.interfaces import TrackSegment

from .align import Alignment
from .load import CHUNK, Recording
from .options import IngestOptions, kind_of
from .quality import ChannelQuality
from .segment import Excluded, Window


def _span(rec: Recording, i0: int, i1: int) -> dict[str, float]:
    g = rec.grid
    j = min(i1, g.n - 1)
    return {"t_start_s": g.t0 + i0 / g.fs, "t_end_s": g.t0 + i1 / g.fs,
            "odometer_start_m": float(rec.distance[i0]), "odometer_end_m": float(rec.distance[j])}


def build(opts: IngestOptions, rec: Recording, quality: dict[str, ChannelQuality], al: Alignment,
          kept: Sequence[Window], segs: Sequence[TrackSegment], provs: Sequence[dict], excluded: Sequence[Excluded],
          warnings: Sequence[str], track_path: Path, acc_path: Path, out: Path) -> dict[str, Any]:
    """The content of ``ingest.json``."""
    g = rec.grid
    channels = {}
    for c in rec.channels:
        i = rec.info[c]
        channels[c] = {"name": i.name, "file_unit": i.file_unit, "declared_unit": i.declared_unit,
                       "factor_to_si": i.factor, "fs_file_hz": i.fs_file, "jitter": i.jitter, "gaps": i.n_gaps,
                       "resampled": i.resampled, **quality[c].to_dict()}
    motion = "speed" if "speed" in rec.info else "distance"
    mi = rec.info[motion]
    segments = []
    for w, s, prov in zip(kept, segs, provs):
        a = rec.accelerations[:, w.i0:w.i1]
        segments.append({"name": s.name, **prov, "length_m": s.length, "speed_mps": float(s.speed),
                         "duration_s": (w.i1 - w.i0) / g.fs,
                         "rms": {c: float(np.sqrt(np.mean((row - row.mean()) ** 2))) for c, row in zip(rec.channels, a)}})
    return {
        "recording": str(rec.path), "format": rec.reader, "fs_hz": g.fs, "n_samples": g.n,
        "duration_s": g.n / g.fs, "distance_m": float(rec.distance[-1] - rec.distance[0]),
        "motion": {"channel": mi.name, "kind": motion, "declared_unit": mi.declared_unit, "file_unit": mi.file_unit,
                   "fs_file_hz": mi.fs_file, "jitter": mi.jitter, "gaps": mi.n_gaps},
        "channels": channels,
        "track": {"path": str(opts.track.path), "quantities": list(opts.track.channels),
                  "band": opts.track.band.describe(), "curvature": opts.track.curvature is not None,
                  "cant": opts.track.cant is not None},
        "alignment": al.to_dict(),
        "segments": segments,
        "excluded": [{"reason": e.reason, **_span(rec, e.i0, e.i1), "duration_s": (e.i1 - e.i0) / g.fs}
                     for e in excluded],
        "warnings": list(warnings),
        "output": {"dir": str(out), "format": opts.output.format, "track_file": str(track_path),
                   "measurements": str(acc_path)},
    }


def markdown(rep: dict[str, Any]) -> str:
    """``ingest.md`` from the content of ``ingest.json``."""
    al = rep["alignment"]
    lines = [f"# Ingest of {Path(rep['recording']).name}", "",
             f"Recording `{rep['recording']}` (reader `{rep['format']}`): {rep['duration_s']:.1f} s at "
             f"{rep['fs_hz']:g} Hz, {rep['distance_m'] / 1000:.3f} km; motion from `{rep['motion']['channel']}` "
             f"({rep['motion']['kind']}, {rep['motion']['declared_unit']}).", "",
             "## Alignment", ""]
    if al["method"] == "given":
        lines.append(f"Offset given in the config: {al['offset_m']:.3f} m.")
    else:
        lever = f"lever {al['lever_m']:.2f} m" + (
            f", found on the model at {3.6 * al['calibration_speed_mps']:.0f} km/h" if al["calibration_speed_mps"] else "")
        lines.append(f"Track distance = odometry distance + **{al['offset_m']:.3f} m**, from the correlation of "
                     f"`{al['channel']}` ({lever}) with the vertical profile: "
                     f"peak correlation {al['rho']:.3f}, peak ratio **{al['peak_ratio']:.2f}** (confidence).")
    tr = rep["track"]
    design = [q for q in ("curvature", "cant") if tr.get(q)]
    lines += ["", "## Track record", "",
              f"`{tr['path']}`: {', '.join(tr['quantities'])}{(', ' + ', '.join(design)) if design else ''}; "
              f"measured as: **{tr.get('band', 'full band')}** (data.track_band of the config: validate and run "
              f"restrict the spectra to the band it supports at each segment's speed)."]
    lines += ["", "## Warnings", ""]
    lines += [f"- {w}" for w in rep["warnings"]] or ["None."]
    lines += ["", "## Channels", "",
              "| channel | recorded | unit (declared / file) | fs file Hz | jitter % | gaps | dropouts | clipped | "
              "flat | spikes | RMS moving m/s^2 | plausible |",
              "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for c, q in rep["channels"].items():
        rng = q["rms_range"]
        ok = "-" if rng is None else ("yes" if rng[0] <= q["rms_moving"] <= rng[1] else "**no**")
        jitter = f"{100 * q['jitter']:.2g}" if q["jitter"] > 1e-8 else "0"    # float time stamps: ~1e-10
        lines.append(f"| {c} | {q['name']} | {q['declared_unit']} / {q['file_unit'] or '-'} | {q['fs_file_hz']:g} | "
                     f"{jitter} | {q['gaps']} | {q['dropouts']} | {q['clipped']} | {q['flat']} | "
                     f"{q['spikes']} | {q['rms_moving']:.4g} | {ok} |")
    lines += ["", f"## Segments ({len(rep['segments'])})", "",
              "| segment | t s | odometer m | track m | speed km/h (min-max) | RMS m/s^2 per channel |",
              "| --- | --- | --- | --- | --- | --- |"]
    for s in rep["segments"]:
        rms = ", ".join(f"{v:.3g}" for v in s["rms"].values())
        lines.append(f"| {s['name']} | {s['t_start_s']:.1f}-{s['t_end_s']:.1f} | {s['odometer_start_m']:.1f} | "
                     f"{s['track_start_m']:.1f} | {3.6 * s['speed_mps']:.1f} ({3.6 * s['speed_min_mps']:.1f}-"
                     f"{3.6 * s['speed_max_mps']:.1f}) | {rms} |")
    lines += ["", "## Excluded", "", "| from s | to s | odometer m | reason |", "| --- | --- | --- | --- |"]
    for e in rep["excluded"]:
        lines.append(f"| {e['t_start_s']:.1f} | {e['t_end_s']:.1f} | {e['odometer_start_m']:.0f}-"
                     f"{e['odometer_end_m']:.0f} | {e['reason']} |")
    o = rep["output"]
    lines += ["", "## Use", "", "In a config for measured data:", "", "```yaml", "data:", "  source: measured",
              f"  track_file: {o['track_file']}", f"  measurements: {o['measurements']}", "```", ""]
    lines += [f"![{f}]({f})" for f in rep.get("figures", [])]
    return "\n".join(lines) + "\n"


def write(rep: dict[str, Any], out: Path) -> None:
    write_json(out / "ingest.json", rep)
    write_text(out / "ingest.md", markdown(rep))


def spectrogram(a: np.ndarray, fs: float, max_columns: int = 1200) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """PSD ``(n_freqs, n_columns)`` of ``a`` ((m/s^2)^2/Hz, NaN as 0) over disjoint windows of about 2 s,
    neighbouring windows averaged down to at most ``max_columns``; returns (freqs Hz, times s, PSD).

    The windows do not overlap, so the record is taken a block of whole columns at a time: the working
    memory does not grow with the recording.
    """
    nper = int(min(4096, max(64, 2 ** np.round(np.log2(2 * fs)))))
    n_win = a.size // nper
    avg = max(1, int(np.ceil(n_win / max_columns)))
    per_block = max(1, CHUNK // (nper * avg)) * avg * nper      # samples per block: whole columns
    cols, times = [], []
    for b0 in range(0, n_win // avg * avg * nper, per_block):
        x = a[b0:b0 + per_block]
        x = np.where(np.isfinite(x), x, 0.0)
        f, tt, s = sps.spectrogram(x, fs=fs, nperseg=nper, noverlap=0)
        k = tt.size // avg
        cols.append(s[:, :k * avg].reshape(s.shape[0], k, avg).mean(axis=2))
        times.append(b0 / fs + tt[:k * avg].reshape(k, avg).mean(axis=1))
    if not cols:   # shorter than one column: one window over what there is
        f, tt, s = sps.spectrogram(np.where(np.isfinite(a), a, 0.0), fs=fs, nperseg=min(nper, a.size), noverlap=0)
        return f, tt, s
    return f, np.concatenate(times), np.concatenate(cols, axis=1)


def figures(opts: IngestOptions, rec: Recording, al: Alignment, kept: Sequence[Window],
            excluded: Sequence[Excluded], out: Path) -> list[Path]:
    """The PNG figures of the module docstring; returns their paths."""
    plt = pyplot()
    g = rec.grid
    paths = []
    step = max(1, g.n // 20000)
    t = g.t0 + np.arange(0, g.n, step) / g.fs
    fig, ax = plt.subplots(figsize=(10, 3.6))
    ax.plot(t, 3.6 * rec.speed[::step], "k-", lw=0.8, label="speed")
    for i, w in enumerate(kept):
        ax.axvspan(g.t0 + w.i0 / g.fs, g.t0 + w.i1 / g.fs, color="tab:green", alpha=0.25,
                   label="kept segments" if i == 0 else None)
    shown = set()
    for e in excluded:
        if "km/h" in e.reason:
            continue
        lab = "excluded (quality, speed, track)" if not shown else None
        shown.add(1)
        ax.axvspan(g.t0 + e.i0 / g.fs, g.t0 + e.i1 / g.fs, color="tab:red", alpha=0.15, label=lab)
    ax.axhline(opts.segments.min_speed_kmh, color="grey", ls=":", lw=0.8, label="min speed")
    ax.set_xlabel("time, s")
    ax.set_ylabel("speed, km/h")
    ax.legend(loc="lower center", fontsize=8)
    ax.set_title(f"{Path(rec.path).name}: {len(kept)} segments of {opts.segments.length_m:g} m")
    fig.tight_layout()
    paths.append(save_figure(fig, out / "speed.png"))
    if al.lags_m.size:
        fig, ax = plt.subplots(figsize=(8, 3.2))
        ax.plot(al.lags_m, al.correlation, "k-", lw=0.8)
        ax.axvline(al.offset_m, color="tab:red", lw=0.8)
        ax.set_xlabel("offset of the track record, m")
        ax.set_ylabel("normalised correlation")
        ax.set_title(f"alignment ({al.channel}): offset {al.offset_m:.2f} m, peak ratio {al.peak_ratio:.2f}")
        fig.tight_layout()
        paths.append(save_figure(fig, out / "alignment.png"))
    kinds: dict[str, str] = {}
    for c in rec.channels:
        k = kind_of(c, list(opts.quality.rms_range)) or c.split("_")[0]
        kinds.setdefault(k, c)
    for k, c in kinds.items():
        f, tt, s = spectrogram(rec.accelerations[rec.channels.index(c)], g.fs)
        db = 10 * np.log10(s + 1e-20)
        fig, ax = plt.subplots(figsize=(10, 3.6))
        m = ax.imshow(db, origin="lower", aspect="auto", cmap="viridis", vmin=np.percentile(db, 5),
                      extent=(g.t0 + tt[0], g.t0 + tt[-1], f[0], f[-1]))
        fig.colorbar(m, ax=ax, label="dB (m/s^2)^2/Hz")
        ax.set_ylim(0, min(g.fs / 2, 50.0))
        ax.set_xlabel("time, s")
        ax.set_ylabel("frequency, Hz")
        ax.set_title(f"{c} ({k})")
        fig.tight_layout()
        paths.append(save_figure(fig, out / f"spectrogram_{k}.png"))
    return paths
