"""Helpers for the multi-process runtime tests (tests/test_runtime*.py, test_resilience.py).

Everything here drives real processes over real zenoh; nothing is mocked. A run is
observed as any client of it would: while it goes, through the world's info query over a
zenoh client session of this test process (`Observer`, the client of swarm/live/client.py) and
the launcher's output; once it has ended, through its results (summary.json with every
event, trajectory.npz); and through psutil. The world's log is only ever shown when a
test fails, never read for events. Processes are only ever started with subprocess
(fork + exec), so an open zenoh session in this process does not matter to them.

- `ProcessTracker` starts every process in its own session (a `swarm.runtime.procs.Group`, so its
  pgid is its pid), records every descendant (pid + create time) while they run, and at
  the end kills only the groups it created and the descendants it recorded.
- `wait_for` is the only way to wait: a condition polled until a deadline
  (`swarm.runtime.procs.wait_until`), failing with what was awaited.
- `replay_events` rebuilds the `out` and `alive` columns a run must have recorded from
  its event list (the world applies a tick's events before recording that tick).
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import psutil
import pytest
from deadlines import DEADLINE
from typer.testing import CliRunner

from swarm.cli.main import app
from swarm.contracts import credentials
from swarm.contracts.scenario import load_scenario
from swarm.contracts.transport import open_client, socket_path
from swarm.contracts.vocabulary import EventKind, ExitCode
from swarm.live.client import LiveRun, NoRun, RunRef
from swarm.runtime.procs import Group, agent_id_of, wait_until

REPO = Path(__file__).resolve().parents[2]
SCENARIOS = REPO / "scenarios"

# launcher progress line: "t=   1.84s tick 184/500 ..."
PROGRESS_RE = re.compile(r"^t=\s*\S+s tick (\d+)/(\d+)", re.M)
# launcher banner: "run case2-734b0c  endpoint unixsock-stream//tmp/... agents 6  clock lockstep"
BANNER_RE = re.compile(r"^run (\S+)\s+endpoint (\S+)\s+agents", re.M)


def swarm_cmd(*args) -> list[str]:
    return [sys.executable, "-m", "swarm", *map(str, args)]


def agent_cmd(agent_id: int, endpoint: str, run: str) -> list[str]:
    return [sys.executable, "-m", "swarm.agents.process", str(agent_id), endpoint, run]


BACKOFF_MAX_S = 0.1  # wait_for's polling slows down to this


def wait_for(cond: Callable[[], object], timeout: float, what: str, interval: float | None = None):
    """Poll `cond` until it returns something truthy (returned) or fail after `timeout` s. By
    default every 10 ms at first, then less and less often, down to every BACKOFF_MAX_S: a
    long wait polls 10 times a second, not 100 (conditions read logs, scan the process table,
    ask the bus: on two cores that polling took CPU from the processes waited for); an explicit
    `interval` polls at that rate throughout."""
    if interval is not None:
        value = wait_until(cond, timeout, interval)
    else:
        t_end, step = time.monotonic() + timeout, 0.01
        while True:
            late = time.monotonic() >= t_end
            value = cond()
            if value or late:
                break
            time.sleep(step)
            step = min(step * 1.5, BACKOFF_MAX_S)
    if not value:
        raise AssertionError(f"timed out after {timeout} s waiting for {what}")
    return value


def read_text(path: Path) -> str:
    try:
        return Path(path).read_text(errors="replace")
    except FileNotFoundError:
        return ""


def short_runtime_dir() -> str:
    """A private directory short enough for Unix socket paths (< 108 bytes)."""
    return tempfile.mkdtemp(prefix="sw", dir="/tmp")


# --- processes ------------------------------------------------------------------------------
@dataclass
class Tracked:
    """One process this test started (a session leader: pgid == pid)."""

    name: str
    group: Group
    log: Path
    started: float  # time.time() at start

    @property
    def popen(self) -> subprocess.Popen:
        return self.group.leader

    @property
    def pid(self) -> int:
        return self.popen.pid

    def text(self) -> str:
        return read_text(self.log)

    def poll(self) -> int | None:
        return self.popen.poll()

    def check_running(self, what: str) -> None:
        """Fail, with its output, if it has exited (a `check` while waiting for `what`)."""
        if self.poll() is not None:
            raise AssertionError(
                f"{self.name} (pid {self.pid}) exited ({self.poll()}) while waiting for {what}:\n{self.text()[-3000:]}"
            )

    def wait(self, timeout: float = DEADLINE) -> int:
        try:
            return self.popen.wait(timeout)
        except subprocess.TimeoutExpired:
            raise AssertionError(
                f"{self.name} (pid {self.pid}) still running after {timeout} s; its output:\n{self.text()[-3000:]}"
            ) from None


@dataclass
class Seen:
    pid: int
    create_time: float
    cmdline: list[str]
    root: int  # pid of the tracked process it descends from


class ProcessTracker:
    """Starts processes in their own sessions and remembers every descendant."""

    POLL_S = 0.2  # a poll scans the whole process table (psutil's children): ~20% of a core at 0.05 s

    def __init__(self, env: dict, log_dir: Path, cwd: Path | None = None):
        self.env = env
        self.log_dir = Path(log_dir)
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self.cwd = cwd
        self.roots: list[Tracked] = []
        self.seen: dict[int, Seen] = {}
        self.closing: list[Callable[[], None]] = []  # run first by close() (observer sessions)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, name="process-tracker", daemon=True)
        self._thread.start()

    def spawn(self, args: list[str], name: str, cwd: Path | None = None, env: dict | None = None) -> Tracked:
        log = self.log_dir / f"{name}.out"
        group = Group(session=True)
        with open(log, "ab") as f:
            p = group.start(
                args,
                stdin=subprocess.DEVNULL,
                stdout=f,
                stderr=subprocess.STDOUT,
                env=self.env if env is None else env,
                cwd=cwd or self.cwd,
            )
        t = Tracked(name, group, log, time.time())
        with self._lock:
            self.roots.append(t)
            try:
                ct = psutil.Process(p.pid).create_time()
                self.seen[p.pid] = Seen(p.pid, ct, args, p.pid)
            except psutil.NoSuchProcess:
                pass
        self.poll_once()
        return t

    def poll_once(self) -> None:
        """Record the current descendants of every tracked process still running."""
        with self._lock:
            roots = [r for r in self.roots if r.popen.returncode is None]
        for r in roots:
            try:
                kids = psutil.Process(r.pid).children(recursive=True)
            except psutil.NoSuchProcess:
                continue
            for k in kids:
                try:
                    seen = Seen(k.pid, k.create_time(), k.cmdline(), r.pid)
                except (psutil.NoSuchProcess, psutil.ZombieProcess, psutil.AccessDenied):
                    continue
                with self._lock:
                    old = self.seen.get(k.pid)
                    if old is None or abs(old.create_time - seen.create_time) < 0.01:
                        # (re)record: a child seen between fork and exec still shows its
                        # parent's command line, so refresh it while the process lives.
                        self.seen[k.pid] = seen if old is None else Seen(k.pid, old.create_time, seen.cmdline, old.root)

    def _watch(self) -> None:
        while not self._stop.wait(self.POLL_S):
            try:
                self.poll_once()
            except Exception:  # never let the watcher die; the next poll retries
                pass

    def descendants(self, root: Tracked) -> list[Seen]:
        with self._lock:
            return [s for s in self.seen.values() if s.root == root.pid and s.pid != root.pid]

    def agent_pids(self, root: Tracked) -> dict[int, int]:
        """{agent id: pid} of the agent processes started under `root` (by their command line)."""
        out = {}
        for s in self.descendants(root):
            aid = agent_id_of(s.cmdline)
            if aid is not None:
                out[aid] = s.pid
        return out

    def wait_agent_pids(self, root: Tracked, n: int, timeout: float = DEADLINE) -> dict[int, int]:
        """{agent id: pid} once `n` agent processes run under `root`."""

        def found():
            self.poll_once()
            pids = self.agent_pids(root)
            return pids if len(pids) >= n else None

        return wait_for(found, timeout, f"{n} agent processes under {root.name}")

    def world_pid(self, root: Tracked) -> int | None:
        for s in self.descendants(root):
            if "swarm" in s.cmdline and "world" in s.cmdline:
                return s.pid
        return None

    @staticmethod
    def _is_alive(s: Seen) -> bool:
        try:
            p = psutil.Process(s.pid)
            if abs(p.create_time() - s.create_time) > 0.01:
                return False  # pid reused by another process
            return p.status() != psutil.STATUS_ZOMBIE
        except (psutil.NoSuchProcess, psutil.ZombieProcess):
            return False

    def living(self) -> list[str]:
        """Every process this tracker started or saw that is still alive (not a zombie)."""
        for r in self.roots:
            r.popen.poll()  # reap what has exited
        with self._lock:
            seen = list(self.seen.values())
        return [f"pid {s.pid}: {' '.join(s.cmdline[:6])}" for s in seen if self._is_alive(s)]

    def assert_none_left(self, timeout: float = DEADLINE) -> None:
        """Fail if a process this tracker started or saw is still alive `timeout` s from now
        (what is exiting is waited for: on a loaded machine that takes its time)."""
        left: list[str] = []

        def none_left() -> bool:
            left[:] = self.living()
            return not left

        if not wait_until(none_left, timeout, 0.02):
            raise AssertionError("processes left alive:\n  " + "\n  ".join(left))

    def close(self, wait: float = 0.0) -> list[str]:
        """Stop watching; kill what is left (only our groups and recorded descendants).

        Returns what was still alive `wait` s after the observers closed (processes that are
        exiting are given that long: on a loaded machine an exit takes its time), before
        killing it.
        """
        for close in self.closing:
            try:
                close()
            except Exception:
                pass
        self._stop.set()
        self._thread.join(timeout=2)
        wait_until(lambda: not self.living(), wait, 0.05)
        left = self.living()
        for r in self.roots:
            try:
                r.group.signal(signal.SIGKILL)  # only while unreaped: the group id is still ours
            except PermissionError:
                pass
        with self._lock:
            seen = list(self.seen.values())
        for s in seen:
            if self._is_alive(s):
                try:
                    os.kill(s.pid, signal.SIGKILL)
                except (ProcessLookupError, PermissionError):
                    pass
        for r in self.roots:
            r.group.reap(timeout=DEADLINE)
        return left


def make_env(runtime_dir: str) -> dict:
    env = dict(os.environ)
    env["SWARM_RUNTIME_DIR"] = runtime_dir
    env["PYTHONUNBUFFERED"] = "1"  # so the launcher's progress lines reach its log at once
    env.pop("PYTHONFAULTHANDLER", None)
    return env


class Runtime:
    """A private runtime dir + a process tracker; `close()` cleans both.

    As a context manager (`with Runtime(dir) as r:`) it closes at the end and, unless the
    block failed already, fails if any process was still alive then (now killed).
    """

    def __init__(self, log_dir: Path, cwd: Path | None = None):
        self.dir = short_runtime_dir()
        self.env = make_env(self.dir)
        self.tracker = ProcessTracker(self.env, log_dir, cwd=cwd or log_dir)

    def close(self, wait: float = 0.0) -> list[str]:
        try:
            return self.tracker.close(wait)
        finally:
            shutil.rmtree(self.dir, ignore_errors=True)

    def __enter__(self) -> Runtime:
        return self

    def __exit__(self, exc_type, *_) -> None:
        # After a passing test, what is still exiting gets DEADLINE s to go (a real leftover
        # stays, and fails the test then); after a failing one, everything is killed at once.
        left = self.close(DEADLINE if exc_type is None else 0.0)
        if exc_type is None:
            assert not left, "processes left alive after the test (now killed):\n  " + "\n  ".join(left)


# --- observing a live run ----------------------------------------------------------------------
def run_credentials(endpoint: str, run: str, runtime_dir: str | Path | None = None):
    """The credentials of a local run (from `runtime_dir`, default the one its socket is
    in), or None while the world has not written them."""

    d = Path(runtime_dir) if runtime_dir is not None else socket_path(endpoint).parent
    path = d / f"{run}{credentials.SUFFIX}"
    try:
        return credentials.read(path)
    except credentials.CredentialsError:
        return None


def open_hub(rt: Runtime) -> None:
    """Processes this runtime starts from now on open their hub to anyone (SWARM_OPEN_HUB):
    for tests of what garbage from a stranger does behind the hub's checks."""
    rt.env["SWARM_OPEN_HUB"] = "1"


