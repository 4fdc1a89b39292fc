"""A study's jobs on a Dask `distributed` cluster (`swarm study ... --scheduler tcp://HOST:8786`,
`swarm.study.dask_executor(address)`; docs/design/studies.md#cluster).

The client connects to the scheduler; the study's jobs go out as tasks, each a few jobs (a
chunk of runs each: the batch engine's batches, or runs of the per-agent engine grouped so every
worker thread gets about four tasks), at most `workers` tasks at a time (every worker thread by
default), and rows come back task by task (`as_completed`) into the same runs.csv, table and
figures as a local study. A worker that dies has its tasks run again by the scheduler
elsewhere; a row whose run is already in runs.csv is dropped (swarm/study/plan.py `execute`),
so nothing is written twice.

With a run timeout, a task runs its jobs in a child process of the Dask worker
(swarm/study/pool.py `run_jobs`, one process), which is killed and replaced when a job runs past
its budget (a thread cannot be ended; a process can), and the task reports the job timed out.

`distributed` is imported only here, when a study is given a scheduler: without the extra
`swarm-circumnav[cluster]`, a one-line error says to install it.
"""

from __future__ import annotations

import math
import re
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any

from swarm.contracts.errors import SwarmError, UsageError
from swarm.study.plan import StudyExecutor, Worker
from swarm.study.pool import Rows, Timeouts, run_jobs

TASKS_PER_THREAD = 4  # at least this many tasks per worker thread, when there are jobs enough
CONNECT_S = 10.0  # the scheduler must answer within this
WORKERS_S = 30.0  # ... and have a worker within this


class ClusterError(SwarmError):
    """The cluster cannot run the study (no scheduler at the address, no worker)."""


def _distributed() -> Any:
    try:
        import distributed  # lazy: an optional dependency (the extra swarm-circumnav[cluster]), for a cluster only
    except ImportError:
        raise UsageError(
            "--scheduler: a Dask cluster needs the package distributed: pip install 'swarm-circumnav[cluster]'"
        ) from None
    return distributed


def run_task(worker: Worker, jobs: list[tuple[Any, int]], run_timeout: float | None) -> list[tuple[str, Any]]:
    """A task on a Dask worker: each (job, runs) in turn; per job ("rows", rows) or, past
    `run_timeout` x runs s, ("timeout", elapsed s)."""
    if run_timeout is None:
        return [("rows", r if isinstance(r, list) else [r]) for r in (worker(j) for j, _ in jobs)]
    sizes = {id(j): n for j, n in jobs}
    outcome: dict[int, tuple[str, Any]] = {}

    def on_rows(job: Any, rows: Rows) -> None:
        outcome[id(job)] = ("rows", rows)

    def timed_out(job: Any, elapsed: float) -> list:
        outcome[id(job)] = ("timeout", elapsed)
        return []

    run_jobs(worker, [j for j, _ in jobs], 1, on_rows, Timeouts(run_timeout, lambda j: sizes[id(j)], timed_out))
    return [outcome[id(j)] for j, _ in jobs]


ADDRESS = re.compile(r"^(tcp|tls)://[^\s/:]+:[0-9]{1,5}$")


def dask_executor(address: str, workers: int = 0) -> StudyExecutor:
    """Run a study's jobs on the Dask cluster whose scheduler is at `address`
    ("tcp://HOST:8786"), at most `workers` tasks at a time (0: one per worker thread; a study
    caps it at that). Connects when first used; `close()` lets go of the connection. Needs the
    extra `swarm-circumnav[cluster]`. UsageError for an address that is not tcp:// or tls://
    HOST:PORT."""
    if not ADDRESS.match(address):
        raise UsageError(
            f"--scheduler: {address!r} is not a scheduler's address: give tcp://HOST:PORT, e.g. tcp://10.0.0.1:8786"
        )
    _distributed()  # the extra's absence said now, before anything runs
    return DaskExecutor(address, workers)


class DaskExecutor(StudyExecutor):
    """A study's jobs on the Dask cluster whose scheduler is at `address` (see the module)."""

    def __init__(self, address: str, workers: int = 0):
        self.address = address
        self.workers = workers
        self._client: Any = None

    def client(self) -> Any:
        if self._client is None:
            distributed = _distributed()
            try:
                self._client = distributed.Client(self.address, timeout=CONNECT_S, set_as_default=False)
            except (OSError, TimeoutError, ValueError) as e:
                raise ClusterError(f"--scheduler {self.address}: no Dask scheduler answers there ({e})") from None
            try:
                self._client.wait_for_workers(1, timeout=WORKERS_S)
            except (OSError, TimeoutError) as e:
                self.close()
                raise ClusterError(f"--scheduler {self.address}: no worker within {WORKERS_S:g} s ({e})") from None
        return self._client

    def threads(self) -> int:
        return int(sum(self.client().nthreads().values()))

    def capacity(self) -> tuple[int, str]:
        n = self.threads()
        return n, f"the cluster at {self.address} has {n} worker thread{'s' * (n != 1)}"

    def where(self, n: int) -> str:
        return f"on the Dask cluster at {self.address}, {n} task{'s' * (n != 1)} at a time"

    def close(self) -> None:
        if self._client is not None:
            client, self._client = self._client, None
            client.close()

    def __call__(
        self,
        worker: Worker,
        jobs: Sequence[Any],
        on_row: Callable[[dict], None],
        timeouts: Timeouts | None = None,
    ) -> None:
        distributed = _distributed()
        client = self.client()
        n = max(1, self.workers or self.threads())
        per = max(1, math.ceil(len(jobs) / (TASKS_PER_THREAD * n)))
        size = timeouts.size if timeouts is not None else (lambda _j: 1)
        waiting: deque[list[tuple[Any, int]]] = deque(
            [(j, size(j)) for j in jobs[k : k + per]] for k in range(0, len(jobs), per)
        )
        running: dict[Any, list[tuple[Any, int]]] = {}
        done = distributed.as_completed(loop=client.loop)
        run_timeout = timeouts.run_timeout if timeouts is not None else None

        def submit() -> None:
            while waiting and len(running) < n:
                task = waiting.popleft()
                future = client.submit(run_task, worker, task, run_timeout, pure=False)
                running[future] = task
                done.add(future)

        try:
            submit()
            for future in done:
                task = running.pop(future)
                try:
                    outcomes = future.result()
                except distributed.KilledWorker as e:  # the task's workers died, again and again
                    raise ClusterError(f"--scheduler {self.address}: a task's workers kept dying ({e})") from None
                for (job, _), (kind, payload) in zip(task, outcomes):
                    if kind == "rows":
                        for row in payload:
                            on_row(row)
                    elif timeouts is not None:
                        again = timeouts.timed_out(job, payload)
                        waiting.extend([(j, size(j))] for j in again)
                submit()
        except BaseException:
            for future in running:
                future.cancel()
            raise
