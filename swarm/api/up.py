"""`swarm.up(...)`: `swarm up` started from Python, as a handle (`UpRun`).

The launcher is `swarm up` itself, as a child process in a session of its own (a
`swarm.runtime.procs.Group`), its output collected by a thread (`output`). It is tied to this
process (the Linux parent-death signal, swarm/contracts/lifeline.py: it gets SIGTERM if
this process dies, even by SIGKILL) and it ties the world and the agents to itself, so
nothing of a run outlives the Python process that started it. (Linux ties it to the
thread that started it: start runs from a thread that outlives them, e.g. the main one.) `stop()` (also on leaving
a `with` block, and at interpreter exit) is `swarm up`'s Ctrl-C: SIGTERM, the world
writes the results, then every process ends; SIGKILL after a grace period.

    with swarm.up("scenarios/case2.toml", clock="lockstep", duration=20, out="runs/x") as run:
        print(run.state().agents[2].radial_error)   # live, over zenoh (swarm/live/client.py)
        run.wait()
    results = run.results()                          # swarm.open_run(out)

Live state is read as `swarm agents` and `swarm graph` read it, through the object
`swarm.connect(...)` returns (swarm/api/live.py): the world's info merged with the agents'
own statuses, and the communication graph.
"""

from __future__ import annotations

import atexit
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

from swarm.api.launch import check_clock, name_stem, scenario_file
from swarm.api.live import Live, LiveState
from swarm.api.runs import Results, open_run
from swarm.api.scenario import Builder, Scenario, as_scenario, source_of, with_duration
from swarm.contracts import credentials
from swarm.contracts.errors import NoRunError, UpError
from swarm.contracts.laws import ENV_LAW_PATH, with_law_path
from swarm.contracts.lifeline import LAUNCHER_PID_ENV
from swarm.live.client import LiveRun, NoRun, RunRef
from swarm.offline.results import OutDirError, results_in
from swarm.runtime.procs import Group, wait_until

__all__ = ["UpError", "UpRun", "LiveState"]

# `swarm up`'s first line: "run case2-734b0c  endpoint unixsock-stream//tmp/...  agents 6  clock lockstep"
BANNER_RE = re.compile(r"^run (\S+)\s+endpoint (\S+)\s+agents", re.M)
# `swarm up`, tied to this process first (it does not tie itself: it is the one others tie to)
_BOOT = (
    "import sys; from swarm.contracts.lifeline import tie_to_launcher; tie_to_launcher(); "
    "sys.argv[0] = 'swarm'; from swarm.cli import main; main()"
)
_RUNNING: set[UpRun] = set()  # stopped at interpreter exit


