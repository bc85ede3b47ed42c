"""Running the robustness study's cells (a local process pool, or a Dask distributed cluster)
and reporting it: one table, the JSON export. The cells and their reduction are
:mod:`exo_ilc_ros.core.programs.study`; the figure is :mod:`.study_figure`.

Results are placed by the cell's index, never by the order they finish in, so every way of
running gives the same table.
"""

from __future__ import annotations

import ctypes
import json
import multiprocessing
import os
import signal
import threading
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__
from ..core.convergence.growth import MIN_TRIALS
from ..core.errors import ExoIlcError
from ..core.params.redact import redact
from ..core.programs.study import CellResult, StudyCell, run_cell
from ..core.programs.study_rows import FLOOR_WINDOW, StudyRow, growth_window

OnDone = Callable[[StudyCell], None]
"""Called in the caller's process once per finished cell (progress)."""
OnResult = Callable[[StudyCell, CellResult], None]
"""Called in the caller's process with each cell's result as it finishes (written at once)."""


PR_SET_PDEATHSIG = 1
"""prctl(2): the signal a process gets when its parent dies."""
CONNECT_TIMEOUT = "20s"
"""How long to try to reach a Dask scheduler before giving up."""


class ClusterError(ExoIlcError):
    """The Dask cluster cannot be reached or its workers cannot run the cells."""


def _ignore_interrupt() -> None:
    """Worker initializer: Ctrl-C is the parent's to handle (no tracebacks from the workers);
    the SIGINT the worker was started with blocked (:func:`_interrupt_deferred`) is ignored
    from here on, one already pending with it. A worker dies with the study (SIGTERM when its
    parent dies): a killed study leaves no worker computing on."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    parent = multiprocessing.parent_process()
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):  # not Linux: workers end when their queue breaks
        return
    if parent is not None and os.getppid() != parent.pid:  # the study died before that
        os._exit(1)


@contextmanager
def _interrupt_deferred() -> Iterator[None]:
    """SIGINT blocked while worker processes are started: they inherit the mask, so a Ctrl-C
    while they import (before the initializer runs) prints no KeyboardInterrupt of theirs, and
    here it stays pending and is raised as soon as the workers are started. (Ignoring it instead
    lost a Ctrl-C that came in that window: the study ran on; seen in CI under load.) A no-op
    outside the main thread (only it handles signals)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def run_cells(cells: Sequence[StudyCell], workers: int = 1, dask: str | Any | None = None,
              on_done: OnDone | None = None,
              on_result: OnResult | None = None) -> list[CellResult]:
    """Every cell's result, in the cells' order: on a Dask cluster when ``dask`` is given (a
    scheduler address such as ``tcp://host:8786``, or a cluster object), else over ``workers``
    local processes (1: in this process). ``on_result`` gets each result as it finishes (before
    ``on_done``). Ctrl-C stops the workers and raises KeyboardInterrupt."""
    def finished(cell: StudyCell, result: CellResult) -> None:
        if on_result is not None:
            on_result(cell, result)
        if on_done is not None:
            on_done(cell)

    if dask is not None:
        return _run_on_dask(cells, dask, finished)
    if workers <= 1 or len(cells) <= 1:
        results = []
        for cell in cells:
            results.append(run_cell(cell))
            finished(cell, results[-1])
        return results
    return _run_on_pool(cells, min(workers, len(cells)), finished)


BLAS_THREADS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
"""The environment variables that set a worker's BLAS threads."""


@contextmanager
def _one_blas_thread() -> Iterator[None]:
    """Worker processes started within inherit one BLAS thread each (unless the user set the
    count): a cell's matrices are small (the identification's 7 x 7 to 9 x 9 solves, products
    of a few thousand samples by a few hundred columns), and each worker is one of as many as
    there are CPUs, so a second BLAS thread per worker only contends for the same CPUs (it
    spins while it waits). The results are the same bits: BLAS splits a product's output, not
    its sums. Dask's nanny does the same for its workers."""
    saved = {name: os.environ.get(name) for name in BLAS_THREADS}
    for name in BLAS_THREADS:
        os.environ.setdefault(name, "1")
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def _run_on_pool(cells: Sequence[StudyCell], workers: int,
                 finished: OnResult) -> list[CellResult]:
    context = multiprocessing.get_context("spawn")  # no fork of numba's or tqdm's threads
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=context,
                               initializer=_ignore_interrupt)
    results: list[CellResult | None] = [None] * len(cells)
    try:
        # the workers start (on submit) with SIGINT blocked and one BLAS thread each
        with _interrupt_deferred(), _one_blas_thread():
            pending: dict[Future[CellResult], int] = {
                pool.submit(run_cell, cell): i for i, cell in enumerate(cells)}
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in done:
                index = pending.pop(future)
                results[index] = result = future.result()
                finished(cells[index], result)
    except BaseException:  # Ctrl-C or a worker's error: stop every worker now, not after its cell
        processes = list(getattr(pool, "_processes", {}).values())
        for process in processes:
            process.terminate()
        for process in processes:  # joined here with a bound: shutdown(wait=True) waits for the
            process.join(timeout=10.0)  # pool's manager thread, which a killed worker may stall
            if process.is_alive():
                process.kill()
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown(wait=True)
    return [r for r in results if r is not None]


