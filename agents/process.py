"""One agent process: one unicycle's brain on the bus.

Connects to the run's endpoint as a client (as `agent-<id>`, with the run's credentials),
claims its id with the world's join query (which also hands it its configuration: only
the id is needed), and hands the session to its `AgentNode` (agents/node.py), which
answers each of its own sensor frames with a command. Started by `swarm up`, it also
stops when the launcher dies (swarm/contracts/lifeline.py). Exit codes: 0 the run ended,
1 crashed (an exception, e.g. in a follower law: the traceback is the last thing in its
output), 3 refused (id live, unknown, no usable credentials, unusable configuration),
4 the world vanished, 5 the world did not answer within the grace, 6 no world to join
(started before its world: nothing listens on the endpoint, or no world of the run answers),
128+signal when stopped by a signal. Before it has joined, every way of ending is one line
on stderr (a signal while it connects included), never a traceback.
"""

from __future__ import annotations

import json
import logging
import os
import re
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any

from swarm.agents.joining import AgentExit, claim
from swarm.agents.node import AgentNode
from swarm.contracts import credentials
from swarm.contracts import log as logs
from swarm.contracts.identities import CredentialsError, agent_user
from swarm.contracts.laws import trusted_laws
from swarm.contracts.lifeline import LAUNCHER_PID_ENV, endpoint_refuses, tie_to_launcher
from swarm.contracts.stop_signals import StopSignals
from swarm.contracts.transport import CONNECT_TIMEOUT_MS, open_client
from swarm.contracts.vocabulary import ExitCode, signal_exit

log = logging.getLogger(__name__)
WORLD_GRACE = 10.0  # s an agent waits for a world that stopped answering (--world-grace)
# Started by `swarm up`, an agent waits longer for its connection: hundreds of agents starting
# at once on two cores (and the world admitting them) took more than the 10 s of a lone one.
LAUNCHED_CONNECT_TIMEOUT_MS = 60_000
_RUST_SOURCE = re.compile(r"\s+at /\S+?\.rs:\d+\.?")  # zenoh errors name their source line: not for users


def _stopped(signum: int) -> AgentExit:
    return AgentExit(signal_exit(signum), "")


def run_agent(
    agent_id: int,
    connect: str,
    run: str | None = None,
    wait_world: bool = False,
    spec: dict | None = None,
    world_grace: float = WORLD_GRACE,
    creds_file: Path | None = None,
    trust: tuple[str, ...] = (),
    world_wait: float = CONNECT_TIMEOUT_MS / 1000,
) -> int:
    """Entry point of an agent process; returns its exit code. It connects as `agent-<id>`
    with the run's credentials (`creds_file`, else $SWARM_CREDENTIALS, else the local run's
    file in the runtime directory) and imports only a law that is built in or trusted."""
    # SIGTERM/SIGINT raise AgentExit, held back while the session opens: once open, it is
    # closed however the agent ends (an open one hangs the exit: swarm/contracts/stop_signals.py)
    logs.setup(f"agent {agent_id}")  # "[agent 3] ..." notes, "swarm agent 3: ..." errors
    stops = StopSignals(_stopped).install()
    session = None
    code: int = ExitCode.FAILED  # a crash, unless it ends otherwise
    try:
        try:
            tie_to_launcher()  # started by `swarm up`: SIGTERM when the launcher dies
            with stops.held():  # a signal meanwhile is raised once `session` holds the session
                opened = _connect(agent_id, connect, run, creds_file, world_wait, stops)
                if isinstance(opened, int):
                    return opened
                session, creds = opened
        except AgentExit as e:  # a signal before it joined
            name = signal.Signals(e.code - 128).name
            log.error("stopped by %s while connecting to %s", name, connect)
            code = e.code
            return code
        run = run or creds.run
        reply = claim(session, run, agent_id, spec=spec)
        log.debug("joined run %s through %s (pid %d)", run, connect, os.getpid())
        node = AgentNode(session, run, agent_id, reply, wait_world, connect, world_grace, trusted_laws(trust))
        node.open()
        code = node.loop()
    except AgentExit as e:
        if e.message:
            log.error("swarm agent: %s", e.message, extra=logs.VERBATIM)  # (the message names the agent)
        code = e.code
    except Exception:  # a bug, or an exception in a follower law: the traceback ends the log
        import traceback  # lazy: only a crash needs it (an agent process imports little)

        log.error("%s", traceback.format_exc().rstrip(), extra=logs.VERBATIM)
    finally:
        stops.ignore()
        if session is not None:
            _close(session, code)
    return code


def _connect(
    agent_id: int, connect: str, run: str | None, creds_file: Path | None, world_wait: float, stops: StopSignals
) -> Any:
    """(session, credentials) of agent `agent_id` on `connect`, or the exit code, said in one
    line: ExitCode.NO_WORLD when nothing listens there (started before its world, which it waits
    for as long as a connection may take), ExitCode.REFUSED when there are no usable credentials
    or what listens there refuses the session. Called with the stop signals held: a signal
    while it waits for a world ends the wait at once, one in the open as the open ends."""
    t_end = time.monotonic() + world_wait  # a world starting meanwhile is waited for
    while endpoint_refuses(connect):  # no socket file, or a refused connection: no world (yet)
        stops.check()
        if time.monotonic() > t_end:
            log.error(
                "no world at %s: nothing listened there for %g s (start the run first: swarm up, or swarm world)",
                connect,
                world_wait,
            )
            return ExitCode.NO_WORLD
        time.sleep(0.1)
    user = agent_user(agent_id)
    try:
        creds = credentials.find(run, connect, creds_file)
        creds.check_agent(agent_id)
        creds.identity(user)
    except CredentialsError as e:
        log.error("%s", e)
        return ExitCode.REFUSED
    launched = bool(os.environ.get(LAUNCHER_PID_ENV))
    try:
        # a stop while it connects is raised as the open returns or fails (zenoh.open runs to
        # its connect timeout); a session it had just made, with nothing declared, just goes
        session = stops.interruptible(
            open_client,
            connect,
            LAUNCHED_CONNECT_TIMEOUT_MS if launched else CONNECT_TIMEOUT_MS,
            creds=creds,
            user=user,
        )
    except Exception as e:
        why = " ".join(_RUST_SOURCE.sub("", str(e)).split())
        log.error(
            "cannot connect to %s as %s of run %s: %s (something listens there, but it refused these "
            "credentials or is not this run's world)",
            connect,
            user,
            creds.run,
            why,
        )
        return ExitCode.REFUSED
    return session, creds


def _close(session: Any, code: int) -> None:
    """Close the session, but exit with `code` anyway if that takes more than a moment: with a
    silent hub, zenoh's close waits for its reconnection attempt (up to ~10 s)."""

    def force() -> None:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)

    t = threading.Timer(1.0 if code == ExitCode.WORLD_SILENT else 3.0, force)
    t.daemon = True
    t.start()
    session.close()
    t.cancel()


def main(argv: list[str] | None = None) -> None:
    """Lean entry for launchers (no typer/rich):
    `python -m swarm.agents.process ID ENDPOINT [RUN [SPEC_JSON]] [--world-grace S]`."""
    args = list(sys.argv[1:] if argv is None else argv)
    grace = WORLD_GRACE
    if "--world-grace" in args:
        i = args.index("--world-grace")
        grace = float(args[i + 1])
        del args[i : i + 2]
    spec = json.loads(args[3]) if len(args) > 3 else None
    sys.exit(
        run_agent(int(args[0]), args[1], args[2] if len(args) > 2 and args[2] else None, spec=spec, world_grace=grace)
    )


if __name__ == "__main__":
    main()
