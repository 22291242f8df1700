"""Start-up cost of the command line: ``suspid --help`` against a bare Python start, measured in one run.

The root package imports only the hook markers and the CLI loads the
workflows lazily, so ``--help`` and ``--version`` should cost little more
than the interpreter and typer. Prints the median, minimum and maximum wall
time of each command over ``--runs`` runs, and their ratio.

    python benchmarks/bench_startup.py [--runs 15]
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
from pathlib import Path


def wall_times(argv: list[str], runs: int) -> list[float]:
    """Wall time in s of ``runs`` runs of ``argv`` (output discarded), after one warm-up run."""
    subprocess.run(argv, stdout=subprocess.DEVNULL, check=True)
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        subprocess.run(argv, stdout=subprocess.DEVNULL, check=True)
        times.append(time.perf_counter() - t0)
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=15)
    args = parser.parse_args()
    cli = Path(sys.executable).with_name("suspid")
    commands = {"python -c pass": [sys.executable, "-c", "pass"],
                "import suspid": [sys.executable, "-c", "import suspid"],
                "suspid --help": [str(cli), "--help"],
                "suspid --version": [str(cli), "--version"]}
    rows = {name: wall_times(argv, args.runs) for name, argv in commands.items()}
    base = statistics.median(rows["python -c pass"])
    print(f"{'command':<18} {'median s':>9} {'min s':>7} {'max s':>7} {'x python':>9}  ({args.runs} runs)")
    for name, t in rows.items():
        print(f"{name:<18} {statistics.median(t):9.3f} {min(t):7.3f} {max(t):7.3f} "
              f"{statistics.median(t) / base:9.1f}")


if __name__ == "__main__":
    main()