class UpRun:
    """A `swarm up` of `scenario` (a file, a Scenario, a dict or a Builder) started now.

    Options: out (default runs/<name>-up-<time>-<random>), clock ("lockstep" |
    "realtime"), duration (s), time_scale, listen (endpoint), force (replace results in
    out), world_grace (s), robots (a robots file: the agents drive ROS 2 robots,
    docs/guides/robots.md), env (the launcher's environment; default this process's)."""

    def __init__(
        self,
        scenario: Any,
        out: str | Path | None = None,
        *,
        clock: str | None = None,
        duration: float | None = None,
        time_scale: float | None = None,
        listen: str | None = None,
        force: bool = False,
        world_grace: float | None = None,
        robots: str | Path | None = None,
        env: dict | None = None,
    ):
        s = as_scenario(scenario)  # bad scenarios and options fail here, before any process
        with_duration(s, duration, source_of(scenario))
        check_clock(clock)
        self.scenario = s
        self.out = (
            Path(out)
            if out is not None
            else Path("runs") / (f"{name_stem(scenario, s)}-up-{time.strftime('%Y%m%d-%H%M%S')}-{os.urandom(3).hex()}")
        )
        if self.out.is_dir() and results_in(self.out) and not force:
            raise OutDirError(
                f"out {self.out} already holds the results of a run ({', '.join(results_in(self.out))}); "
                "choose another directory, or pass force=True to replace them"
            )
        path, self._tmp = scenario_file(scenario, s)  # the world reads a file
        args = [sys.executable, "-c", _BOOT, "up", str(path), "--out", str(self.out), "--no-plots"]
        for flag, value in (
            ("--clock", clock),
            ("--duration", duration),
            ("--time-scale", time_scale),
            ("--listen", listen),
            ("--world-grace", world_grace),
            ("--robots", robots),
        ):
            if value is not None:
                args += [flag, str(value)]
        if force:
            args.append("--force")
        env = {**(os.environ if env is None else env), "PYTHONUNBUFFERED": "1", LAUNCHER_PID_ENV: str(os.getpid())}
        if self._tmp is not None:  # the file is in a temporary dir: its laws resolve as they did here
            env[ENV_LAW_PATH] = with_law_path([p for p in sys.path if p and os.path.isdir(p)])
        self._lines: list[str] = []
        self._live: Live | None = None  # opened by the first state()
        self._group = Group(session=True)  # no terminal's Ctrl-C reaches it: stop() does
        self.process = self._group.start(
            args, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env
        )
        self._reader = threading.Thread(target=self._read, name=f"swarm-up-{self.process.pid}", daemon=True)
        self._reader.start()
        _RUNNING.add(self)

    # -- the launcher ---------------------------------------------------------------------
    def _read(self) -> None:
        stdout = self.process.stdout
        assert stdout is not None  # (started with stdout=PIPE)
        for raw in stdout:
            self._lines.append(raw.decode("utf-8", "replace").rstrip("\r\n").split("\r")[-1])
        stdout.close()

    @property
    def pid(self) -> int:
        return self.process.pid

    @property
    def output(self) -> str:
        """What `swarm up` has printed so far (stdout and stderr)."""
        return "\n".join(self._lines)

    @property
    def returncode(self) -> int | None:
        """`swarm up`'s exit code (docs/reference/exit-codes.md#swarm-up), None while it runs."""
        return self.process.poll()

    def running(self) -> bool:
        return self.process.poll() is None

    def _why(self, what: str) -> UpError:
        tail = "\n".join(self._lines[-15:])
        return UpError(f"{what} (swarm up exit code {self.returncode}); its output:\n{tail}")

    def banner(self, timeout: float = 30.0) -> tuple[str, str]:
        """(run id, endpoint), as `swarm up` prints them at start; UpError if it ends first."""

        def found():
            m = BANNER_RE.search(self.output)
            if m is not None:
                return m
            return "ended" if not self.running() and not self._reader.is_alive() else None

        m = wait_until(found, timeout, 0.02)
        if not isinstance(m, re.Match):
            raise self._why("swarm up ended before it started the run" if m else f"no run id within {timeout} s")
        return m[1], m[2]

    @property
    def run_id(self) -> str:
        return self.banner()[0]

    def wait(self, timeout: float | None = None) -> int:
        """Until `swarm up` has exited (TimeoutError after `timeout` s); its exit code."""
        try:
            code = self.process.wait(timeout)
        except subprocess.TimeoutExpired:
            raise TimeoutError(f"swarm up (pid {self.pid}) still running after {timeout} s") from None
        self._finish()
        return code

    def stop(self, grace: float = 20.0) -> int:
        """Stop the run as Ctrl-C does (results written, exit 143); SIGKILL after `grace` s.
        Returns the exit code. Harmless when it has ended already."""
        self._close_live()
        if self.running():
            self._group.signal(signal.SIGTERM)
            try:
                self.process.wait(grace)
            except subprocess.TimeoutExpired:  # the world and agents get SIGTERM when it dies
                self._group.stop(grace=3.0)
                # ... and write what they have: give them the grace to (results() reads it)
                wait_until(lambda: (self.out / "summary.json").exists(), grace, 0.1)
        self._finish()
        return self.process.returncode

    def _finish(self) -> None:
        self._close_live()
        self._group.reap(timeout=5.0)
        self._reader.join(timeout=5.0)
        if self._tmp is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._tmp = None
        _RUNNING.discard(self)

    def __enter__(self) -> UpRun:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def results(self, timeout: float | None = None) -> Results:
        """The run's results once it has ended (waits up to `timeout` s): `open_run(out)`."""
        self.wait(timeout)
        try:
            return open_run(self.out)
        except Exception as e:
            raise self._why(f"no results in {self.out}: {e}") from None

    # -- live state -----------------------------------------------------------------------
    def live(self, timeout: float = 30.0) -> Live:
        """A new session to the running world: what `swarm.connect(...)` returns (a
        `swarm.api.live.Live`: agents(), graph(), info(), pause(), kill(...)...); close it,
        or use it in a `with` block."""
        run, _ = self.banner(timeout)

        def attempt():
            if not self.running():
                raise self._why("the run has ended")
            try:  # the world writes the run's credentials just before it listens
                creds = credentials.read(credentials.run_file(run))
                return Live(LiveRun(RunRef(run, creds.endpoint, creds)).__enter__())
            except (credentials.CredentialsError, NoRun):
                return None

        live = wait_until(attempt, timeout, 0.05)
        if not live:
            raise self._why(f"cannot reach the world of run {run} within {timeout} s")
        return live

    def state(self, timeout: float = 30.0) -> LiveState:
        """The live run now, as a `LiveState` (agents, poses, graph); UpError once it has ended."""
        if self._live is None:
            self._live = self.live(timeout)
        deadline = time.monotonic() + timeout
        while True:
            try:
                return self._live.state()
            except NoRunError:  # listening, not answering yet; or gone
                if not self.running() or time.monotonic() > deadline:
                    raise self._why("the world did not answer") from None
                time.sleep(0.05)

    def _close_live(self) -> None:
        if self._live is not None:
            live, self._live = self._live, None
            live.close()

    def __repr__(self) -> str:
        state = "running" if self.running() else f"exit code {self.returncode}"
        return f"UpRun(pid {self.pid}, {state}, out={self.out})"


@atexit.register
def _stop_all() -> None:
    for run in list(_RUNNING):
        try:
            run.stop(grace=10.0)
        except Exception:
            pass


def up(scenario: Scenario | dict | str | Path | Builder, out: str | Path | None = None, **options: Any) -> UpRun:
    """`swarm up` from Python: see `UpRun` for the options and the handle."""
    return UpRun(scenario, out, **options)
