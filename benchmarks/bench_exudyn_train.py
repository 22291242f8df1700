"""Speed of the exudyn-train simulator's two solvers, and (--physics) what the model does at its nominal values.

Case: 2 km segments of synthetic track (German low disturbance, dx 0.25 m)
at 300 km/h, i.e. 24 s simulated per segment, 10 channels at fs = 100 Hz.

- **time solver**: exudyn generalised-alpha at a 2 ms step, linear contact,
  one segment; the model (and its symbolic track tables) is built once, the
  timed runs then only set the track and integrate. Target: >= 50x faster
  than real time (<= 0.48 s per segment).
- **frequency solver**: a run of 50 segments per parameter vector (random
  vectors in the default identification box); the model is built and the
  input spectra cached by a first call. Target: <= 30 ms per parameter
  vector.

Prints both, the ratio between them per segment, and the rms agreement of the
two solvers on the time solver's segment. BLAS threads are pinned to one
before numpy loads (the frequency solver also does this itself for its small
products).

    python benchmarks/bench_exudyn_train.py [--repeat 5] [--vectors 20] [--segments 50]
        [--vehicle tgv-articulated] [--frequency-only]

``--physics`` prints instead the model's physics (RESULTS.md, "exudyn train
model: modes, stability, ride"; ``docs/model.md`` describes the model) for a vehicle
preset (``--vehicle``, default conventional-hs): modes at 300 km/h, linear
critical speed against conicity and yaw damping, ride rms on German
low-disturbance track at 300 km/h, the influence of a 30 % change of c_yaw on
the carbody vertical spectra, time vs frequency solver, creep saturation.

    python benchmarks/bench_exudyn_train.py --physics [--vehicle manchester-coach]

``--c-yaw-shift`` prints only that influence and the critical speed, for a
preset with other nominal values (``--set k_trac=10e6``, repeatable).
``--pitch-paths`` prints the carbody pitch response to vertical track input
through the vertical suspension alone (links at the carbody's centre of mass)
and as modelled, and its shift for c_yaw x 0.7 (one car).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import datetime  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from bench_objectives import best_time as timed  # noqa: E402  (same folder: best/median wall, best CPU)
from suspid.plugins.simulators.exudyn_train import ExudynTrain  # noqa: E402
from suspid.plugins.simulators.exudyn_train.contact import creep_usage  # noqa: E402
from suspid.data.track import synthetic_segments  # noqa: E402

LENGTH_M, SPEED_KMH, FS_HZ, STEP_S = 2000.0, 300.0, 100.0, 0.002


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5, help="timed runs of the time solver")
    ap.add_argument("--vectors", type=int, default=20, help="parameter vectors for the frequency solver")
    ap.add_argument("--segments", type=int, default=50, help="segments per frequency-solver run")
    ap.add_argument("--physics", action="store_true",
                    help="print the model's modes, stability, ride and solver agreement instead")
    ap.add_argument("--vehicle", default="conventional-hs", help="vehicle preset")
    ap.add_argument("--frequency-only", action="store_true", help="time the frequency solver only")
    ap.add_argument("--c-yaw-shift", action="store_true",
                    help="print only the c_yaw influence on the carbody spectra and the critical speed")
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                    help="with --c-yaw-shift: another nominal value of a vehicle parameter (repeatable)")
    ap.add_argument("--pitch-paths", action="store_true",
                    help="print the carbody pitch response by path and its c_yaw shift (one car)")
    args = ap.parse_args()
    if args.pitch_paths:
        pitch_paths(args.vehicle)
        return
    if args.physics:
        physics(args.vehicle)
        return
    if args.c_yaw_shift:
        overrides = {k: float(v) for k, v in (item.split("=", 1) for item in args.set)}
        sim = ExudynTrain(vehicle={"preset": args.vehicle, **overrides}, fs_hz=FS_HZ)
        segs = synthetic_segments({"spectrum": "german-low", "n_segments": 3, "length_m": 1500.0,
                                   "speed_kmh": 300.0, "seed": 2})
        print(f"# vehicle {args.vehicle} {overrides}: linear critical speed {3.6 * sim.critical_speed():.0f} km/h")
        c_yaw_shift(sim, segs, sim.simulate({}, segs))
        return

    import exudyn

    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"# bench_exudyn_train  {datetime.date.today()}  python {platform.python_version()}  "
          f"numpy {np.__version__}  exudyn {exudyn.__version__}  {platform.machine()}  "
          f"{os.cpu_count()} cpus  load average {load:.2f}")
    n_channels = len(ExudynTrain(vehicle=args.vehicle).channels())
    print(f"# case: vehicle {args.vehicle}, {LENGTH_M:g} m segments, German low disturbance, {SPEED_KMH:g} km/h, "
          f"{LENGTH_M / (SPEED_KMH / 3.6):.1f} s simulated each, fs {FS_HZ:g} Hz, {n_channels} channels")

    segments = synthetic_segments({"spectrum": "german-low", "n_segments": args.segments, "length_m": LENGTH_M,
                                   "speed_kmh": SPEED_KMH, "seed": 1})
    duration = segments[0].duration()

    # ---- time solver
    if not args.frequency_only:
        tsim = ExudynTrain(solver="time", fs_hz=FS_HZ, step_s=STEP_S, vehicle=args.vehicle)
        w0 = time.perf_counter()
        (rt,) = tsim.simulate({}, segments[:1])
        first_t = time.perf_counter() - w0
        best_t, med_t, cpu_t = timed(lambda: tsim.simulate({}, segments[:1]), args.repeat)
        steps = int(round((duration + 0.5) / STEP_S))

    # ---- frequency solver
    fsim = ExudynTrain(solver="frequency", fs_hz=FS_HZ, vehicle=args.vehicle)
    w0 = time.perf_counter()
    rf_all = fsim.simulate({}, segments)
    first_f = time.perf_counter() - w0
    rng = np.random.default_rng(0)
    bounds = {p.name: (p.lower, p.upper) for p in fsim.parameters()}
    vectors = [{n: float(rng.uniform(*bounds[n])) for n in fsim.default_parameters()} for _ in range(args.vectors)]
    for w in vectors:            # first pass: the input spectra of every FFT length get cached
        fsim.simulate(w, segments)
    walls, cpus = [], []
    for w in vectors:            # each call is a new vector: linearisation and FRF are recomputed
        w0, c0 = time.perf_counter(), time.process_time()
        fsim.simulate(w, segments)
        walls.append(time.perf_counter() - w0)
        cpus.append(time.process_time() - c0)
    best_f, med_f, cpu_f = min(walls), float(np.median(walls)), min(cpus)
    target = "<= 90 ms" if fsim.opts.layout.articulated else "<= 30 ms"
    frequency_row = (f"| frequency | {args.segments} segments per parameter vector | {first_f:.2f} | "
                     f"{1e3 * best_f:.1f} ms | {1e3 * med_f:.1f} ms | {1e3 * cpu_f:.1f} ms | "
                     f"{duration * args.segments / med_f:.0f}x real time ({1e3 * med_f / args.segments:.2f} ms "
                     f"per segment) | {target} |")
    if args.frequency_only:
        print()
        print("| solver | case | first call (s) | best wall | median wall | best CPU | speed | target |")
        print("| --- | --- | --- | --- | --- | --- | --- | --- |")
        print(frequency_row)
        print(f"load average after the run: {os.getloadavg()[0]:.2f}")
        return

    # ---- agreement on the time solver's segment (nominal parameters)
    rms_t = np.sqrt(np.mean(rt.accelerations ** 2, axis=1))
    rms_f = np.sqrt(np.mean(rf_all[0].accelerations ** 2, axis=1))
    worst = float(np.max(np.abs(rms_t / rms_f - 1)))

    print()
    print("| solver | case | first call (s) | best wall | median wall | best CPU | speed | target |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    print(f"| time | 1 segment, 2 ms step ({steps} steps) | {first_t:.2f} | {best_t:.3f} s | {med_t:.3f} s | "
          f"{cpu_t:.3f} s | {duration / best_t:.0f}x real time (CPU: {duration / cpu_t:.0f}x; "
          f"{1e6 * cpu_t / steps:.0f} us/step) | >= 50x |")
    print(frequency_row)
    print()
    ratio = med_t / (med_f / args.segments)
    print(f"ratio per segment (median wall): time solver / frequency solver = {ratio:.0f}")
    print(f"time vs frequency solver, nominal parameters, rms of the {n_channels} channels: worst difference "
          f"{100 * worst:.2f} %")


def dynamic_wheel_load(vehicle: str, segments, fs: float = 400.0) -> list[float]:
    """rms of the dynamic wheel load / static wheel load, wheelset 1 left wheel, per segment.

    The wheel-rail force is the force on the rail mass under the wheel:
    (k_track + i w c_track - w^2 m_track) z_rail, from the linear model solved at each frequency line
    (M, K, D and the track inputs of exudyn's linearisation); 2 s at each end left out.
    """
    from suspid.plugins.simulators.exudyn_train.layout import layout_of
    from suspid.plugins.simulators.exudyn_train.solvers import InputSpectra, fft_length, output_samples

    sim = ExudynTrain(vehicle=vehicle, fs_hz=fs)
    p = {q.name: q.nominal for q in sim.parameters()}
    spectra = InputSpectra()
    out = []
    for seg in segments:
        v = float(np.asarray(seg.speed, dtype=float).flat[0])
        lin = sim.linear_system({}, v)
        rail = lin.labels.index(("track", "wheelset_1_left"))
        n_t = output_samples(seg, fs)
        n_fft = fft_length(n_t, fs, float(np.max(np.abs(lin.wheelset_x))) / v, 8.0)
        U = spectra.get(seg, fs, n_fft, 20.0)
        w = 2 * np.pi * np.arange(n_fft // 2 + 1) * fs / n_fft
        Z = np.zeros(w.size, dtype=complex)
        for k, wk in enumerate(w[1:], start=1):   # the static line (k = 0) is left out: the std removes it
            rhs = sum(lin.G[j] @ U[:, k] * np.exp(1j * wk * lin.wheelset_x[j] / v) for j in range(lin.G.shape[0]))
            z = np.linalg.solve(lin.K - wk ** 2 * lin.M + 1j * wk * lin.D, rhs)[rail]
            Z[k] = (p["k_track"] + 1j * wk * p["c_track"] - wk ** 2 * p["m_track"]) * z
        force = np.fft.irfft(Z, n=n_fft)[:n_t][int(2 * fs):-int(2 * fs)]
        out.append(float(np.std(force)) / layout_of(vehicle).wheel_load(p, 0))
    return out


IDENTIFICATION_SPECTRA = {"f_min_hz": 0.4, "f_max_hz": 20.0, "n_freqs": 200}
"""The spectra grid of configs/quickstart.yaml and configs/table1.yaml (the identification band)."""


def c_yaw_shift(sim, segs, base) -> None:
    """Shift of the segment-averaged carbody spectra (identification band) for c_yaw x 0.7 and x 1.3:
    mean over the band / largest bin (its frequency, and how far below the channel's spectral peak it lies)."""
    from suspid.method.spectra import compute_spectra

    y0, f = compute_spectra(base, IDENTIFICATION_SPECTRA)
    level = y0.mean(axis=0)
    c_yaw = {p.name: p.nominal for p in sim.parameters()}["c_yaw"]
    for factor in (0.7, 1.3):
        y1, _ = compute_spectra(sim.simulate({"c_yaw": factor * c_yaw}, segs), IDENTIFICATION_SPECTRA)
        d = np.abs(np.mean(y1 - y0, axis=0))
        k = d.argmax(axis=1)
        print(f"c_yaw x {factor}: spectrum shift (dB, mean / largest bin at Hz, that bin's level below the "
              "channel's peak, 0.4-20 Hz, 200 bins): " + "  ".join(
                  f"{c}: {d[i].mean():.2f}/{d[i, k[i]]:.2f} at {f[k[i]]:.1f} Hz ({level[i].max() - level[i, k[i]]:.0f} dB)"
                  for i, c in enumerate(sim.channels()) if c.startswith("carbody")))


def pitch_paths(vehicle: str, freqs=(4.0, 8.0, 9.6, 10.5, 10.8, 11.1, 12.0, 14.4), speed_kmh: float = 300.0) -> None:
    """Carbody pitch per unit vertical track level (the same at every wheelset, delayed), relative to its value at
    the first frequency: vertical path only (traction rod and yaw dampers at the carbody's centre of mass), as
    modelled, and the shift (dB) of the modelled one for c_yaw x 0.7."""
    v = speed_kmh / 3.6
    f = np.asarray(freqs)

    def pitch(overrides, w=None):
        sim = ExudynTrain(vehicle={"preset": vehicle, **overrides}, fs_hz=FS_HZ)
        lin = sim.linear_system(w or {}, v)
        i = lin.labels.index(("carbody", "pitch"))
        out = []
        for fk in f:
            wk = 2 * np.pi * fk
            rhs = sum(lin.G[j][:, 0] * np.exp(1j * wk * lin.wheelset_x[j] / v) for j in range(lin.G.shape[0]))
            out.append(abs(np.linalg.solve(lin.K - wk ** 2 * lin.M + 1j * wk * lin.D, rhs)[i]))
        return np.array(out)

    p = {q.name: q.nominal for q in ExudynTrain(vehicle=vehicle).parameters()}
    h = p["h_car"]
    alone = pitch({"h_yaw": h, "h_trac": h})
    base = pitch({})
    low = pitch({}, {"c_yaw": 0.7 * p["c_yaw"]})
    print(f"# {vehicle}, {speed_kmh:.0f} km/h: carbody pitch per vertical track level, relative to {f[0]:g} Hz")
    print("f (Hz):                " + "  ".join(f"{x:7.1f}" for x in f))
    print("vertical path only:    " + "  ".join(f"{x:7.4f}" for x in alone / alone[0]))
    print("as modelled:           " + "  ".join(f"{x:7.4f}" for x in base / base[0]))
    print("c_yaw x 0.7 (dB):      " + "  ".join(f"{x:+7.2f}" for x in 20 * np.log10(low / base)))


def physics(vehicle: str) -> None:
    """The physics figures of one vehicle preset (see the module docstring)."""
    from suspid.workflows.simulate import format_modes, modes_report
    from suspid.method.spectra import compute_spectra

    kmh = 1 / 3.6
    sim = ExudynTrain(vehicle=vehicle, fs_hz=FS_HZ)
    print(f"# vehicle preset: {vehicle}")
    print(format_modes(modes_report(sim, 300 * kmh), max_hz=80.0))
    sweep = sim.stability(conicities=(0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.4))
    print(f"\nlinear critical speed, nominal parameters: {sweep['nominal_kmh']:.0f} km/h")
    print("conicity:  " + "  ".join(f"{c:g}: {v:.0f}" for c, v in sweep["conicity"]))
    for name, row in sweep["parameters"].items():
        print(f"{name:<9} " + "  ".join(f"{x:.4g}: {v:.0f}" for x, v in row))
    yaw = {c: 3.6 * sim.critical_speed({"c_yaw": c}) for c in (150e3, 225e3, 300e3, 450e3)}
    print("c_yaw (N s/m): " + "  ".join(f"{c:.3g}: {v:.0f}" for c, v in yaw.items()))
    ks = {k: 3.6 * sim.critical_speed({"k_yaw_s": k}) for k in (5e6, 10e6, 20e6, 1e9)}
    print("k_yaw_s (N/m): " + "  ".join(f"{k:.3g}: {v:.0f}" for k, v in ks.items()))

    segs = synthetic_segments({"spectrum": "german-low", "n_segments": 3, "length_m": 1500.0,
                               "speed_kmh": 300.0, "seed": 2})
    ch = sim.channels()
    base = sim.simulate({}, segs)
    rms = np.sqrt(np.mean([np.mean(r.accelerations ** 2, axis=1) for r in base], axis=0))
    print("\nride rms at 300 km/h, German low disturbance, 3 x 1.5 km, fs 100 Hz (m/s^2):")
    print("  " + "  ".join(f"{c}: {v:.3f}" for c, v in zip(ch, rms)))
    y0, _ = compute_spectra(base)
    c_yaw_shift(sim, segs, base)

    load = dynamic_wheel_load(vehicle, segs)
    print("dynamic wheel load (wheelset 1, left wheel, fs 400 Hz), rms / static: "
          + "  ".join(f"{100 * x:.1f} %" for x in load))

    tsim = ExudynTrain(vehicle=vehicle, solver="time", fs_hz=FS_HZ)
    (rt,) = tsim.simulate({}, segs[:1])
    yt, _ = compute_spectra([rt])
    rel = np.sqrt(np.mean(rt.accelerations ** 2, axis=1)) / np.sqrt(np.mean(base[0].accelerations ** 2, axis=1)) - 1
    db = np.median(np.abs(yt[0] - y0[0]), axis=1)
    print(f"\ntime vs frequency solver (1.5 km): rms difference max {100 * np.max(np.abs(rel)):.2f} %, "
          f"median |dB| max {np.max(db):.2f} dB")
    usage = creep_usage(sim, segs[0], 0.4)
    print("linear creep forces against mu N (friction 0.4, static wheel load), per wheelset: "
          + "  ".join(f"{j + 1}: N {u['wheel_load_n'] / 1e3:.1f} kN, Fx {u['fx_rms_n'] / 1e3:.2f} / Fy "
                      f"{u['fy_rms_n'] / 1e3:.2f} kN rms, u rms {u['u_rms']:.2f} max {u['u_max']:.2f}"
                      for j, u in enumerate(usage)))
    for mu in (0.4, 0.3):
        ssim = ExudynTrain(vehicle=vehicle, solver="time", fs_hz=FS_HZ,
                           contact={"creep_saturation": True, "friction": mu})
        (rs,) = ssim.simulate({}, segs[:1])
        r = np.std(rs.accelerations, axis=1) / np.std(rt.accelerations, axis=1) - 1
        print(f"creep saturation, friction {mu}: rms change vs linear (time solver): " + "  ".join(
            f"{c}: {100 * v:+.1f} %" for c, v in zip(ch, r)))


if __name__ == "__main__":
    main()