def open_session(
    endpoint: str,
    timeout: float = DEADLINE,
    check: Callable[[], None] | None = None,
    creds=None,
    user: str = "operator",
):
    """A zenoh client session of this test process on `endpoint` (as `user` with `creds`;
    without, a stranger, which only an open hub lets in), retried until it listens.
    `check()` runs before each try (to fail early, e.g. when the process to listen exited)."""

    def attempt():
        if check is not None:
            check()
        try:
            return open_client(endpoint, timeout_ms=500, creds=creds, user=user)
        except Exception:
            return None

    return wait_for(attempt, timeout, f"a zenoh session on {endpoint}", interval=0.05)


def agent_info(info: dict, agent: int) -> dict:
    """One agent's row of the world's info (state, alive, joins, drops, missed, pid...)."""
    return info["agents"][str(agent)]


def has_started(info: dict) -> bool:
    """Whether the run has started: the world says so (every agent joined, the clock runs)."""
    return bool(info["started"])


class Observer:
    """This test process as an observer of a live run (as `swarm agents` is): the world's
    info query, through swarm/live/client.py. Events of the run are read from summary.json once it
    has ended; while it goes, the world's counters (joins, drops, alive, tick) tell."""

    def __init__(
        self,
        endpoint: str,
        run: str,
        timeout: float = DEADLINE,
        check: Callable[[], None] | None = None,
        runtime_dir: str | None = None,
    ):

        def attempt():
            if check is not None:
                check()
            creds = run_credentials(endpoint, run, runtime_dir)
            if creds is None:  # the world writes them just before it listens
                return None
            try:
                # dialled as the run's own file says (a wildcard listen address as 127.0.0.1)
                return LiveRun(RunRef(run, creds.endpoint, creds)).__enter__()
            except NoRun:  # not listening yet
                return None

        self._no_run = NoRun
        self.live = wait_for(attempt, timeout, f"a zenoh session on {endpoint}", interval=0.05)

    def info(self) -> dict | None:
        """The world's info now, or None when it does not answer (not up yet, or ended)."""
        try:
            return self.live.info()
        except self._no_run:
            return None

    def wait(
        self,
        cond: Callable[[dict], object],
        timeout: float,
        what: str,
        check: Callable[[], None] | None = None,
        interval: float = 0.05,
    ) -> dict:
        """The world's info once `cond(info)` holds; `check()` runs before each query."""

        def ready():
            if check is not None:
                check()
            info = self.info()
            return info if info is not None and cond(info) else None

        return wait_for(ready, timeout, what, interval)

    def close(self) -> None:
        self.live.__exit__(None, None, None)


