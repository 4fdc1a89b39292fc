"""`swarm host`: an agent host. A zenoh router on this machine, connected to the run's hub
(the world), and this machine's agent processes, connected to that router.

    world machine:  world (hub, router) <──── one link per host (tcp/ or tls/) ────┐
    agent host:     swarm host (router) <── agents 3, 4, 5 (clients, Unix socket) ─┘

zenoh routes router to router, so agents behind it are the same agents as anywhere else;
one link crosses the network per host instead of one per agent. docs/protocol.md, section
13, has the whole story: what goes through, the `host` identity (the hub sees the host
router's link, not the agents behind it, so `host` may do what any agent may) and the
host router's own rules (its agents confined as at the hub; its upstream link, the hub
known by its zenoh id, let through).

In order: find the credentials (from `swarm credentials --host`, or the local run's own),
learn the hub's zenoh id (a short client session), open the router on a private Unix
socket, wait until the world's token is seen through it, give each agent a file with its
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
import socket
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from swarm.contracts import access, credentials, wire
from swarm.contracts.credentials import HOST, CredentialsError, agent_user
from swarm.contracts.laws import ENV_TRUSTED_LAWS, with_trusted_laws
from swarm.contracts.lifeline import LAUNCHER_PID_ENV, endpoint_refuses, exit_status
from swarm.contracts.transport import client_tls, host_router_config, open_client, socket_path
from swarm.procs import Group, wait_until
from swarm.supervision import AgentExitReport, agent_exit

EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_AGENT_FAILED = 0, 1, 2, 4
WORLD_GONE_CODES = (4, 5)  # agent exits: the world vanished, or stopped answering past the grace


class HostError(Exception):
    """The host cannot start; one line, and the exit code."""

    def __init__(self, message: str, code: int = EXIT_FAILED):
        super().__init__(message)
        self.code = code


@dataclass
class HostConfig:
    connect: str | None = None  # the world's endpoint (default: the credentials')
    agents: tuple[int, ...] | None = None  # default: the host file's agents, else the scenario's
    creds_file: Path | None = None  # default: $SWARM_CREDENTIALS, else the local run's own file
    run: str | None = None
    name: str | None = None  # default: the host file's name, else this machine's host name
    listen: str | None = None  # where the agents connect (default: a Unix socket, private dir)
    logs: Path | None = None  # default runs/<run>-host-<name>
    world_grace: float = 10.0
    trust: tuple[str, ...] = ()
    wait: float = 30.0  # s to wait for the world to answer before giving up


def _say(msg: str) -> None:
    print(msg, flush=True)


@dataclass
class Host:
    cfg: HostConfig
    say: Callable[[str], None] = _say
    creds: credentials.Credentials | None = None
    ids: tuple[int, ...] = ()
    name: str = ""
    upstream: str = ""
    local: str = ""  # the router's endpoint for this host's agents
    dir: Path | None = None  # private: the router's socket and the agents' credentials
    logs: Path | None = None
    router: object | None = None
    hub_zid: str | None = None
    group: Group = field(default_factory=Group)
    procs: dict[int, subprocess.Popen] = field(default_factory=dict)
    exits: list[AgentExitReport] = field(default_factory=list)
    stop_signal: int | None = None
    world_gone: bool = False
    world_ended: bool = False  # the world's end notice came (only the world may send one)
    events: queue.SimpleQueue = field(default_factory=queue.SimpleQueue)

    # -- setting up ------------------------------------------------------------------------------
    def prepare(self) -> None:
        """Credentials, agent ids, name, endpoints, directories; HostError says what is wrong."""
        c = self.cfg
        try:
            creds = credentials.find(c.run, c.connect, c.creds_file)
            ids = c.agents or creds.host_agents() or creds.ids
            if not ids:
                raise CredentialsError("no agents to run: give --agents (e.g. 3,4,5 or 3-5)")
            for aid in ids:
                creds.check_agent(aid)
                creds.identity(agent_user(aid))
            if not creds.hub_is_open:
                creds.identity(HOST)
            self.name = credentials.check_host_name(c.name or creds.host or _host_name())
            d = credentials.private_dir(credentials.runtime_dir() / f"{creds.run}-host-{self.name}")
        except CredentialsError as e:
            raise HostError(str(e), EXIT_USAGE) from None
        self.creds, self.ids = creds, tuple(ids)
        self.upstream = c.connect or creds.endpoint
        self.local = c.listen or f"unixsock-stream/{d / 'router.sock'}"
        other = _pid_in(d / "pid")
        if other is not None and other != os.getpid() and credentials.pid_alive(other):
            raise HostError(f"host {self.name} of run {creds.run} is already running here (pid {other}); give "
                            "another --name", EXIT_USAGE)
        sock = socket_path(self.local)
        if sock is not None and sock.exists():
            if not endpoint_refuses(self.local):
                raise HostError(f"{self.local} is in use", EXIT_USAGE)
            sock.unlink()  # left by a host that was killed
        credentials.write_private(d / "pid", f"{os.getpid()}\n".encode())
        self.dir = d  # ours from here on (removed at the end)
        self.logs = c.logs or Path("runs") / f"{creds.run}-host-{self.name}"
        try:
            self.logs.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise HostError(f"cannot create the log directory {self.logs}: {e.strerror or e}", EXIT_USAGE) from None

    def probe_hub(self) -> str:
        """The hub's zenoh id, from a short client session as `host` (retried for cfg.wait s
        until the world answers); the host router lets its upstream link in by that id."""
        creds, run = self.creds, self.creds.run
        found: list[str] = []
        last = ["no answer"]

        def attempt() -> bool:
            if self.stop_signal is not None:
                return True
            try:
                ses = open_client(self.upstream, timeout_ms=1000, creds=creds, user=HOST)
            except Exception as e:  # not up yet, or refused
                last[0] = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
                return False
            try:
                zids = [str(z) for z in ses.info.routers_zid()]
                world = any(r.ok is not None for r in ses.liveliness().get(wire.world_alive_key(run), timeout=1.0))
                if zids and world:
                    found.append(zids[0])
                    return True
                last[0] = f"no world of run {run} there"
                return False
            finally:
                ses.close()

        wait_until(attempt, self.cfg.wait, 0.2)
        if self.stop_signal is not None:
            raise HostError("stopped", 128 + self.stop_signal)
        if not found:
            raise HostError(f"cannot reach the world of run {run} at {self.upstream} as {HOST!r} within "
                            f"{self.cfg.wait:g} s ({last[0]}; no world there, or it refused these credentials)")
        return found[0]

    def open_router(self) -> None:
        import zenoh

        creds, run = self.creds, self.creds.run
        tls = client_tls(creds) if self.upstream.startswith("tls/") else None
        if creds.hub_is_open:  # the hub checks nothing: nor does its host
            cfg = host_router_config(self.local, self.upstream, run, tls=tls)
            self.router = _open(zenoh, cfg, self.local)
        else:
            users = self.dir / "users"  # read once by zenoh at open, then removed
            credentials.write_private(users, access.host_dictionary(
                creds.identity(agent_user(a)) for a in self.ids).encode())
            try:
                cfg = host_router_config(self.local, self.upstream, run, creds.identity(HOST), users,
                                         access.host_router_access(run, self.ids, self.hub_zid), tls)
                self.router = _open(zenoh, cfg, self.local)
            finally:
                users.unlink(missing_ok=True)
        put = self.events.put
        self.router.liveliness().declare_subscriber(wire.world_alive_key(run), lambda s: put(("alive", s.kind)),
                                                    history=True)
        self.router.declare_subscriber(wire.world_control_key(run), lambda s: put(("control", s.payload.to_bytes())))

        def linked() -> bool:
            if self.stop_signal is not None:
                return True
            return any(r.ok is not None for r in
                       self.router.liveliness().get(wire.world_alive_key(run), timeout=0.5))

        if not wait_until(linked, self.cfg.wait, 0.1):
            raise HostError(f"the host router reached no world of run {run} at {self.upstream} within "
                            f"{self.cfg.wait:g} s (did the world restart meanwhile?)")
        if self.stop_signal is not None:
            raise HostError("stopped", 128 + self.stop_signal)

    def agent_file(self, aid: int) -> Path:
        """Agent `aid`'s own identity (nothing else), for dialling this host's router."""
        from dataclasses import replace

        one = replace(self.creds.export(agent_user(aid)), endpoint=self.local, tls_ca=None)
        return credentials.write(one, self.dir / f"agent-{aid}.cred")

    def start_agent(self, aid: int) -> subprocess.Popen:
        env = {**os.environ, LAUNCHER_PID_ENV: str(os.getpid()),  # they stop when the host dies
               credentials.ENV_CREDENTIALS: str(self.agent_file(aid)),
               ENV_TRUSTED_LAWS: with_trusted_laws(self.cfg.trust)}
        with open(self.logs / f"agent-{aid}.log", "ab") as log:
            p = self.group.start([sys.executable, "-m", "agents.process", str(aid), self.local, self.creds.run,
                                  "--world-grace", str(self.cfg.world_grace)],
                                 stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT, env=env)
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
                return e.code if self.stop_signal is None else 128 + self.stop_signal
            run = self.creds.run
            self.say(f"host {self.name}: router on {self.local}, linked to the world of run {run} at "
                     f"{self.upstream} (hub {self.hub_zid[:8]}...)")
            for aid in self.ids:
                self.start_agent(aid)
            self.say(f"host {self.name}: agents {', '.join(f'{a} (pid {p.pid})' for a, p in self.procs.items())}; "
                     f"logs in {self.logs}")
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
            if code != 0 and not quiet:
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
            elif str(value).endswith("DELETE") and not (self.world_gone or self.world_ended) \
                    and self.router is not None and endpoint_refuses(self.upstream):
                self.world_gone = True
                self._close_router()
                self.say(f"host {self.name}: the world of run {self.creds.run} is gone ({self.upstream} "
                         "refuses connections); router closed")

    def stop(self) -> None:
        """The agents first (SIGTERM, SIGKILL 3 s later; every one reaped), then the router;
        the agents' credentials and the router's socket go with it."""
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
            return 128 + self.stop_signal
        if any(r.crash for r in self.exits):
            return EXIT_AGENT_FAILED
        if any(r.code in WORLD_GONE_CODES for r in self.exits):
            return EXIT_FAILED
        return EXIT_OK

    def summary(self) -> str:
        by = {}
        for r in sorted(self.exits, key=lambda r: r.agent):
            by.setdefault(exit_status(r.code), []).append(str(r.agent))
        return "; ".join(f"agent{'s' if len(a) > 1 else ''} {', '.join(a)}: {s}"
                         for s, a in sorted(by.items())) or "no agent started"

    def _on_signal(self, signum, _frame) -> None:
        self.stop_signal = signum


def _pid_in(path: Path) -> int | None:
    try:
        return int(path.read_text().strip())
    except (OSError, ValueError):
        return None


def _host_name() -> str:
    """This machine's host name as a host name of ours (first label, other characters as -)."""
    import re

    name = re.sub(r"[^A-Za-z0-9_.-]", "-", socket.gethostname().split(".")[0])[:32]
    return name or "host"


def _open(zenoh, cfg, local: str):
    try:
        return zenoh.open(cfg)
    except Exception as e:
        raise HostError(f"cannot open the host router on {local}: {str(e).strip().splitlines()[0]}") from None


def run_host(cfg: HostConfig, say: Callable[[str], None] = _say) -> int:
    """Run an agent host to the end; its exit code (see `Host.outcome`)."""
    host = Host(cfg, say)
    code = host.run()
    if host.exits:
        say(f"host {host.name}: {host.summary()}")
    return code
