"""A run's robots, for `swarm estop` on its machine, and its last word to them: `RunRecord`, what
`swarm up --robots` leaves in the runtime dir (`<run>.robots`, private to the user: the run,
its pids, the robots file and the `HaltPlan` with the command types it learned), found again by
`find_record`; and `WorldExitStop`, the zero twist to every robot as soon as the run's world
process exits, for any reason (docs/guides/robots.md#stops). The stops themselves are
swarm/robots/halt.py's `Halt`. Imports little: `swarm estop` reads a record first thing.
"""

from __future__ import annotations

import json
import os
import signal
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from swarm.contracts.runtime_dir import pid_alive, read_private, runtime_dir, write_private
from swarm.robots.halt import Halt, HaltPlan

if TYPE_CHECKING:
    from swarm.robots.config import RobotsFile

RECORD_SUFFIX = ".robots"  # <runtime dir>/<run>.robots: a run's HaltPlan (RunRecord)


# -- a run's record: its robots, for `swarm estop` on its machine -------------------------------------
@dataclass(frozen=True)
class RunRecord:
    """What `swarm up --robots` leaves in the runtime dir while it runs: its run, its own pid
    and its world's, the robots file, and the plan (types as learned)."""

    run: str
    launcher_pid: int
    world_pid: int | None
    robots_file: str
    plan: HaltPlan
    written: float = field(default_factory=time.time)

    def to_bytes(self) -> bytes:
        return (json.dumps({**asdict(self), "plan": self.plan.to_json()}, indent=1) + "\n").encode()

    @classmethod
    def from_bytes(cls, raw: bytes) -> RunRecord:
        try:
            data = json.loads(raw)
            return cls(
                str(data["run"]),
                int(data["launcher_pid"]),
                None if data.get("world_pid") is None else int(data["world_pid"]),
                str(data["robots_file"]),
                HaltPlan.from_json(data["plan"]),
                float(data.get("written", 0.0)),
            )
        except (KeyError, TypeError, ValueError, RecursionError) as e:
            raise ValueError(f"not a run's robots record: {e}") from None


def record_path(run: str) -> Path:
    return runtime_dir() / f"{run}{RECORD_SUFFIX}"


def write_record(record: RunRecord) -> Path:
    path = record_path(record.run)
    write_private(path, record.to_bytes())
    return path


def read_records() -> list[tuple[Path, RunRecord, bool]]:
    """The records in the runtime dir: (path, record, its swarm up still runs), newest first;
    unreadable ones left out."""
    out = []
    for p in runtime_dir().glob(f"*{RECORD_SUFFIX}"):
        try:
            rec = RunRecord.from_bytes(read_private(p))
        except Exception:
            continue
        out.append((p, rec, pid_alive(rec.launcher_pid)))
    return sorted(out, key=lambda x: -x[1].written)


def find_record(run: str | None) -> RunRecord:
    """The runtime dir's record of run `run`, or of the only run whose `swarm up` still runs,
    or (none runs) of the latest one; UsageError (one line) otherwise."""
    from swarm.contracts.errors import UsageError  # lazy: for the error's path only (the e-stop's start-up)

    records = read_records()
    if run is not None:
        for _p, rec, _alive in records:
            if rec.run == run:
                return rec
        raise UsageError(f"no robots of run {run} on this machine: give --robots FILE")
    alive = [rec for _p, rec, up in records if up]
    if len(alive) == 1:
        return alive[0]
    if not alive and records:
        return records[0][1]  # the latest run to drive robots here, ended: its robots all the same
    if not alive:
        raise UsageError("no run has driven robots on this machine (swarm up --robots records it): give --robots FILE")
    names = ", ".join(r.run for r in alive)
    raise UsageError(f"{len(alive)} runs drive robots ({names}): pick one with --run, or give --robots FILE")


