"""`swarm up`: start a world and one OS process per agent, supervise, show progress.

All children run in one process group that the launcher owns (a `swarm.runtime.procs.Group`, led
by the world, which is not reaped until the end, so the group outlives any agent; the
agents are reaped as they exit, by a `swarm.runtime.procs.Reaper` thread). The world writes the
results. Agents are forked by a fork server that has imported what they need (swarm/runtime/forks.py,
agents/forkserver.py; exec'd if it cannot), and are this process's children all the same (it
is their subreaper). The launcher watches the run over zenoh like any observer would (ground truth and
events), reports progress, and once told to `stop(signum)` (by whoever handles Ctrl-C/SIGTERM:
swarm/api/launch.py; SIGINT on the world's `stop` event, i.e. `swarm stop` from any terminal)
stops the world first with that signal (so the results are written, and say which signal),
then the agents, then anything left in the group. Each child's
output goes to `<out>/logs/`. The agents start once the world has said that it listens
(its own word on a pipe, swarm/contracts/startup.py), never after a fixed wait.

It supervises (swarm/runtime/oversight.py: agent exits reported, the world's scripted process
faults carried out): an agent process that exits by itself is reported live, sent to the world
(an `agent_exit` request on the world's supervise key, which only the launcher's own
`supervisor` identity may use: the world records a `crash` or `exit` event, see
swarm/runtime/supervision.py) and listed at the end; one that exits before the run started, or a
world that does, stops the run with one line naming the cause. Children get the
launcher's pid (swarm/contracts/lifeline.py) and stop by themselves if it dies.
"""

from __future__ import annotations

import os
import secrets
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from swarm.contracts import credentials, wire
from swarm.contracts.freetext import printable
from swarm.contracts.identities import ENV_SUPERVISOR, SUPERVISOR
from swarm.contracts.laws import ENV_LAW_PATH, ENV_TRUSTED_LAWS, with_law_path, with_trusted_laws
from swarm.contracts.lifeline import LAUNCHER_PID_ENV
from swarm.contracts.scenario import Scenario
from swarm.contracts.startup import ENV_READY_FD, ReadyWait
from swarm.contracts.transport import default_endpoint, dial_endpoint, open_client
from swarm.contracts.vocabulary import EventKind, ExitCode
from swarm.runtime.forks import AgentStarter
from swarm.runtime.oversight import Oversight
from swarm.runtime.procs import Group, Reaper, wait_until
from swarm.runtime.progress import AddedSpec, added_specs, truth_progress
from swarm.runtime.supervision import AgentExitReport

# The world says when it listens (swarm/contracts/startup.py); these bounds are last resorts
# only, for a world that neither gets there nor exits, and for our own session after that.
READY_DEADLINE = 300.0
CONNECT_DEADLINE = 60.0


def _say(msg: str) -> None:
    """A line on stdout, clearing the progress line first on a terminal."""
    print(("\r\033[K" if sys.stdout.isatty() else "") + msg, flush=True)


@dataclass
class UpConfig:
    scenario_path: Path
    scenario: Scenario
    out_dir: Path  # where the results go
    run: str
    listen: str | None = None
    duration: float | None = None
    clock: str | None = None
    time_scale: float = 1.0  # realtime clock: simulated s per wall s
    join_timeout: float = 60.0
    world_grace: float = 10.0  # s agents wait for a world that stopped answering
    foxglove: tuple[str, int] | None = None  # (host, port): the world serves a live view (--foxglove)
    robots: Path | None = None  # the robots file: the world drives ROS 2 robots (--robots, realtime only)


