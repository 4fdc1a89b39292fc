"""The options and arguments several commands share, declared once as `Annotated` types, and
the checks of their values (one line naming the option, exit 2). Command modules import
these; they never import each other."""

from __future__ import annotations

import secrets
import socket
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Optional

import typer

from swarm.api.live import ENV_CONNECT, ENV_RUN
from swarm.cli.errors import fail
from swarm.contracts.identities import CredentialsError
from swarm.contracts.runtime_dir import runtime_dir
from swarm.contracts.vocabulary import ExitCode

if TYPE_CHECKING:  # the scenario model (pydantic) is imported by the commands that read one:
    from swarm.contracts.scenario import Scenario  # live commands start without it (~0.13 s)

ConnectOpt = Annotated[
    Optional[str],
    typer.Option(
        "--connect",
        envvar=ENV_CONNECT,
        help="endpoint of the run, e.g. tcp/HOST:7447 or unixsock-stream/PATH "
        "(default: $SWARM_CONNECT, else local runs in $SWARM_RUNTIME_DIR or /tmp/swarm-<uid>)",
        show_default=False,
    ),
]
LiveRunOpt = Annotated[
    Optional[str],
    typer.Option(
        "--run",
        envvar=ENV_RUN,
        help="run id (default: $SWARM_RUN, else the only live run found; several runs up: `export SWARM_RUN=ID` once)",
        show_default=False,
    ),
]
RunOpt = Annotated[
    Optional[str],
    typer.Option(  # commands that are not live ones: no default from the environment
        "--run", help="run id (default: the only live run found)", show_default=False
    ),
]
JsonOpt = Annotated[bool, typer.Option("--json", help="machine-readable JSON (see docs/reference/cli.md)")]
CredentialsOpt = Annotated[
    Optional[Path],
    typer.Option(
        "--credentials",
        metavar="FILE",
        help="the run's credentials (default: $SWARM_CREDENTIALS, else the "
        "local run's own file); for a run on another machine, a file from `swarm credentials`",
        show_default=False,
    ),
]
TrustLawOpt = Annotated[
    Optional[list[str]],
    typer.Option(
        "--trust-law",
        metavar="MODULE:FUNCTION",
        help="a follower law of your own the agent may import if the run uses it (repeatable; built-in laws "
        "need nothing)",
    ),
]


def console(err: bool = False):
    # lazy: rich costs ~14 ms; a live command that prints JSON or finds no run needs none
    from rich.console import Console

    stream = sys.stderr if err else sys.stdout
    return Console(file=stream, width=None if stream.isatty() else 160, highlight=False)


ScenarioArg = Annotated[
    Path, typer.Argument(help="scenario file (TOML), e.g. scenarios/case2.toml", show_default=False)
]


def read_scenario(path: Path) -> Scenario:
    """`swarm.load(path)`: a bad file raises ScenarioError, its message and exit 2 (swarm/cli/errors.py)."""
    from swarm.api.scenario import load  # lazy: the scenario model (pydantic, ~90 ms): live commands import this module

    return load(path)


def out_option(help: str):
    return Annotated[Optional[Path], typer.Option("--out", "-o", help=help)]


SimOutOpt = out_option(
    "output directory (default runs/<scenario>-sim-<time>-<random>); one that "
    "already holds results is refused unless --force"
)
WorldOutOpt = out_option(
    "where to write the results (default: nowhere); one that already holds results is refused unless --force"
)
ForceOpt = Annotated[bool, typer.Option("--force", help="replace the results already in --out")]
# (no range of typer's: the scenario's own checks say what is wrong with any value, check_duration)
DurationOpt = Annotated[Optional[float], typer.Option(help="simulated seconds (default: the scenario's run.duration)")]
ClockOpt = Annotated[Optional[str], typer.Option(help="lockstep | realtime (default: the scenario's)")]
TimeScaleOpt = Annotated[
    float, typer.Option("--time-scale", "--speed", help="realtime clock: simulated seconds per wall second", min=1e-6)
]
EndPlotsOpt = Annotated[bool, typer.Option(help="render PNG plots at the end")]
FoxgloveOpt = Annotated[
    bool,
    typer.Option(
        "--foxglove",
        help="serve the run live to the Foxglove app "
        "(WebSocket, ws://HOST:PORT; `--foxglove PORT` for another port "
        "than 8765; docs/reference/outputs.md#foxglove)",
    ),
]
FoxglovePortOpt = Annotated[
    int,
    typer.Option("--foxglove-port", help="--foxglove: the port (`--foxglove PORT` says the same)", min=1, max=65535),
]
FoxgloveHostOpt = Annotated[
    str,
    typer.Option(
        "--foxglove-host",
        help="--foxglove: the address to bind (0.0.0.0: every interface, anyone who can reach it sees the run)",
    ),
]


def default_out(scenario_path: Path, kind: str) -> Path:
    """A new directory under runs/: the time and a random part, so two runs never share one."""
    return Path("runs") / f"{scenario_path.stem}-{kind}-{time.strftime('%Y%m%d-%H%M%S')}-{secrets.token_hex(3)}"


def claim_out(out: Path, force: bool) -> None:
    # lazy: swarm.offline.results brings numpy and the recording (~0.14 s): live commands import this module
    from swarm.offline.results import OutDirError, claim_out_dir

    try:
        claim_out_dir(out, force)
    except OutDirError as e:
        raise fail(str(e), ExitCode.USAGE) from None


def check_duration(s, duration: float | None, path: Path) -> None:
    """--duration goes through the scenario's own checks (positive, finite, at least one
    step, a recording that fits in memory): one line naming the option and its value, as
    typer's range errors are said (swarm/cli/errors.py), exit 2."""
    if duration is None:
        return
    # lazy: the scenario model (pydantic, ~90 ms): live commands import this module
    from swarm.contracts.scenario import ScenarioError, parse_scenario

    try:
        parse_scenario(
            {**s.model_dump(), "run": {**s.run.model_dump(), "duration": duration}},
            f"{path} with --duration {duration:g}",
        )
    except ScenarioError as e:
        why = []
        for line in str(e).splitlines()[1:]:
            line = line.strip().removeprefix("run.duration: ")
            why.append(line[len("Input ") :] if line.startswith("Input should be ") else line)
        raise fail(f"--duration {duration:g}: {'; '.join(why)} ({path})", ExitCode.USAGE) from None


def check_runtime_dir() -> None:
    """The runtime dir (sockets, credentials) must be the user's own: one line, exit 2."""
    try:
        runtime_dir()
    except CredentialsError as e:
        raise fail(f"swarm: {e}", ExitCode.USAGE) from None


def check_clock(clock: str | None) -> None:
    if clock is not None and clock not in ("lockstep", "realtime"):
        raise fail(f"--clock must be lockstep or realtime, not {clock!r}", ExitCode.USAGE)


def check_foxglove(host: str, port: int) -> None:
    """The --foxglove port must be free to bind: one line naming the option, exit 2 (the
    world checks again when it binds, world/live_view.py)."""
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
        with socket.socket(infos[0][0], socket.SOCK_STREAM) as so:
            so.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            so.bind(infos[0][4])
    except OSError as e:
        raise fail(f"--foxglove: cannot serve on {host}:{port}: {e.strerror or e}", ExitCode.USAGE) from None
