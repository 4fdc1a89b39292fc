"""`swarm credentials`: hand one identity of a local run to another machine.

A run's own credentials file (in the runtime dir, mode 0600) holds the run's secret, from
which every identity's password is derived (swarm/contracts/credentials.py). This command
writes a file that holds one identity only: an agent's (`--agent ID`: it can act as that
agent and nothing else) or the operator's (`--operator`: what `swarm agents`, `pause`,
`kill`... need on a remote terminal) or an agent host's (`--host NAME --agents 3-5`: the
run's `host` identity, which its router connects with, and the identities of the agents it
runs; swarm/runtime/host.py). Copy it over a channel you trust (scp), then on the other machine:
`swarm agent --id ID --credentials FILE`, or `swarm host --credentials FILE`.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Annotated, Optional

import typer

from swarm.cli.errors import fail
from swarm.cli.options import RunOpt
from swarm.contracts import credentials as C
from swarm.contracts.identities import OPERATOR, CredentialsError, agent_user
from swarm.contracts.vocabulary import ExitCode
from swarm.contracts.wire import MAX_AGENT_ID


def credentials(
    agent: Annotated[
        Optional[int],
        typer.Option(
            "--agent", metavar="ID", min=0, max=MAX_AGENT_ID, help="export agent ID's identity", show_default=False
        ),
    ] = None,
    operator: Annotated[
        bool,
        typer.Option(
            "--operator",
            help="export the operator's identity (the live commands: agents, graph, watch, pause, resume, kill)",
        ),
    ] = False,
    host: Annotated[
        Optional[str],
        typer.Option(
            "--host",
            metavar="NAME",
            help="export what agent host NAME needs for `swarm host` (with --agents)",
            show_default=False,
        ),
    ] = None,
    agents: Annotated[
        Optional[str],
        typer.Option(
            "--agents", metavar="IDS", help="with --host: the agents it runs, e.g. 3,4,5 or 3-5", show_default=False
        ),
    ] = None,
    run: RunOpt = None,
    endpoint: Annotated[
        Optional[str],
        typer.Option(
            help="the endpoint the other machine dials, e.g. tls/10.0.0.5:7447 (needed when the run's own "
            "endpoint is a Unix socket or loopback)",
            show_default=False,
        ),
    ] = None,
    out: Annotated[
        Optional[Path],
        typer.Option(
            "--out",
            "-o",
            help="file to write (mode 0600; default "
            "<run>-agent-<ID>.cred, <run>-operator.cred or "
            "<run>-host-<NAME>.cred here)",
            show_default=False,
        ),
    ] = None,
    force: Annotated[bool, typer.Option("--force", help="replace --out if it exists")] = False,
) -> None:
    """Write one identity of a local run to a file, for an agent, a terminal or an agent host on another machine.

    Example: swarm credentials --agent 3 --endpoint tcp/10.0.0.5:7447 -o agent-3.cred
    (an agent host: swarm credentials --host a --agents 3-5 --endpoint tls/10.0.0.5:7447 -o host-a.cred)
    """
    if sum((agent is not None, operator, host is not None)) != 1:
        raise fail("give one of --agent ID, --operator or --host NAME --agents IDS", ExitCode.USAGE)
    if (host is None) != (agents is None):
        raise fail("--host NAME goes with --agents IDS (the agents that host runs, e.g. 3-5)", ExitCode.USAGE)
    user = OPERATOR if operator else agent_user(agent) if agent is not None else f"host-{host}"
    try:
        own = C.find_local(run)  # the run's own file ($SWARM_CREDENTIALS is for connecting, not this)
        if host is not None:
            assert agents is not None  # (--host goes with --agents: checked above)
            exported = own.export_host(host, C.parse_ids(agents))
        else:
            if agent is not None:
                own.check_agent(agent)
            exported = own.export(user)
    except CredentialsError as e:
        raise fail(str(e), ExitCode.USAGE) from None
    if endpoint is None and _local_only(own.endpoint):
        raise fail(
            f"run {own.run} is reached at {own.endpoint} from this machine only: give --endpoint, the "
            "address the other machine dials (e.g. tls/10.0.0.5:7447; start the run with --listen "
            "tls/0.0.0.0:7447 to be reachable)",
            ExitCode.USAGE,
        )
    if endpoint is not None:
        exported = replace(exported, endpoint=endpoint)
    path = out or Path(f"{own.run}-{user}.cred")
    if path.exists() and not force:
        raise fail(f"{path} exists; pass --force to replace it", ExitCode.USAGE)
    try:
        C.write(exported, path)
    except OSError as e:
        raise fail(f"cannot write {path}: {e.strerror or e}", ExitCode.FAILED) from None
    what = user if host is None else f"host {host} with agents {', '.join(map(str, exported.host_agents() or ()))}"
    typer.echo(f"wrote {path} ({what} of run {own.run}, endpoint {exported.endpoint}, mode 0600)")
    if host is not None:
        typer.echo(f"on the other machine: swarm host --credentials {path.name}")
    elif not operator:
        typer.echo(
            f"on the other machine: swarm agent --id {agent} --connect {exported.endpoint} --credentials {path.name}"
        )


def _local_only(endpoint: str) -> bool:
    proto, _, rest = endpoint.partition("/")
    return proto.startswith("unix") or rest.startswith(("127.", "localhost:", "[::1]:"))


def register(app: typer.Typer) -> None:
    app.command("credentials")(credentials)
