"""Time one evaluation of J (eq. 5) with the baseline objectives ``mean-spectrum`` and ``wasserstein``.

The case of ``bench_objectives.py`` (v = 100 measured and 100 modelled
samples, 8 channels, 1000 frequencies), J through
:class:`suspid.method.objective.ObjectiveFunction`, best of ``--repeat`` calls
after a warm-up. For ``wasserstein`` the vectorised quantile form is compared
with a plain loop of ``scipy.stats.wasserstein_distance`` over the 8000
(channel, ω) pairs (time and largest difference of the per-pair distances).

Run on one core::

    python benchmarks/bench_baseline_objectives.py [--repeat 5]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.stats import wasserstein_distance

from bench_objectives import N_CH, N_F, V, best_time, synthetic_spectra  # also pins the threads to 1
from suspid.method.kde import prepare
from suspid.method.objective import ObjectiveFunction
from suspid.plugins.objectives.mean_spectrum import MeanSpectrumObjective
from suspid.plugins.objectives.wasserstein import WassersteinObjective, wasserstein_rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    freqs, y_mes, y_sim, noise = synthetic_spectra(np.random.default_rng(0))
    print(f"# case: v = {V} measured and {V} modelled samples, {N_CH} channels, {N_F} frequencies; "
          f"best of {args.repeat} J evaluations after a warm-up\n")
    print("| objective | best wall (s) | median wall (s) | best CPU (s) |\n|---|---|---|---|")
    for obj in (MeanSpectrumObjective(), WassersteinObjective()):
        fn = ObjectiveFunction.from_noise_model(obj, y_mes, freqs, noise, seed=1)
        fn.evaluate(y_sim)
        best, median, cpu = best_time(lambda: fn.evaluate(y_sim), args.repeat)
        print(f"| {obj.name} | {best:.4f} | {median:.4f} | {cpu:.4f} |")
    x, y, _, _ = prepare(y_mes, y_sim, freqs)
    t0 = time.perf_counter()
    reference = np.array([wasserstein_distance(a, b) for a, b in zip(x, y)])
    loop = time.perf_counter() - t0
    t0 = time.perf_counter()
    ours = wasserstein_rows(x, y)
    vectorised = time.perf_counter() - t0
    print(f"\nwasserstein, {x.shape[0]} pairs: scipy loop {loop:.3f} s, vectorised {vectorised:.3f} s "
          f"({loop / vectorised:.1f} times faster), largest difference {np.max(np.abs(ours - reference)):.1e} dB")


if __name__ == "__main__":
    main()
