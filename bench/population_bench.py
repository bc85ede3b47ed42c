"""The population certificate's wall time (issue 33: the 1000-patient certificate on 2 workers
and on Dask): docs/every-patient.md "What it costs".

Run with ``.venv/bin/python -m bench.population_bench`` (defaults: config/patient_aware.yaml on
the paper's arm, 40 patients x 25 trials, 2 local worker processes, then the same patients on a
local Dask cluster of 2 single-threaded workers). Each way is run once after a warm-up patient
(numba's compiled kernels cached); prints the wall time, the CPU seconds per trial the cells
report, and the 1000-patient wall time EXTRAPOLATED linearly from the measured N (the cells are
independent, so the time is linear in N on a fixed number of workers; a machine others load
gives a longer time). ``--patients 1000`` measures the full size instead. Asserts nothing.

The pool's workers start with one BLAS thread each, as Dask's nanny starts its workers
(``OPENBLAS_NUM_THREADS`` and the like set to 1 unless already set): ``--blas-threads 2``
measures the pool as it ran before that (two workers of two BLAS threads on two CPUs).
"""

from __future__ import annotations

import argparse
import os
import time
from typing import Any

from distributed import LocalCluster

from exo_ilc_ros.analysis.certificate import run_population
from exo_ilc_ros.analysis.study import BLAS_THREADS
from exo_ilc_ros.core.loop.rate import with_control_rate
from exo_ilc_ros.core.params.config import config_dir, load_config
from exo_ilc_ros.core.population.certificate import certificate, patient_cell, patient_config
from exo_ilc_ros.core.population.distributions import PopulationSpec, draw_population
from exo_ilc_ros.core.programs.study import StudyCell, run_cell

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")  # no node here; house rule
TARGET = 1000


def _cells(config: str, overlays: list[str], patients: int, trials: int,
           seed: int) -> list[StudyCell]:
    base = with_control_rate(load_config(config, overlays=overlays))  # as certify runs it
    return [patient_cell("bench", patient_config(base, p, trials), p)
            for p in draw_population(base, PopulationSpec(), patients, seed)]


def _measure(name: str, cells: list[StudyCell], trials: int, workers: int,
             dask: Any | None) -> None:
    start = time.perf_counter()
    outcomes = run_population(cells, trials, workers, dask, None, {})
    wall = time.perf_counter() - start
    cert = certificate("bench", len(cells), trials, 0.005, outcomes)
    n = len(cells)
    per_patient = wall / n
    print(f"{name}: {n} patients x {trials} trials in {wall:.1f} s wall "
          f"({per_patient:.2f} s per patient); 1000 patients EXTRAPOLATED: "
          f"{per_patient * TARGET / 60:.1f} min; certificate passes: {cert.passes}, "
          f"within by 10: {100 * cert.share('within_by_10'):.1f} %", flush=True)


def main() -> None:
    """Measure the certificate on the pool and on Dask."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default=str(config_dir() / "patient_aware.yaml"))
    parser.add_argument("--overlay", nargs="*", default=[])
    parser.add_argument("--patients", type=int, default=40)
    parser.add_argument("--trials", type=int, default=25)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-dask", action="store_true")
    parser.add_argument("--blas-threads", type=int, default=None,
                        help="BLAS threads of each pool worker (default: 1)")
    args = parser.parse_args()
    if args.blas_threads is not None:  # the workers inherit it (the pool sets only unset ones)
        for name in BLAS_THREADS:
            os.environ[name] = str(args.blas_threads)
    cells = _cells(args.config, args.overlay, args.patients, args.trials, args.seed)
    print(f"population bench: {args.config} {' '.join(args.overlay)}, {args.patients} "
          f"patients x {args.trials} trials, {args.workers} workers, {os.cpu_count()} CPUs",
          flush=True)
    start = time.perf_counter()
    warm = run_cell(cells[0])
    print(f"warm-up patient (compiles or loads numba's kernels): "
          f"{time.perf_counter() - start:.1f} s wall, its run {warm.seconds:.2f} s", flush=True)
    _measure(f"process pool ({args.workers} workers)", cells, args.trials, args.workers, None)
    if not args.no_dask:
        with LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True,
                          dashboard_address=None) as cluster:
            _measure(f"Dask LocalCluster ({args.workers} workers x 1 thread)", cells,
                     args.trials, 1, cluster)


if __name__ == "__main__":
    main()
