"""Running a study's jobs on worker processes of this machine, each row handed on as it
finishes, and its tables written as CSV (appended and flushed row by row, so a stop loses no
finished row).

`run_jobs` is the pool: `processes` child processes (`python -m swarm.study.child`, speaking
pickles over their stdin/stdout), each running one job at a time with the next one already
queued on it (so a busy machine's scheduling of this process never leaves a child waiting).
A pool of our own rather than `multiprocessing.Pool` or `concurrent.futures`, because a run
that hangs must be ended without ending the others: a job past its time budget has its process
killed (SIGKILL: a hung law may ignore anything gentler) and replaced, and the study goes on
(`Timeouts`); the jobs queued behind it go to the other children. Neither standard pool can
kill one worker (`ProcessPoolExecutor` breaks as a whole when one dies; `Pool.terminate`
ends them all), and pebble would be a new dependency for some 150 lines. Plain subprocesses,
not `multiprocessing.Process`, so the same pool also runs inside a Dask worker (a daemonic
process, which multiprocessing refuses children: swarm/study/cluster.py).

The children ignore SIGINT from birth (started while this process ignores it: the disposition
survives exec and Python keeps it), so a terminal's Ctrl-C reaches this process alone: it ends
the children and raises KeyboardInterrupt once, no traceback from any child.
"""

from __future__ import annotations

import csv
import os
import pickle
import signal
import subprocess
import sys
import time
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from pathlib import Path
from typing import Any

from swarm.contracts.errors import SwarmError

Rows = list[dict]
PIPELINE = 2  # jobs queued on a child at most: the next is there when one ends (no round trip between)
STARTUP_S = 60.0  # a worker's imports before a job's run starts (its time budget) may take this long


@dataclass
class Timeouts:
    """A time budget per job: `run_timeout` s per run of it (`size(job)` runs); a job past its
    budget is ended and `timed_out(job, elapsed_s)` says what to run again (jobs)."""

    run_timeout: float
    size: Callable[[Any], int]
    timed_out: Callable[[Any, float], list]

    def budget(self, job: Any) -> float:
        return self.run_timeout * max(1, self.size(job))


class RemoteTraceback(Exception):
    """The traceback of an exception raised in a worker process (its `__cause__`)."""

    def __str__(self) -> str:
        return "\n" + str(self.args[0])


class WorkerDied(SwarmError):
    """A worker process ended without a reply, twice for the same job (not a timeout of ours):
    one line, exit 1, the rows finished before it kept."""


def cores() -> int:
    """The cores this process may run on (its CPU affinity; else the machine's count)."""
    try:
        return len(os.sched_getaffinity(0)) or 1
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


@contextmanager
def _sigint_ignored() -> Iterator[None]:
    """SIGINT ignored while children are started, so they inherit it ignored (main thread only:
    elsewhere, e.g. a Dask worker's thread, nothing changes and nothing there sends SIGINT)."""
    try:
        old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:  # not the main thread
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


class _Slot:
    """One child process and the job it runs."""

    def __init__(self) -> None:
        with _sigint_ignored():
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "swarm.study.child"],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                close_fds=True,
            )
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.send = Connection(os.dup(self.proc.stdin.fileno()), readable=False)
        self.recv = Connection(os.dup(self.proc.stdout.fileno()), writable=False)
        self.proc.stdin.close()
        self.proc.stdout.close()
        self.jobs: deque[tuple[int, Any, float]] = deque()  # (tag, job, budget): the first one runs
        self.started = 0.0  # when the first one's run started

    @property
    def job(self) -> Any:
        """The job running (None: idle)."""
        return self.jobs[0][1] if self.jobs else None

    @property
    def budget(self) -> float:
        return self.jobs[0][2] if self.jobs else float("inf")

    def _clock(self) -> None:
        # the clock starts when the child says STARTED (its imports done: seconds on a busy
        # machine); until then it has STARTUP_S more, for a module that hangs as it is imported
        self.started = time.monotonic() + STARTUP_S

    def give(self, tag: int, worker: Callable, job: Any, budget: float) -> None:
        """Queue a job on this child (it runs them in turn; the next is sent while one runs)."""
        self.jobs.append((tag, job, budget))
        if len(self.jobs) == 1:
            self._clock()
        try:
            self.send.send_bytes(pickle.dumps((worker, job)))
        except BrokenPipeError:
            # the child died since its last reply (its pipe's end of file is waiting to be
            # read): the job stays queued on it, and the loss is handled there (`lost`)
            pass

    def done(self) -> tuple[int, Any]:
        """The running job finished: its (tag, job); the next one's clock set."""
        tag, job, _ = self.jobs.popleft()
        if self.jobs:
            self._clock()
        return tag, job

    def end(self, kill: bool = False) -> None:
        """Ask the child to exit (or kill it), and reap it."""
        try:
            if kill:
                self.proc.kill()
            else:
                self.send.send_bytes(pickle.dumps(None))
        except OSError:
            pass
        for c in (self.send, self.recv):
            c.close()
        try:
            self.proc.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


