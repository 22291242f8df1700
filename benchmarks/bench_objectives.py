"""Time one evaluation of J (eq. 5) with each objective, against a straightforward scipy loop.

Case of issue 3: v = 100 measured and 100 modelled samples, n = 8 channels,
1000 frequencies (8000 (channel, ω) pairs). J is evaluated through
:class:`suspid.method.objective.ObjectiveFunction` (y_mod = y_sim + b, Ψ_k,
α-weighted sum). The reference is a plain loop over (channel, ω) with
``scipy.stats.gaussian_kde`` on a subset of pairs, timed in the same run and
scaled to 8000 pairs; the ratio is reference / suspid. The reference's values
on the subset are also compared with suspid's.

Run on one core (BLAS threads pinned to 1 before numpy loads)::

    OMP_NUM_THREADS=1 python benchmarks/bench_objectives.py [--repeat 7] [--subset 40]
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
from scipy.stats import gaussian_kde  # noqa: E402

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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=7, help="timed calls per objective (best is reported)")
    parser.add_argument("--subset", type=int, default=40, help="(channel, ω) pairs in the scipy reference loop")
    args = parser.parse_args()

    rng = np.random.default_rng(2026)
    freqs, y_mes, y_sim, noise = synthetic_spectra(rng)
    pairs = [(k % N_CH, int(j)) for k, j in enumerate(rng.choice(N_F, size=args.subset, replace=False))]
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"# bench_objectives  {datetime.date.today()}  python {platform.python_version()}  "
          f"numpy {np.__version__}  {platform.processor() or platform.machine()}  "
          f"load average {load:.2f}  threads: OMP={os.environ['OMP_NUM_THREADS']}")
    print(f"# case: v = {V} measured and {V} modelled samples, {N_CH} channels, {N_F} frequencies "
          f"({N_CH * N_F} (channel, ω) pairs); reference: scipy.stats.gaussian_kde loop on {args.subset} pairs")
    print()
    print("| objective | J evaluation, best wall (s) | median wall (s) | best CPU (s) | scipy loop, "
          "scaled to all pairs (s) | speed-up | max difference on the subset |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for objective, reference in ((LikelihoodObjective(), reference_likelihood),
                                 (OverlapObjective(), reference_overlap)):
        j_of = ObjectiveFunction.from_noise_model(objective, y_mes, freqs, noise, seed=1)
        j_of(y_sim)  # warm-up (imports, caches)
        best, median, cpu = best_time(lambda: j_of(y_sim), args.repeat)
        y_mod = y_sim + j_of.noise_paths
        t0 = time.perf_counter()
        ref = reference(y_mes, y_mod, pairs)
        t_ref = (time.perf_counter() - t0) * (N_CH * N_F) / len(pairs)
        if objective.name == "likelihood":
            ours = np.array([LikelihoodObjective().psi(y_mes[:, [k]][:, :, [j]], y_mod[:, [k]][:, :, [j]],
                                                       freqs[[j]])[0] for k, j in pairs])
            diff = f"{np.max(np.abs(ours - ref) / np.abs(ref)):.1e} (relative)"
        else:
            ours = np.array([OverlapObjective().psi(y_mes[:, [k]][:, :, [j]], y_mod[:, [k]][:, :, [j]],
                                                    freqs[[j]])[0] for k, j in pairs])
            diff = f"{np.max(np.abs(ours - ref)):.1e} (absolute)"
        print(f"| {objective.name} | {best:.3f} | {median:.3f} | {cpu:.3f} | {t_ref:.1f} | "
              f"{t_ref / best:.0f}x | {diff} |")
    print()
    print(f"# floor of the exact likelihood: numpy exp of {V * V * N_CH * N_F:.0e} float64 values "
          f"(one per kernel term) takes {exp_floor(args.repeat):.3f} s CPU here")


if __name__ == "__main__":
    main()
