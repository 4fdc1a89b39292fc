"""`swarm host`: an agent host. A zenoh router on this machine, connected to the run's hub
(the world), and this machine's agent processes, connected to that router.

    world machine:  world (hub, router) <──── one link per host (tcp/ or tls/) ────┐
    agent host:     swarm host (router) <── agents 3, 4, 5 (clients, Unix socket) ─┘

zenoh routes router to router, so agents behind it are the same agents as anywhere else;
one link crosses the network per host instead of one per agent. docs/reference/protocol.md#hosts
has the whole story: what goes through, the `host` identity (the hub sees the host
router's link, not the agents behind it, so `host` may do what any agent may) and the
host router's own rules (its agents confined as at the hub; its upstream link, the hub
known by its zenoh id, let through).

In order: set up (swarm/runtime/host_setup.py: the credentials, the hub's zenoh id, the router
on a private Unix socket, linked to the world), give each agent a file with its
own identity only and start them (one process group; they die with the host, even if it
is killed), then supervise: one line per exit; a world gone (no end notice, its token
vanished, its endpoint refusing) closes the router, so the agents' endpoint refuses too
and they exit 4 at once as direct agents do. Ctrl-C / SIGTERM stops the agents (SIGTERM,
SIGKILL 3 s later), then the router; nothing is left.
"""

from __future__ import annotations

import os
import queue
import shutil
import signal
import subprocess
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import zenoh

from swarm.contracts import credentials, wire
from swarm.contracts.identities import agent_user
from swarm.contracts.laws import ENV_TRUSTED_LAWS, with_trusted_laws
from swarm.contracts.lifeline import LAUNCHER_PID_ENV, endpoint_refuses, exit_status
from swarm.contracts.vocabulary import ExitCode, signal_exit
from swarm.runtime.forks import AgentStarter
from swarm.runtime.host_setup import HostConfig, HostError, HostSetup
from swarm.runtime.procs import Group
from swarm.runtime.supervision import AgentExitReport, agent_exit

# agent exits: the world vanished, or stopped answering past the grace
WORLD_GONE_CODES = (ExitCode.WORLD_GONE, ExitCode.WORLD_SILENT)


def _say(msg: str) -> None:
    print(msg, flush=True)