def _as_rows(rows: dict | Rows) -> Rows:
    return rows if isinstance(rows, list) else [rows]


def run_jobs(
    worker: Callable[[Any], dict | Rows],
    jobs: Sequence[Any],
    processes: int,
    on_rows: Callable[[Any, Rows], None],
    timeouts: Timeouts | None = None,
) -> None:
    """Run `worker` over `jobs` on `processes` child processes (1 without `timeouts`: in this
    process), calling `on_rows(job, rows)` as each job finishes (a worker returns a row, or
    a list of rows for a batch of runs). With `timeouts`, a job past its budget has its process
    killed and replaced, and the jobs `timeouts.timed_out` gives are run too. A child that dies
    by itself has its job run once more, then WorkerDied. An exception in a worker is raised
    here (its traceback as the cause). Ctrl-C ends the children and re-raises
    KeyboardInterrupt; every row finished before it has been handed to `on_rows`."""
    if processes <= 1 and timeouts is None:
        for j in jobs:
            on_rows(j, _as_rows(worker(j)))
        return
    queue: deque[tuple[int, Any]] = deque(enumerate(jobs))
    tags = len(queue)
    died: set[int] = set()
    slots: list[_Slot] = []

    def lost(s: _Slot) -> tuple[int, Any, float]:
        """A slot's child is gone: its queued jobs back to the front of the queue; the one it ran."""
        head, *rest = s.jobs
        queue.extendleft(reversed([(t, j) for t, j, _ in rest]))
        return head

    try:
        slots = [_Slot() for _ in range(max(1, min(processes, len(queue))))]
        while queue or any(s.jobs for s in slots):
            for depth in range(1, PIPELINE + 1):  # every child one job, then a second one queued
                for s in slots:
                    if len(s.jobs) < depth and queue:
                        tag, job = queue.popleft()
                        s.give(tag, worker, job, timeouts.budget(job) if timeouts else float("inf"))
            busy = [s for s in slots if s.jobs]
            now = time.monotonic()
            left = min(s.started + s.budget - now for s in busy)
            ready = wait([s.recv for s in busy], None if left == float("inf") else max(0.0, left))
            for k, s in enumerate(slots):
                if not s.jobs:
                    continue
                if s.recv in ready:
                    try:
                        ok, payload = pickle.loads(s.recv.recv_bytes())
                    except (EOFError, OSError):  # the child died without a reply
                        tag, job, _ = lost(s)
                        s.end(kill=True)
                        if tag in died:
                            why = f"a study's worker process died twice on one job (exit code {s.proc.returncode})"
                            raise WorkerDied(why) from None
                        died.add(tag)
                        queue.appendleft((tag, job))
                        slots[k] = _Slot()
                        continue
                    if ok is None:  # the child has the job and its modules: the run starts now
                        s.started = time.monotonic()
                        continue
                    if not ok:
                        exc, tb = payload
                        raise exc from RemoteTraceback(tb)
                    _, job = s.done()
                    on_rows(job, _as_rows(payload))
                elif timeouts is not None and time.monotonic() - s.started >= s.budget:
                    elapsed = time.monotonic() - s.started
                    _, job, _ = lost(s)
                    s.end(kill=True)
                    slots[k] = _Slot()
                    for again in timeouts.timed_out(job, elapsed):
                        queue.append((tags, again))
                        tags += 1
        for s in slots:
            s.end()
        slots = []
    finally:
        for s in slots:
            s.end(kill=True)


class CsvSink:
    """Rows appended to a CSV file as they arrive (flushed: a stop loses no finished row);
    `append`: after the rows already there (their header is these columns)."""

    def __init__(self, path: Path, columns: list[str], append: bool = False):
        path.parent.mkdir(parents=True, exist_ok=True)
        self.f = path.open("a" if append else "w", newline="")
        self.w = csv.DictWriter(self.f, fieldnames=columns, extrasaction="ignore")
        if not append:
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
