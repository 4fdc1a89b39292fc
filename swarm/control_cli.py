"""Live commands that act on a run (`swarm kill / spawn / pause / resume`), and how to tell
that a local pid is still the agent's process. Like the read-only ones (swarm/live_cli.py,
whose options and attaching they share), they talk to the run over zenoh; `kill` signals a
process of this machine directly, and `spawn` starts one here.
"""

from __future__ import annotations

import json
import os
import signal as sig
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Annotated, Optional

import typer

from swarm.contracts.credentials import ENV_CREDENTIALS
from swarm.contracts.identities import CredentialsError, agent_user
from swarm.contracts.laws import ENV_TRUSTED_LAWS, with_trusted_laws
from swarm.live_cli import EXIT_USAGE, ConnectOpt, CredentialsOpt, LiveRunOpt, TrustLawOpt, attached, fail
from swarm.procs import wait_until

SPAWN_DEADLINE = 10.0  # s for a spawned agent to show up alive in the world's info
DROP_DEADLINE = 3.0  # s for a signalled agent to be dropped (SIGSTOP: the 1 s link lease)

SIGNALS = {"KILL": sig.SIGKILL, "TERM": sig.SIGTERM, "STOP": sig.SIGSTOP, "CONT": sig.SIGCONT}


def _looks_like_agent(pid: int, agent_id: int) -> bool:
    """Whether local process `pid` is still agent `agent_id`'s (not a reused pid)."""
    try:
        argv = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
    except FileNotFoundError:
        return False
    except OSError:
        return True  # no /proc here: trust the pid
    args = [a.decode(errors="replace") for a in argv]
    if "agents.process" in args:
        k = args.index("agents.process")
        return len(args) > k + 1 and args[k + 1] == str(agent_id)
    if "agent" in args and "--id" in args:
        k = args.index("--id")
        return len(args) > k + 1 and args[k + 1] == str(agent_id)
    return False


def kill(
    agent_id: Annotated[int, typer.Argument(metavar="ID", help="the agent's id", show_default=False)],
    signal: Annotated[str, typer.Option("--signal", "-s", help="KILL | TERM | STOP | CONT")] = "KILL",
    connect: ConnectOpt = None,
    run: LiveRunOpt = None,
    credentials: CredentialsOpt = None,
) -> None:
    """Send a signal (default KILL) to an agent's process.

    On this machine it is os.kill; an agent on another host is asked over zenoh to
    signal itself (so SIGCONT cannot be delivered that way). Waits until the world drops
    the agent (KILL, TERM, STOP) and prints the tick.

    Example: swarm kill 3 --signal STOP
    """
    name = signal.upper().removeprefix("SIG")
    if name not in SIGNALS:
        raise fail(f"--signal {signal!r}: use one of {', '.join(SIGNALS)}", EXIT_USAGE)
    with attached(connect, run, credentials) as live:
        info = live.info()
        a = info["agents"].get(str(agent_id))
        if a is None:
            raise fail(f"agent {agent_id} is not in run {info['run']} "
                       f"(ids: {', '.join(sorted(info['agents'], key=int))})")
        st = live.statuses({agent_id}).get(agent_id) if a["alive"] else None
        pid = (st or a).get("pid")
        host = (st or a).get("host")
        if pid is None:
            raise fail(f"agent {agent_id} has no process (it never joined run {info['run']})")
        # Same host name and the pid is that agent's process (host names can repeat across
        # machines; pids get reused): signal it here, otherwise over zenoh.
        local = host == socket.gethostname() and _looks_like_agent(pid, agent_id)
        if not a["alive"]:
            if host != socket.gethostname():
                raise fail(f"agent {agent_id} is not live (state {a['state']}); it can only be signalled "
                           f"on its own host {host} (kill -{name} {pid})")
            if not local:
                raise fail(f"agent {agent_id} is not live (state {a['state']}) and its process "
                           f"(pid {pid}) is gone")
        if local:
            try:
                os.kill(pid, SIGNALS[name])
            except ProcessLookupError:
                raise fail(f"agent {agent_id}: no process {pid} on this machine") from None
            except PermissionError:
                raise fail(f"agent {agent_id}: not allowed to signal pid {pid}") from None
            how = "sent"
        else:
            if name == "CONT":
                raise fail(f"agent {agent_id} runs on {host}: SIGCONT cannot be delivered over zenoh "
                           f"(a stopped process cannot act on a message); run `kill -CONT {pid}` on {host}")
            live.signal_agent(agent_id, name)
            how = "asked over zenoh to take"
        typer.echo(f"{how} SIG{name} to agent {agent_id} (pid {pid} on {host})")
        if name == "CONT" or not a["alive"]:
            return
        def dropped():
            now = live.info()
            return None if now["agents"][str(agent_id)]["alive"] else now

        now = wait_until(dropped, DROP_DEADLINE, 0.02)
        if not now:
            raise fail(f"agent {agent_id} is still live in the world {DROP_DEADLINE:g} s after SIG{name}")
        typer.echo(f"agent {agent_id} dropped at tick {now['tick']}")