@dataclass
class Host(HostSetup):
    cfg: HostConfig
    say: Callable[[str], None] = _say
    creds: credentials.Credentials = field(init=False, repr=False)  # (HostSetup.prepare)
    ids: tuple[int, ...] = ()
    name: str = ""
    upstream: str = ""
    local: str = ""  # the router's endpoint for this host's agents
    dir: Path | None = None  # private: the router's socket and the agents' credentials
    logs: Path = field(init=False, repr=False)  # (HostSetup.prepare)
    router: zenoh.Session | None = None
    hub_zid: str = ""
    group: Group = field(default_factory=Group)
    procs: dict[int, subprocess.Popen] = field(default_factory=dict)
    starter: AgentStarter | None = None
    exits: list[AgentExitReport] = field(default_factory=list)
    stop_signal: int | None = None
    world_gone: bool = False
    world_ended: bool = False  # the world's end notice came (only the world may send one)
    events: queue.SimpleQueue = field(default_factory=queue.SimpleQueue)

    # -- the agents (after HostSetup: credentials, router) ----------------------------------------
    def agent_file(self, aid: int) -> Path:
        """Agent `aid`'s own identity (nothing else), for dialling this host's router."""
        one = replace(self.creds.export(agent_user(aid)), endpoint=self.local, tls_ca=None)
        return credentials.write(one, self.private_dir() / f"agent-{aid}.cred")

    def start_agent(self, aid: int) -> subprocess.Popen:
        if self.starter is None:  # forked by a fork server where it can (swarm/runtime/forks.py)
            env = {
                **os.environ,
                LAUNCHER_PID_ENV: str(os.getpid()),  # they stop when the host dies
                ENV_TRUSTED_LAWS: with_trusted_laws(self.cfg.trust),
            }
            self.starter = AgentStarter(self.group, env, self.logs, lambda m: self.say(f"swarm host: {m}"))
        p = self.starter.start(
            [str(aid), self.local, self.creds.run, "--world-grace", str(self.cfg.world_grace)],
            f"agent-{aid}.log",
            {credentials.ENV_CREDENTIALS: str(self.agent_file(aid))},
        )
        self.procs[aid] = p
        return p

    # -- running ---------------------------------------------------------------------------------
    def run(self) -> int:
        handlers = {sig: signal.signal(sig, self._on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
        try:
            try:
                self.prepare()
                self.hub_zid = self.probe_hub()
                self.open_router()
            except HostError as e:
                if self.stop_signal is None:
                    self.say(f"swarm host: {e}")
                return e.code if self.stop_signal is None else signal_exit(self.stop_signal)
            run = self.creds.run
            self.say(
                f"host {self.name}: router on {self.local}, linked to the world of run {run} at "
                f"{self.upstream} (hub {self.hub_zid[:8]}...)"
            )
            for aid in self.ids:
                self.start_agent(aid)
            self.say(
                f"host {self.name}: agents {', '.join(f'{a} (pid {p.pid})' for a, p in self.procs.items())}; "
                f"logs in {self.logs}"
            )
            while self.stop_signal is None:
                self.supervise()
                if all(p.poll() is not None for p in self.procs.values()):
                    break
                self.watch_world()
                time.sleep(0.1)
        finally:
            self.stop()
            for sig, h in handlers.items():
                signal.signal(sig, h)
        return self.outcome()

    def supervise(self, quiet: bool = False) -> None:
        """One line for each agent process that exited since the last look (quiet: the host
        stopped them; the last line sums them up)."""
        seen = {r.pid for r in self.exits}
        for aid, p in self.procs.items():
            code = p.poll()
            if code is None or p.pid in seen:
                continue
            r = agent_exit(aid, p.pid, code, self.logs / f"agent-{aid}.log", before_start=False)
            self.exits.append(r)
            if code != ExitCode.OK and not quiet:
                self.say(f"host {self.name}: {r.line()}")

    def watch_world(self) -> None:
        """The world's token vanished, its endpoint refuses, and it sent no end notice: the
        world is gone (killed). Closing the router makes the agents' own endpoint refuse, so
        they exit 4 at once (otherwise they would take a silent world, and wait out their
        grace). After an end notice the router stays until the agents have taken it."""
        while True:
            try:
                what, value = self.events.get_nowait()
            except queue.Empty:
                return
            if what == "control":
                try:
                    self.world_ended = self.world_ended or isinstance(wire.decode_control(value), int)
                except wire.WireError:
                    pass
            elif (
                str(value).endswith("DELETE")
                and not (self.world_gone or self.world_ended)
                and self.router is not None
                and endpoint_refuses(self.upstream)
            ):
                self.world_gone = True
                self._close_router()
                self.say(
                    f"host {self.name}: the world of run {self.creds.run} is gone ({self.upstream} "
                    "refuses connections); router closed"
                )

    def stop(self) -> None:
        """The agents first (SIGTERM, SIGKILL 3 s later; every one reaped), then the router;
        the agents' credentials and the router's socket go with it."""
        if self.starter is not None:
            self.starter.close()
        if self.procs:
            self.group.stop(grace=3.0)
            self.supervise(quiet=True)
        self._close_router()
        if self.dir is not None:
            shutil.rmtree(self.dir, ignore_errors=True)

    def _close_router(self) -> None:
        r, self.router = self.router, None
        if r is not None:
            r.close()

    def outcome(self) -> int:
        """Exit code: 128+signal when stopped; 4 when an agent failed (a crash: an exception,
        refused); 1 when the world went away before the run ended; otherwise 0."""
        if self.stop_signal is not None:
            return signal_exit(self.stop_signal)
        if any(r.crash for r in self.exits):
            return ExitCode.AGENT_FAILED
        if any(r.code in WORLD_GONE_CODES for r in self.exits):
            return ExitCode.FAILED
        return ExitCode.OK

    def summary(self) -> str:
        by: dict[str, list[str]] = {}
        for r in sorted(self.exits, key=lambda r: r.agent):
            by.setdefault(exit_status(r.code), []).append(str(r.agent))
        return (
            "; ".join(f"agent{'s' if len(a) > 1 else ''} {', '.join(a)}: {s}" for s, a in sorted(by.items()))
            or "no agent started"
        )

    def _on_signal(self, signum, _frame) -> None:
        self.stop_signal = signum


def run_host(cfg: HostConfig, say: Callable[[str], None] = _say) -> int:
    """Run an agent host to the end; its exit code (see `Host.outcome`)."""
    host = Host(cfg, say)
    code = host.run()
    if host.exits:
        say(f"host {host.name}: {host.summary()}")
    return code