def observe_world(
    tracker: ProcessTracker, world: Tracked, endpoint: str, run: str, timeout: float = DEADLINE
) -> Observer:
    """An observer of a world started by hand, once it listens (failing if the world exits
    first); the tracker closes it."""
    obs = Observer(
        endpoint,
        run,
        timeout,
        check=lambda: world.check_running("it to listen"),
        runtime_dir=tracker.env.get("SWARM_RUNTIME_DIR"),
    )
    tracker.closing.append(obs.close)
    return obs


# --- runs -------------------------------------------------------------------------------------
@dataclass
class UpRun:
    """A `swarm up` started by a test."""

    launcher: Tracked
    out: Path
    tracker: ProcessTracker
    observer: Observer | None = None

    @property
    def world_log(self) -> Path:
        return self.out / "logs" / "world.log"

    def world_text(self) -> str:
        """The world's log: for failure messages only (events come from summary.json or the info query)."""
        return read_text(self.world_log)

    def banner(self) -> tuple[str, str]:
        """(run id, endpoint) printed by the launcher."""
        m = wait_for(lambda: BANNER_RE.search(self.launcher.text()), DEADLINE, "the launcher's banner")
        return m[1], m[2]

    def progress_tick(self) -> int:
        ticks = [int(m[0]) for m in PROGRESS_RE.findall(self.launcher.text())]
        return max(ticks) if ticks else -1

    def running(self, what: str = "the run") -> None:
        """Fail (with the launcher's and the world's output) when the launcher has exited."""
        if self.launcher.poll() is not None:
            raise AssertionError(
                f"launcher exited ({self.launcher.poll()}) while waiting for {what}:\n"
                f"{self.launcher.text()[-3000:]}\n{self.world_text()[-3000:]}"
            )

    def observe(self, timeout: float = DEADLINE) -> Observer:
        """The observer of this run (opened once the world listens; the tracker closes it)."""
        if self.observer is None:
            run, endpoint = self.banner()
            self.observer = Observer(
                endpoint,
                run,
                timeout,
                check=lambda: self.running("the world to listen"),
                runtime_dir=self.tracker.env.get("SWARM_RUNTIME_DIR"),
            )
            self.tracker.closing.append(self.observer.close)
        return self.observer

    def info(self) -> dict | None:
        """The world's info now (None if it does not answer)."""
        return self.observe().info()

    def wait_info(self, cond: Callable[[dict], object], timeout: float, what: str) -> dict:
        """The world's info once `cond(info)` holds; fails at once if the launcher exits."""
        return self.observe().wait(cond, timeout, what, check=lambda: self.running(what))

    def wait_started(self, timeout: float = DEADLINE) -> dict:
        """Until the run has started (every agent joined; the world's info says so)."""
        info = self.wait_info(has_started, timeout, "the run to start (every agent joined)")
        self.tracker.poll_once()
        return info

    def summary(self) -> dict:
        return json.loads((self.out / "summary.json").read_text())

    def results(self, timeout: float = DEADLINE) -> tuple[dict, dict[str, np.ndarray]]:
        """(summary, trajectory) once the run has ended by itself (exit 0) leaving no process."""
        rc = self.launcher.wait(timeout)
        assert rc == ExitCode.OK, self.launcher.text()[-3000:] + self.world_text()[-3000:]
        self.tracker.assert_none_left()
        return self.summary(), self.trajectory()

    def trajectory(self) -> dict[str, np.ndarray]:
        return load_trajectory(self.out)


