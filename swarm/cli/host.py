"""`swarm host`: run some agents of a run on this machine, behind a zenoh router of its own
connected to the run's world (swarm/runtime/host.py; docs/guides/several-machines.md#hosts)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from swarm.cli.errors import fail
from swarm.cli.options import CredentialsOpt, RunOpt, TrustLawOpt
from swarm.contracts.credentials import parse_ids
from swarm.contracts.identities import CredentialsError
from swarm.contracts.vocabulary import ExitCode


def host(
    connect: Annotated[
        Optional[str],
        typer.Option(
            help="the world's endpoint, e.g. tls/10.0.0.5:7447 (default: the one in the credentials)",
            show_default=False,
        ),
    ] = None,
    agents: Annotated[
        Optional[str],
        typer.Option(
            help="the agent ids to run here, e.g. 3,4,5 or 3-5 (default: those of the credentials file from "
            "`swarm credentials --host`, or every agent of a local run)",
            show_default=False,
        ),
    ] = None,
    credentials: CredentialsOpt = None,
    run: RunOpt = None,
    name: Annotated[
        Optional[str],
        typer.Option(
            help="this host's name (default: the one in the credentials, else the machine's host name)",
            show_default=False,
        ),
    ] = None,
    listen: Annotated[
        Optional[str],
        typer.Option(
            help="where this host's agents reach its router (default: a Unix socket in $SWARM_RUNTIME_DIR "
            "or /tmp/swarm-<uid>)",
            show_default=False,
        ),
    ] = None,
    logs: Annotated[
        Optional[Path], typer.Option(help="the agents' logs (default runs/<run>-host-<name>)", show_default=False)
    ] = None,
    world_grace: Annotated[
        float, typer.Option(help="s the agents wait for a world that stopped answering", min=0.0)
    ] = 10.0,
    wait: Annotated[float, typer.Option(help="s to wait for the world to answer before giving up", min=0.0)] = 30.0,
    trust_law: TrustLawOpt = None,
) -> None:
    """Run agents of a run on this machine, behind a zenoh router of this host's own.

    Opens a router here (a Unix socket for this machine's agents), connected to the run's
    world as the run's `host` identity, starts one agent process per id, and supervises
    them until the run ends; Ctrl-C or SIGTERM stops them, leaving nothing behind.

    Exit codes: 0 the run ended, 1 no world to reach (or it went away before the end),
    2 bad options or credentials, 4 an agent process failed, 130/143 stopped.

    Example: swarm host --credentials host-a.cred (a file written on the world's machine by
    `swarm credentials --host a --agents 3-5 --endpoint tls/10.0.0.5:7447 -o host-a.cred`)
    """
    # lazy: the agent host's modules (router, forks, supervision: ~10 ms), which `swarm --help` must not pay
    from swarm.runtime.host import HostConfig, run_host

    try:
        ids = parse_ids(agents) if agents is not None else None
    except CredentialsError as e:
        raise fail(str(e), ExitCode.USAGE) from None
    raise typer.Exit(
        run_host(
            HostConfig(
                connect=connect,
                agents=ids,
                creds_file=credentials,
                run=run,
                name=name,
                listen=listen,
                logs=logs,
                world_grace=world_grace,
                trust=tuple(trust_law or ()),
                wait=wait,
            )
        )
    )


def register(app: typer.Typer) -> None:
    app.command("host")(host)