def _last_line(path: Path) -> str:
    try:
        lines = [ln.strip() for ln in path.read_text(errors="replace").splitlines() if ln.strip()]
    except OSError:
        return ""
    return lines[-1] if lines else ""


def spawn(
    agent_id: Annotated[int, typer.Option("--id", help="the agent's id: a dropped one rejoins from "
                                          "where it dropped; a new one needs --x --y --heading --speed",
                                          min=0, show_default=False)],
    x: Annotated[Optional[float], typer.Option(help="new agent: x (m)", show_default=False)] = None,
    y: Annotated[Optional[float], typer.Option(help="new agent: y (m)", show_default=False)] = None,
    heading: Annotated[Optional[float], typer.Option(help="new agent: heading (rad)", show_default=False)] = None,
    speed: Annotated[Optional[float], typer.Option(help="new agent: speed (m/s)", show_default=False)] = None,
    role: Annotated[Optional[str], typer.Option(help="new agent: leader | follower [default: follower]",
                                                show_default=False)] = None,
    orbit_radius: Annotated[Optional[float], typer.Option(help="new leader: orbit radius (m)",
                                                          show_default=False)] = None,
    direction: Annotated[Optional[str], typer.Option(help="new leader: ccw | cw [default: ccw]",
                                                     show_default=False)] = None,
    follow: Annotated[Optional[int], typer.Option(help="new follower: fixed out-neighbour id",
                                                  show_default=False)] = None,
    max_turn_rate: Annotated[Optional[float], typer.Option(help="new agent: turn-rate limit (rad/s)",
                                                           show_default=False)] = None,
    connect: ConnectOpt = None,
    run: LiveRunOpt = None,
    credentials: CredentialsOpt = None,
    trust_law: TrustLawOpt = None,
) -> None:
    """Start an agent process on this machine (detached) and wait until it is live.

    A dropped id rejoins from the pose it had; a new id joins the run with the given spec
    (new ids: the range `swarm check` shows for the scenario, up to run.max_added_agents).
    Its output goes to a log file in the runtime dir.

    Example: swarm spawn --id 7 --x 10 --y -5 --heading 0 --speed 20 --follow 1
    """
    from pydantic import ValidationError

    from swarm.contracts.scenario import format_validation_error
    from swarm.contracts.scenario_tables import AgentSpec
    from swarm.contracts.transport import runtime_dir

    given = {k: v for k, v in dict(x=x, y=y, heading=heading, speed=speed, role=role, orbit_radius=orbit_radius,
                                   direction=direction, follow=follow, max_turn_rate=max_turn_rate).items()
             if v is not None}
    with attached(connect, run, credentials) as live:
        info = live.info()
        ref = live.ref
        spec = None
        if str(agent_id) in info["agents"]:
            if given:
                raise fail(f"agent {agent_id} is already in run {ref.run}: it rejoins from where it dropped; "
                           f"--{'/--'.join(k.replace('_', '-') for k in given)} only apply to a new id",
                           EXIT_USAGE)
        else:
            lo, hi = info.get("added_ids", (None, None))
            if lo is not None and not lo <= agent_id <= hi:
                raise fail(f"--id {agent_id}: agents added to run {ref.run} take ids {lo}..{hi} "
                           "(the hub's access rules are made for those ids before the run starts)", EXIT_USAGE)
            if info.get("added", 0) >= info.get("max_added", float("inf")):
                raise fail(f"run {ref.run} has added {info['added']} agents already, its limit "
                           "(run.max_added_agents in the scenario)", EXIT_USAGE)
            spec = {"role": "follower", **given}
            try:
                AgentSpec.model_validate({**spec, "id": agent_id})
            except ValidationError as e:
                msg = format_validation_error(f"agent {agent_id}", e).splitlines()
                raise fail(f"{msg[0].replace('invalid scenario', 'invalid spec')}: "
                           f"{'; '.join(m.strip() for m in msg[1:])} (a new agent needs --x --y --heading --speed)",
                           EXIT_USAGE) from None
            if follow is not None and str(follow) not in info["agents"]:
                raise fail(f"--follow {follow}: no agent has that id in run {ref.run}", EXIT_USAGE)
        logs = runtime_dir() / "logs"
        logs.mkdir(mode=0o700, parents=True, exist_ok=True)
        log_path = logs / f"{ref.run}-agent-{agent_id}-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}.log"
        args = [sys.executable, "-m", "agents.process", str(agent_id), ref.endpoint, ref.run]
        if spec is not None:
            args.append(json.dumps(spec))
        try:  # the agent connects as itself: the run's own file, or one of agent_id's
            ref.creds.identity(agent_user(agent_id))
        except CredentialsError as e:
            raise fail(f"swarm spawn needs the run's own credentials (on the run's machine) or a file from "
                       f"`swarm credentials --agent {agent_id}`: {e}", EXIT_USAGE) from None
        env = {**os.environ, ENV_TRUSTED_LAWS: with_trusted_laws(trust_law or [])}
        if ref.creds.path is not None:
            env[ENV_CREDENTIALS] = str(Path(ref.creds.path).resolve())
        with open(log_path, "ab") as log:
            proc = subprocess.Popen(args, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
                                    start_new_session=True, close_fds=True, env=env)
        def started():
            rc = proc.poll()
            if rc is not None:
                return ("exited", rc)
            a = live.info()["agents"].get(str(agent_id))
            return ("live", 0) if a is not None and a["alive"] and a["pid"] == proc.pid else None

        got = wait_until(started, SPAWN_DEADLINE, 0.05)
        if got and got[0] == "live":
            typer.echo(f"agent {agent_id} is live: pid {proc.pid} (log {log_path})")
            return
        if got:
            why = _last_line(log_path) or "no output"
            raise fail(f"agent {agent_id} did not start (exit {got[1]}): {why.removeprefix('swarm agent: ')}")
        proc.terminate()
        try:
            proc.wait(timeout=3)
        except subprocess.TimeoutExpired:
            proc.kill()
        raise fail(f"agent {agent_id} (pid {proc.pid}) did not join within {SPAWN_DEADLINE:g} s; "
                   f"stopped it (log {log_path})")


def _clock(connect: str | None, run: str | None, credentials: Path | None, cmd: str, done: str) -> None:
    with attached(connect, run, credentials) as live:
        rep = live.admin(cmd)
        typer.echo(f"run {live.ref.run} {done} at tick {rep.get('tick')}")


def pause(connect: ConnectOpt = None, run: LiveRunOpt = None, credentials: CredentialsOpt = None) -> None:
    """Pause the world's clock and print the tick it stopped at.

    Agents stay connected; no tick happens until `swarm resume`.

    Example: swarm pause --run case2-1a2b3c
    """
    _clock(connect, run, credentials, "pause", "paused")


def resume(connect: ConnectOpt = None, run: LiveRunOpt = None, credentials: CredentialsOpt = None) -> None:
    """Resume the world's clock after `swarm pause` and print the tick.

    Example: swarm resume --run case2-1a2b3c
    """
    _clock(connect, run, credentials, "resume", "resumed")


def register(app: typer.Typer) -> None:
    """Add the acting live commands to the main app."""
    app.command("kill")(kill)
    app.command("spawn")(spawn)
    app.command("pause")(pause)
    app.command("resume")(resume)
