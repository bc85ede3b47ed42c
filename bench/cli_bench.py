"""Benchmark of the command line: how long ``exo-ilc --help`` and a one-trial ``exo-ilc
simulate`` take to answer (fresh processes), and what ``simulate`` costs per trial beside
``run_trials`` for the same trials (in one process, kernels warm), with and without
``--metrics`` (the therapy metrics of every trial).

Run with ``.venv/bin/python -m bench.cli_bench [--trials K] [--repeats R]``. Prints medians of R
runs; asserts nothing (wall-clock timing is noisy on a shared machine). Targets (issue 36):
``--help`` <= 0.5 s, ``simulate --trials 1`` <= 1.5 s, simulate per trial within 1.2x of
``run_trials``.

Measured once (a shared 2-core machine, load average 2-3, other jobs running; ``--trials 20
--repeats 5``): ``--help`` 0.56 s (4.1 s before the commands deferred their heavy imports),
``simulate --help`` 0.54 s, ``simulate --trials 1`` 3.6 s (kernel cache warm; most of it is
loading the experiment); per trial run_trials 12.3 ms, simulate 17.1 ms (1.40x, a fixed cost
per run spread over 20 trials: config, report), simulate --json 16.8 ms, simulate --metrics
--json 31.2 ms (2.54x: the therapy metrics cost ~14 ms per trial).

Measured again (2026-12-05, load average 2.5-3.2) after ``exo-ilc run`` stopped importing the
live view's layout (and with it numba) at start-up and scipy.signal became a first-use import:
``--help`` 0.66 s, ``simulate --help`` 0.61-0.62 s, ``simulate --trials 1`` 2.63-2.71 s (was
3.9 s under the same load; its module imports 1.5 s, were 2.8 s); per trial with ``--trials 20
--repeats 5`` run_trials 13.5 ms, simulate 18.3 ms (1.35x), ``--metrics --json`` 41.7 ms; with
``--trials 100 --repeats 3`` run_trials 14.8 ms, simulate 13.6 ms (0.92x), ``--json`` 13.7 ms,
``--metrics --json`` 29.1 ms (1.97x). A bare ``python -c "import numpy"`` took 0.29-0.31 s then.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from exo_ilc_ros.cli.main import main
from exo_ilc_ros.core import load_config, run_trials


def median_seconds(action: Callable[[], object], repeats: int) -> float:
    """Median wall time of ``action`` over ``repeats`` calls."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        action()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def command_seconds(argv: list[str], repeats: int) -> float:
    """Median wall time of ``exo-ilc ARGV`` in a fresh Python process."""
    command = [sys.executable, "-m", "exo_ilc_ros.cli.main", *argv]
    return median_seconds(lambda: subprocess.run(command, capture_output=True, check=True),
                          repeats)


def quiet_main(argv: list[str]) -> None:
    """``exo-ilc ARGV`` in this process, its output discarded."""
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        code = main(argv)
    if code != 0:
        raise SystemExit(f"exo-ilc {' '.join(argv)} exited {code}")


def main_bench(argv: list[str] | None = None) -> None:
    """Print the start-up times and the per-trial costs."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--trials", type=int, default=10)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--delta", type=float, default=0.05)
    args = parser.parse_args(argv)
    k, r, delta = args.trials, args.repeats, args.delta
    print(f"exo-ilc --help                 {command_seconds(['--help'], r):6.2f} s")
    print(f"exo-ilc simulate --help        {command_seconds(['simulate', '--help'], r):6.2f} s")
    print(f"exo-ilc simulate --trials 1    "
          f"{command_seconds(['simulate', '--trials', '1', '--quiet'], r):6.2f} s")
    config = load_config(None)
    run_trials(config, delta, 1)  # kernels compiled and loaded
    base = ["simulate", "--trials", str(k), "--mass-uncertainty", f"{delta:g}", "--quiet"]
    with tempfile.TemporaryDirectory() as tmp:
        out = str(Path(tmp) / "run.json")
        rows = [
            ("run_trials", lambda: run_trials(config, delta, k)),
            ("exo-ilc simulate", lambda: quiet_main(base)),
            ("exo-ilc simulate --json", lambda: quiet_main([*base, "--json", out])),
            ("exo-ilc simulate --metrics --json",
             lambda: quiet_main([*base, "--metrics", "--json", out])),
        ]
        reference = None
        print(f"\nper trial, {k} trials at delta {delta:g}, median of {r} runs:")
        for label, action in rows:
            per_trial = median_seconds(action, r) / k
            reference = reference or per_trial
            print(f"{label:34s} {per_trial * 1e3:7.2f} ms  ({per_trial / reference:.2f}x "
                  "run_trials)")


if __name__ == "__main__":
    main_bench()