def _run_on_dask(cells: Sequence[StudyCell], address: str | Any,
                 finished: OnResult) -> list[CellResult]:
    try:
        from distributed import Client, as_completed
    except ImportError as exc:  # pragma: no cover - a dependency of the package
        raise ClusterError(f"--dask needs the 'distributed' package ({exc})") from None
    try:
        client = Client(address, timeout=CONNECT_TIMEOUT)
    except (OSError, TimeoutError, ValueError) as exc:
        raise ClusterError(f"cannot reach the Dask scheduler {redact(repr(address))}: "
                           f"{redact(str(exc))}") from None
    futures: list[Any] = []
    try:
        futures = client.map(run_cell, list(cells), pure=False)
        index = {future.key: i for i, future in enumerate(futures)}
        results: list[CellResult | None] = [None] * len(cells)
        for future in as_completed(futures):
            i = index[future.key]
            result = future.result()
            if result.version != __version__:
                raise ClusterError(f"a Dask worker runs exo_ilc_ros {result.version}, this "
                                   f"client {__version__}: install the same version on every "
                                   "worker")
            results[i] = result
            finished(cells[i], result)
        return [r for r in results if r is not None]
    finally:
        if futures:
            client.cancel(futures)
        client.close()


# --- the table --------------------------------------------------------------------------------

def _trial(value: int | None) -> str:
    return "-" if value is None else str(value)


def _long_run(row: StudyRow) -> str:
    if not row.finite:
        return "FAILED"
    parts = []
    if row.trials < MIN_TRIALS and not row.late_aborts:
        return f"- (< {MIN_TRIALS} trials)"
    if row.growing_seeds:
        joints = ",".join(f"j{j}" for j in row.growing_joints)
        seeds = f" {row.growing_seeds}/{row.seeds}" if row.seeds > 1 else ""
        parts.append(f"GROWING {joints}{seeds} {100 * row.max_growth_rate:+.1f}%/tr")
    if row.late_aborts:
        parts.append("ABORTS")
    return ", ".join(parts) if parts else "bounded"


def _floor(row: StudyRow) -> str:
    if not np.isfinite(row.floor):
        return "-"
    text = f"{row.floor:.2e}"
    if row.seeds > 1:
        text += f" [{row.floor_low:.1e}-{row.floor_high:.1e}]"
    return text + ("*" if row.floor > row.error_bound else " ")


def format_study_table(rows: Sequence[StudyRow]) -> str:
    """The study's table: one row per law x scenario x uncertainty (seeds reduced)."""
    if not rows:
        return "(no cells)"
    head = rows[0]
    window = min(FLOOR_WINDOW, head.trials)
    seeds = f", {head.seeds} seeds: the latest seed / floor median [min-max]" \
        if head.seeds > 1 else ""
    header = ["law", "scenario", "delta", "first", "settled", "floor (rad)", "long run",
              "peak effort", "at limit", "aborts"]
    body = []
    for r in rows:
        aborts = "0" if not r.aborts else f"{r.aborts} (last {r.last_abort})"
        body.append([r.law, r.scenario, f"{100 * r.mass_uncertainty:g} %", _trial(r.first),
                     _trial(r.settled), _floor(r), _long_run(r), f"{r.peak_effort:.1f} N m"
                     if np.isfinite(r.peak_effort) else "-", f"{100 * r.at_limit:.1f} %",
                     aborts])
    widths = [max(len(header[i]), *(len(b[i]) for b in body)) for i in range(len(header))]
    right = {2, 3, 4, 7, 8}

    def line(cells: Sequence[str]) -> str:
        return "  ".join(c.rjust(w) if i in right else c.ljust(w)
                         for i, (c, w) in enumerate(zip(cells, widths, strict=True))).rstrip()

    lines = [f"Robustness study: {head.trials} trials per cell{seeds}. first/settled: trials "
             f"until every joint's true max |e| <= {head.error_bound:g} rad ('-': never / not "
             f"at the end); floor: median true max |e| over the last {window} trials, worst "
             "joint ('*': above the bound); long run: growth check of the learned input over "
             f"the last {growth_window(head.trials)} trials; at limit: share of samples with "
             "some joint at its effort limit.",
             line(header), line(["-" * w for w in widths])]
    lines += [line(b) for b in body]
    failures = [f"  {r.law} / {r.scenario} / {100 * r.mass_uncertainty:g} %: {f}"
                for r in rows for f in r.failures]
    if failures:
        lines += ["", "Runs that failed:", *failures]
    return "\n".join(lines)


# --- JSON ------------------------------------------------------------------------------------

def _table(a: np.ndarray) -> list[list[float | None]]:
    return [[float(x) if np.isfinite(x) else None for x in row] for row in a]


def study_json(setup: dict[str, Any], rows: Sequence[StudyRow],
               results: Sequence[CellResult]) -> dict[str, Any]:
    """The study as JSON: what was run, the rows, and per cell its per-trial tables (true and
    measured max |e|, max |u_ff|; with a person, the cuffs' peak force and torque; non-finite
    numbers as null)."""
    cells = [{"law": r.law, "scenario": r.scenario, "mass_uncertainty": r.mass_uncertainty,
              "seed": r.seed, "trials": r.trials, "aborted": r.aborted, "failure": r.failure,
              "nonfinite": r.nonfinite, "seconds": r.seconds,
              "true_max_abs_error": _table(r.true_max_abs_error),
              "max_abs_error": _table(r.max_abs_error),
              "max_abs_feedforward": _table(r.max_abs_feedforward),
              "samples_at_limit": [int(x) for x in r.samples_at_limit],
              **({} if r.peak_cuff_force is None else {  # a person with muscles: per trial
                  "peak_cuff_force_N": _table(r.peak_cuff_force),  # and cuff
                  "peak_cuff_torque_Nm": _table(np.asarray(r.peak_cuff_torque))})}
             for r in results]
    return {"study": setup, "rows": [row.to_json() for row in rows], "cells": cells}


def write_study_json(path: Path | str, setup: dict[str, Any], rows: Sequence[StudyRow],
                     results: Sequence[CellResult]) -> None:
    """Write :func:`study_json` to ``path``."""
    Path(path).write_text(json.dumps(study_json(setup, rows, results)) + "\n")
