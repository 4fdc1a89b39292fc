"""The e-stop (`swarm estop`, `swarm.estop()`, `Live.estop()`; docs/guides/robots.md#estop):
every robot zero-twisted straight onto the robots' network first, then the run ended through
its world. It does not depend on the world: it works with the world running, stalled or gone.

Which robots: `robots` (a robots file) if given; else the record that `swarm up --robots` keeps
in the runtime dir (`<run>.robots`, private to the user: swarm/robots/run_record.py `RunRecord`, with
the command types it learned; it stays after the run until the next one's replaces it): the run
`run`'s, or the only one whose `swarm up` runs, or else the latest. The
zero twists go first (`Halt`, STOP_REPEAT times), and go on every HOLD_GAP s until the run has
ended (a running world would drive them again until it has taken the stop).

Ending the run: a world that answers is asked to stop, as `swarm stop` does (it needs the run's
operator credentials: the local run's own file, or `credentials`); its `swarm up` ends as on
Ctrl-C. A world that is stopped (SIGSTOP: its state on this machine, from the record's pid) is
killed with SIGKILL: it cannot take a stop, and must never drive again; its `swarm up` then ends
the run (zero twists again, results rebuilt from its recording). A world that is gone: its
`swarm up` ends the run by itself; this waits for it.
"""

from __future__ import annotations

import os
import signal
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from swarm.contracts.errors import NoRunError, SwarmError
from swarm.contracts.vocabulary import ExitCode
from swarm.robots.halt import Halt, HaltError, HaltPlan
from swarm.robots.run_record import RunRecord, find_record, read_records

HOLD_GAP = 0.05  # s between the zero twists sent while the run ends
END_DEADLINE = 60.0  # s for the run to have ended after the robots were stopped
ASK_DEADLINE = 10.0  # s for a world that answers to take the stop


class EstopError(SwarmError):
    """The robots could not be zero-twisted (their router cannot be reached): exit 1. The run
    was still ended if it could be; the message says both."""

    exit_code = ExitCode.FAILED


@dataclass(frozen=True)
class Estopped:
    """What the e-stop did: `robots` zero-twisted (their count) via `connect`, `took` s from
    its start to the first zero twists sent; `run`: the run ended (None: none known), `ended`:
    one line on how (or why not)."""

    robots: int
    connect: str
    took: float
    run: str | None
    ended: str | None

    def lines(self) -> list[str]:
        out = [f"estop: zero twist sent to {self.robots} robots via {self.connect} ({self.took * 1000:.0f} ms)"]
        if self.ended is not None:
            out.append(f"estop: {self.ended}")
        return out


