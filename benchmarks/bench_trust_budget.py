"""Model-error checks within budget: the linearised checks against the full ones, on both independent trains.

For every generator (``tests/independent`` and ``tests/independent2``), seed,
measurement-date suspension w_ref and objective, ``bench_model_form.py`` writes
the two dates and identifies w with the default checks (``method: linearised``);
then ``--compare-methods`` runs both methods in this process on each run's
problem, ledger, w_opt and sampling spread (:func:`bench_model_form.compare_methods`):
per component each method's flag (trust under model error, with the "too uncertain"
verdict of the bias-aware half-width), whether its interval holds the truth, each
source of bias as each method measured it, the simulator calls of each check, and
the agreement of the flags (the target is >= 90 %). Both methods combine the sources
on one rule (:func:`suspid.workflows.trust.combine_sources`); they differ only in
how each source's shift of w_opt is obtained.

Usage (from the repository root)::

    python benchmarks/bench_trust_budget.py OUT_DIR [--generators independent independent2] [--seeds 7]
        [--w-refs w0 quickstart] [--objectives overlap likelihood] [--segments 100]

100 segments of 1 km per date by default, the acceptance setting of ``bench_model_form.py`` (the paper's
"about one hundred" track realisations per date); runs that ``bench_model_form.py`` finished in the same
OUT_DIR/GENERATOR folders are reused, not identified again.

Each comparison is kept beside its run (``compare_methods.json``): running again completes a cut grid, and the
last table (both generators) holds every comparison finished so far.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import bench_model_form as MF  # noqa: E402


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--generators", nargs="+", default=list(MF.GENERATORS), choices=list(MF.GENERATORS))
    ap.add_argument("--seeds", nargs="+", default=["7"])
    ap.add_argument("--w-refs", nargs="+", default=["w0", "quickstart"])
    ap.add_argument("--objectives", nargs="+", default=["overlap", "likelihood"])
    ap.add_argument("--segments", default="100", help="segments of 1 km per date (default 100, the acceptance "
                    "setting; 24 was the earlier, faster comparison)")
    a = ap.parse_args(argv)
    cfgs = []
    for objective in a.objectives:     # run by run, the generators alternating: a cut grid still holds both
        for w_ref in a.w_refs:
            for seed in a.seeds:
                for generator in a.generators:
                    print(f"\n# generator {generator}, seed {seed}, {w_ref}, {objective}", flush=True)
                    MF.main([str(a.out / generator), "--generator", generator, "--seeds", seed, "--w-refs", w_ref,
                             "--objectives", objective, "--segments", a.segments, "--jobs", "1",
                             "--compare-methods", "--weights", "equal"])   # the setting its figures were measured at
                    cfgs.append(a.out / generator / f"seed{seed}-{w_ref}" / f"{objective}.yaml")
    print("\n# both generators", flush=True)
    done = [c for c in cfgs if (c.parent / "runs" / c.stem / "compare_methods.json").exists()]
    MF.compare_table(done)
    print("\nself-check bias, % of the interval: linearised on the nominal reference spectra extrapolated to the "
          "calibrated model (the former rule) / linearised on the calibrated model simulated (the rule now) / full "
          "(MF.self_check_why)")
    for cfg in done:
        why = MF.self_check_why(cfg)
        print(f"  {cfg.parent.parent.name}:{cfg.parent.name}/{cfg.stem}: "
              + ", ".join(f"{n} {a:+.1f} / {b:+.1f} / {c:+.1f}" for n, (a, b, c) in why.items()), flush=True)


if __name__ == "__main__":
    main()