def start_up(tracker: ProcessTracker, scenario: Path | str, out: Path, *extra, name: str = "up") -> UpRun:
    args = swarm_cmd("up", scenario, "--out", out, "--no-plots", *extra)
    return UpRun(tracker.spawn(args, name), Path(out), tracker)


def start_ticking(
    tracker: ProcessTracker, out: Path, duration: float, scenario: Path | str = SCENARIOS / "case2.toml"
) -> tuple[UpRun, dict[int, int], dict]:
    """A lockstep `swarm up` of `scenario` for `duration` s, once every agent process is known
    and the world ticks: (the run, agent pids by id, the world's info at that moment)."""
    up = start_up(tracker, scenario, out, "--duration", str(duration), "--clock", "lockstep")
    up.wait_started()
    pids = tracker.wait_agent_pids(up.launcher, len(load_scenario(scenario).agents))
    info = up.wait_info(lambda i: i["tick"] > 0, DEADLINE, "the run to tick")
    return up, pids, info


def ring_scenario(
    path: Path, n: int, leaders: int = 2, clock: str = "realtime", dt: float = 0.05, duration: float = 600.0
) -> Path:
    """Write a scenario of `n` agents on a spiral round the target (the first `leaders` of them
    leaders) to `path`: for runs larger than the shipped scenarios."""

    lines = [
        f'name = "ring{n}"',
        "[run]",
        f"dt = {dt}",
        f"duration = {duration}",
        f'clock = "{clock}"',
        "seed = 1",
        "[target]",
        "x = 0.0",
        "y = 0.0",
        "[gains]",
        "c1 = 1.0",
        "c2 = 0.5",
    ]
    for i in range(1, n + 1):
        a, r, v = 2 * math.pi * i / n, 30.0 + 2 * i, 20.0 + (i % 7) * 3
        lines += [
            "[[agents]]",
            f"id = {i}",
            f'role = "{"leader" if i <= leaders else "follower"}"',
            f"x = {r * math.cos(a):.3f}",
            f"y = {r * math.sin(a):.3f}",
            f"speed = {v}",
            f"heading = {a + 1.57:.3f}",
        ]
        if i <= leaders:
            lines += [f"orbit_radius = {v}", 'direction = "ccw"']
    path.write_text("\n".join(lines) + "\n")
    return path


