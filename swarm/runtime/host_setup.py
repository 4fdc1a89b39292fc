"""Setting up an agent host (swarm/runtime/host.py), before any of its agents starts.

In order: find the credentials (from `swarm credentials --host`, or the local run's own)
and check that they hold every identity the host needs, claim a private directory (the
router's socket, the agents' files) that no other host of the same name and run is
using, learn the hub's zenoh id (a short client session as `host`), then open the router
on its Unix socket, with its own rules (its agents confined as at the hub, its upstream
link let in by the hub's zenoh id), and wait until the world's token is seen through it.
A mixin of `Host`, whose state it fills in; `HostError` says what is wrong, in one line.
"""

from __future__ import annotations

import os
import queue
import re
import socket
from dataclasses import dataclass
from pathlib import Path

import zenoh

from swarm.contracts import access, credentials, wire
from swarm.contracts.identities import HOST, CredentialsError, agent_user, check_host_name
from swarm.contracts.lifeline import endpoint_refuses
from swarm.contracts.runtime_dir import pid_alive, private_dir, runtime_dir, write_private
from swarm.contracts.transport import client_tls, host_router_config, open_client, socket_path
from swarm.contracts.vocabulary import ExitCode, signal_exit
from swarm.runtime.procs import wait_until


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


class HostError(Exception):
    """The host cannot start; one line, and the exit code."""

    def __init__(self, message: str, code: int = ExitCode.FAILED):
        super().__init__(message)
        self.code = code


class HostSetup:
    """What `Host` does before its agents start (a mixin: the state is Host's)."""

    # Host's state (swarm/runtime/host.py) that these steps read or fill in
    cfg: HostConfig
    creds: credentials.Credentials  # from prepare() on
    ids: tuple[int, ...]
    name: str
    upstream: str
    local: str
    dir: Path | None  # from prepare() on
    logs: Path  # from prepare() on
    router: zenoh.Session | None
    hub_zid: str  # from probe_hub() on
    stop_signal: int | None
    events: queue.SimpleQueue

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
            self.name = check_host_name(c.name or creds.host or _host_name())
            d = private_dir(runtime_dir() / f"{creds.run}-host-{self.name}")
        except CredentialsError as e:
            raise HostError(str(e), ExitCode.USAGE) from None
        self.creds, self.ids = creds, tuple(ids)
        self.upstream = c.connect or creds.endpoint
        self.local = c.listen or f"unixsock-stream/{d / 'router.sock'}"
        other = _pid_in(d / "pid")
        if other is not None and other != os.getpid() and pid_alive(other):
            raise HostError(
                f"host {self.name} of run {creds.run} is already running here (pid {other}); give another --name",
                ExitCode.USAGE,
            )
        sock = socket_path(self.local)
        if sock is not None and sock.exists():
            if not endpoint_refuses(self.local):
                raise HostError(f"{self.local} is in use", ExitCode.USAGE)
            sock.unlink()  # left by a host that was killed
        write_private(d / "pid", f"{os.getpid()}\n".encode())
        self.dir = d  # ours from here on (removed at the end)
        self.logs = c.logs or Path("runs") / f"{creds.run}-host-{self.name}"
        try:
            self.logs.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise HostError(f"cannot create the log directory {self.logs}: {e.strerror or e}", ExitCode.USAGE) from None

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
            raise HostError("stopped", signal_exit(self.stop_signal))
        if not found:
            raise HostError(
                f"cannot reach the world of run {run} at {self.upstream} as {HOST!r} within "
                f"{self.cfg.wait:g} s ({last[0]}; no world there, or it refused these credentials)"
            )
        return found[0]

    def private_dir(self) -> Path:
        """The host's private directory (claimed by prepare())."""
        if self.dir is None:
            raise HostError("the host has no private directory (prepare() first)")
        return self.dir

    def open_router(self) -> None:
        creds, run = self.creds, self.creds.run
        tls = client_tls(creds) if self.upstream.startswith("tls/") else None
        if creds.hub_is_open:  # the hub checks nothing: nor does its host
            cfg = host_router_config(self.local, self.upstream, run, tls=tls)
            router = _open(cfg, self.local)
        else:
            users = self.private_dir() / "users"  # read once by zenoh at open, then removed
            write_private(users, access.host_dictionary(creds.identity(agent_user(a)) for a in self.ids).encode())
            try:
                cfg = host_router_config(
                    self.local,
                    self.upstream,
                    run,
                    creds.identity(HOST),
                    users,
                    access.host_router_access(run, self.ids, self.hub_zid),
                    tls,
                )
                router = _open(cfg, self.local)
            finally:
                users.unlink(missing_ok=True)
        self.router = router
        put = self.events.put
        router.liveliness().declare_subscriber(
            wire.world_alive_key(run), lambda s: put(("alive", s.kind)), history=True
        )
        router.declare_subscriber(wire.world_control_key(run), lambda s: put(("control", s.payload.to_bytes())))

        def linked() -> bool:
            if self.stop_signal is not None:
                return True
            return any(r.ok is not None for r in router.liveliness().get(wire.world_alive_key(run), timeout=0.5))

        if not wait_until(linked, self.cfg.wait, 0.1):
            raise HostError(
                f"the host router reached no world of run {run} at {self.upstream} within "
                f"{self.cfg.wait:g} s (did the world restart meanwhile?)"
            )
        if self.stop_signal is not None:
            raise HostError("stopped", signal_exit(self.stop_signal))


def _pid_in(path: Path) -> int | None:
    try:
        return int(path.read_text().strip())
    except (OSError, ValueError):
        return None


def _host_name() -> str:
    """This machine's host name as a host name of ours (first label, other characters as -)."""
    name = re.sub(r"[^A-Za-z0-9_.-]", "-", socket.gethostname().split(".")[0])[:32]
    return name or "host"


def _open(cfg: zenoh.Config, local: str) -> zenoh.Session:
    try:
        return zenoh.open(cfg)
    except Exception as e:
        raise HostError(f"cannot open the host router on {local}: {str(e).strip().splitlines()[0]}") from None
