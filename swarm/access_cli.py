"""`swarm credentials`: hand one identity of a local run to another machine.

A run's own credentials file (in the runtime dir, mode 0600) holds the run's secret, from
which every identity's password is derived (swarm/contracts/credentials.py). This command
writes a file that holds one identity only: an agent's (`--agent ID`: it can act as that
agent and nothing else) or the operator's (`--operator`: what `swarm agents`, `pause`,
`kill`... need on a remote terminal). Copy it over a channel you trust (scp), then on the
other machine: `swarm agent --id ID --connect tcp/HOST:PORT --credentials FILE`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from swarm.live_cli import EXIT_USAGE, RunOpt, fail


def credentials(
    agent: Annotated[Optional[int], typer.Option("--agent", metavar="ID", min=0,
                                                 help="export agent ID's identity", show_default=False)] = None,
    operator: Annotated[bool, typer.Option("--operator", help="export the operator's identity (the live "
                                           "commands: agents, graph, watch, pause, resume, kill)")] = False,
    run: RunOpt = None,
    endpoint: Annotated[Optional[str], typer.Option(
        help="the endpoint the other machine dials, e.g. tls/10.0.0.5:7447 (needed when the run's own "
             "endpoint is a Unix socket or loopback)", show_default=False)] = None,
    out: Annotated[Optional[Path], typer.Option("--out", "-o", help="file to write (mode 0600; default "
                                                "<run>-agent-<ID>.cred or <run>-operator.cred here)",
                                                show_default=False)] = None,
    force: Annotated[bool, typer.Option("--force", help="replace --out if it exists")] = False,
) -> None:
    """Write one identity of a local run to a file, for an agent or a terminal on another machine.

    Example: swarm credentials --agent 3 --endpoint tcp/10.0.0.5:7447 -o agent-3.cred
    """
    from dataclasses import replace

    from swarm.contracts import credentials as C

    if (agent is None) == (not operator):
        raise fail("give one of --agent ID or --operator", EXIT_USAGE)
    user = C.OPERATOR if operator else C.agent_user(agent)
    try:
        own = C.find_local(run)  # the run's own file ($SWARM_CREDENTIALS is for connecting, not this)
        if agent is not None:
            own.check_agent(agent)
        exported = own.export(user)
    except C.CredentialsError as e:
        raise fail(str(e), EXIT_USAGE) from None
    if endpoint is None and _local_only(own.endpoint):
        raise fail(f"run {own.run} is reached at {own.endpoint} from this machine only: give --endpoint, the "
                   "address the other machine dials (e.g. tls/10.0.0.5:7447; start the run with --listen "
                   "tls/0.0.0.0:7447 to be reachable)", EXIT_USAGE)
    if endpoint is not None:
        exported = replace(exported, endpoint=endpoint)
    path = out or Path(f"{own.run}-{user}.cred")
    if path.exists() and not force:
        raise fail(f"{path} exists; pass --force to replace it", EXIT_USAGE)
    try:
        C.write(exported, path)
    except OSError as e:
        raise fail(f"cannot write {path}: {e.strerror or e}", 1) from None
    typer.echo(f"wrote {path} ({user} of run {own.run}, endpoint {exported.endpoint}, mode 0600)")
    if not operator:
        typer.echo(f"on the other machine: swarm agent --id {agent} --connect {exported.endpoint} "
                   f"--credentials {path.name}")


def _local_only(endpoint: str) -> bool:
    proto, _, rest = endpoint.partition("/")
    return proto.startswith("unix") or rest.startswith(("127.", "localhost:", "[::1]:"))


def register(app: typer.Typer) -> None:
    app.command("credentials")(credentials)