class Launcher(Oversight):
    def __init__(self, cfg: UpConfig, say: Callable[[str], None] = _say):
        self.cfg = cfg
        self.say = say
        self.endpoint = cfg.listen or default_endpoint(cfg.run)
        self.dial = dial_endpoint(self.endpoint)  # where the agents and the launcher connect
        self.world: subprocess.Popen | None = None
        self.agents: dict[int, subprocess.Popen] = {}
        self.group = Group()  # led by the world, which is reaped last
        self.stop_signal: int | None = None
        self.lock = threading.Lock()
        self.latest_truth: bytes | None = None
        self.events: list[dict] = []
        self.logs = cfg.out_dir / "logs"
        self.failed = False
        self.notices: list[bytes] = []  # world/control notices (faults to carry out)
        self.dropped_notices = 0  # malformed control notices ignored
        self.dropped_noted = 0.0
        self.started = False  # the world's `start` event was seen (every agent joined)
        self.listening = False  # the world listens (and so handles SIGINT/SIGTERM as a stop)
        self.procs: list[tuple[int, subprocess.Popen]] = []  # every agent process started
        self.seen_exit: set[int] = set()  # pids whose exit was handled
        self.scripted: set[int] = set()  # pids signalled for a scripted fault
        self.exits: list[AgentExitReport] = []
        self.failure: str | None = None  # one line: why the run could not start
        self.operator_stop: str | None = None  # `swarm stop` ended the run: the world's reason ("asked by ...")
        self.added: dict[int, AddedSpec] = {}  # agents added at run time (`swarm spawn`), for the progress line
        self.unknown_added: set[int] = set()  # added agents whose spec is still to be asked for
        self.starter: AgentStarter | None = None  # starts the agents (forked, or exec'd)
        self.ready_wait: ReadyWait | None = None  # the world's start-up pipe (start_world)
        # The supervisor's password (swarm/contracts/access.py): this process and its world
        # alone have it; only with it may the world be told of agent exits and faults done.
        self.supervisor_password = secrets.token_hex(16)
        # --robots: `started(world pid)` once the world runs, `join()` once it has ended: a zero
        # twist to every robot as soon as the world exits (swarm/robots/halt.py WorldExitStop,
        # set by swarm/api/launch.py; this layer does not import the robots')
        self.world_exit: Any = None

    # -- processes --------------------------------------------------------------------------
    def _env(self) -> dict:
        return {
            **os.environ,
            LAUNCHER_PID_ENV: str(os.getpid()),  # children stop when we die
            # the laws of our own scenario are the laws our agents may import, from its directory too
            ENV_TRUSTED_LAWS: with_trusted_laws(self.cfg.scenario.law_names),
            ENV_LAW_PATH: with_law_path([self.cfg.scenario_path.resolve().parent]),
            # our agents use our run's own credentials, whatever the shell says
            credentials.ENV_CREDENTIALS: str(credentials.run_file(self.cfg.run)),
        }

    def start_world(self) -> None:
        c = self.cfg
        args = [
            sys.executable,
            "-m",
            "swarm",
            "world",
            str(c.scenario_path),
            "--listen",
            self.endpoint,
            "--run",
            c.run,
            "--out",
            str(c.out_dir),
            "--time-scale",
            str(c.time_scale),
            "--no-plots",
            "--join-timeout",
            str(c.join_timeout),
        ]
        if c.duration is not None:
            args += ["--duration", str(c.duration)]
        if c.clock is not None:
            args += ["--clock", c.clock]
        if c.foxglove is not None:
            args += ["--foxglove", "--foxglove-host", c.foxglove[0], "--foxglove-port", str(c.foxglove[1])]
        if c.robots is not None:
            args += ["--robots", str(c.robots.resolve())]
        # the world says on this pipe what it is doing, and `ready` once it listens (wait_ready)
        r, w = os.pipe()
        try:
            with open(self.logs / "world.log", "ab") as log:
                env = {**self._env(), ENV_SUPERVISOR: self.supervisor_password, ENV_READY_FD: str(w)}
                self.world = self.group.start(
                    args, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT, pass_fds=(w,), env=env
                )
        except BaseException:
            os.close(r)
            raise
        finally:
            os.close(w)
        self.ready_wait = ReadyWait(r)
        if self.world_exit is not None:
            self.world_exit.started(self.world.pid)

    def wait_ready(self, timeout: float = READY_DEADLINE) -> bool:
        """Wait for the world's own word that it listens (swarm/contracts/startup.py): True.
        False when it exited first (the run loop reports its exit), when the run is stopped,
        or, the last resort, after `timeout` s (then `failure` says what it was still doing)."""
        w, world = self.ready_wait, self.world
        if w is None or world is None:  # (start_world first)
            return False
        if w.wait(timeout, lambda: self.stop_signal is not None):
            return True
        if w.ended:  # it exited (or closed its end and exits): its exit code comes in a moment
            wait_until(lambda: self.world_exit_code() is not None, 5.0, 0.02)
        elif self.stop_signal is None and self.world_exit_code() is None:
            self.failure = (
                f"the world (pid {world.pid}) did not get ready within {timeout:g} s: it was "
                f"still {w.doing()} (see {self.logs / 'world.log'})"
            )
            self.failed = True
        return False

    def start_starter(self) -> AgentStarter:
        """What starts the agents (swarm/runtime/forks.py: a fork server, which imports meanwhile); after
        the world, which leads the group."""
        if self.starter is None:
            self.starter = AgentStarter(self.group, self._env(), self.logs, lambda m: self.say(f"swarm up: {m}"))
        return self.starter

    def start_agent(self, agent_id: int) -> subprocess.Popen:
        p = self.start_starter().start(
            [str(agent_id), self.dial, self.cfg.run, "--world-grace", str(self.cfg.world_grace)],
            f"agent-{agent_id}.log",
        )
        self.agents[agent_id] = p
        self.procs.append((agent_id, p))
        return p

    def world_exit_code(self) -> int | None:
        """The world's exit status without reaping it (it leads the process group)."""
        assert self.world is not None
        return self.group.exit_code(self.world)

    def stop_all(self, grace: float = 10.0) -> None:
        """World first (it writes the results), then agents, then the whole group."""
        if self.world is not None and self.world_exit_code() is None:
            # the user's signal (summary.json says it); SIGTERM to a world not listening (no handlers yet)
            sig = self.stop_signal if self.stop_signal and self.listening else signal.SIGTERM
            try:
                os.kill(self.world.pid, sig)
            except ProcessLookupError:
                pass
            wait_until(lambda: self.world_exit_code() is not None, grace, 0.02)
        if self.group.pgid is not None:
            wait_until(lambda: all(p.poll() is not None for p in self.agents.values()), 3.0, 0.02)
        # SIGTERM to the group, SIGKILL if anything of ours still runs 3 s later; every child
        # reaped, and anything else that joined the group (a grandchild) killed too.
        self.group.stop(grace=3.0)

    # -- observing -------------------------------------------------------------------------------
    def connect(self, timeout: float = CONNECT_DEADLINE):
        """Open an observer session (the world listens); None if the world died first, the
        run was stopped, or it did not let us in within `timeout` s."""
        opened = []

        def ready() -> bool:  # True: connected, or no point in trying any more
            if self.stop_signal is not None or self.world_exit_code() is not None:
                return True
            try:  # the world writes the run's credentials before it listens
                creds = credentials.read(credentials.run_file(self.cfg.run))
                creds = replace(creds, secret=None, user=SUPERVISOR, password=self.supervisor_password)
                ses = open_client(self.dial, timeout_ms=500, creds=creds, user=SUPERVISOR)
            except Exception:
                return False
            if any(r.ok for r in ses.liveliness().get(wire.world_alive_key(self.cfg.run), timeout=1.0)):
                opened.append(ses)
                return True
            ses.close()
            return False

        wait_until(ready, timeout, 0.05)
        return opened[0] if opened else None

    def _on_truth(self, sample) -> None:
        self.latest_truth = sample.payload.to_bytes()

    def _on_event(self, sample) -> None:
        try:
            ev = wire.decode_event(sample.payload.to_bytes())
        except wire.WireError:
            return
        with self.lock:
            self.events.append(ev)
        if ev["kind"] == EventKind.START:
            self.started = True
        elif ev["kind"] == EventKind.STOP and ev.get("agent") is None:
            # `swarm stop` (world/inbox.py): the world stops itself, and this run ends as on Ctrl-C
            # escaped again here (swarm/contracts/freetext.py): it is printed on this terminal
            self.operator_stop = printable(ev.get("reason", "asked by the operator"))
            self.stop(signal.SIGINT)
        elif ev["kind"] == EventKind.ADD and isinstance(ev.get("agent"), int):
            self.unknown_added.add(ev["agent"])

    def progress(self, session=None) -> dict | None:
        """Figures for the progress line from the latest ground truth (swarm/runtime/progress.py),
        agents added at run time included once the world's info has told their spec."""
        if self.unknown_added and session is not None:
            self.added.update(added_specs(session, self.cfg.run, set(self.unknown_added)))
            self.unknown_added -= set(self.added)
        return truth_progress(self.latest_truth, self.cfg.scenario, self.added)

    # -- the run -------------------------------------------------------------------------------
    def run(self, show: Callable[[dict | None, float], None]) -> int:
        """Start everything, supervise until the world ends (or `stop`); returns the world's
        exit code. `show(figures, wall)` gets the progress line's figures as they come."""
        self.logs.mkdir(parents=True, exist_ok=True)
        session = None
        reaper = Reaper(self.group)  # a child killed from outside (`swarm kill`) is no zombie meanwhile
        try:
            if self.stop_signal is None:  # (stopped before anything started: nothing to start)
                self.start_world()
                self.start_starter()  # the fork server imports while the world starts
                # agents start once the world listens: its own word on the pipe, then our session
                session = self.connect() if self.wait_ready() else None
            if session is not None:
                self.listening = True
                self._subs = [
                    session.declare_subscriber(wire.truth_key(self.cfg.run), self._on_truth),
                    session.declare_subscriber(wire.events_key(self.cfg.run), self._on_event),
                    session.declare_subscriber(
                        wire.world_control_key(self.cfg.run), lambda s: self.notices.append(s.payload.to_bytes())
                    ),
                ]
                for a in self.cfg.scenario.agents:
                    if self.stop_signal is not None:
                        break  # stopped while the agents start: no more of them
                    self.start_agent(a.id)
            elif not self.failed and self.stop_signal is None and self.world_exit_code() is None:
                self.failure = (
                    f"the world listens on {self.endpoint} but did not let the launcher in within "
                    f"{CONNECT_DEADLINE:g} s (see {self.logs / 'world.log'})"
                )
                self.failed = True
            t0 = time.monotonic()
            while self.stop_signal is None and not self.failed:
                code = self.world_exit_code()
                if code is not None:
                    break
                for _ in range(5 if self.cfg.scenario.faults else 1):
                    self.carry_out_faults(session)
                    if self.supervise(session):
                        break
                    time.sleep(0.05 if self.cfg.scenario.faults else 0.25)
                show(self.progress(session), time.monotonic() - t0)
            if self.world_exit is not None and self.world_exit_code() is not None:
                self.world_exit.join()  # the robots' zero twist (and its line) before anything else
            if self.stop_signal is None and not self.failed:
                self.supervise(None)  # exits just before the world ended (the world has ended)
            if self.operator_stop is not None:
                self.say(f"swarm up: the run was stopped from another terminal ({self.operator_stop})")
        finally:
            reaper.stop()
            if self.ready_wait is not None:
                self.ready_wait.close()
            if self.starter is not None:
                self.starter.close()
            if session is not None:
                session.close()
            self.stop_all()
            if self.world_exit is not None:
                self.world_exit.join()
        if self.failed or self.world is None:
            return ExitCode.FAILED  # the world failed
        return self.world.returncode

    def stop(self, signum: int = signal.SIGTERM) -> None:
        """Stop the run as signal `signum` asks (`run` returns soon after, the world told with
        it). Only sets a field: callable from a signal handler or another thread."""
        self.stop_signal = int(signum)