def _stat(pid: int) -> list[bytes] | None:
    """/proc/PID/stat's fields after the command's name (state, ppid, ...); None when gone."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            return f.read().rsplit(b")", 1)[1].split()
    except (OSError, IndexError):
        return None


def _stopped_child(pid: int, parent: int | None) -> bool:
    """Whether process `pid` is stopped (SIGSTOP, a debugger) and a child of `parent` (the
    record's world still, not another process that got its pid)."""
    st = _stat(pid)
    return st is not None and len(st) > 1 and st[0] in (b"T", b"t") and parent is not None and st[1] == b"%d" % parent


def _alive(pid: int) -> bool:
    """Whether process `pid` exists and is no zombie."""
    try:
        os.kill(pid, 0)
        with open(f"/proc/{pid}/stat", "rb") as f:
            return f.read().rsplit(b")", 1)[1].split()[0] != b"Z"
    except PermissionError:
        return True
    except (OSError, IndexError):
        return False


def _wait_gone(pid: int, timeout: float) -> bool:
    end = time.monotonic() + timeout
    while _alive(pid):
        if time.monotonic() >= end:
            return False
        time.sleep(0.05)
    return True


def end_run(
    record: RunRecord | None,
    run: str | None,
    connect: str | None,
    credentials: str | Path | None,
    live: Any = None,
    timeout: float = END_DEADLINE,
) -> tuple[str | None, str | None]:
    """End the run (see the module's doc): (its id, one line on how); (None, None) when no run
    is known (a robots file given without --run or --connect, and no run of it here)."""
    if live is not None:
        return live.ref.run, _ask(live, timeout)
    run = run or (record.run if record is not None else None)
    if run is None and connect is None:
        return None, None
    world = record.world_pid if record is not None else None
    launcher = record.launcher_pid if record is not None else None
    silent: str | None = None  # why a world that is alive did not answer
    if launcher is not None and not _alive(launcher):
        return run, f"run {run} had ended (its swarm up, pid {launcher}, is gone)"
    if world is not None and _stopped_child(world, launcher):
        try:
            os.kill(world, signal.SIGKILL)
        except ProcessLookupError:  # killed meanwhile (its swarm up's own end): gone as wanted
            pass
        how = f"its world (pid {world}) was stopped (SIGSTOP): killed with SIGKILL"
        if launcher is not None and _wait_gone(launcher, timeout):
            return run, f"run {run} ended: {how}; its swarm up (pid {launcher}) has ended the run"
        return run, f"run {run}: {how}"
    if world is None or _alive(world):
        from swarm.live.client import open_run_session  # lazy: swarm.live's client, when a world may answer

        try:
            live_run = open_run_session(connect, run, None if credentials is None else Path(credentials))
        except NoRunError as e:
            if launcher is None or not _alive(launcher):
                return run, f"no run ended: {e}"
            silent = str(e)  # alive (or just gone) and not answering: its swarm up may still end the run
        else:
            with live_run:
                return live_run.ref.run, _ask(live_run, timeout)
    if launcher is not None:  # the world is gone (or does not answer): its swarm up ends the run by itself
        if silent is None:
            was, world_is = "its world was gone", "its world is gone"
        else:
            was = world_is = f"its world did not answer ({silent})"
        if _wait_gone(launcher, timeout):
            return run, f"run {run} ended: {was}; its swarm up (pid {launcher}) has ended the run"
        return run, f"run {run}: {world_is}; its swarm up (pid {launcher}) has not ended within {timeout:g} s"
    return run, None


def _ask(live: Any, timeout: float) -> str:
    from swarm.live.stop import stop_run  # lazy: as Live.stop

    by = f"swarm estop (pid {os.getpid()})"
    try:
        done = stop_run(live, by=by, wait=True, timeout=timeout)
    except SwarmError as e:
        return f"run {live.ref.run}: asked to stop, but: {e}"
    return done.line()


def which(
    run: str | None = None, robots: str | Path | None = None, live: Any = None
) -> tuple[RunRecord | None, HaltPlan]:
    """The robots to stop and the run's record: (record or None, plan); see the module's doc.
    UsageError when no robots are known."""
    if robots is None:
        record = find_record(run or (live.ref.run if live is not None else None))
        return record, record.plan
    from swarm.robots.config import load_robots  # lazy: pydantic, for a robots file given only

    plan = HaltPlan.from_robots(load_robots(robots))
    here = Path(robots).resolve()
    records = read_records()
    if run is not None:
        return next((rec for _p, rec, _up in records if rec.run == run), None), plan
    mine = [rec for _p, rec, up in records if up and Path(rec.robots_file) == here]
    if live is None and len(mine) == 1:
        return mine[0], plan  # the run of this robots file on this machine: ended too
    return None, plan


def arm(run: str | None = None, robots: str | Path | None = None) -> tuple[RunRecord | None, Halt]:
    """The session to the robots' router open, nothing sent yet (`swarm estop --ready`):
    (record or None, Halt); `estop(..., sent_first=...)` after the zero twists. HaltError when
    the router cannot be reached."""
    record, plan = which(run, robots)
    return record, Halt(plan, learn=any(len(t.types) > 1 for t in plan.targets), name="swarm_estop")


def estop(
    run: str | None = None,
    robots: str | Path | None = None,
    connect: str | None = None,
    credentials: str | Path | None = None,
    *,
    end: bool = True,
    say: Callable[[str], None] | None = None,
    live: Any = None,
    timeout: float = END_DEADLINE,
    sent_first: tuple[RunRecord | None, Halt, int, float] | None = None,
) -> Estopped:
    """Zero-twist every robot, then end the run (see the module's doc). `robots`: a robots
    file (default: the run's record on this machine); `run`, `connect`, `credentials`: which
    run to end, as `swarm.connect` takes them (or `live`, an open swarm.live.client.LiveRun:
    `Live.estop`); `end` False: the robots only. `say(line)` gets the first line as soon as
    the robots are stopped. `sent_first`: (record or None, open Halt, robots, s taken) of zero
    twists sent already (swarm/cli/estop_first.py, `arm`). UsageError when no robots are
    known; EstopError when their router cannot be reached (the run is still ended)."""
    t0 = time.monotonic()
    halt: Halt | None = None
    failed: str | None = None
    if sent_first is not None:
        record, halt, sent, took = sent_first
        plan = halt.plan
    else:
        record, plan = which(run, robots, live)
        try:
            halt = Halt(plan, learn=any(len(t.types) > 1 for t in plan.targets), name="swarm_estop")
            sent = halt.zero()
        except HaltError as e:
            failed, sent = str(e), 0
        took = (halt.first_sent if halt is not None and halt.first_sent else time.monotonic()) - t0
    quit = threading.Event()
    holder = None
    if halt is not None:
        h = halt

        def hold() -> None:
            while not quit.wait(HOLD_GAP):
                h.zero(repeat=1)

        holder = threading.Thread(target=hold, name="estop-hold", daemon=True)
        holder.start()
    try:
        if halt is not None and say is not None:
            try:
                say(Estopped(sent, plan.connect, took, None, None).lines()[0])
            except OSError:  # the output is gone (a closed pipe): the run is still to be ended
                pass
        ended: tuple[str | None, str | None] = (None, None)
        if end:
            ended = end_run(record, run, connect, credentials, live, timeout)
    finally:
        quit.set()
        if holder is not None:
            holder.join()
        if halt is not None:
            halt.zero()
            halt.close()
    if failed is not None:
        raise EstopError(f"NO zero twist sent: {failed}" + (f"; {ended[1]}" if ended[1] else ""))
    return Estopped(sent, plan.connect, took, ended[0], ended[1])
