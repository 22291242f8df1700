"""Time one evaluation of J (eq. 5) with each objective, against the numpy reference and a scipy loop.

Case: v = 100 measured and 100 modelled samples, n = 8 channels, 1000
frequencies (8000 (channel, ω) pairs). J is evaluated through
:class:`suspid.method.objective.ObjectiveFunction` (y_mod = y_sim + b, Ψ_k,
α-weighted sum); each figure is the best of ``--repeat`` calls after a warm-up.

- likelihood: the compiled kernel (``kernel: auto``) against the numpy
  reference (``kernel: numpy``) timed in the same run; the ratio is
  reference / kernel, and the largest relative difference is taken over the
  8000 per-(channel, ω) log-likelihoods Σ_i log p and over J.
- overlap: one implementation (numpy, binned), no separate reference.
- both: a plain loop over (channel, ω) with ``scipy.stats.gaussian_kde`` on a
  subset of pairs, scaled to 8000 pairs, as an independent check of the values.
- first call of the kernel: compile and cache write in a fresh process with an
  empty numba cache, then a second process loading that cache.

Run on one core (BLAS and numba threads pinned to 1 before numpy loads)::

    python benchmarks/bench_objectives.py [--repeat 5] [--subset 40]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import datetime  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

import numba  # noqa: E402
import numpy as np  # noqa: E402
from scipy.stats import gaussian_kde  # noqa: E402

from suspid.method.kde import bandwidths, log_kde, prepare  # noqa: E402
from suspid.method.noise import NoiseModel  # noqa: E402
from suspid.method.objective import ObjectiveFunction  # noqa: E402
from suspid.plugins.objectives.likelihood import LikelihoodObjective  # noqa: E402
from suspid.plugins.objectives.overlap import OverlapObjective  # noqa: E402

V, N_CH, N_F = 100, 8, 1000


def synthetic_spectra(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray, NoiseModel]:
    """Spectra in dB shaped like carbody/bogie accelerations, 2.8 dB scatter per line."""
    freqs = np.linspace(0.3, 30.0, N_F)
    f_n = np.linspace(0.8, 9.0, N_CH)[:, None]
    shape = -10 * np.log10(np.abs(1 - (freqs / f_n) ** 2) + 0.3 * freqs / f_n) - 15.0
    y_sim = shape + rng.normal(0.0, 2.8, size=(V, N_CH, N_F))
    y_mes = shape + 0.5 + rng.normal(0.0, 3.0, size=(V, N_CH, N_F))
    noise = NoiseModel(variance_fraction=0.95).fit(rng.normal(0.5, 1.0, size=(V, N_CH, N_F)), freqs=freqs)
    return freqs, y_mes, y_sim, noise


def best_time(fn, repeat: int) -> tuple[float, float, float]:
    """(best wall, median wall, best CPU) seconds over ``repeat`` calls."""
    wall, cpu = [], []
    for _ in range(repeat):
        w0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - w0)
        cpu.append(time.process_time() - c0)
    return min(wall), float(np.median(wall)), min(cpu)


def exp_floor(repeat: int) -> float:
    """Best CPU seconds numpy needs for V·V·N_CH·N_F float64 exponentials (one per kernel term), in blocks."""
    block = np.linspace(-30.0, 0.0, 1 << 16)
    calls = V * V * N_CH * N_F // block.size
    out = np.empty_like(block)

    def run():
        for _ in range(calls):
            np.exp(block, out=out)

    return best_time(run, repeat)[2]


def reference_likelihood(y_mes, y_mod, pairs):
    return np.array([gaussian_kde(y_mod[:, k, j], bw_method="silverman").logpdf(y_mes[:, k, j]).sum()
                     for k, j in pairs])


def reference_overlap(y_mes, y_mod, pairs, points=2048):
    out = []
    for k, j in pairs:
        p, q = gaussian_kde(y_mes[:, k, j], bw_method="silverman"), gaussian_kde(y_mod[:, k, j], bw_method="silverman")
        h = max(np.sqrt(p.covariance[0, 0]), np.sqrt(q.covariance[0, 0]))
        lo = min(y_mes[:, k, j].min(), y_mod[:, k, j].min()) - 6 * h
        hi = max(y_mes[:, k, j].max(), y_mod[:, k, j].max()) + 6 * h
        u = np.linspace(lo, hi, points)
        out.append(np.trapezoid(np.minimum(p(u), q(u)), u))
    return np.array(out)


FIRST_CALL = """
import time
t0 = time.perf_counter()
import numpy as np
from suspid.method.kde import log_kde
t1 = time.perf_counter()
rng = np.random.default_rng(0)
log_kde(rng.normal(size=(4, 100)), rng.normal(size=(4, 100)), np.ones(4), method="numba")
print(t1 - t0, time.perf_counter() - t1)
"""


def first_call() -> tuple[tuple[float, float], tuple[float, float]]:
    """(import s, first call s) of the kernel with an empty numba cache, then with the cache it wrote."""
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        runs = [subprocess.run([sys.executable, "-c", FIRST_CALL], env=env, check=True, capture_output=True,
                               text=True).stdout.split() for _ in range(2)]
    return tuple(tuple(float(v) for v in run) for run in runs)


def row_log_likelihoods(y_mes, y_mod, freqs, method):
    """Σ_i log p per (channel, ω), ``(8000,)``, by one log_kde implementation (Silverman, as the objective)."""
    x, y, _, _ = prepare(y_mes, y_mod, freqs)
    return log_kde(x, y, bandwidths(y, "silverman", 1e-3), method=method).sum(axis=1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5, help="timed calls per objective (best is reported)")
    parser.add_argument("--subset", type=int, default=40, help="(channel, ω) pairs in the scipy reference loop")
    args = parser.parse_args()

    rng = np.random.default_rng(2026)
    freqs, y_mes, y_sim, noise = synthetic_spectra(rng)
    pairs = [(k % N_CH, int(j)) for k, j in enumerate(rng.choice(N_F, size=args.subset, replace=False))]
    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    print(f"# bench_objectives  {datetime.date.today()}  python {platform.python_version()}  "
          f"numpy {np.__version__}  numba {numba.__version__}  {platform.processor() or platform.machine()}  "
          f"{os.cpu_count()} cpus  load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}  "
          f"threads: OMP={os.environ['OMP_NUM_THREADS']} NUMBA={os.environ['NUMBA_NUM_THREADS']}")
    print(f"# case: v = {V} measured and {V} modelled samples, {N_CH} channels, {N_F} frequencies "
          f"({N_CH * N_F} (channel, ω) pairs); best of {args.repeat} J evaluations after a warm-up")
    print()
    print("| objective | implementation | best wall (s) | median wall (s) | best CPU (s) | "
          "numpy reference / this, wall (CPU) | max relative difference to the numpy reference |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    scipy_rows = []
    for name, objective, reference in (
            ("likelihood", LikelihoodObjective(), LikelihoodObjective(kernel="numpy")),
            ("overlap", OverlapObjective(), None)):
        j_of = ObjectiveFunction.from_noise_model(objective, y_mes, freqs, noise, seed=1)
        j_val, psi = j_of(y_sim)  # warm-up (imports, compilation or cache load)
        best, median, cpu = best_time(lambda: j_of(y_sim), args.repeat)
        y_mod = y_sim + j_of.noise_paths
        if reference is None:
            print(f"| {name} | numpy (binned, unchanged) | {best:.3f} | {median:.3f} | {cpu:.3f} | - | - |")
        else:
            j_ref_of = ObjectiveFunction(reference, y_mes, freqs, j_of.noise_paths)
            j_ref, psi_ref = j_ref_of(y_sim)
            ref_best, ref_median, ref_cpu = best_time(lambda: j_ref_of(y_sim), args.repeat)
            rows = row_log_likelihoods(y_mes, y_mod, freqs, "numba")
            rows_ref = row_log_likelihoods(y_mes, y_mod, freqs, "numpy")
            diff = (f"{np.max(np.abs(rows - rows_ref) / np.abs(rows_ref)):.1e} over the {rows.size} "
                    f"Σ_i log p, {np.max(np.abs(psi - psi_ref) / np.abs(psi_ref)):.1e} over the "
                    f"{psi.size} Ψ_k, {abs(j_val - j_ref) / abs(j_ref):.1e} on J")
            print(f"| {name} | numba kernel | {best:.3f} | {median:.3f} | {cpu:.3f} | "
                  f"{ref_best / best:.2f} ({ref_cpu / cpu:.2f}) | {diff} |")
            print(f"| {name} | numpy reference | {ref_best:.3f} | {ref_median:.3f} | {ref_cpu:.3f} | 1 | 0 |")
        t0 = time.perf_counter()
        ref = (reference_likelihood if name == "likelihood" else reference_overlap)(y_mes, y_mod, pairs)
        t_ref = (time.perf_counter() - t0) * (N_CH * N_F) / len(pairs)
        ours = np.array([type(objective)().psi(y_mes[:, [k]][:, :, [j]], y_mod[:, [k]][:, :, [j]],
                                               freqs[[j]])[0] for k, j in pairs])
        if name == "likelihood":
            diff = f"{np.max(np.abs(ours - ref) / np.abs(ref)):.1e} (relative)"
        else:
            diff = f"{np.max(np.abs(ours - ref)):.1e} (absolute)"
        scipy_rows.append(f"| {name} | {t_ref:.1f} | {t_ref / best:.0f}x | {diff} |")
    print()
    print(f"Independent check: scipy.stats.gaussian_kde loop on {args.subset} pairs, scaled to all pairs")
    print()
    print("| objective | scipy loop (s) | scipy / suspid, wall | max difference on the subset |")
    print("| --- | --- | --- | --- |")
    print("\n".join(scipy_rows))
    print()
    (imp_cold, call_cold), (imp_warm, call_warm) = first_call()
    print(f"# first call of the kernel in a new process: {call_cold:.2f} s with an empty numba cache "
          f"(compilation; import of suspid.method.kde {imp_cold:.2f} s), {call_warm:.2f} s once cached "
          f"(import {imp_warm:.2f} s)")
    print(f"# numpy exp of {V * V * N_CH * N_F:.0e} float64 values (one per kernel term) takes "
          f"{exp_floor(args.repeat):.3f} s CPU here (the numpy reference's floor)")


if __name__ == "__main__":
    main()
