"""SIGINT and SIGTERM at any moment of a command's start-up (swarm/contracts/stop_signals.py
`CliStops`, installed first thing by the `swarm` entry point, swarm/cli/__init__.py): one line,
no traceback, exit 128 + signum (docs/reference/exit-codes.md), and no process left behind.

Each case starts a real `swarm` process in its own process group and sends the signal at a
delay after swarm has taken the signals over (its handler shows in /proc/PID/status:
SigCgt has SIGTERM, which Python itself never catches): 0 s is during the heavy imports of the
command line, later ones while the world starts, while the agents start, while a run goes.
Before that moment the signal is the interpreter's own (its start-up, before swarm's first
line), which no code of swarm's can change. The delays are where the signal lands, not an
expectation of speed: on a slow machine a delay lands earlier in the start-up, and every case
must hold wherever it lands. The only waits are bounds on a hang (runtime_helpers.DEADLINE).
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import psutil
import pytest
from deadlines import DEADLINE
from runtime_helpers import SCENARIOS, short_runtime_dir, wait_for

from swarm.contracts.vocabulary import ExitCode
from swarm.runtime.procs import wait_until

pytestmark = pytest.mark.slow  # a Python process of its own per case (its tier, process, is its folder)

MARK = "SWARM_TEST_STOP_MARK"  # in the environment of every process a case starts, and of theirs
SIGNALS = {"SIGINT": (signal.SIGINT, ExitCode.INTERRUPTED), "SIGTERM": (signal.SIGTERM, ExitCode.TERMINATED)}


def swarm_exe() -> list[str]:
    """The console script (`swarm.cli:main`) next to this interpreter, as a user runs it; else
    `python -m swarm` (the same entry point)."""
    script = Path(sys.executable).parent / "swarm"
    return [str(script)] if script.exists() else [sys.executable, "-m", "swarm"]


def command(name: str, tmp: Path, rt: str) -> list[str]:
    out = str(tmp / "out")
    if name == "up":  # a realtime run far longer than any delay: the signal always lands in it
        return ["up", str(SCENARIOS / "case1.toml"), "--out", out, "--no-plots", "--clock", "realtime"]
    if name == "sim":
        return ["sim", str(SCENARIOS / "case2.toml"), "--out", out, "--no-plots", "--duration", "3000"]
    if name == "world":  # waits for agents that never come
        ep = f"unixsock-stream/{rt}/w.sock"
        return ["world", str(SCENARIOS / "case1.toml"), "--listen", ep, "--run", "stopw", "--out", out, "--no-plots"]
    if name == "agent":  # waits for a world that never comes
        return ["agent", "--id", "1", "--connect", f"unixsock-stream/{rt}/none.sock", "--connect-timeout", "3000"]
    raise ValueError(name)


def catches_sigterm(pid: int) -> bool:
    """Whether process `pid` has a handler for SIGTERM (swarm's own: Python installs none)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    for line in status.splitlines():
        if line.startswith("SigCgt:"):
            return bool(int(line.split()[1], 16) >> (signal.SIGTERM - 1) & 1)
    return False


def marked(mark: str) -> list[psutil.Process]:
    """Every living process (not a zombie) with `mark` in its environment."""
    found = []
    for p in psutil.process_iter():
        try:
            if p.environ().get(MARK) == mark and p.status() != psutil.STATUS_ZOMBIE:
                found.append(p)
        except (psutil.NoSuchProcess, psutil.AccessDenied, psutil.ZombieProcess):
            pass
    return found


# (command, signal, where, delay): the signal goes `delay` s after swarm took the signals over
# (where None), or after the file `where` (in the case's out dir or runtime dir) appeared: the
# world's log (the launcher starts the world), agent logs (the launcher starts the agents; the
# last one: the run goes), the world's socket (it listens), the recording (the sim runs).
# Where the delays landed on a 2-core sandbox at load 2-5 (2026-11-29, s after the handler):
# the command line's imports until 0.4-1.2 s (0.0 and 0.2 land in them, 0.5 in them or just
# after); `up` starts the world at 0.9-1.8 s (1.0: before or as it starts; 2.0: while the world
# imports or opens its hub; the files pin the later steps); `sim` builds its run until 1.3-2.0 s
# (1.0 lands there; the recording pins the run), `world` listens from 1.2-2.0 s (2.0: waiting
# for agents), `agent` waits for its world from about 0.8 s (2.0).
HANDLER = (0.0, 0.2, 0.5, 1.0, 2.0)
CASES = (
    [("up", sig, None, d) for sig in SIGNALS for d in HANDLER]
    + [("up", sig, "out/logs/world.log", d) for sig in SIGNALS for d in (0.0, 0.2)]
    + [("up", sig, "out/logs/agent-1.log", 0.0) for sig in SIGNALS]
    + [("up", sig, "out/logs/agent-5.log", d) for sig in SIGNALS for d in (0.0, 0.5)]
    + [("sim", sig, None, d) for sig in SIGNALS for d in (0.0, 0.5, 1.0)]
    + [(name, sig, None, d) for name in ("world", "agent") for sig in SIGNALS for d in (0.0, 0.5, 2.0)]
    + [("sim", sig, "out/recording.mcap", 0.2) for sig in SIGNALS]
    + [("world", sig, "rt/w.sock", 0.0) for sig in SIGNALS]
)


@pytest.mark.parametrize(("name", "sig", "where", "delay"), CASES)
def test_stop_at_any_moment_of_startup(name, sig, where, delay, tmp_path):
    signum, code = SIGNALS[sig]
    rt = short_runtime_dir()
    mark = uuid.uuid4().hex
    env = {**os.environ, "SWARM_RUNTIME_DIR": rt, MARK: mark, "PYTHONUNBUFFERED": "1"}
    with open(tmp_path / "stdout", "wb") as stdout, open(tmp_path / "stderr", "wb") as stderr:
        p = subprocess.Popen(
            [*swarm_exe(), *command(name, tmp_path, rt)],
            stdin=subprocess.DEVNULL,
            stdout=stdout,
            stderr=stderr,
            env=env,
            cwd=tmp_path,
            start_new_session=True,  # its own process group (pgid == its pid)
        )
    if where is not None:
        anchor = Path(rt) / where[3:] if where.startswith("rt/") else tmp_path / where
        delay_text = f"+{delay} s after {anchor.name} appeared"
    else:
        delay_text = f"+{delay} s after swarm took the signals over"
    try:
        wait_for(lambda: catches_sigterm(p.pid) or p.poll() is not None, DEADLINE, "swarm to take the signals over")
        if where is not None:
            wait_for(lambda: anchor.exists() or p.poll() is not None, DEADLINE, f"{anchor} to appear")
        assert p.poll() is None, f"swarm {name} exited ({p.returncode}) before the signal"
        time.sleep(delay)
        os.kill(p.pid, signum)
        try:
            rc = p.wait(DEADLINE)
        except subprocess.TimeoutExpired:
            raise AssertionError(f"swarm {name} still running {DEADLINE:g} s after {sig}") from None
        # its children exit before it (the launcher waits for its own); anything else of the
        # case (its group, or anything with its mark) is given a deadline to go
        left: list[psutil.Process] = []

        def gone() -> bool:
            left[:] = marked(mark)
            return not left

        wait_until(gone, DEADLINE, 0.05)
        out, err = (tmp_path / "stdout").read_text(errors="replace"), (tmp_path / "stderr").read_text(errors="replace")
        said = f"stdout:\n{out[-2000:]}\nstderr:\n{err[-3000:]}"
        for words in ("Traceback", "KeyboardInterrupt", "Exception ignored", "Aborted"):
            assert words not in out + err, f"swarm {name}: {sig} {delay_text}\n{said}"
        assert rc == code, f"swarm {name} exited {rc} on {sig} {delay_text} (expected {int(code)})\n{said}"
        # one line says it (what the command had said before, it says on any run)
        stopped = [ln for ln in (out + err).splitlines() if "stopped by" in ln]
        assert len(stopped) == 1, f"swarm {name}: {sig} {delay_text}: not one line saying it was stopped\n{said}"
        if not out.strip() and name != "world":  # stopped before it said anything: that line alone
            assert err.strip() == stopped[0], f"swarm {name}: {sig} {delay_text}\n{said}"
        assert not left, f"swarm {name}: processes left after {sig}: " + ", ".join(
            f"{q.pid} {' '.join(q.cmdline()[:4])}" for q in left if q.is_running()
        )
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
        for q in marked(mark):
            try:
                q.kill()
            except psutil.NoSuchProcess:
                pass
        shutil.rmtree(rt, ignore_errors=True)