# -- swarm up: a zero twist to every robot when the world exits -----------------------------------------
def exit_words(status: int | None) -> str:
    """How a process ended, in words: "killed by SIGKILL", "exit code 0"."""
    if status is None:
        return "its exit not known"
    if status < 0:
        try:
            return f"killed by {signal.Signals(-status).name}"
        except ValueError:
            return f"killed by signal {-status}"
    return f"exit code {status}"


class WorldExitStop:
    """`swarm up --robots`: as soon as its world process exits, for any reason, a zero twist to
    every robot (STOP_REPEAT times), then one line: "robots: zero twist sent to N robots (the
    world exited: killed by SIGKILL)". The session to the robots' router is opened when the
    world starts (`started`), so nothing is left to do at the exit but send; a thread waits for
    the exit (waitid without reaping: the launcher reaps the world). The run's record is in the
    runtime dir (`swarm estop`) from the world's start on, and stays after the run (the next
    run's replaces it); `join()` (the launcher, once the world has ended) waits for the line."""

    def __init__(
        self,
        robots: RobotsFile,
        robots_file: Path,
        run: str,
        say: Callable[[str], None],
        ran: Callable[[], bool] = lambda: True,
    ):
        self.plan = HaltPlan.from_robots(robots)
        self.robots_file = robots_file.resolve()
        self.run, self.say, self.ran = run, say, ran
        self.thread: threading.Thread | None = None
        self.record: Path | None = None
        self.sent: int | None = None
        self.done = threading.Event()

    def started(self, world_pid: int) -> None:
        self.write(world_pid, self.plan)  # at once: an estop from now on knows the robots
        self.thread = threading.Thread(target=self._watch, args=(world_pid,), name="robots-world-exit", daemon=True)
        self.thread.start()

    def write(self, world_pid: int | None, plan: HaltPlan) -> None:
        try:
            self.record = write_record(RunRecord(self.run, os.getpid(), world_pid, str(self.robots_file), plan))
        except OSError:
            self.record = None
            return
        for path, rec, up in read_records():  # the records of runs ended before: this one is the latest
            if not up and rec.run != self.run:
                try:
                    path.unlink()
                except OSError:
                    pass

    def _watch(self, pid: int) -> None:
        halt: Halt | None = None
        why: str | None = None
        try:
            try:
                halt = Halt(self.plan, name="swarm_up")
                self.write(pid, halt.plan)  # with the types learned
            except Exception as e:  # unreachable now: tried again at the exit
                why = str(e)
            status = _wait_exit(pid)
            if halt is None and not self.ran():  # the world could not start (e.g. no router): said by it
                return
            if halt is None:
                try:
                    halt = Halt(self.plan, name="swarm_up")
                except Exception as e:
                    if self.ran():
                        self.say(f"robots: NO zero twist sent (the world exited: {exit_words(status)}): {e or why}")
                    return
            self.sent = halt.zero()
            self.say(
                f"robots: zero twist sent to {self.sent} robots (the world exited: {exit_words(status)})"
                if self.sent != 1
                else f"robots: zero twist sent to 1 robot (the world exited: {exit_words(status)})"
            )
        finally:
            if halt is not None:
                halt.close()
            self.done.set()

    def join(self, timeout: float = 10.0) -> None:
        """Until the zero twists were sent and said (at most `timeout` s). The record stays: an
        estop after the run still finds its robots (the next run's record replaces it)."""
        if self.thread is not None:
            self.done.wait(timeout)


def _wait_exit(pid: int) -> int | None:
    """Block until child `pid` has exited, without reaping it; its status (negative: the
    signal), None when it is no child of ours any more (reaped meanwhile)."""
    while True:
        try:
            info = os.waitid(os.P_PID, pid, os.WEXITED | os.WNOWAIT)
        except ChildProcessError:
            return None
        except InterruptedError:
            continue
        if info is None:
            continue
        return info.si_status if info.si_code == os.CLD_EXITED else -info.si_status
