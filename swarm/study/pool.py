"""Running a study (swarm/study/swarms.py, swarm/study/gains.py): its jobs on a process pool,
each row handed on as it finishes, and its tables written as CSV (appended and flushed
row by row, so a stop loses no finished row).
"""

from __future__ import annotations

import csv
import multiprocessing
import signal
from collections.abc import Callable
from pathlib import Path


def _quiet_worker() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C and ends the pool


def run_rows(
    worker: Callable[[object], dict | list[dict]], jobs: list, jobs_n: int, on_row: Callable[[dict], None]
) -> None:
    """Run `worker` over `jobs` on `jobs_n` spawned processes (1: in this process), calling
    `on_row` with each row as it finishes (a worker returns a row, or a list of rows for
    a batch of runs). Ctrl-C ends the workers and re-raises KeyboardInterrupt; every row
    finished before it has been handed to `on_row`."""

    def emit(rows: dict | list[dict]) -> None:
        for row in rows if isinstance(rows, list) else [rows]:
            on_row(row)

    if jobs_n <= 1:
        for j in jobs:
            emit(worker(j))
        return
    ctx = multiprocessing.get_context("spawn")  # never fork a process that may hold threads
    pool = ctx.Pool(jobs_n, initializer=_quiet_worker)
    try:
        for rows in pool.imap_unordered(worker, jobs):
            emit(rows)
        pool.close()
    except BaseException:
        pool.terminate()
        raise
    finally:
        pool.join()


class CsvSink:
    """Rows appended to a CSV file as they arrive (flushed: a stop loses no finished row)."""

    def __init__(self, path: Path, columns: list[str]):
        path.parent.mkdir(parents=True, exist_ok=True)
        self.f = path.open("w", newline="")
        self.w = csv.DictWriter(self.f, fieldnames=columns, extrasaction="ignore")
        self.w.writeheader()
        self.f.flush()

    def __call__(self, row: dict) -> None:
        self.w.writerow(row)
        self.f.flush()

    def close(self) -> None:
        self.f.close()


def write_csv(path: Path, rows: list[dict]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as f:
        if not rows:
            return
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