def reaped(pid: int) -> bool:
    """Whether process `pid` is gone for good: exited and reaped by its parent (no zombie)."""
    try:
        return psutil.Process(pid).status() == psutil.STATUS_DEAD
    except psutil.NoSuchProcess:
        return True


def load_trajectory(out: Path) -> dict[str, np.ndarray]:
    with np.load(Path(out) / "trajectory.npz", allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def run_sim(tracker: ProcessTracker, scenario: Path | str, out: Path, *extra, timeout: float = DEADLINE):
    """`swarm sim` as a process; returns (trajectory arrays, summary)."""
    p = tracker.spawn(swarm_cmd("sim", scenario, "--out", out, "--no-plots", *extra), f"sim-{Path(out).name}")
    rc = p.wait(timeout)
    assert rc == ExitCode.OK, f"swarm sim exited {rc}:\n{p.text()[-3000:]}"
    return load_trajectory(out), json.loads((Path(out) / "summary.json").read_text())


def still_running(started: list[tuple[int, float]]) -> list:
    """The processes of `started` ((pid, create time) pairs) still running: not exited, not
    a zombie, and not another process that got the same pid since."""
    alive = []
    for pid, ct in started:
        try:
            p = psutil.Process(pid)
            if abs(p.create_time() - ct) < 0.01 and p.status() != psutil.STATUS_ZOMBIE:
                alive.append(p)
        except psutil.NoSuchProcess:
            pass
    return alive


def sim_results(out: Path) -> tuple[dict[str, np.ndarray], dict]:
    """(trajectory arrays, summary) of a finished `swarm sim` in `out`."""
    return load_trajectory(out), json.loads((Path(out) / "summary.json").read_text())


def first_ticks(traj: dict[str, np.ndarray], summary: dict, ticks: int) -> tuple[dict, dict]:
    """A whole run cut to its first `ticks` ticks: the rows 0..ticks of every per-tick array,
    and the events of those ticks (a run is the same whatever its duration, up to its end)."""
    rows = len(traj["t"])
    cut = {k: v[: ticks + 1] if v.ndim and v.shape[0] == rows else v for k, v in traj.items()}
    return cut, {**summary, "events": [e for e in summary["events"] if e.get("tick", 0) <= ticks]}


def replay_events(events: list[dict], ids, rows: int) -> tuple[np.ndarray, np.ndarray]:
    """The (out, alive) arrays a recording must hold given its events.

    join/rejoin -> alive; drop -> not alive and out -1; switch -> out = its `to`. The
    events of tick k take effect in row k (the world records a tick after handling them).
    """
    col = {int(a): k for k, a in enumerate(ids)}
    n = len(col)
    cur_out = np.full(n, -1, dtype=np.int64)
    cur_alive = np.zeros(n, dtype=bool)
    out = np.empty((rows, n), dtype=np.int64)
    alive = np.empty((rows, n), dtype=bool)
    evs = sorted((e for e in events if e.get("agent") is not None), key=lambda e: e["tick"])  # stable
    i = 0
    for t in range(rows):
        while i < len(evs) and evs[i]["tick"] <= t:
            e = evs[i]
            k = col[int(e["agent"])]
            if e["kind"] in (EventKind.JOIN, EventKind.REJOIN):
                cur_alive[k] = True
            elif e["kind"] == EventKind.DROP:
                cur_alive[k] = False
                cur_out[k] = -1
            elif e["kind"] == EventKind.SWITCH:
                cur_out[k] = -1 if e["to"] is None else int(e["to"])
            i += 1
        out[t] = cur_out
        alive[t] = cur_alive
    return out, alive


def events_of(summary: dict, kind: str, agent: int | None = None) -> list[dict]:
    return [e for e in summary["events"] if e["kind"] == kind and (agent is None or e["agent"] == agent)]


def check_time_column(traj: dict, ticks: int, dt: float) -> None:
    """ticks+1 rows, t strictly increasing by dt."""
    t = traj["t"]
    assert t.shape == (ticks + 1,), f"t has {t.shape[0]} rows, expected {ticks + 1}"
    assert np.all(np.isfinite(t))
    d = np.diff(t)
    assert np.all(d > 0), "t is not strictly increasing"
    np.testing.assert_allclose(d, dt, rtol=0, atol=1e-9)
    assert t[0] == 0.0
    for k in ("x", "y", "heading", "out", "alive"):
        assert traj[k].shape[0] == ticks + 1, f"{k} has {traj[k].shape[0]} rows"


@contextmanager
def live_swarm(base: Path, scenario: Path | str, n: int, *up_args, timeout: float = DEADLINE):
    """`swarm up` of `scenario` (`n` agents, realtime) in a private runtime dir under `base`,
    once `swarm runs` shows all `n` live: yields a dict with run, endpoint, runtime dir, the
    up run, the tracker and `extra_pids` ((pid, create time) of agents a test starts outside
    the launcher). At the end: Ctrl-C, exit 130, and no process left, spawned agents included."""

    rt = Runtime(base)
    state = {"runtime": rt.dir, "tracker": rt.tracker, "extra_pids": []}
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("SWARM_RUNTIME_DIR", rt.dir)
        up = start_up(rt.tracker, scenario, base / "run", "--clock", "realtime", *up_args)
        state["up"] = up
        try:

            def ready():
                if up.launcher.poll() is not None:
                    raise AssertionError(f"swarm up exited {up.launcher.poll()}:\n{up.launcher.text()[-3000:]}")
                res = CliRunner().invoke(app, ["runs", "--json"])
                docs = json.loads(res.stdout) if res.exit_code == ExitCode.OK else []
                ok = len(docs) == 1 and docs[0]["agents_live"] == docs[0]["agents_total"] == n and docs[0]["tick"]
                return docs[0] if ok else None

            doc = wait_for(ready, timeout, f"swarm runs to show the run with {n} live agents", interval=0.1)
            state.update(run=doc["run"], endpoint=doc["endpoint"])
            rt.tracker.poll_once()
            yield state
        finally:
            if up.launcher.poll() is None:
                os.kill(up.launcher.pid, signal.SIGINT)
            code = up.launcher.wait(DEADLINE)
            # Agents started by `swarm spawn` are not the launcher's: they leave on their own when
            # the world ends (its "end" notice, or its token gone); give them a deadline to.
            wait_until(lambda: not (rt.tracker.living() or still_running(state["extra_pids"])), DEADLINE, 0.05)
            left = rt.close()  # kills only our groups / recorded descendants, removes the runtime dir
            strays = still_running(state["extra_pids"])
            for proc in strays:
                proc.kill()
            assert code == ExitCode.INTERRUPTED, f"swarm up exited {code} on SIGINT:\n{up.launcher.text()[-3000:]}"
            assert not left, "processes left alive (now killed):\n  " + "\n  ".join(left)
            assert not strays, f"spawned agents left alive (now killed): {[x.pid for x in strays]}"
